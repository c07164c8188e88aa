"""Bodies of ``/v1/sweeps``: a full-factorial grid or a design of experiments, tagged by ``design``."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import (
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    PrivateAttr,
    Tag,
    WrapValidator,
    create_model,
)

from microbearing import physics
from microbearing.physics.spans import no_range

from .base import (
    REQUIRED_INPUTS,
    Convention,
    ConventionName,
    OutputName,
    ResponseModel,
    StrictModel,
    WholeNumber,
    given_at,
    in_one_place,
    parameter_fields,
    physics_value_schema,
    whole_number,
)
from .friction import INPUT_WARNINGS, InputKeys

__all__ = ["Axis", "AxisValues", "GridAxis", "GridSweep", "LatinHypercubeSweep", "SobolSweep", "SweepRange",
           "SweepRequest", "SweepResult"]

#: Inputs a sweep can vary: every numeric parameter (booleans are set in ``fixed``).
SWEEPABLE = [name for name, spec in physics.PARAMETERS.items() if spec.kind != "bool"]

Spacing = Literal["linear", "log"]
_SPACING = Field(default="linear", description="linear, or log (evenly spaced logarithms; needs values > 0).")


class GridAxis(StrictModel):
    """Evenly spaced values of one input, in its own unit; whole numbers for integer inputs."""

    start: float = Field(description="First value [the unit of the input named by the axis's key, e.g. N "
                                     "for load_N].")
    stop: float = Field(description="Last value [the unit of the input named by the axis's key].")
    num: WholeNumber = Field(ge=1, le=1_000_000, description=(
        "Number of values [1]; a whole-number input (balls) takes the distinct whole numbers they round "
        "to, so balls from 4 to 6 gives at most 3 (count says how many)."))
    spacing: Spacing = _SPACING


class AxisValues(StrictModel):
    """Given values of one input, in its own unit, in the order given; whole numbers for integer inputs."""

    values: list[float] = Field(min_length=1, max_length=1_000_000, description=(
        "The values [the unit of the input named by the axis's key, e.g. N for load_N]."))


def _not_a_list(value: Any) -> Any:
    if isinstance(value, list):
        raise ValueError('an axis is {"start", "stop", "num"} (evenly spaced values) or {"values": [...]} '
                         '(given values): write a list of values as {"values": [...]}')
    keys = set(value) if isinstance(value, dict) else set()
    if keys & {"low", "high"} and not keys & {"start", "stop", "values"}:
        raise ValueError('an axis is {"start", "stop", "num"} (evenly spaced values) or {"values": [...]} '
                         '(given values); a range {"low", "high"} has no number of values: give start, stop '
                         'and num, or sample the range with design sobol or latin_hypercube (ranges)')
    return value


def _axis_form(value: Any) -> str:
    given = isinstance(value, AxisValues) or (isinstance(value, dict) and "values" in value)
    return "axis-values" if given else "axis-grid"


#: One axis of a grid: evenly spaced values, or given ones.
Axis = Annotated[Annotated[GridAxis, Tag("axis-grid")] | Annotated[AxisValues, Tag("axis-values")],
                 Discriminator(_axis_form), BeforeValidator(_not_a_list)]


class SweepRange(StrictModel):
    """Interval of one input sampled by a design of experiments, in its own unit."""

    low: float = Field(description="Lower end [the unit of the input named by the range's key, e.g. N "
                                   "for load_N].")
    high: float = Field(description="Upper end [the unit of the input named by the range's key].")
    spacing: Spacing = _SPACING
    _pair: bool = PrivateAttr(default=False)

    def sent_as_pair(self) -> SweepRange:
        """This range, remembering that it was sent as the pair ``[low, high]`` (:meth:`pointer`)."""
        self._pair = True
        return self

    def pointer(self, end: str) -> str:
        """The JSON pointer step of an end (``low`` or ``high``) as the range was sent: ``0``/``1`` for the
        pair ``[low, high]``, the key otherwise."""
        return str(("low", "high").index(end)) if self._pair else end


def _pair_as_range(value: Any, handler: Any) -> Any:
    """A range spelled as the pair ``[low, high]``, read as ``{"low", "high"}``, as every route reads a range
    (an optimization's bounds, an experiment space's); a set of values or another list refused in words."""
    refused = no_range(value)
    if refused is not None:
        raise ValueError(f"{refused} (with \"spacing\": \"log\" for evenly spaced logarithms)")
    if isinstance(value, list):
        return handler({"low": value[0], "high": value[1]}).sent_as_pair()
    if isinstance(value, dict) and "values" in value:
        raise ValueError("a set of values is no range here: a range is [low, high] or {\"low\": low, "
                         "\"high\": high}; given values are a grid's axis (design grid, axes "
                         "{\"values\": [...]})")
    return handler(value)


#: A design's range of one input: {low, high[, spacing]}, or the pair [low, high].
Range = Annotated[SweepRange, WrapValidator(_pair_as_range)]


def _per_input(kind: type, what: str) -> dict:
    return {name: (kind | None, Field(default=None, description=f"{what} {name} "
                                      f"[{physics.PARAMETERS[name].unit}]."))
            for name in SWEEPABLE}


GridAxes = create_model("GridAxes", __base__=InputKeys, __doc__="The varied inputs and their values.",
                        **_per_input(Axis, "Values of"))
SweepRanges = create_model("SweepRanges", __base__=InputKeys, __doc__="The varied inputs and their ranges.",
                           **_per_input(Range, "Range ([low, high] or {low, high[, spacing]}) of"))
SweepFixed = create_model(
    "SweepFixed", __base__=InputKeys,
    __doc__="Values of the inputs that are not varied; omitted optional ones take their defaults.",
    **parameter_fields(optional=True),
)

def _cross_field_rules(varied: str, ends: tuple[str, str]) -> dict[str, Any]:
    """What the server checks across fields of a sweep, in JSON Schema (``allOf`` of a design's schema).

    ``varied`` is the object of the varied inputs (``axes`` or ``ranges``), ``ends`` the names of
    the two ends of an axis or range: at least one input varied; each required input (balls,
    load_N, speed_m_s) either fixed or varied, not both; the ends of each varied input within its
    allowed range (the physics' bounds, in its unit). A null value counts as absent.

    The server also refuses an optional input both fixed and varied, a range whose high end is below
    its low end, and a design over the size limit (a setting); these the schema does not say (a
    generator of test data then meets too many alternatives).
    """
    rules: list[dict[str, Any]] = [{"anyOf": [given_at((varied, name), {"type": "object"})
                                              for name in SWEEPABLE]}]
    rules += [in_one_place((("fixed", name), None), ((varied, name), {"type": "object"}))
              for name in REQUIRED_INPUTS]
    bounds = {name: {"anyOf": [{"type": "null"}, {"type": "object", "properties": {
        **{end: physics_value_schema(name) for end in ends},
        **({"values": {"type": "array", "items": physics_value_schema(name)}} if varied == "axes" else {})}}]}
        for name in SWEEPABLE}
    rules.append({"properties": {varied: {"properties": bounds}}})
    return {"allOf": rules}


class _SweepBase(StrictModel):
    """What every design shares: the fixed inputs, the outputs and the convention."""

    fixed: SweepFixed = Field(  # type: ignore[valid-type]
        default_factory=SweepFixed, description="Inputs held constant.")
    outputs: list[OutputName] | None = Field(  # type: ignore[valid-type]
        default=None, min_length=1, description="Outputs to return (default: all of them).")
    convention: ConventionName = Field(  # type: ignore[valid-type]
        default=Convention(physics.DEFAULT_CONVENTION), description="Reading of the paper's ball-ball terms.")


class _SampledSweep(_SweepBase):
    """A design of experiments drawn from ``scipy.stats.qmc`` over the ranges."""

    model_config = ConfigDict(**StrictModel.model_config,
                              json_schema_extra=_cross_field_rules("ranges", ("low", "high")))

    ranges: SweepRanges = Field(description="Varied inputs and their ranges.")  # type: ignore[valid-type]
    points: WholeNumber = Field(ge=1, le=100_000_000, description="Number of sample points [1].")
    seed: Annotated[int, Field(ge=0, le=2**63 - 1), BeforeValidator(whole_number)] | None = Field(
        default=None, description="Seed of the scrambling, for repeatable designs [1].")


class GridSweep(_SweepBase):
    """Full-factorial grid: every combination of the axes' values."""

    model_config = ConfigDict(**StrictModel.model_config,
                              json_schema_extra=_cross_field_rules("axes", ("start", "stop")))

    design: Literal["grid"] = Field(description="Design tag: grid.")
    axes: GridAxes = Field(description="Varied inputs and their values.")  # type: ignore[valid-type]


class SobolSweep(_SampledSweep):
    """Scrambled Sobol' low-discrepancy sequence over the ranges (``scipy.stats.qmc.Sobol``)."""

    design: Literal["sobol"] = Field(description="Design tag: sobol.")


class LatinHypercubeSweep(_SampledSweep):
    """Latin hypercube sample over the ranges (``scipy.stats.qmc.LatinHypercube``)."""

    design: Literal["latin_hypercube"] = Field(description="Design tag: latin_hypercube.")


SweepRequest = Annotated[GridSweep | SobolSweep | LatinHypercubeSweep, Field(discriminator="design")]


class SentColumn(ResponseModel):
    """An input the request sent under another key: the column it was read as and how its values convert
    into the key's unit."""

    column: str = Field(description="The input it was read as (a column of columns, or of fixed).")
    unit: str | None = Field(default=None, description=(
        "The unit the key was sent in (mm/min of 'speed [mm/min]'; the column's own when the key only "
        "renamed it)."))
    factor: float | None = Field(default=None, description=(
        "A value in the key's unit is the column's value x factor + offset (60000 for speed [mm/min] from "
        "speed_m_s) [key's unit per column's unit]."))
    offset: float | None = Field(default=None, description=(
        "See factor (0 but for an offset scale) [key's unit]."))
    values: float | list[float] | None = Field(default=None, description=(
        "A fixed input's value in the key's unit, to the digits it holds [the key's unit]. Absent for a "
        "varied input: its values are the column's in columns (SI) converted by factor and offset, not "
        "repeated here (they would double a large sweep's JSON and its size limit); the CSV form gives them "
        "under the key, in its unit. A list in results stored before."))


class SweepResult(ResponseModel):
    """The sweep as a table: the varied inputs, then the chosen outputs, one row per point."""

    design: Literal["grid", "sobol", "latin_hypercube"] = Field(description="Design that made the points.")
    count: int = Field(ge=0, description="Number of points [1].")
    varied: list[str] = Field(description="Names of the varied inputs, in the order of the parameter table "
                              "(the first columns; the last one varies fastest in a grid).")
    fixed: dict[str, float | bool] | None = Field(default=None, description=(
        "The inputs the request fixed, name -> value in its unit (the CSV form of the table has them as "
        "columns after the varied inputs; null for results stored before it)."))
    columns: dict[str, list[float]] = Field(
        description="Column name to values: varied inputs in their units, then outputs in theirs.")
    as_sent: dict[str, SentColumn] | None = Field(default=None, description=(
        "Each input the request sent under another key ('speed [mm/min]', 'load [gf]'), under that key: the "
        "column it was read as, the unit and factors that convert the column's values into the key's unit, "
        "and a fixed input's value so; a varied input's values are not repeated (a key map, not a second "
        "copy of the columns: a 10^4-point sweep's JSON would grow by 30-40 %). The CSV form of the table "
        "gives these columns under the keys sent, in their units, to the digits each value holds, in place "
        "of the input's. Absent when every input was sent under its own name."))
    input_warnings: INPUT_WARNINGS[0] = INPUT_WARNINGS[1]
