"""Bodies of ``/v1/optimizations``: a minimum-friction design problem and its certified answer."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BeforeValidator, ConfigDict, Field, create_model

from microbearing import physics
from microbearing.optimize.general import SPEED_GRID_POINTS
from microbearing.optimize.over_envelope import GROUP_LABEL_OVER_ENVELOPE
from microbearing.optimize.problem import DESIGN_VARIABLES
from microbearing.physics.spans import NO_SPACING

from .base import (
    UNIT_KEYS,
    ColumnKeys,
    Convention,
    ConventionName,
    PairSpelling,
    RangeSpelling,
    ResponseModel,
    StrictModel,
    WholeNumber,
    given_at,
    in_one_place,
    only_with_model,
    parameter_fields,
    whole_number,
)
from .friction import INPUT_KEYS, INPUT_WARNINGS, InputKeys

__all__ = ["MODEL_PATTERN", "OptimizationRequest", "OptimizationResult"]

#: ``physics`` (certified DGP), a stored surrogate or a stored calibration (local method).
MODEL_PATTERN = r"^(physics|surrogate:[0-9a-f]{32}|calibrated:[0-9a-f]{32})$"


_LOAD = physics.PARAMETERS["load_N"]
_ANGLE = physics.PARAMETERS["groove_angle_deg"]


def _pair(what: str) -> Field:
    return Field(min_length=2, max_length=2,
                 description=f"[lower, upper] {what}, both included (or {{low, high}}).")


class DesignBounds(InputKeys):
    """Box of the three design variables (a name may carry its unit: ``load [mN]``, converted)."""

    balls: Annotated[list[Annotated[int, Field(ge=1, le=100_000), BeforeValidator(whole_number)]],
                     _pair("total number of balls (both grooves), whole numbers in [1, 100000] [1]"),
                     PairSpelling]
    groove_angle_deg: Annotated[list[Annotated[float, Field(ge=_ANGLE.minimum, le=_ANGLE.maximum)]],
                                _pair(f"groove angle, {_ANGLE.range_text()} [deg]"), PairSpelling]
    load_N: Annotated[list[Annotated[float, Field(ge=_LOAD.minimum, le=_LOAD.maximum)]] | None,
                      Field(default=None, min_length=2, max_length=2, description=(
                          f"[lower, upper] (or {{low, high}}) normal load on the slider, "
                          f"{_LOAD.range_text()}, both included [N]; or give a payload in fixed.load_N "
                          "instead (a given load, not a range).")), PairSpelling] = None


class DesignLimits(StrictModel):
    """Engineering limits; omit one to switch it off."""

    max_contact_pressure_Pa: float | None = Field(
        default=None, ge=1.0, le=1e13,
        description="Upper limit on the peak Hertz pressure 3Q/(2 pi a^2) of a ball-race "
        "contact (the physics output max_contact_pressure_Pa) [Pa].")
    max_friction_force_N: float | None = Field(
        default=None, ge=1e-15, le=1e6,
        description="Upper limit on the friction force mu G at the worst-case speed [N].")
    min_load_capacity_N: float | None = Field(
        default=None, ge=_LOAD.minimum, le=_LOAD.maximum,
        description="The design must carry at least this load: load_N >= it [N].")
    max_load_per_ball_N: float | None = Field(
        default=None, ge=1e-15, le=_LOAD.maximum,
        description="Upper limit on the load per ball G / balls [N].")
    groove_length_m: float | None = Field(
        default=None, ge=1e-7, le=10.0,
        description="Length of each of the two grooves: the fuller one holds "
        "n = ceil(balls/2) balls, which must fit with min_ball_gap_m between neighbours: "
        "n d + (n - 1) gap <= groove_length_m; with balls_touching=false and min_ball_gap_m=0 strictly "
        "n d < groove_length_m, so that balls that would just touch do not fit [m].")
    min_ball_gap_m: float = Field(
        default=0.0, ge=0, le=1.0,
        description="Clearance between neighbouring balls in a groove; 0 lets them just "
        "touch if balls_touching=true, and with balls_touching=false (the default) requires only some "
        "positive clearance (strict fit); > 0 keeps them that far apart [m].")


OptimizationFixed = create_model(
    "OptimizationFixed", __base__=InputKeys,
    __doc__="Physics inputs held fixed (omitted ones take their defaults, or a calibrated model's values). "
            "speed_m_s may be given here or at the top level, not both.",
    **parameter_fields(optional=True, names=[n for n in physics.PARAMETERS
                                             if n not in DESIGN_VARIABLES or n == "load_N"]),
)


class DesignTolerances(InputKeys):
    """Manufacturing tolerances: the design must hold anywhere within nominal +- the tolerance (a name may
    carry its unit: ``groove angle [rad]``, converted)."""

    groove_angle_deg: float | None = Field(
        default=None, ge=0.0, le=10.0,
        description="Half-width of the groove angle's tolerance: the angle made lies anywhere in nominal +- "
                    "this [deg].")


class ConditionSpan(StrictModel):
    """A range of a condition, spelled as an object (read as the pair [low, high])."""

    low: float = Field(description="Lowest value [unit of the column].")
    high: float = Field(description="Highest value, >= low [unit of the column].")


def _condition_spelling(value: Any) -> Any:
    """A condition's value or range as the other routes spell it (:func:`physics.spans.read_span`): ``[v]``
    is the one value v; a longer list, or a set of values (``{"values": [...]}``, which the design has no
    worst case over), refused in words."""
    if isinstance(value, dict) and "spacing" in value:  # one sentence, not pydantic's extra field
        raise ValueError(NO_SPACING)
    if isinstance(value, list) and any(isinstance(v, str) for v in value):  # one sentence, not one per label
        raise ValueError(f"a list of labels is no condition: {GROUP_LABEL_OVER_ENVELOPE}")
    if isinstance(value, list) and len(value) == 1:
        return value[0]
    if isinstance(value, list) and len(value) != 2:
        raise ValueError(f"a list of {len(value)} values is ambiguous: a range is [low, high] or "
                         f"{{\"low\": low, \"high\": high}}, one value a number")
    if isinstance(value, dict) and "values" in value:
        raise ValueError("a set of values is no envelope: a design holds over a range, [low, high] or "
                         "{\"low\": low, \"high\": high} (e.g. the set's lowest and highest), or at one "
                         "value")
    if isinstance(value, bool) or value is None:  # one sentence, not each member's of the union
        raise ValueError(f"must be a number, a range [low, high] or {{\"low\": low, \"high\": high}}, or a "
                         f"factor column's label; not {str(value).lower() if value is not None else 'null'}")
    return value


#: A condition's value or its range (the envelope), [low, high] or {low, high}, in the calibration data's
#: unit; a group label for a factor column.
ConditionRange = Annotated[float | Annotated[list[float], Field(min_length=2, max_length=2)] | ConditionSpan
                           | str, BeforeValidator(_condition_spelling)]



class ParetoRequest(StrictModel):
    """Ask for the Pareto front of mu against a second objective (always runs as a job)."""

    objective: Literal["load_N", "max_contact_pressure_Pa"] = Field(
        description="Second objective: load_N (load capacity, larger is better) or max_contact_pressure_Pa "
                    "(smaller is better).")
    points: WholeNumber = Field(default=10, ge=2, le=50,
                                description="Number of epsilon-constraint levels [1].")


class OptimizationRequest(InputKeys):
    """Minimize mu over integer balls, groove angle and load within bounds and limits."""

    # What the server checks across fields: load_N in bounds (a range) or in fixed (a payload), not
    # both; speed_m_s at the top level or in fixed, not both (or neither for a stored model that holds
    # one); a Pareto front for model physics only; objective mu_upper for a stored model only;
    # conditions for a calibrated model only. (That a
    # lower bound is not above its upper one is checked by the server only.)
    model_config = ConfigDict(**InputKeys.model_config, json_schema_extra={"allOf": [
        in_one_place((("bounds", "load_N"), None), (("fixed", "load_N"), None)),
        {"anyOf": [*in_one_place((("speed_m_s",), None), (("fixed", "speed_m_s"), None))["anyOf"],
                   given_at(("model",), {"pattern": "^(calibrated|surrogate):"})]},
        {"anyOf": [{"properties": {"pareto": {"type": "null"}}},
                   {"properties": {"model": {"const": "physics"}}}]},
        {"anyOf": [{"properties": {"objective": {"const": "mu"}}},
                   given_at(("model",), {"pattern": "^(calibrated|surrogate):"})]},
        only_with_model("conditions")]})

    bounds: DesignBounds = Field(description="Box of the design variables." + INPUT_KEYS)
    fixed: OptimizationFixed = Field(  # type: ignore[valid-type]
        default_factory=OptimizationFixed, description="Physics inputs held fixed." + INPUT_KEYS)
    speed_m_s: Annotated[float | Annotated[list[Annotated[float, Field(ge=0, le=1e3)]], Field(
        min_length=2, max_length=2)] | None, RangeSpelling] = Field(
        default=None, description="Slider speed [m/s], or [low, high] (or {low, high}) to design for the "
        "worst case over "
        "the range (the operating envelope, with the condition ranges and tolerances; the result's "
        "worst_case says where it occurs and proof what is proven): for model physics the high end, proven "
        "(mu grows with speed); for a calibrated model its worst end when its terms are monotone, else the "
        "worst case searched over the whole envelope; for a surrogate without other ranges or tolerances "
        f"the largest mu over {SPEED_GRID_POINTS} equally spaced speeds, both ends included. Required here "
        "or in fixed.")
    constraints: DesignLimits = Field(default_factory=DesignLimits, description="Engineering limits.")
    model: str = Field(default="physics", pattern=MODEL_PATTERN, description=(
        "physics (a certified global optimum by geometric programming), surrogate:<id> or "
        "calibrated:<id> (a local optimum by sequential convex approximation; over an envelope, proven by "
        "geometric programming when the calibrated model's terms allow, see proof)."))
    conditions: Annotated[dict[str, ConditionRange] | None, ColumnKeys] = Field(
        default=None, description="Condition columns a calibrated model's terms read (e.g. "
        "relative_humidity, temperature_C), in the calibration data's units: a value, or a range [low, high] "
        "(or {low, high}) to design for the worst case over the range (the operating envelope); a factor "
        "column takes a group label (e.g. specimen: S3) in a point design; without one the design is judged "
        "for a new group, the spread between groups in its interval." + UNIT_KEYS,
        examples=[{"relative_humidity": [0.3, 0.7], "temperature_C": [20, 60]}])
    tolerances: DesignTolerances | None = Field(
        default=None, description="Tolerances of design variables: the design must hold (objective and "
        "limits) anywhere within nominal +- each.")
    objective: Literal["mu", "mu_upper"] = Field(
        default="mu", description="What the design minimizes the worst case of over the envelope: mu [1], "
        "or mu_upper [1], the 95 % upper bound of a calibrated or surrogate model's prediction (a friction "
        "limit to guarantee).")
    starts: WholeNumber = Field(default=3, ge=1, le=9, description="Starting points per ball count of the "
                                "local method for surrogate and calibrated models [1].")
    time_limit_s: float = Field(default=60.0, gt=0.0, le=3600.0, description=(
        "Over an envelope, for a model without a proof: no new round of the outer approximation starts "
        "after this time; the result then says so, with the worst case found [s]."))
    convention: ConventionName = Field(  # type: ignore[valid-type]
        default=Convention(physics.DEFAULT_CONVENTION), description="Reading of the paper's ball-ball terms.")
    pareto: ParetoRequest | None = Field(default=None, description="Also compute a Pareto front (physics "
                                         "model only).")


class BearingDesign(ResponseModel):
    """A bearing design: ball count, groove angle and load."""

    balls: int = Field(description="Total number of balls [1].")
    groove_angle_deg: float = Field(description="Groove angle [deg].")
    load_N: float = Field(description="Normal load on the slider [N].")


def _design_as_sent() -> Any:
    """A design's variables as the request sent them (beside the design, which stays a physics input)."""
    return Field(default_factory=dict, description=(
        "The design's balls, groove_angle_deg and load_N under the keys the request's bounds (or a fixed "
        "load) were sent with, each in the unit its key states ({'balls': 4, 'groove angle [rad]': 0.87, "
        "'load [gf]': 1.2} where groove_angle_deg is 49.847 and load_N 0.01176798); under their own names "
        "when sent so. Beside the design, not in it: the design stays a point /v1/friction takes as it is."))


class ConstraintStatus(ResponseModel):
    """A bound or limit at the returned design, from the exact physics."""

    name: str = Field(description="balls_min, balls_max, groove_angle_deg_min/max, load_N_min/max or a limit "
                                  "of constraints.")
    value: float = Field(description="The constrained quantity at the design, in the unit its name ends "
                                     "with [1 (balls), deg, N, Pa or m].")
    limit: float = Field(description="The bound or limit, in the unit its name ends with "
                                     "[1 (balls), deg, N, Pa or m].")
    sense: Literal["<=", ">="] = Field(description="value <= limit or value >= limit.")
    active: bool = Field(description="Whether the design sits on it (within 1e-5 relative).")
    satisfied: bool = Field(description="Whether value meets it.")
    decided_by: str = Field(default="physics", description=(
        "The model whose value decided satisfied: physics for the bounds and the limits that do not "
        "depend on mu; for max_friction_force_N the model judging mu (a surrogate's source model, "
        "physics or calibrated:<id>, when the design was verified; else the model optimized)."))
    value_model: float | None = Field(default=None, description=(
        "For a surrogate, the quantity under the surrogate (its friction force mu G; the other limits "
        "repeat value), in the unit its name ends with [1 (balls), deg, N, Pa or m]; null otherwise."))


class BallCountRow(ResponseModel):
    """The optimum of one ball count."""

    balls: int = Field(description="Ball count [1].")
    status: str = Field(description="optimal, optimal_inaccurate, infeasible, does not fit the groove, "
                                    "local optimum, iteration cap reached (the local method's best run for "
                                    "this count stopped unconverged), or no feasible local optimum found.")
    groove_angle_deg: float | None = Field(default=None, description="Optimal groove angle [deg].")
    load_N: float | None = Field(default=None, description="Optimal load [N].")
    mu: float | None = Field(default=None, description="mu of the model at that design [1].")
    mu_solver: float | None = Field(default=None, description="The solver's value [1]; null for the local "
                                    "method (no value apart from the model's).")
    relative_gap: float | None = Field(default=None, description="mu_solver / mu - 1 [1]; null when "
                                       "mu_solver is.")


class Tie(ResponseModel):
    """A design whose mu is within 1e-6 relative of the best."""

    balls: int = Field(description="Ball count [1].")
    groove_angle_deg: float = Field(description="Groove angle [deg].")
    load_N: float = Field(description="Load [N].")
    load_per_ball_N: float = Field(description="Load per ball [N].")
    mu: float = Field(description="mu [1].")


class ParetoPoint(ResponseModel):
    """One Pareto-optimal design."""

    level: float = Field(description="The epsilon level of the second objective [N for load_N, Pa for "
                                     "max_contact_pressure_Pa].")
    mu: float = Field(description="Minimum mu at that level [1].")
    value: float = Field(description="The second objective at the design [N for load_N, Pa for "
                                     "max_contact_pressure_Pa].")
    design: BearingDesign = Field(description="The design.")
    design_as_sent: dict[str, int | float] = _design_as_sent()


class ParetoFront(ResponseModel):
    """Pareto front of mu against a second objective."""

    objective: str = Field(description="The second objective.")
    unit: str = Field(description="Its unit.")
    points: list[ParetoPoint] = Field(description="Non-dominated designs, by increasing value.")
    infeasible_levels: int = Field(description="Levels no design could meet [1].")
    plot_url: str | None = Field(default=None, description="Path of the plot as PNG.")


class Verification(ResponseModel):
    """A design found on a surrogate, checked by the model it stands for."""

    source_model: str = Field(description="physics or calibrated:<id>.")
    model: str = Field(description="The surrogate optimized (surrogate:<id>).")
    mu_model: float = Field(description="mu of the surrogate at the design [1].")
    mu_source: float = Field(description="mu of the source model at the design [1].")
    speed_m_s_source: float = Field(description="Speed of the source's worst case [m/s].")
    relative_difference: float = Field(description="mu_model / mu_source - 1 [1].")
    friction_force_N_model: float = Field(description="Friction force mu G under the surrogate [N].")
    friction_force_N_source: float = Field(description="Friction force mu G under the source model [N].")
    friction_force_ratio: float = Field(description="friction_force_N_source / friction_force_N_model [1].")
    violated: list[str] = Field(description="Limits the source model breaks at the design (empty when none).")
    satisfied: bool = Field(description="Whether the source model meets every limit at the design.")
    resolves: int = Field(description="Re-solves with max_friction_force_N tightened by the ratio of the two "
                                      "friction forces (and a 1e-3 margin) after the source broke it [1].")
    mu_source_certified: bool | None = Field(default=None, description=(
        "Over an envelope: whether mu_source is the source's proven worst case (the physics grows with the "
        "angle made and the speed: exact at the envelope's worst vertex) rather than the largest found by a "
        "search; null for a design at one speed."))


class Envelope(ResponseModel):
    """The operating envelope of a robust design."""

    speed_m_s: list[float] = Field(description="[low, high] slider speed [m/s].")
    conditions: dict[str, list[float]] = Field(
        description="[low, high] of each condition column, in the calibration data's unit.")
    as_sent: dict[str, list[float]] = Field(default_factory=dict, description=(
        "speed_m_s and conditions under the request's keys as sent, each in the unit its key states "
        "({'speed [mm/s]': [20, 50], 'RH [%]': [30, 60], 'temp_F': [70, 100]} where speed_m_s is "
        "[0.02, 0.05], relative_humidity [0.3, 0.6] and temp_K [294.26, 310.93])."))
    tolerances: dict[str, float] = Field(
        description="Half-width of each tolerance (groove_angle_deg [deg]).")
    tolerances_as_sent: dict[str, float] = Field(default_factory=dict, description=(
        "The same under the request's keys as sent, each in the unit its key states "
        "({'groove angle [rad]': 0.01} where groove_angle_deg is 0.5729577951)."))


class WorstCase(ResponseModel):
    """The worst case of the objective over the envelope at the returned design."""

    mu: float | None = Field(default=None, description="The worst mu over the envelope (objective mu) [1].")
    mu_upper: float | None = Field(default=None, description=(
        "The worst 95 % upper bound over the envelope (objective mu_upper) [1]."))
    speed_m_s: float = Field(description="Speed where it occurs [m/s].")
    groove_angle_deg: float = Field(
        description="The angle made (nominal + offset within the tolerance) where it occurs [deg].")
    conditions: dict[str, float] = Field(
        description="Condition values where it occurs, in the calibration data's units.")
    as_sent: dict[str, float] = Field(default_factory=dict, description=(
        "speed_m_s, the conditions and groove_angle_deg under the request's keys as sent (the groove angle "
        "under the bounds'), each in the unit its key states ({'speed [mm/s]': 50, 'RH [%]': 60, "
        "'groove angle [rad]': 0.88} where speed_m_s is 0.05, relative_humidity 0.6 and groove_angle_deg "
        "50.42)."))


class OuterRound(ResponseModel):
    """One round of the outer approximation (models without a proof)."""

    round: int = Field(description="Round number [1].")
    points: int = Field(description="Envelope points the design was optimized over [1].")
    on_set: float = Field(description="The largest objective over those points at the round's design [1].")
    searched: float = Field(description="The largest objective found over the whole envelope there [1].")


class Proof(ResponseModel):
    """What is proven about a robust design."""

    proven: bool = Field(description="Whether the worst case is proven optimal to the gap target.")
    method: str = Field(description=(
        "robust-gp-vertex (the physics, or a calibrated model whose terms are monotone positive monomials: "
        "geometric programming at the envelope's worst vertex), outer-approximation-certified (a calibrated "
        "model with other effect terms: the design by the outer approximation, its worst case certified by "
        "branch and bound; for mu, a lower bound from geometric programs at the worst points) or "
        "outer-approximation-local (no bound: the worst case searched)."))
    lower_bound: float | None = Field(description=(
        "Certified lower bound on the best achievable worst case [1]; null when none could be certified. For "
        "mu_upper of a calibrated model: branch and bound over the designs at the worst envelope points "
        "(interval bounds of mu_upper over each box of designs)."))
    upper_bound: float = Field(description=(
        "The worst case at the returned design [1]: exact, or certified by branch and bound "
        "(outer-approximation-certified), or as searched (outer-approximation-local)."))
    relative_gap: float | None = Field(description=(
        "(upper_bound - lower_bound) / upper_bound [1]; null without a lower bound."))
    gap_target: float = Field(description="The relative gap aimed at [1].")
    statement: str = Field(description=(
        "The argument, in words. A speed or condition value is named under the request's key and in its "
        "unit, the model's column and its value in brackets where they differ ('temp_F at 70 (temp_K "
        "294.261)', 'speed [mm/s] at 50 (speed_m_s 0.05)'); the figures in the model's units are in "
        "worst_case and envelope, the request's in their as_sent."))
    rounds: list[OuterRound] | None = Field(default=None, description="The outer approximation's rounds.")
    worst_case_boxes: int | None = Field(default=None, description=(
        "Boxes of the envelope the branch and bound bounded at the design [1] "
        "(outer-approximation-certified)."))
    worst_case_relative_gap: float | None = Field(default=None, description=(
        "(upper_bound - the worst case found) / upper_bound at the design [1] "
        "(outer-approximation-certified)."))
    lower_bound_boxes: int | None = Field(default=None, description=(
        "For mu_upper: boxes of the designs (groove angle and load per ball count) the branch and bound of "
        "the certified lower bound bounded [1]."))
    upper_bound_certified: bool | None = Field(default=None, description=(
        "For mu_upper: whether upper_bound is certified (branch and bound over the envelope at the design) "
        "or searched; proven needs it."))


class PricedDesign(ResponseModel):
    """A design with its objective at the envelope's centre and over the envelope."""

    design: BearingDesign = Field(description="The design (nominal groove angle).")
    design_as_sent: dict[str, int | float] = _design_as_sent()
    at_centre: float = Field(description="The objective at the envelope's centre [1].")
    worst_case: float = Field(description="The objective's worst case over the envelope [1].")
    limits_hold_over_envelope: bool = Field(description="Whether every limit holds over the whole envelope.")
    worst_case_certified: bool | None = Field(default=None, description=(
        "Whether the worst case is certified (exact at the envelope's worst vertex, or bracketed by branch "
        "and bound) rather than searched."))
    worst_case_upper_bound: float | None = Field(default=None, description=(
        "A certified upper bound of the objective over the envelope [1] (null when searched only)."))


class PriceOfRobustness(ResponseModel):
    """The nominal optimum beside the robust one."""

    nominal: PricedDesign = Field(description="The optimum at the envelope's centre, without tolerances.")
    robust: PricedDesign = Field(description="The robust optimum.")
    ratio: float = Field(description=(
        "nominal worst case / robust worst case [1] (below 1 only when the nominal design breaks a limit "
        "somewhere in the envelope)."))


class OptimizationResult(ResponseModel):
    """The best design, checked with the exact physics, and why it is the best."""

    model: str = Field(description="The model optimized.")
    method: str = Field(description="dgp-enumeration (certified global), sequential-convex-approximation "
                                    "(local), or for an envelope robust-gp-vertex (proven), "
                                    "outer-approximation-certified (the worst case at the design certified; "
                                    "proof.proven says whether the design is) or outer-approximation-local "
                                    "(not proven).")
    design: BearingDesign = Field(description="The best design (the fewest balls among ties).")
    design_as_sent: dict[str, int | float] = _design_as_sent()
    mu: float = Field(description="mu of the model at the design (the exact physics for model physics) [1].")
    mu_solver: float = Field(description="The solver's value of mu [1].")
    relative_gap: float = Field(description=(
        "mu_solver / mu - 1 [1]: the solver's value of mu against the model's own at the design (rounding of "
        "the solve, may be negative); not the optimality gap, which is proof.relative_gap with an envelope "
        "and the certificate otherwise."))
    mu_physics: float | None = Field(default=None, description="The exact physics at the design (equal to mu "
                                     "for model physics) [1].")
    source_model: str | None = Field(default=None, description=(
        "For a surrogate: the model it stands for (physics or calibrated:<id>), which verified the design "
        "and judged every limit; null otherwise."))
    mu_source: float | None = Field(default=None, description=(
        "For a surrogate: mu of its source model at the design (worst case over the speeds) [1]."))
    verification: Verification | None = Field(default=None, description=(
        "For a surrogate: the design checked by its source model."))
    speed_m_s: float = Field(description="Speed designed for: the worst case of a range (its high end for "
                             "model physics, the worst speed of the grid for other models) [m/s].")
    constraints: list[ConstraintStatus] = Field(description="Every bound and limit at the design.")
    per_ball_count: list[BallCountRow] = Field(description="One row per ball count of the bounds.")
    ties: list[Tie] = Field(description="Designs within 1e-6 relative of the best mu, the returned one "
                                        "included.")
    certificate: str = Field(description="What is proven about the design, and how.")
    solve_time_s: float = Field(description="Time of the optimization [s].")
    pareto: ParetoFront | None = Field(default=None, description="The Pareto front, when asked for.")
    mu_lower: float | None = Field(default=None, description=(
        "For a calibrated model or a surrogate: lower bound of the 95 % prediction interval of mu at the "
        "design [1]."))
    mu_upper: float | None = Field(default=None, description=(
        "For a calibrated model or a surrogate: upper bound of the 95 % prediction interval of mu at the "
        "design [1]."))
    in_domain: bool | None = Field(default=None, description=(
        "For a calibrated model: whether the optimum lies within the ranges of the calibration data; for a "
        "surrogate: within its trained space (false: it is an extrapolation, see domain_warnings)."))
    domain_warnings: list[str] | None = Field(default=None, description=(
        "For a calibrated model (a surrogate): one sentence per input outside the calibration data (the "
        "trained space) at the optimum, naming the column, the value and the range."))
    objective: Literal["mu", "mu_upper"] | None = Field(default=None, description=(
        "With an operating envelope: the objective whose worst case the design minimizes (mu is then that "
        "worst case) [1]."))
    envelope: Envelope | None = Field(default=None, description="The operating envelope designed for.")
    worst_case: WorstCase | None = Field(default=None, description=(
        "With an envelope: the worst case of the objective at the returned design and where it occurs."))
    input_warnings: INPUT_WARNINGS[0] = INPUT_WARNINGS[1]
    proof: Proof | None = Field(default=None, description=(
        "With an envelope: what is proven, the certified lower bound on the best achievable worst case and "
        "the gap."))
    price_of_robustness: PriceOfRobustness | None = Field(default=None, description=(
        "With an envelope: the nominal optimum (at the envelope's centre) beside the robust one, each with "
        "its worst case."))
