"""Bodies of ``/v1/calibrations``: measured data in, the calibration report out."""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated, Any

from pydantic import Field, create_model

import physics

from .base import Convention, ConventionName, ResponseModel, StrictModel, parameter_fields

__all__ = ["FITTABLE_PARAMETERS", "MODEL_FIELDS", "MODEL_PATTERN", "MODEL_RESPONSE_FIELDS",
           "CalibrationFixed", "CalibrationRequest", "CalibrationResult", "FittableParameterName"]

#: Declared physics parameters a calibration may fit: the optional real-valued ones.
FITTABLE_PARAMETERS = [n for n, p in physics.PARAMETERS.items() if p.kind == "float" and not p.required]
FittableParameter = StrEnum("FittableParameter", {name: name for name in FITTABLE_PARAMETERS})
#: One of :data:`FITTABLE_PARAMETERS`.
FittableParameterName = Annotated[FittableParameter, Field(strict=False)]

CalibrationFixed = create_model(
    "CalibrationFixed", __base__=StrictModel,
    __doc__="Physics inputs fixed for every measurement (those that are not data columns).",
    **parameter_fields(optional=True),
)

#: A model reference: the plain physics or a stored calibration.
MODEL_PATTERN = r"^(physics|calibrated:[0-9a-f]{32})$"

#: Request fields choosing the model of /v1/friction, for ``create_model``.
MODEL_FIELDS: dict[str, Any] = {
    "model": (str, Field(default="physics", pattern=MODEL_PATTERN, description=(
        "'physics' (the declared model) or 'calibrated:<id>' from /v1/calibrations: its fixed and fitted "
        "parameters replace the defaults, its convention is used and its effect is added to mu."))),
    "conditions": (dict[str, float] | None, Field(default=None, description=(
        "Condition columns the calibrated model's effect reads, e.g. relative_humidity [1] "
        "[unit of each column as in the calibration data]."))),
}

#: Response fields added when a calibrated model answers.
MODEL_RESPONSE_FIELDS: dict[str, Any] = {
    "model": (str | None, Field(default=None, description="The calibrated model used (absent for physics).")),
    "mu_effect": (float | None, Field(default=None, description=(
        "Share of mu due to the calibrated model's added effect [1]; the other outputs are the declared "
        "model's with the fitted parameters (absent for physics)."))),
}

_ROW_DESCRIPTION = (
    "One measurement: physics inputs by name in their units (see /v1/meta), mu_measured [1] > 0, "
    "optionally mu_measured_std [1] > 0, and any other numeric columns describing the conditions "
    "(e.g. relative_humidity [1], temperature_C [degC], cycle [1]); every row gives the same columns."
)


class CalibrationRequest(StrictModel):
    """Measured data and what to fit."""

    data: list[dict[str, float | bool]] = Field(min_length=1, description=_ROW_DESCRIPTION)
    fit_parameters: list[FittableParameterName] = Field(  # type: ignore[valid-type]
        default_factory=list, max_length=len(FITTABLE_PARAMETERS),
        description="Declared physics parameters to fit, e.g. mu_pivot, adhesion_energy_J_m2.")
    fixed: CalibrationFixed = Field(  # type: ignore[valid-type]
        default_factory=CalibrationFixed, description="Physics inputs fixed for every row.")
    folds: int = Field(default=5, ge=2, le=20, description="Cross-validation folds [1].")
    convention: ConventionName = Field(  # type: ignore[valid-type]
        default=Convention(physics.DEFAULT_CONVENTION),
        description="Reading of the paper's ambiguous ball-ball terms.")


class ErrorFigures(ResponseModel):
    """Errors of predicted against measured μ."""

    rmse: float = Field(description="Root mean square error of mu [1].")
    relative_rmse: float = Field(description="Root mean square of log(predicted / measured mu) [1].")
    max_abs_error: float = Field(description="Largest absolute error of mu [1].")


class Estimate(ResponseModel):
    """A fitted value and its standard deviation from the Jacobian."""

    value: float = Field(description="Fitted value [unit of the parameter].")
    std: float = Field(description="Standard deviation [unit of the parameter].")


class MissingEffect(ResponseModel):
    """The effect added to the model."""

    name: str = Field(description="Effect name (physics.effects.EFFECTS).")
    title: str = Field(description="What the effect is.")
    drivers: list[str] = Field(description="Driving columns, main driver first.")
    formula: str = Field(description="Corrected mu in terms of the declared model's mu_model.")
    parameters: dict[str, float] = Field(description="Fitted parameters [units in parameter_units].")
    parameter_std: dict[str, float] = Field(description="Their standard deviations [same units].")
    parameter_units: dict[str, str] = Field(description="Unit of each parameter.")
    constants: dict[str, float] = Field(description="Constants fixed from the data [unit of the driver].")
    reference: str = Field(description="Source of the effect's physics.")


class GPDiscrepancy(ResponseModel):
    """Gaussian-process discrepancy baseline (Kennedy-O'Hagan) on the log residual."""

    errors: ErrorFigures = Field(description="Held-out errors of the declared model plus the GP.")
    features: list[str] = Field(description="Columns the GP uses.")
    length_scales: dict[str, float] = Field(
        description="Fitted RBF length scale per column [standard deviations of the column]; "
                    "short = relevant.")
    noise_std_log: float | None = Field(description="Fitted noise standard deviation of log mu [1].")
    max_train_rows: int = Field(description="Most training rows per fold [1].")


class FoldChoice(ResponseModel):
    """What the effect search chose on one fold's training rows."""

    effect: str | None = Field(description="Effect name; null when nothing was added.")
    drivers: list[str] = Field(description="Driving columns, main driver first (empty if nothing was added).")


class EffectStability(ResponseModel):
    """How often the search on each fold's training rows chose what it chose on all rows."""

    folds: int = Field(description="Outer folds of the nested cross-validation [1].")
    agreeing: int = Field(description="Folds that chose the same effect on the same drivers, or nothing "
                                      "when nothing was added [1].")
    same_driver: int = Field(description="Folds whose choice has the same main driver (any effect form), or "
                                         "that added nothing when nothing was added [1].")
    choices: list[FoldChoice] = Field(description="The choice of each fold.")
    summary: str = Field(description="The same in words, e.g. '5 of 5 outer folds chose humidity_meniscus on "
                                     "relative_humidity, as all rows did'.")


class CandidateSummary(ResponseModel):
    """Cross-validated score of one candidate effect."""

    effect: str | None = Field(description="Effect name; null for the declared model alone.")
    drivers: list[str] = Field(description="Driving columns.")
    n_parameters: int = Field(description="Fitted parameters, declared and effect's [1].")
    cv_rmse_log: float = Field(description="Held-out RMS of the (weighted) log residual [1].")
    score: float = Field(description="n log(CV MSE) + n_parameters log(n); lower is better [1].")
    z_vs_declared: float = Field(
        description="Paired z of the held-out improvement over the declared model [1].")
    joint_refit: bool = Field(description="Refitted jointly with the declared parameters (else screened).")


class CalibrationResult(ResponseModel):
    """The calibration report."""

    id: str = Field(description="Calibration id.")
    model_id: str = Field(description="Model id for /v1/friction and optimization: calibrated:<id>.")
    n_points: int = Field(description="Measurements used [1].")
    fit_parameters: list[str] = Field(description="Declared parameters fitted.")
    error_default: ErrorFigures = Field(description="In-sample errors of the declared model with defaults.")
    fitted_declared: dict[str, Estimate] = Field(description="Declared-only fit (the 'before' model).")
    fitted_parameters: dict[str, Estimate] = Field(description="Declared parameters of the calibrated model.")
    error_before: ErrorFigures = Field(description="Held-out (k-fold) errors of the fitted declared model.")
    error_after: ErrorFigures = Field(description=(
        "Held-out errors of the calibrated model by nested cross-validation: every fold predicted by the "
        "model that the whole procedure (declared fit, effect search, fit of the chosen effect) built on "
        "the other folds; equal to error_before when no fold added an effect."))
    error_after_selection: ErrorFigures | None = Field(default=None, description=(
        "Held-out errors of the chosen effect on the same folds that chose it among the candidates "
        "(error_before when nothing was added): optimistic by the selection; null for calibrations stored "
        "before nested cross-validation (their error_after is this figure)."))
    effect_stability: EffectStability | None = Field(default=None, description=(
        "How stable the effect search is across folds; null for calibrations stored before nested "
        "cross-validation."))
    missing_effect: MissingEffect | None = Field(
        description="The added effect; null when only noise remains.")
    discrepancy_gp: GPDiscrepancy = Field(description="The GP discrepancy baseline.")
    candidates: list[CandidateSummary] = Field(description="Every candidate's score, declared model first.")
    decision: str = Field(description="Why the effect was chosen or nothing was added.")
    folds: int = Field(description="Cross-validation folds [1].")
    model: dict[str, Any] = Field(description="The calibrated model as JSON data.")
    plots: dict[str, str] = Field(description="Residual plots: name -> URL of the PNG.")
