"""Bodies of ``/v1/surrogates``: a space and a budget in, a Gaussian-process surrogate out."""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated, Any, ClassVar

from pydantic import BeforeValidator, ConfigDict, Field, create_model

import microbearing.surrogate.sampling  # noqa: F401  (loads the submodule)
from microbearing import physics, surrogate

from .base import (
    NEXT_URL,
    REQUIRED_INPUTS,
    UNIT_KEYS,
    ColumnKeys,
    Convention,
    ConventionName,
    DateTimeText,
    PairSpelling,
    ResponseModel,
    StrictModel,
    WholeNumber,
    given_at,
    in_one_place,
    only_with_model,
    parameter_description,
    parameter_fields,
    parameter_type,
)
from .calibrations import MODEL_PATTERN
from .friction import INPUT_KEYS, InputKeys

__all__ = ["MAX_BUDGET", "MAX_VALIDATION_POINTS", "SamplingDesignName", "PredictRequest", "PredictResponse",
           "SensitivityResponse", "SurrogateList", "SurrogateMetrics", "SurrogateRequest", "SurrogateResult",
           "SurrogateSpace"]

#: Most physics evaluations one surrogate may use: GP fitting grows as budget³.
MAX_BUDGET = 1000
#: Most validation evaluations one surrogate may ask for (each costs one evaluation and one prediction).
MAX_VALIDATION_POINTS = 4096

# Named SamplingDesign, not Design: a generated client has one namespace of models, and the bearing
# design of an optimization result is BearingDesign.
SamplingDesign = StrEnum("SamplingDesign", {name: name for name in surrogate.sampling.DESIGNS})
#: One of :data:`surrogate.sampling.DESIGNS`.
SamplingDesignName = Annotated[SamplingDesign, Field(strict=False)]


def _bounds_field(name: str) -> tuple[Any, Any]:
    spec = physics.PARAMETERS[name]
    pair = "[false, true]" if spec.kind == "bool" else "[lower, upper] with lower < upper"
    scalar = parameter_type(spec)
    return (Annotated[list[scalar] | None, PairSpelling],
            Field(default=None, min_length=2, max_length=2,
                  description=f"Range as {pair} (or {{low, high}}). {parameter_description(spec)}"))


def _one_condition(value: Any) -> Any:
    """A condition of a surrogate is one number: a range or a group label said in one sentence."""
    if isinstance(value, list | dict):
        raise ValueError("a surrogate is trained at one value each of its conditions, not over a range (its "
                         "space holds physics inputs)")
    if isinstance(value, str):
        raise ValueError("a group label is no condition of a surrogate: it is trained for a new group (the "
                         "spread between groups in its interval); leave it out")
    return value


SurrogateSpace = create_model(
    "SurrogateSpace", __base__=InputKeys,
    __doc__="The dimensions of the surrogate: physics inputs with their ranges (at least one).",
    **{name: _bounds_field(name) for name in physics.PARAMETERS},
)

SurrogateFixed = create_model(
    "SurrogateFixed", __base__=InputKeys,
    __doc__="Values of physics inputs that are not dimensions (others take their defaults).",
    **parameter_fields(optional=True),
)


class SurrogateRequest(StrictModel):
    """What to learn and how many physics evaluations it may cost."""

    # What the server checks across fields: at least one dimension; balls, load_N and speed_m_s each
    # a dimension or fixed, not both (a calibrated model may hold them itself); conditions only for a
    # calibrated model. (It also refuses an optional input both a dimension and fixed; the schema
    # leaves that out, to stay simple for generators of test data.)
    model_config = ConfigDict(**StrictModel.model_config, json_schema_extra={"allOf": [
        {"anyOf": [given_at(("space", name), {"type": "array"}) for name in physics.PARAMETERS]},
        *({"anyOf": [*in_one_place((("fixed", name), None), (("space", name), {"type": "array"}))["anyOf"],
                     given_at(("model",), {"pattern": "^calibrated:"})]} for name in REQUIRED_INPUTS),
        only_with_model("conditions")]})

    space: SurrogateSpace = Field(  # type: ignore[valid-type]
        description="Dimensions and their ranges, e.g. {\"balls\": [3, 40], \"load_N\": [0.001, 0.05]}.")
    fixed: SurrogateFixed = Field(  # type: ignore[valid-type]
        default_factory=SurrogateFixed,
        description="Inputs held fixed; balls, load_N and speed_m_s must be a dimension or fixed (for a "
                    "calibrated model, the values its calibration fixed count as fixed unless given here).")
    budget: WholeNumber = Field(default=100, ge=2, le=MAX_BUDGET,
                        description="Most physics evaluations for training [1].")
    target_relative_error: float = Field(
        default=0.001, gt=0, le=1,
        description="Stop adding evaluations once the estimated median relative error of mu is at most "
                    "this and its 95th percentile at most 5 times this [1].")
    design: SamplingDesignName = Field(  # type: ignore[valid-type]
        default=SamplingDesign("sobol"), description="Starting design of experiments.")
    adaptive: bool = Field(default=True, description="Add evaluations where the surrogate is least "
                                                     "sure (else spend the budget on the design).")
    seed: WholeNumber = Field(default=0, ge=0, le=2**31 - 1, description="Seed of designs and optimizer [1].")
    validation_points: WholeNumber = Field(
        default=surrogate.sampling.VALIDATION_POINTS, ge=0, le=MAX_VALIDATION_POINTS,
        description="Evaluations of the model beyond the budget, at a space-filling design never trained "
                    "on, that calibrate the 95 % intervals by split conformal prediction (they then cover "
                    "95 +- 1 % of new points); 0 calibrates them by cross-validation of the training "
                    "evaluations instead (no extra evaluation, much less reliable below 100 evaluations). "
                    "Spaces of integer and boolean dimensions only are always cross-validated [1].")
    convention: ConventionName = Field(  # type: ignore[valid-type]
        default=Convention(physics.DEFAULT_CONVENTION),
        description="Reading of the paper's ambiguous ball-ball terms (a calibrated model's own "
                    "convention applies; giving another one is an error).")
    model: str = Field(default="physics", pattern=MODEL_PATTERN, description=(
        "The model to learn: 'physics' (the declared model) or 'calibrated:<id>' from /v1/calibrations "
        "(its fixed and fitted parameters replace the defaults, values in fixed override them, and its "
        "effect is added to mu)."))
    conditions: Annotated[dict[str, Annotated[float, BeforeValidator(_one_condition)]] | None,
                          ColumnKeys] = Field(default=None, description=(
        "Condition columns a calibrated model's effect reads, one value each for the whole space, e.g. "
        "relative_humidity [1] [unit of each column as in the calibration data]." + UNIT_KEYS))


class SurrogateMetrics(ResponseModel):
    """Accuracy on held-out evaluations of the model (never training points)."""

    median_relative_error: float | None = Field(description="Median of |predicted/true mu - 1| [1] "
                                                            "(null when too few held-out points, see note).")
    p95_relative_error: float | None = Field(description="95th percentile of |predicted/true mu - 1| [1].")
    nrmse: float | None = Field(description="Root-mean-square error of mu over the standard deviation of "
                                            "mu [1].")
    coverage_95: float | None = Field(description="Fraction of true mu inside the predicted 95 % interval "
                                                  "[1].")
    n_test: int = Field(description="Held-out points: a Sobol' design of the space less the training "
                                    "points, or for a small space of integer and boolean dimensions "
                                    "every point of it that is not a training point [1].")
    note: str | None = Field(default=None, description="Why the figures are null: every point of a finite "
                                                       "space (but at most one) was a training point.")


class SurrogateResult(ResponseModel):
    """A trained surrogate."""

    id: str = Field(description="Surrogate id.")
    model_id: str = Field(description="Model reference for other routes: surrogate:<id>.")
    space: dict[str, list[float | bool]] = Field(description="Dimensions and ranges [their units].")
    fixed: dict[str, float | bool] = Field(description="Fixed inputs [their units].")
    scales: dict[str, str] = Field(description="Scale of each dimension in the design: log, power or linear.")
    features: list[str] = Field(description="Inputs of the Gaussian process.")
    budget: int = Field(description="Evaluation budget requested [1].")
    n_train: int = Field(description="Evaluations used for training, at most budget; no point is "
                                     "evaluated twice [1].")
    stop_reason: str = Field(description="target_reached, budget_exhausted or candidates_exhausted "
                                         "(every candidate point already evaluated, e.g. a space of integer "
                                         "and boolean dimensions with fewer points than the budget).")
    metrics: SurrogateMetrics = Field(description="Held-out accuracy.")
    history: list[dict[str, float]] = Field(
        description="Per refit: n_train [1]; estimated (predictive spread) and leave-one-out median and "
                    "95th-percentile relative errors [1]; loo_median_upper_bound and loo_p95_upper_bound, "
                    "95 % upper confidence bounds of the leave-one-out quantiles that the stop rule compares "
                    "with the target [1] (absent while too few points bound them: 59 for the 95th "
                    "percentile).")
    kernel: str = Field(description="Fitted kernel with its hyperparameters (standardized features).")
    fit_seconds: float = Field(description="Training time [s].")
    convention: str = Field(description="Physics convention trained on.")
    model: str = Field(default="physics", description="The model learned: physics or calibrated:<id>.")
    conditions: dict[str, float] = Field(default_factory=dict, description=(
        "Condition columns of a calibrated model, as trained on [their units]."))
    package_version: str = Field(description="microbearing version trained with.")
    variance_calibration: str | None = Field(default=None, description=(
        "How the 95 % intervals were calibrated: validation (split conformal on validation_points "
        "evaluations never trained on), or on the training evaluations: kfold (5 folds, the Gaussian "
        "process refitted without each; below 10 evaluations per feature) or loo (closed-form "
        "leave-one-out errors at the space-filling starting design); null for surrogates stored before "
        "it was recorded."))
    std_scale: float | None = Field(default=None, description=(
        "Factor applied to the Gaussian process's own standard deviation of log mu: for validation, the "
        "split-conformal 95 % quantile of all the standardized validation errors over 1.96 (the intervals "
        "then use radius_scales, one such factor per bin of distance from the centre); else the root mean "
        "square of the standardized cross-validation errors [1]."))
    calibration_points: int | None = Field(default=None, description=(
        "Evaluations whose standardized errors set std_scale: the validation points, or the training "
        "evaluations cross-validated [1]."))
    radius_scales: dict[str, list[float]] | None = Field(default=None, description=(
        "With validation: the factors used instead of std_scale by a point's distance from the centre of "
        "the space (the root mean square over the inputs of 2 u - 1, u the input's place in its range on "
        "the design's scale, 0 to 1; booleans left out): 'scales', one per bin between the increasing "
        "distances 'edges', each the split-conformal quantile of the validation points in that bin (spread "
        "over the distance, about equally many a bin), never less than a bin nearer the centre's, so that "
        "the 95 % interval holds near the bounds and corners as near the centre [1]. Null otherwise, and "
        "for surrogates stored before it was kept."))
    validation_points: int = Field(default=0, description=(
        "Evaluations of the model beyond the budget, never trained on, that calibrated the intervals (0: "
        "none; cross-validation did) [1]."))
    target_relative_error: float | None = Field(default=None, description=(
        "The target median relative error of mu the training aimed at (null for surrogates stored before "
        "it was recorded) [1]."))
    warnings: list[str] = Field(default_factory=list, description=(
        "Where the surrogate falls short of what it promises, measured on its held-out points: coverage "
        "of the 95 % interval below 90 %, median (95th-percentile) relative error above the target (5 "
        "times it); where the space leaves the data of the calibrated model it learns (there the model "
        "extrapolates and the surrogate's interval is its approximation error only); and other reasons to "
        "distrust the stored figures, e.g. a package_version other than the running one (the physics may "
        "have changed since: retrain). Empty when none."))
    created_at: DateTimeText = Field(description="Creation time, ISO 8601 UTC.")


class SurrogateList(ResponseModel):
    """A page of the stored surrogates the caller sees, newest first."""

    surrogates: list[SurrogateResult] = Field(description="The surrogates of this page (at most limit).")
    next_url: str | None = NEXT_URL


PredictPoints = create_model(
    "PredictPoints", __base__=InputKeys,
    __doc__="Columnar points: every dimension of the surrogate; other inputs optional (a value other than "
            "the one it was trained at is refused: the surrogate does not read it)." + INPUT_KEYS,
    **parameter_fields(columns=True, optional=True),
)


class PredictRequest(StrictModel):
    """Where to predict."""

    #: The long lists of numbers of ``points`` in a large body are read as arrays (parse_json_body).
    array_objects: ClassVar[frozenset[str]] = frozenset({"points"})

    points: PredictPoints = Field(description="Columnar inputs by name.")  # type: ignore[valid-type]


class PredictResponse(ResponseModel):
    """Predicted mu with its 95 % interval."""

    mu: list[float] = Field(description="Predicted friction coefficient [1].")
    mu_lower: list[float] = Field(description="Lower end of the 95 % interval [1].")
    mu_upper: list[float] = Field(description="Upper end of the 95 % interval [1].")
    outside_space: list[bool] = Field(
        description="True where the point leaves the trained space (the interval then does not apply).")
    warnings: list[str] = Field(default_factory=list, description=(
        "The surrogate's own warnings (see GET /v1/surrogates/{id}: held-out coverage or error short of "
        "what it promises, another package version) and a count of the points outside the space; empty "
        "when none."))


class SensitivityResponse(ResponseModel):
    """Sobol' indices of mu over the space, computed on the surrogate."""

    first_order: dict[str, float] = Field(description="Variance share of each input alone [1].")
    total_order: dict[str, float] = Field(description="Variance share involving each input [1].")
    first_order_interval: dict[str, list[float]] = Field(description=(
        "95 % bootstrap confidence interval [low, high] of each first-order index (scipy's "
        "sobol_indices(...).bootstrap(), 999 resamples of the evaluations) [1]."))
    total_order_interval: dict[str, list[float]] = Field(description=(
        "95 % bootstrap confidence interval [low, high] of each total index [1]."))
    confidence_level: float = Field(description="Confidence level of the intervals [1].")
    n: int = Field(description="Base sample size; n (d + 2) surrogate evaluations [1].")
    distribution: str = Field(description="Input distribution the indices refer to.")
