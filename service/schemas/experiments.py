"""Bodies of ``/v1/calibrations/{id}/next-experiments`` and ``/v1/experiments``: the runs to measure next."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BeforeValidator, ConfigDict, Field

from microbearing import physics
from microbearing.physics.spans import SPAN_SPELLINGS

from .base import (
    REQUIRED_INPUTS,
    CheckedColumnKeys,
    Convention,
    ConventionName,
    ResponseModel,
    StrictModel,
    WholeNumber,
    check_column_keys,
    given_at,
    physics_value_schema,
)
from .calibrations import FITTABLE_PARAMETERS, FittableParameterName

__all__ = ["MAX_PLANNED_RUNS", "MAX_RUNS", "MAX_SPACE_COLUMNS", "MAX_SPACE_VALUES", "ExperimentsResult",
           "FirstExperimentsRequest", "NextExperimentsRequest", "SpaceRange", "SpaceValues"]

#: Runs one proposal may ask for at most. [1]
MAX_RUNS = 500
#: Runs already planned that a request may list at most. [1]
MAX_PLANNED_RUNS = 500
#: Columns of a space (or envelope) at most. [1]
MAX_SPACE_COLUMNS = 12
#: Allowed values of one column given as a set at most. [1]
MAX_SPACE_VALUES = 200


class SpaceRange(StrictModel):
    """A continuous range a lab can set (for ``balls``: every whole count in it)."""

    low: float = Field(description="Lowest value [unit of the column: physics inputs as in /v1/parameters, "
                                   "conditions as in the calibration data].")
    high: float = Field(description="Highest value, >= low [unit of the column].")
    spacing: Literal["linear", "log"] = Field(
        default="linear", description="How the candidate grid spreads over the range: evenly, or evenly in "
                                      "logarithms (low > 0).")


class SpaceValues(StrictModel):
    """A set of allowed values a lab can set (e.g. humidity set-points, a mask set's groove angles)."""

    values: list[float] = Field(min_length=1, max_length=MAX_SPACE_VALUES, description=(
        "The allowed values [unit of the column]."))


def _one_spelling(value: Any) -> Any:
    """A plain list is a range [low, high] (one value: that value): longer ones are refused, the two spellings
    explained."""
    given = value.get("values") if isinstance(value, dict) else value
    if isinstance(given, list) and any(isinstance(v, str) for v in given):  # one sentence, not four
        raise ValueError("group labels are no range or set here: this is a factor column, and the runs are "
                         "planned for the model over its groups (a new one's spread in the interval); leave "
                         "it out")
    if isinstance(value, list) and len(value) > 2:
        raise ValueError(f"a list of {len(value)} values is ambiguous: {SPAN_SPELLINGS}")
    if not isinstance(value, list | dict):  # one sentence, not each member's of the union
        what = "null" if value is None else str(value).lower() if isinstance(value, bool) else "a number"
        raise ValueError(f"{what} is no range or set here: {SPAN_SPELLINGS} (a value held in every run "
                         f"goes in fixed)")
    if isinstance(value, dict) and "values" in value:  # a set: one sentence, not the range's errors too
        values = value["values"]
        if set(value) != {"values"}:
            raise ValueError(f"a set of allowed values has the key values only; got "
                             f"{', '.join(map(str, value))}")
        if not isinstance(values, list) or not values:
            raise ValueError("a set of allowed values is a list of at least one: {\"values\": [v1, v2, ...]}")
    elif isinstance(value, dict) and not {"low", "high"} <= set(value):
        raise ValueError(f"a range spelled as an object has the keys low and high (and spacing); got "
                         f"{', '.join(map(str, value)) or 'none'}")
    return value


SpaceColumn = Annotated[
    SpaceRange | SpaceValues | Annotated[list[float], Field(min_length=1, max_length=2)],
    BeforeValidator(_one_spelling),
    Field(description="A range, [low, high] or {low, high, spacing}, or a set of allowed values "
                      "{\"values\": [...]} (e.g. humidity set-points, a mask set's groove angles [deg]), in "
                      "the column's unit; [value] is that one value. A range reads the same in every route."),
]

def _space_keys(space: dict[str, Any] | None) -> dict[str, Any] | None:
    """A space's columns kept as sent, keys checked as the calibration upload reads its header (a unit not
    known or not of its quantity, two keys read as one physics input): the route reads them against the
    model (:func:`service.experiments.next_experiments_job`: ``speed [mm/s]`` is speed_m_s, converted),
    so that a refusal names the key and value as sent."""
    check_column_keys(space)
    return space


_UNIT_NAMES = (" A column's name may carry its unit as the calibration upload's header does ('speed [mm/s]', "
               "'relative humidity [%]'), its values converted.")

_SPACE = ("What the lab can set, per column: balls (a range of whole counts or a set), load_N [N], "
          "speed_m_s [m/s], any other physics input in its unit, and the calibration's condition columns "
          "(e.g. relative_humidity, in the calibration data's unit). balls, load_N and speed_m_s and the "
          "columns the model reads must be in the space or in fixed.")
_ENVELOPE = ("Where the model will be used, like space (ranges or sets per column, the space's columns "
             "all given): goal predict shrinks the 95 % interval of mu over it; with another goal the "
             "interval there before and after is reported too.")
_FIXED = ("Inputs held at one value in every run: physics inputs in their units (e.g. groove_angle_deg "
          "[deg]) and condition columns in the calibration data's units.")
_PLANNED = ("Runs already planned, one object per run with a value for every column of the space: their "
            "information counts as taken.")


def _one_value(value: Any) -> Any:
    """A fixed value is one number, flag or label: a range, a set or null said in one sentence, not each
    member's of the union."""
    if value is None or isinstance(value, list | dict):
        got = "null" if value is None else "a range or set"
        raise ValueError(f"fixed holds one value per column; got {got} (a column the runs vary goes in "
                         f"space)")
    return value


class _ExperimentsRequest(StrictModel):
    runs: WholeNumber = Field(ge=1, le=MAX_RUNS, description="How many measurements to propose [1].")
    space: Annotated[dict[str, SpaceColumn], AfterValidator(_space_keys)] = Field(
        min_length=1, max_length=MAX_SPACE_COLUMNS, description=_SPACE + _UNIT_NAMES)
    envelope: Annotated[dict[str, SpaceColumn] | None, AfterValidator(_space_keys)] = Field(
        default=None, max_length=MAX_SPACE_COLUMNS, description=_ENVELOPE)
    # text is taken to be refused in words (a factor's label: the runs serve every group)
    fixed: Annotated[dict[str, Annotated[float | bool | str, BeforeValidator(_one_value)]] | None,
                     CheckedColumnKeys] = Field(
        default=None, max_length=64, description=_FIXED + _UNIT_NAMES)
    planned: list[Annotated[dict[str, float], CheckedColumnKeys]] | None = Field(
        default=None, max_length=MAX_PLANNED_RUNS, description=_PLANNED + _UNIT_NAMES)
    seed: WholeNumber = Field(default=0, ge=0, le=2**31 - 1, description="Seed of the candidate set [1].")


class NextExperimentsRequest(_ExperimentsRequest):
    """The next measurements for a calibrated model."""

    goal: Literal["discriminate", "parameters", "predict"] = Field(
        default="discriminate",
        description="discriminate: tell apart the laws and effects the calibration could not separate "
                    "(T-optimal); parameters: shrink the fitted parameters' covariance (D-optimal); "
                    "predict: shrink the 95 % interval over the envelope (I-optimal; summed over the "
                    "calibrated model and its rivals when it has any, so that the runs also serve the laws "
                    "the data could not yet tell apart).")


#: Columns a first design's space, envelope or fixed may name: the numeric physics inputs (no
#: calibration, so no condition columns).
_PHYSICS_COLUMNS = [name for name, spec in physics.PARAMETERS.items() if spec.kind != "bool"]


def _column_bounds(name: str) -> dict:
    """JSON Schema of a space column of the physics input ``name`` within its bounds: a range (any
    ends for balls, whose whole counts in it are taken) or a set of values (whole counts for balls)."""
    value = physics_value_schema(name)
    end = {**value, "type": "number"}
    return {"anyOf": [{"type": "object", "properties": {"low": end, "high": end}},
                      {"type": "object", "properties": {"values": {"type": "array", "items": value}}},
                      {"type": "array", "minItems": 2, "maxItems": 2, "items": end},
                      {"type": "array", "minItems": 1, "maxItems": 1, "items": value}]}


_COLUMN_BOUNDS = {name: _column_bounds(name) for name in _PHYSICS_COLUMNS}
_FIXED_BOUNDS = {name: physics_value_schema(name) for name in _PHYSICS_COLUMNS}


class FirstExperimentsRequest(_ExperimentsRequest):
    """A first design on the declared physics, before any calibration."""

    # What the server checks across fields: columns of the space, the envelope and fixed are physics
    # inputs, their values within the inputs' bounds; guesses name fittable parameters; balls, load_N
    # and speed_m_s each in the space or fixed; goal predict with an envelope.
    # (A column both in the space and fixed, guesses of parameters not fitted and a range whose low end
    # exceeds its high one are refused by the server only.)
    # (Each clause on a nullable field sits in a one-branch anyOf: openapi-python-client merges the
    # properties of allOf into the model's and cannot merge an object with "object or null".)
    model_config = ConfigDict(**StrictModel.model_config, json_schema_extra={"allOf": [
        {"anyOf": [{"properties": {field: {"propertyNames": {"enum": _PHYSICS_COLUMNS}}
                                   for field in ("space", "envelope", "fixed")}
                    | {"guess": {"propertyNames": {"enum": FITTABLE_PARAMETERS}}}}]},
        {"anyOf": [{"properties": {field: {"properties": _COLUMN_BOUNDS} for field in ("space", "envelope")}
                    | {"fixed": {"properties": _FIXED_BOUNDS}}}]},
        *({"anyOf": [given_at(("space", name)), given_at(("fixed", name))]} for name in REQUIRED_INPUTS),
        {"anyOf": [{"properties": {"goal": {"const": "parameters"}}},
                   given_at(("envelope",), {"type": "object", "minProperties": 1})]}]})

    goal: Literal["parameters", "predict"] = Field(
        default="parameters",
        description="parameters: D-optimal for the declared parameters to fit; predict: I-optimal over "
                    "the envelope.")
    fit_parameters: list[FittableParameterName] = Field(  # type: ignore[valid-type]
        min_length=1, max_length=len(physics.PARAMETERS),
        description="Declared parameters the measurements will fit, e.g. mu_pivot [1].")
    guess: dict[str, float] | None = Field(
        default=None, description="Values of the fitted parameters where their effect is linearized, in "
                                  "their units (default: the physics defaults).")
    noise_std_log: float = Field(
        default=0.05, gt=0, le=5,
        description="Expected standard deviation of one measurement of log mu, i.e. the relative scatter "
                    "of mu [1].")
    convention: ConventionName = Field(  # type: ignore[valid-type]
        default=Convention(physics.DEFAULT_CONVENTION),
        description="Reading of the paper's ambiguous ball-ball terms.")


class ProposedRun(ResponseModel):
    """One measurement to take."""

    balls: int = Field(description="Number of balls [1].")
    load_N: float = Field(description="Normal load on the slider [N].")
    speed_m_s: float = Field(description="Sliding speed [m/s].")
    inputs: dict[str, float | bool] = Field(
        description="Other physics inputs of the space and of fixed, in their units (see /v1/parameters).")
    conditions: dict[str, float] = Field(description="Condition columns, in the calibration data's units.")
    as_sent: dict[str, float | bool] = Field(default_factory=dict, description=(
        "The run's settings under the keys of the request's space and fixed values as sent, each in the unit "
        "its key states (what a technician sets: {'load [mN]': 3, 'RH (%)': 85} where load_N is 0.003 and "
        "the column RH holds the fraction 0.85)."))
    mu: float = Field(description="mu the model predicts for the run [1].")
    mu_lower: float | None = Field(default=None, description="Lower end of its 95 % prediction interval "
                                                             "[1] (absent before a calibration).")
    mu_upper: float | None = Field(default=None, description="Upper end of the same interval [1].")
    in_domain: bool | None = Field(default=None, description=(
        "Whether the run lies within the range of the calibration data (false: the model extrapolates "
        "there, which is often the point; absent before a calibration)."))


class ParameterFigures(ResponseModel):
    """A fitted parameter's standard deviation now and expected after the runs."""

    name: str = Field(description="The parameter (declared name, or '<term>: <parameter>').")
    value: float = Field(description="Its value [unit]: in the unit given by unit.")
    unit: str = Field(description="The parameter's unit.")
    std_now: float | None = Field(description="Standard deviation now [unit] (absent before a calibration).")
    std_after: float = Field(description="Expected standard deviation after the runs, linearized [unit].")


class HalfWidth(ResponseModel):
    """Half-widths of 95 % intervals of mu over the envelope."""

    mean: float = Field(description="Mean over the envelope's points [1].")
    max: float = Field(description="Largest over the envelope's points [1].")


class HalfWidthSpan(ResponseModel):
    """Where a mean half-width over the envelope may fall, as far as μ's level is known now."""

    low: float = Field(description="With μ at the lower end of today's 95 % interval at every point [1].")
    high: float = Field(description="With μ at the upper end of today's 95 % interval at every point [1].")


class EnvelopeFigures(ResponseModel):
    """The 95 % interval of mu over the envelope, now and expected after the runs."""

    points: int = Field(description="Points of the envelope the figures average [1].")
    half_width_now: HalfWidth | None = Field(default=None, description=(
        "Half-width of the 95 % prediction interval of a measurement (parameters + scatter) now [1]."))
    half_width_after: HalfWidth = Field(description="The same after the runs [1] (the scatter stays).")
    mean_half_width_now: HalfWidth | None = Field(default=None, description=(
        "Half-width of the 95 % interval of the model's mean (parameters only) now [1]."))
    mean_half_width_after: HalfWidth = Field(description="The same after the runs [1].")
    reported_half_width_now: HalfWidth | None = Field(default=None, description=(
        "Half-width of the 95 % interval the service reports now [1]: (mu_upper - mu_lower) / 2 of the "
        "calibrated model, widened off the data (data cloud, inputs beyond the data's ranges) and holding "
        "the rivals (a calibrated model only)."))
    reported_half_width_after: HalfWidth | None = Field(default=None, description=(
        "The same expected after the runs [1], as a recalibration on the data plus the runs bounds it: the "
        "data cloud and ranges rebuilt with the runs, fitted values and scatter unchanged, rivals settled "
        "(the widest over which of the model and its rivals is true, each with the others its runs leave); "
        "with an envelope beyond the data in a physics input, the widest with each law the catalogue "
        "declares on that input added at a few values of its shape (a recalibration on the runs may add "
        "it)."))
    reported_relative_half_width_now: HalfWidth | None = Field(default=None, description=(
        "reported_half_width_now over the model's mu at each point, a fraction of mu [1]."))
    reported_relative_half_width_after: HalfWidth | None = Field(default=None, description=(
        "reported_half_width_after over the mu of the case that gives it at each point, a fraction of mu "
        "[1]: what a promise can keep when the runs find mu itself moved (a rise the data had not seen, "
        "1.3-1.4x on a Stribeck lab, widens the absolute half-width by as much)."))
    reported_half_width_after_span: HalfWidthSpan | None = Field(default=None, description=(
        "Where the mean of reported_half_width_after may fall once the runs show where μ lies [1]: "
        "reported_relative_half_width_after times the ends of the 95 % interval the service reports now "
        "at each point, or of the μ of a law the data lean to beyond it (the cases the promise weighs). "
        "Wide where the envelope lies off the data: the runs may find μ moved."))


class RivalFigures(ResponseModel):
    """A rival model and how far apart the runs set it from the calibrated model."""

    label: str = Field(description="What the rival changes.")
    terms: list[str] = Field(description="The rival's terms.")
    expected_chi2_separation: float = Field(description=(
        "Expected increase of the rival's chi-square (sum of squared standardized residuals of log mu) "
        "when the runs are measured and the calibrated model is right, the rival refitted to first order "
        "[1]; about 9 or more separates them at 3 standard deviations."))
    max_relative_difference: float = Field(description="Largest |mu_rival / mu - 1| at the runs [1].")
    mu_at_runs: list[float] = Field(description="The rival's mu at each run [1].")


class PlotCurve(ResponseModel):
    """One model's mu along the plot's first axis."""

    label: str = Field(description="The model.")
    x: list[float] = Field(description="Values of the first axis [unit of that column].")
    mu: list[float] = Field(description="mu there [1].")


class PlanPlot(ResponseModel):
    """What the plot draws (also at plot_url as PNG)."""

    axes: list[str] = Field(description="The two columns of the space drawn (first: along which rivals "
                                        "differ most, for discriminate).")
    runs: dict[str, list[float]] = Field(description="The runs on those columns, in their units.")
    data: dict[str, list[float]] = Field(description="The calibration data on those columns (at most 2000 "
                                                     "rows), in their units.")
    curves: list[PlotCurve] = Field(description="discriminate: each model's mu along the first axis.")
    envelope: dict[str, list[float]] | None = Field(default=None, description=(
        "The envelope's [low, high] on the plot's axes, in their units (when one was given) [unit of each "
        "column]."))
    others: dict[str, float] | None = Field(default=None, description=(
        "Values of the other columns along the curves (the runs' medians), in their units."))
    sent_as: dict[str, str] | None = Field(default=None, description=(
        "Each column's key as the request sent it (``{\"load_N\": \"load [mN]\"}``): the PNG draws the "
        "column under that key, in that unit; the numbers here stay in the column's own unit."))


class ExperimentsResult(ResponseModel):
    """The proposed runs, the proof of how good they are, and what they are expected to do."""

    goal: str = Field(description="discriminate, parameters or predict.")
    model: str = Field(description="'calibrated:<id>' or 'physics'.")
    calibration_id: str | None = Field(default=None, description="The calibration (absent for a first "
                                                                 "design on the physics).")
    runs: list[ProposedRun] = Field(description="The runs, replicates repeated, integer ball counts, "
                                                "inside the space.")
    criterion: float = Field(description=(
        "The criterion of the runs with the data taken: parameters, log det of the information "
        "[log of the parameters' units^-2]; predict, mean variance of log mu over the envelope [1]; "
        "discriminate, the smallest expected_chi2_separation of the rivals [1]."))
    efficiency_lower_bound: float = Field(ge=0, le=1, description=(
        "The runs' efficiency under the criterion against the best possible design over the candidate "
        "points is at least this [1] (equivalence-theorem bound at the whole runs, rounding included; "
        "D: (det ratio)^(1/p), I: variance ratio, T: separation ratio)."))
    continuous_efficiency_lower_bound: float = Field(ge=0, le=1, description=(
        "The Kiefer-Wolfowitz bound of the solver's continuous design [1]."))
    rounding_efficiency: float = Field(ge=0, description=(
        "The whole runs' criterion relative to the continuous design's, in the efficiency's scale [1]."))
    support_points: int = Field(description="Distinct settings among the runs [1].")
    solver: str = Field(description="The cvxpy solver and its status.")
    parameters: list[ParameterFigures] = Field(description="Each fitted parameter's standard deviation now "
                                                           "and after.")
    envelope: EnvelopeFigures | None = Field(default=None, description="The interval over the envelope "
                                                                       "(when one was given).")
    rivals: list[RivalFigures] | None = Field(default=None, description="discriminate: the rivals.")
    mu_reference_at_runs: list[float] | None = Field(default=None, description=(
        "discriminate: the calibrated model's mu at each run [1]."))
    plot: PlanPlot = Field(description="The plot's data.")
    plot_url: str | None = Field(default=None, description="The plot as PNG.")
    warnings: list[str] = Field(description="Runs outside the calibration data, a weak bound, ...")
