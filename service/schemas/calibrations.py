"""Bodies of ``/v1/calibrations``: measured data in, the calibration report out."""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated, Any

from pydantic import BeforeValidator, ConfigDict, Field, create_model

from microbearing import physics
from microbearing.calibrate.report import MIN_ROWS

from . import examples
from .base import (
    NEXT_URL,
    UNIT_KEYS,
    ColumnKeys,
    Convention,
    ConventionName,
    DateTimeText,
    ResponseModel,
    StrictModel,
    WholeNumber,
    parameter_fields,
)

__all__ = ["FITTABLE_PARAMETERS", "MODEL_FIELDS", "MODEL_PATTERN", "MODEL_RESPONSE_FIELDS",
           "CalibrationFixed", "CalibrationList", "CalibrationRequest", "CalibrationResult",
           "CalibrationSummary", "FittableParameterName"]

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
def _one_value(value: Any) -> Any:
    """A condition of one point is one value: ``[v]`` is v; a longer list, a range or a flag refused in one
    sentence (not each member's of the union: "a valid number; a valid string")."""
    if isinstance(value, list) and len(value) == 1:
        return value[0]
    if isinstance(value, list):
        raise ValueError(f"one value for one point, not a list of {len(value)}: several points go to "
                         f"/v1/friction/batch")
    if isinstance(value, dict):
        raise ValueError("one value for one point, not a range: a design over a range of conditions is "
                         "/v1/optimizations' envelope")
    if isinstance(value, bool) or value is None:
        raise ValueError(f"must be a number, or a factor column's group label; not "
                         f"{'null' if value is None else str(value).lower()}")
    return value


#: A condition's value at one point (a number, or a factor column's group label).
_OneCondition = Annotated[float | str, BeforeValidator(_one_value)]

MODEL_FIELDS: dict[str, Any] = {
    "model": (str, Field(default="physics", pattern=MODEL_PATTERN, description=(
        "'physics' (the declared model) or 'calibrated:<id>' from /v1/calibrations: its fixed and fitted "
        "parameters replace the defaults, its convention is used and its effect is added to mu."))),
    "conditions": (Annotated[dict[str, _OneCondition] | None, ColumnKeys], Field(default=None, description=(
        "Condition columns of the calibration data, e.g. relative_humidity [1] [unit of each column as in "
        "the calibration data]; those the calibrated model's terms read are required, a column the "
        "calibration never saw is refused (422 naming it). A factor column takes a group label (e.g. "
        "\"specimen\": \"S3\"): a known group is predicted at its own level, a new label (or none) "
        "carries the spread between groups in the interval." + UNIT_KEYS))),
}

#: Response fields added when a calibrated model answers.
MODEL_RESPONSE_FIELDS: dict[str, Any] = {
    "model": (str | None, Field(default=None, description="The calibrated model used (absent for physics).")),
    "mu_effect": (float | None, Field(default=None, description=(
        "Share of mu due to the calibrated model's added terms [1]; friction_force_N is the force at the "
        "model's mu (mu x load_N), the other outputs are the declared model's with the fitted parameters "
        "(absent for physics)."))),
    "mu_lower": (float | None, Field(default=None, description=(
        "Lower bound of the 95 % prediction interval of a measurement of mu at this point [1]: parameter "
        "uncertainty, what the calibrated terms leave unexplained and the noise (absent for physics and for "
        "models calibrated before intervals existed)."))),
    "mu_upper": (float | None, Field(default=None, description=(
        "Upper bound of the same 95 % prediction interval [1]."))),
    "in_domain": (bool | None, Field(default=None, description=(
        "Whether the point lies within the range of every column of the calibration data and within the "
        "joint cloud of its rows (false: the answer is an extrapolation, and the interval is widened; "
        "domain_warnings says where)."))),
    "domain_warnings": (list[str] | None, Field(default=None, description=(
        "One sentence per input or condition outside the calibration data, naming the column, the value "
        "and the range."))),
}

_ROW_DESCRIPTION = (
    "One measurement: physics inputs by name in their units (see /v1/parameters), or with another unit in "
    "the name, converted to SI (speed [mm/s], load (mN), load [g] for a slider mass, speed_mm_s, "
    "ball_diameter [um]), mu_measured [1] > 0, optionally mu_measured_std [1] > 0, and any other numeric "
    "columns describing the conditions (e.g. relative_humidity [1], temperature_C [degC], cycle [1]; with a "
    "unit in brackets converted to SI: relative_humidity [%] -> relative_humidity [1], temperature [degC] -> "
    "temperature_K); every row gives the same columns. A column of text labels (e.g. specimen: S1, S2, ...) "
    "is a factor: its groups' spread is fitted as a random effect."
)


class CalibrationRequest(StrictModel):
    """Measured data and what to fit.

    Column names may carry units, converted to SI (``speed [mm/s]``, ``load (mN)``, ``speed_mm_s``,
    ``load [g]`` for a slider mass, ``relative humidity [%]``); the report's ``intake`` lists each
    conversion.
    """

    model_config = ConfigDict(**StrictModel.model_config,
                              json_schema_extra={"examples": [examples.CALIBRATION_UNITS]})

    # At least MIN_ROWS rows (more for nested cross-validation with many folds or fitted parameters:
    # the server's 422 says how many), checked by the calibration with its own message.
    data: list[dict[str, float | bool | str]] = Field(min_length=1, description=_ROW_DESCRIPTION,
                                                      json_schema_extra={"minItems": MIN_ROWS})
    factors: list[str] = Field(default_factory=list, max_length=20, description=(
        "Condition columns to read as group labels (factors) even when they hold numbers, e.g. integer "
        "codes of specimens; a column with no number in it is a factor anyway."))
    ignore: list[str] = Field(default_factory=list, max_length=100, description=(
        "Columns to leave out, as sent or by the name they are read as, e.g. a comment, or an operator "
        "column that should not become groups."))
    fit_parameters: list[FittableParameterName] = Field(  # type: ignore[valid-type]
        default_factory=list, max_length=len(FITTABLE_PARAMETERS),
        description="Declared physics parameters to fit, e.g. mu_pivot, adhesion_energy_J_m2; none by "
                    "default (the declared parameters keep their defaults; the report's intake.fitting "
                    "says so).")
    fixed: CalibrationFixed = Field(  # type: ignore[valid-type]
        default_factory=CalibrationFixed, description="Physics inputs fixed for every row.")
    folds: WholeNumber = Field(default=5, ge=2, le=20, description=(
        "Cross-validation folds [1]; when not given, 5, or half the rows when there are fewer than 10."))
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
    """A term added to the model: an effect, or a declared parameter drifting with a condition."""

    kind: str | None = Field(default=None, description="'effect' or 'drift' (null for calibrations stored "
                                                       "before drifts existed: an effect).")
    label: str | None = Field(default=None, description="The term in a few words.")
    label_as_sent: str | None = Field(default=None, description=(
        "The same with each column named by the header the upload sent it under (thermal_shear_strength "
        "on temperature [degF]); null for calibrations stored before."))
    parameter: str | None = Field(default=None, description="The drifting physics parameter (drift only).")
    law: str | None = Field(default=None, description="The drift law: linear, arrhenius or kelvin (drift "
                                                      "only).")
    name: str = Field(description="Effect name (physics.effects.EFFECTS), or parameter~law for a drift.")
    title: str = Field(description="What the effect is.")
    drivers: list[str] = Field(description="Driving columns, main driver first.")
    formula: str = Field(description="Corrected mu in terms of the declared model's mu_model.")
    parameters: dict[str, float] = Field(description="Fitted parameters [units in parameter_units].")
    parameter_std: dict[str, float] = Field(description="Their standard deviations [same units].")
    parameter_units: dict[str, str] = Field(description="Unit of each parameter.")
    constants: dict[str, float] = Field(description="Constants fixed from the data [unit of the driver].")
    reference: str = Field(description="Source of the effect's physics.")
    level_fitted: bool | None = Field(default=None, description=(
        "Drift only: whether the parameter's level at the reference condition (<parameter>_ref, in its "
        "unit) was fitted with the law's coefficient, as it is for a parameter neither fitted nor fixed "
        "(null for other terms and for calibrations stored before levels were fitted)."))


class GPDiscrepancy(ResponseModel):
    """Gaussian-process discrepancy baseline (Kennedy-O'Hagan) on the log residual."""

    errors: ErrorFigures = Field(description="Held-out errors of the declared model plus the GP.")
    features: list[str] = Field(description="Columns the GP uses.")
    length_scales: dict[str, float] = Field(
        description="Fitted RBF length scale per column [standard deviations of the column]; "
                    "short = relevant.")
    noise_std_log: float | None = Field(description="Fitted noise standard deviation of log mu [1].")
    max_train_rows: int = Field(description="Most training rows per fold [1].")
    calibrated_errors: ErrorFigures | None = Field(default=None, description=(
        "Held-out errors (nested CV, outliers left out) of the calibrated model corrected by a GP on what "
        "its terms leave; null for calibrations stored before it."))
    calibrated_errors_without: ErrorFigures | None = Field(default=None, description=(
        "The same rows' held-out errors of the calibrated model without that GP."))
    calibrated_z: float | None = Field(default=None, description=(
        "Paired z of the decrease of the squared held-out log error by that GP [1]."))
    in_model: bool | None = Field(default=None, description=(
        "Whether that GP is part of the calibrated model (it beat the terms alone held out, one-sided "
        "1 % test, both in nested CV and on the chosen terms refitted on each fold): its mean then "
        "corrects mu and its predictive std widens mu_lower/mu_upper."))
    chosen_terms_z: float | None = Field(default=None, description=(
        "Paired z of that GP's gain on the held-out rows of the chosen terms refitted on each outer fold "
        "[1]; null when the nested test did not pass (or for calibrations stored before this test)."))
    rows_for_gp: int | None = Field(default=None, description=(
        "Rows that could weigh that GP's hyperparameters (an amplitude, a length scale per column, the white "
        "noise; counted like a term's fitted values) [1], when its nested test passed on fewer rows: it was "
        "held back and the intervals keep the held-out scatter; null otherwise."))
    clipped_rows: int | None = Field(default=None, description=(
        "Rows clipped at a sensor's limit, when that GP's nested test passed on data with any [1]: it was "
        "held back (beside a clip the measured rows are a truncated sample, which a GP would learn as an "
        "effect; the terms take the censored likelihood); null otherwise."))


class FoldChoice(ResponseModel):
    """What the effect search chose on one fold's training rows."""

    effect: str | None = Field(description="Effect name; null when nothing was added.")
    drivers: list[str] = Field(description="Driving columns, main driver first (empty if nothing was added).")
    terms: list[str] | None = Field(default=None, description="Every term the fold added, in order.")


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
    """Score of one candidate term (cross-validated for a joint refit, in-sample for a screening)."""

    effect: str | None = Field(description="Effect name (parameter~law for a drift); null for the current "
                                           "model.")
    kind: str | None = Field(default=None, description="'effect' or 'drift'; null for the current model.")
    label: str | None = Field(default=None, description="The candidate in a few words.")
    cv_robust_loss: float | None = Field(default=None, description="Mean Huber loss of the (weighted) log "
                                                                    "residual [1].")
    drivers: list[str] = Field(description="Driving columns.")
    n_parameters: int = Field(description="Fitted parameters, declared and effect's [1].")
    cv_rmse_log: float = Field(description="Held-out RMS of the (weighted) log residual [1].")
    score: float = Field(description="n log(CV MSE) + n_parameters log(n); lower is better [1].")
    z_vs_declared: float = Field(
        description="Paired z of the held-out improvement over the declared model [1].")
    joint_refit: bool = Field(description="Refitted jointly with the declared parameters (else screened).")


class OutlierRow(ResponseModel):
    """A measurement the robust fit treats as a gross outlier."""

    row: int = Field(description="Data row, 1 = the first row after the header [1].")
    mu_measured: float = Field(description="Measured mu [1].")
    mu_predicted: float = Field(description="The calibrated model's mu [1].")
    standardized_residual: float = Field(description="log(measured / predicted) in robust standard "
                                                     "deviations; "
                                                     "> 0 when measured above the model [1].")


class Outliers(ResponseModel):
    """Rows down-weighted as gross outliers."""

    count: int = Field(description="Outlier rows [1].")
    threshold: float = Field(description="Standardized residual beyond which a row is an outlier [1].")
    rows: list[OutlierRow] = Field(description="The outliers, largest first (at most 200 listed).")
    summary: str = Field(description="The same in words.")


class NoiseTest(ResponseModel):
    """The final model's residual against the declared mu_measured_std."""

    chi2_p_value: float = Field(description="Chi-square p-value of the standardized residual (outliers left "
                                            "out) [1].")
    declared_noise: float = Field(description="Median declared relative noise of mu [1].")
    unexplained_scatter: float = Field(description="Relative scatter of mu the model leaves [1].")
    statement: str = Field(description="The comparison in words.")


class SelectionStep(ResponseModel):
    """One step of forward selection."""

    added: str | None = Field(description="The term added; null for the step that stopped the search.")
    errors: ErrorFigures = Field(description="Held-out errors after the step, on the rows searched.")
    z: float | None = Field(description="Paired z of the added term's improvement [1].")
    z_needed: float = Field(description="Paired z a candidate had to exceed [1].")
    candidates: list[CandidateSummary] = Field(description="The current model, then the best candidates.")
    reason: str = Field(description="Why the term was added or the search stopped.")


class RobustErrors(ResponseModel):
    """Held-out errors without the outlier rows."""

    before: ErrorFigures = Field(description="As error_before, outliers left out.")
    after: ErrorFigures = Field(description="As error_after, outliers left out.")
    excluded_rows: int = Field(description="Outlier rows left out [1].")


class Intake(ResponseModel):
    """How the measured data were read: the dialect of a CSV file and every column's unit conversion."""

    format: str = Field(description="'csv' (POST /v1/calibrations/csv) or 'json' (rows).")
    separator: str | None = Field(default=None, description="comma, semicolon or tab (null for JSON).")
    decimal: str | None = Field(default=None, description="Decimal mark: point or comma (null for JSON).")
    detected: list[str] = Field(description="Which of separator and decimal were detected; the others were "
                                            "stated by query parameters or by the file's sep= line.")
    encoding: str | None = Field(default=None, description=(
        "UTF-8, UTF-8 with BOM, UTF-16 with BOM, or Windows-1252 for a file that is not UTF-8 (null for "
        "JSON)."))
    line_endings: str | None = Field(default=None, description="LF, CRLF or CR (null for JSON).")
    ignored: list[str] = Field(description="What was ignored, e.g. '2 blank lines at the end', '1 empty "
                                           "column at the end', 'column D (operator), as ignore asks'.")
    conversions: list[str] = Field(description="Each unit conversion in words, e.g. 'speed [mm/s] read as "
                                               "speed_m_s / 1000'.")
    columns: dict[str, str] = Field(description="Every column read, as sent -> its name in the data (SI).")
    header_line: int | None = Field(default=None, description=(
        "The file's line of the header row [1]: 1, or 2 after Excel's sep= line; problems name file lines "
        "(null for JSON)."))
    notes: list[str] = Field(default_factory=list, description=(
        "How the file was read where it is not plain, in words: Excel's sep= line, an encoding other "
        "than UTF-8 ('not UTF-8: read as Windows-1252 ...'), a multipart upload."))
    text_columns: dict[str, str] = Field(default_factory=dict, description=(
        "Each column with text in its cells (as sent) -> what it became, e.g. 'random-effect groups (3 "
        "levels)'; leave one out with ignore."))
    fitting: str | None = Field(default=None, description=(
        "What the calibration fits, in words: the parameters named in fit_parameters, or, when none is "
        "named, that the declared parameters keep their defaults and only the added terms are fitted."))


class CsvReading(ResponseModel):
    """How ``POST /v1/calibrations/csv`` reads a file, before any fit: what the calibration would take."""

    rows: int = Field(description="Data rows read [1].")
    columns: list[str] = Field(description="The data's columns, by their names in SI: physics inputs, "
                                           "conditions and factors (groups).")
    factors: list[str] = Field(description="Columns read as group labels (text, or declared in factors).")
    fixed: dict[str, float] = Field(description="Physics inputs fixed for every row, in SI.")
    intake: Intake = Field(description="The dialect, what was ignored, each unit conversion and column.")


class RivalPart(ResponseModel):
    """Where a rival and the calibrated model differ, over one driver."""

    driver: str = Field(description="The data column scanned (in the data's units).")
    data_range: list[float] = Field(description="[min, max] of the column in the data [unit of the column].")
    differ: list[list[float]] = Field(description=(
        "[lo, hi] runs of the column's values [unit of the column] (scanned over the data's range and as "
        "much again on either side) where the two differ by more than two standard deviations of a "
        "measurement's log mu."))
    largest_difference_log: float | None = Field(description=(
        "Largest median |log(mu_rival / mu_model)| scanned [1]."))
    at: float | None = Field(description="Where it is largest [unit of the column].")
    unit: str | None = Field(default=None, description=(
        "The unit of the numbers above: the column's own (m/s, K, 1 for a humidity fraction); null for a "
        "column without one (a run index)."))
    as_sent: RivalPart | None = Field(default=None, description=(
        "The same under the header the upload used and in its unit (speed [mm/s], RH [%], degF), its "
        "unit as written there; null when the column was sent in its own unit."))


class Rival(ResponseModel):
    """A term that fits the data about as well as a chosen one, kept in the model's intervals."""

    label: str = Field(description="'<rival term> instead of <chosen term>'.")
    label_as_sent: str | None = Field(default=None, description=(
        "The same with each column named by the header the upload sent it under; null for calibrations "
        "stored before."))
    gap_se: float = Field(description=(
        "Its mean held-out loss minus the chosen term's, in standard errors of the paired difference [1]."))
    where: list[RivalPart] = Field(description="Where it parts from the calibrated model, per driver.")
    statement: str = Field(description="The same in words.")


class Undecided(ResponseModel):
    """Something the data leave open, and roughly where more rows would settle it."""

    kind: str = Field(description=(
        "near_threshold (a candidate just short of the selection's threshold), barely_chosen (a term added "
        "just above it, or by few outer folds), rivals (terms that fit about as well and part ways) or "
        "few_rows (the rows support fewer terms than the search may add: no further effect is claimed, "
        "rows_to_settle says how many rows would let it weigh one more, and terms names the candidates the "
        "rows lean to, held as rivals in the intervals)."))
    terms: list[str] = Field(description="The terms concerned.")
    z: float | None = Field(default=None, description="Held-out paired z of the term [1].")
    z_needed: float | None = Field(default=None, description="The step's threshold [1].")
    rows_now: int = Field(description="Rows the selection searched [1].")
    rows_to_settle: int | None = Field(default=None, description=(
        "Rows drawn like these that would carry z over the threshold, n (z_needed / z)^2 [1]; fewer if "
        "placed where the term acts."))
    where: Any = Field(default=None, description=(
        "Where new rows would tell the answers apart: {driver, range, data_range, unit, as_sent} [unit "
        "of the driver, named by unit; as_sent the same under the upload's header and in its unit], or for "
        "rivals the list of their RivalPart scans."))
    statement: str = Field(description="The same in words.")


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
        description="The first term added; null when only noise remains.")
    effects: list[MissingEffect] | None = Field(default=None, description=(
        "Every term added by forward selection, in order (null for calibrations stored before it)."))
    steps: list[SelectionStep] | None = Field(default=None, description="Forward selection step by step.")
    robust_errors: RobustErrors | None = Field(default=None, description="Held-out errors without outliers.")
    outliers: Outliers | None = Field(default=None, description="Rows treated as gross outliers.")
    noise: NoiseTest | None = Field(default=None, description=(
        "Chi-square test against mu_measured_std; null without that column."))
    warnings: list[str] | None = Field(default=None, description=(
        "Declared parameters that moved beyond their interval when terms were added or sit on a bound, and a "
        "GP discrepancy that predicts better than the terms."))
    discrepancy_gp: GPDiscrepancy = Field(description="The GP discrepancy baseline.")
    candidates: list[CandidateSummary] = Field(description="Every candidate's score, declared model first.")
    decision: str = Field(description="Why the effect was chosen or nothing was added.")
    folds: int = Field(description="Cross-validation folds [1].")
    model: dict[str, Any] = Field(description="The calibrated model as JSON data.")
    intake: Intake | None = Field(default=None, description=(
        "How the data were read: separator, decimal mark, what was ignored, unit conversions (null for "
        "calibrations stored before it)."))
    groups: list[dict[str, Any]] | None = Field(default=None, description=(
        "Per factor column: the declared parameter (or mu) that varies between groups, spread_relative [1] "
        "(standard deviation of its log) with its 95 % profile-likelihood interval spread_interval_relative "
        "[1] and its upper 95 % confidence bound spread_upper_relative [1] (Q-profile; a new group's "
        "interval carries the spread at that bound when it is wider than Student's t gives, so that it "
        "holds at least 90 % of a new group's measurements in 95 % of data sets), "
        "within_group_scatter_relative [1], each group's relative_shift [1], the restricted "
        "log-likelihood [1] of the random effect on each candidate parameter (the highest carries the "
        "spread), and summary in words."))
    scatter: dict[str, Any] | None = Field(default=None, description=(
        "The scatter model of a new measurement (kind constant, step or loglinear in one column or its log, "
        "chosen by cross-validation; coefficients are logs of the standard deviation of log mu [1]; rows: a "
        "step's rows on each side [1]; covariance: a log-linear trend's inverse Fisher information [1]: "
        "the interval takes Student's t of the degrees of freedom they give; form: the degrees of freedom of "
        "one spread everywhere [1] and the heavy-tail factor on the half-width [1], with the fitted Student "
        "t's tail_dof [1] when the residuals are heavy-tailed), with summary in words, e.g. "
        "'scatter 10 % below speed_m_s = 0.02 [m/s], 1.5 % above'."))
    confounding: list[str] | None = Field(default=None, description=(
        "Columns that move together in the data (their effects cannot be told apart) and what would "
        "separate them; chosen terms whose driver may stand for another."))
    domain: dict[str, Any] | None = Field(default=None, description=(
        "The domain rule: columns of the data cloud, alpha [1] (share of points like the data flagged), "
        "summary in words, and as_sent: each column's range in the data under the header the upload sent "
        "it under, in that unit ({\"load [mN]\": {\"column\": \"load_N\", \"range\": [3, 30], \"unit\": "
        "\"mN\"}}; a column sent in its own unit under its name, in that unit)."))
    measurement_system: dict[str, Any] | None = Field(default=None, description=(
        "What the data say about the measurement system: replicates (design points, pure_error_relative [1] "
        "of log mu between replicates, the lack-of-fit F-test: f [1], p [1], rows left out of it as outliers "
        "or clipped: outliers_left_out [1], clipped_left_out [1]; null without replicates), "
        "saturation (clips: side, level [1], rows [1], share [1]; their rows censored), unit_slips (rows "
        "of one column a unit's factor off the others, left out of the fit: column as sent, factor [1], "
        "below, rows 1-based, share [1], gap [1], summary), constant (the one "
        "value of mu when every row reads it, else null), sessions (order and time columns, candidate "
        "drivers of measurement_drift and measurement_step), clock (columns read from ISO 8601 times as "
        "hours since their start), drift (the instrument's drift over the session, or its step and where, "
        "in words) and summary (sentences); null for calibrations stored before it."))
    plots: dict[str, str] = Field(description=(
        "Plots: name -> URL of the PNG (effect_<k>: the k-th term against its driver with its 95 % band; "
        "residuals: against every input, before and after; measured_vs_predicted)."))
    rivals: list[Rival] | None = Field(default=None, description=(
        "Terms that fit the data about as well as a chosen one (within two standard errors of held-out "
        "loss): the 95 % intervals of /v1/friction, /v1/friction/batch and optimizations hold the envelope "
        "of the model's and the rivals' intervals; null for calibrations stored before rivals."))
    undecided: list[Undecided] | None = Field(default=None, description=(
        "What the data cannot decide (a candidate close to the threshold, a term added barely, rivals) "
        "and roughly where more rows would settle it; null for calibrations stored before."))


class CalibrationSummary(ResponseModel):
    """A stored calibration in a list: what it is and where its report is."""

    id: str = Field(description="Calibration id.")
    model_id: str = Field(description="Model id for /v1/friction and optimization: calibrated:<id>.")
    name: str = Field(description="A label: the number of points and the terms added.")
    created_at: DateTimeText = Field(description="When it was stored (ISO 8601, UTC).")
    n_points: int = Field(description="Measurements used [1].")
    fit_parameters: list[str] = Field(description="Declared parameters fitted.")
    effects: list[str] = Field(description="Names of the terms added, in order (empty: none).")
    error_before: ErrorFigures = Field(description="Held-out errors of the fitted declared model.")
    error_after: ErrorFigures = Field(description="Held-out errors of the calibrated model (nested CV).")
    columns: list[str] = Field(description="Columns of the data (SI names): physics inputs and conditions.")
    url: str = Field(description="Path of the full report, /v1/calibrations/{id}.")


class CalibrationList(ResponseModel):
    """A page of the stored calibrations the caller sees, newest first."""

    calibrations: list[CalibrationSummary] = Field(
        description="The calibrations of this page (at most limit).")
    next_url: str | None = NEXT_URL
