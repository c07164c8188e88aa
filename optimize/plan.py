"""A design request in plain values, planned into a design problem and the envelope it must hold over, and
a surrogate's design verified over that envelope by the model the surrogate stands for.

These are the use cases of a design request below any web layer: a caller (the REST service's
``/v1/optimizations``, a script) writes the request as a :class:`DesignRequest`, checks it with
:func:`check_request` before it looks the named model up, resolves that model, and calls
:func:`plan_design`; it then runs the plan (:func:`optimize.optimize_design` for the physics,
:func:`optimize.optimize_model` for another model, :func:`optimize.robust.optimize_robust` over an
envelope) and, for a surrogate's robust design, :func:`verify_over_envelope`. A request that cannot
become a problem raises :class:`PlanError`, naming each offending field by its dotted path in the
request (``fixed.load_N``, ``conditions.relative_humidity``); limits that conflict whatever the model
raise :class:`~optimize.solve.InfeasibleDesignError` (:func:`optimize.general.check_exact_limits`).

Examples
--------
>>> plan = plan_design(DesignRequest(balls=(3, 12), groove_angle_deg=(30, 60), load_N=(0.001, 0.05),
...                                  speed_m_s=0.05))
>>> plan.envelope is None, plan.problem.bounds.balls
(True, (3, 12))
>>> try:
...     plan_design(DesignRequest(balls=(3, 12), groove_angle_deg=(30, 60), speed_m_s=0.05))
... except PlanError as error:
...     error.errors
[('bounds.load_N', 'required: [lower, upper] [N], or a payload in fixed.load_N')]
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from microbearing import physics
from microbearing.physics.model import Model

from .general import check_exact_limits, compare_with_source
from .over_envelope import GROUP_LABEL_OVER_ENVELOPE
from .problem import DESIGN_VARIABLES, Constraints, DesignBounds, DesignProblem
from .robust import Envelope, certified_worst_case_of, check_model, shifted_problem, worst_case_of

__all__ = ["DesignPlan", "DesignRequest", "PlanError", "check_request", "plan_design", "verify_over_envelope"]

#: Fields of a request that a :class:`DesignProblem` error may name first (``fixed.<name>: ...``).
_PROBLEM_FIELDS = ("bounds", "fixed", "constraints", "speed_m_s", "convention")


class PlanError(ValueError):
    """A design request that cannot become a problem.

    Parameters
    ----------
    errors : list of (str, str)
        ``(field, detail)`` per error: the field's dotted path in the request (``fixed.load_N``,
        ``conditions.x``), or ``""`` for the request as a whole.
    """

    def __init__(self, errors: list[tuple[str, str]]):
        super().__init__("; ".join(f"{name}: {detail}" if name else detail for name, detail in errors))
        self.errors = errors


@dataclass(frozen=True)
class DesignRequest:
    """What a design request asks, in plain values (units as in :data:`physics.PARAMETERS`).

    Attributes
    ----------
    balls : (int, int)
        Bounds of the ball count. [1]
    groove_angle_deg : (float, float)
        Bounds of the groove angle. [deg]
    load_N : (float, float) or None
        Bounds of the load [N]; None when ``fixed`` gives a payload (``fixed["load_N"]``).
    fixed : mapping
        Physics inputs held at one value, name -> value in its unit; may hold ``load_N`` (a payload
        [N]) and ``speed_m_s`` (a speed [m/s] or [low, high]).
    speed_m_s : float, (float, float) or None
        Slider speed or its range [m/s]; None: from ``fixed`` or the value the model holds.
    constraints : mapping
        Keyword arguments of :class:`~optimize.problem.Constraints` (limits, in their units).
    conditions : mapping
        Condition columns of a calibrated model: a value or [low, high] (in the calibration data's
        unit), or a group label (text).
    tolerances : mapping
        Half-widths of design variables made to a tolerance (``groove_angle_deg`` [deg]).
    objective : {"mu", "mu_upper"}
        What to minimize (``mu_upper``, the 95 % upper bound, over an envelope only).
    model : str
        ``"physics"``, ``"calibrated:<id>"`` or ``"surrogate:<id>"``.
    convention : str
        Physics convention (:data:`physics.CONVENTIONS`) of the physics; a stored model has its own.
    pareto : bool
        Whether a Pareto front is asked for as well.
    readings : mapping
        How ``speed_m_s``, each condition and the design bounds (``groove_angle_deg``, ``load_N``) were sent
        (:class:`physics.columns.Reading`, the request's key and unit), for the words of a robust design's
        proof (:attr:`Envelope.readings`).
    """

    balls: tuple[int, int]
    groove_angle_deg: tuple[float, float]
    load_N: tuple[float, float] | None = None
    fixed: Mapping[str, Any] = field(default_factory=dict)
    speed_m_s: Any = None
    constraints: Mapping[str, Any] = field(default_factory=dict)
    conditions: Mapping[str, Any] = field(default_factory=dict)
    tolerances: Mapping[str, float] = field(default_factory=dict)
    objective: str = "mu"
    model: str = "physics"
    convention: str = physics.DEFAULT_CONVENTION
    pareto: bool = False
    readings: Mapping[str, Any] = field(default_factory=dict)

    def is_robust(self, speed_m_s: Any) -> bool:
        """Whether the design must hold over an envelope (condition ranges, tolerances, ``mu_upper``, or a
        range of ``speed_m_s``, the speed it is asked at [m/s]; None leaves speed out)."""
        ranges = any(isinstance(v, list | tuple) for v in self.conditions.values())
        tolerance = self.tolerances.get("groove_angle_deg") is not None
        return ranges or tolerance or self.objective != "mu" or isinstance(speed_m_s, list | tuple)


@dataclass(frozen=True)
class DesignPlan:
    """A checked design request, ready to run.

    Attributes
    ----------
    problem : DesignProblem
        The problem: bounds, limits, the speed (or its range), and fixed values (the model's own
        included).
    envelope : Envelope or None
        Where a robust design must hold (:func:`optimize.robust.optimize_robust`); None for a design at
        one point.
    """

    problem: DesignProblem
    envelope: Envelope | None


def check_request(request: DesignRequest) -> None:
    """The checks of a request that need no model (a caller makes them before it looks the model up).

    Raises
    ------
    PlanError
        ``pareto`` asked of another model than the physics; ``conditions`` given to a model that is not
        calibrated (each label among them named too).
    """
    if request.pareto and request.model != "physics":
        raise PlanError([("pareto", "a Pareto front is computed for model physics only")])
    if request.conditions and not request.model.startswith("calibrated:"):
        # A label (text) is a group of a calibrated model's factor column; named where it stands.
        raise PlanError([("conditions", "extra input columns are read by calibrated models only")]
                        + [(f"conditions.{name}", "must be a number (a label is read by a calibrated model's "
                            "factor column only)")
                           for name, value in request.conditions.items() if isinstance(value, str)])


def plan_design(request: DesignRequest, model: Model | None = None) -> DesignPlan:
    """The design problem of a request, and the envelope a robust design must hold over.

    Parameters
    ----------
    request : DesignRequest
        The request.
    model : Model, optional
        The model ``request.model`` names (resolved by the caller); None for the physics. The values
        it holds (a calibration's fixed and fitted ones, those a surrogate was trained at) are the
        problem's fixed values and its speed when the request gives none; its convention is the
        problem's.

    Returns
    -------
    DesignPlan

    Raises
    ------
    PlanError
        Naming the field: the load given twice or not at all, the speed likewise, a value out of its
        range, a group label over an envelope, a condition or objective the model cannot be asked.
    InfeasibleDesignError
        When the limits that do not depend on the model conflict with each other or the bounds.
    """
    check_request(request)
    values = {} if model is None else {**model.fixed, **model.fitted}
    convention = str(request.convention) if model is None else model.convention
    fixed = dict(request.fixed)
    _refuse_values_the_model_holds(request, model, fixed)
    # A payload is a given, not a range: fixed.load_N is the load's bounds [G, G].
    load = fixed.pop("load_N", None)
    if load is not None and request.load_N is not None:
        raise PlanError([("fixed.load_N",
                          "give load_N in bounds (a range) or in fixed (a payload), not both")])
    if load is None and request.load_N is None:
        raise PlanError([("bounds.load_N", "required: [lower, upper] [N], or a payload in fixed.load_N")])
    load_bounds = (load, load) if load is not None else tuple(request.load_N)
    speed_in_fixed = "speed_m_s" in fixed
    if speed_in_fixed and request.speed_m_s is not None:
        raise PlanError([("speed_m_s", "give speed_m_s here or in fixed, not both")])
    speed = fixed.pop("speed_m_s", request.speed_m_s)
    if speed is None:
        speed = values.get("speed_m_s")
    if speed is None:
        raise PlanError([("speed_m_s", "required: a speed [m/s] or [low, high], here or in fixed")])
    # The values the model holds: the physics checks of limits and of the optimum run there too.
    inherited = {k: v for k, v in values.items()
                 if k in physics.PARAMETERS and k not in DESIGN_VARIABLES and k != "speed_m_s"}
    try:
        problem = DesignProblem(
            DesignBounds(tuple(request.balls), tuple(request.groove_angle_deg), load_bounds),
            speed_m_s=tuple(speed) if isinstance(speed, list | tuple) else speed,
            constraints=Constraints(**request.constraints),
            fixed={**inherited, **fixed}, convention=convention)
    except ValueError as exc:
        name = _problem_field(str(exc), speed_in_fixed)
        raise PlanError([("fixed.load_N" if load is not None and name == "bounds.load_N" else name,
                          str(exc))]) from None
    # Conflicts of the limits that do not depend on the model hold on every model.
    check_exact_limits(problem)
    # A Pareto front over a speed range alone keeps its proven high end; other envelopes have no front.
    if request.pareto and request.is_robust(None):
        raise PlanError([("pareto", "a Pareto front is computed at one point or over a speed range, not over "
                                    "condition ranges, tolerances or mu_upper")])
    if request.pareto or not request.is_robust(speed):
        return DesignPlan(problem, None)
    envelope = _envelope(request, speed)
    try:
        check_model(model, envelope, request.objective)
        shifted_problem(problem, envelope.angle_tolerance_deg, envelope.speed_m_s[1])
    except ValueError as exc:
        raise PlanError([(_field(exc), str(exc))]) from None
    return DesignPlan(problem, envelope)


def _refuse_values_the_model_holds(request: DesignRequest, model: Model | None,
                                   fixed: Mapping[str, Any]) -> None:
    """A fixed physics input the model would not use, refused where it would be dropped without a word.

    A surrogate answers only at the values it was trained at (:attr:`Model.inputs`' defaults, its space's
    fixed values) for an input that is not one of its dimensions; a calibrated model over an envelope
    holds its own fixed and fitted values (a robust design's interval carries a fitted value's
    uncertainty). At one point a calibrated model takes a value given as an override, as
    ``/v1/friction`` does.
    """
    if model is None:
        return
    if model.kind == "surrogate":
        trained = {name: spec.default for name, spec in model.inputs.items() if spec.default is not None}
        speeds = request.speed_m_s if isinstance(request.speed_m_s, list | tuple) else [request.speed_m_s]
        asked = [(f"fixed.{name}", name, value) for name, value in fixed.items()
                 if name not in DESIGN_VARIABLES]
        asked += [("speed_m_s", "speed_m_s", v) for v in speeds if v is not None]  # as in fixed
        found: dict[str, str] = {}  # the first value refused per field
        for field_name, name, value in asked:
            if (name in trained and not isinstance(value, bool)
                    and not math.isclose(float(value), float(trained[name]), rel_tol=1e-12)):
                found.setdefault(field_name, f"{model.reference} {model.unread_words(name, value)}")
        errors = list(found.items())
    elif request.is_robust(fixed.get("speed_m_s", request.speed_m_s)):
        held = {**model.fixed, **model.fitted}
        errors = [(f"fixed.{name}", f"{model.reference} holds {name} = {held[name]:g} "
                   f"({'fitted' if name in model.fitted else 'fixed at calibration'}); a robust design over "
                   f"an envelope keeps the model's value (its uncertainty is in the interval), so {value:g} "
                   "would not be used: leave it out, or calibrate with it fixed")
                  for name, value in fixed.items()
                  if name in held and name not in DESIGN_VARIABLES and name != "speed_m_s"
                  and not isinstance(value, bool) and not isinstance(held[name], bool)
                  and not math.isclose(float(value), float(held[name]), rel_tol=1e-12)]
    else:
        errors = []
    if errors:
        raise PlanError(errors)


def _problem_field(message: str, speed_in_fixed: bool) -> str:
    """The field a :class:`DesignProblem` error names first (``bounds.load_N: ...``), or ``""``."""
    head = message.split(" ", 1)[0].rstrip(":")
    if head == "speed_m_s" and speed_in_fixed:
        return "fixed.speed_m_s"
    return head if head.split(".")[0] in _PROBLEM_FIELDS else ""


def _field(error: ValueError) -> str:
    """The field an envelope or model error names first (``conditions.x: ...``)."""
    return str(error).split(" ", 1)[0].rstrip(":")


def _envelope(request: DesignRequest, speed: Any) -> Envelope:
    labels = [name for name, value in request.conditions.items() if isinstance(value, str)]
    if labels:
        raise PlanError([(f"conditions.{name}", GROUP_LABEL_OVER_ENVELOPE) for name in labels])
    try:
        return Envelope(tuple(speed) if isinstance(speed, list) else speed, request.conditions,
                        request.tolerances, request.readings)
    except ValueError as exc:
        raise PlanError([(_field(exc), str(exc))]) from None


def verify_over_envelope(problem: DesignProblem, envelope: Envelope, design: Mapping[str, Any],
                         model: Callable[[Mapping[str, Any]], Any], model_name: str,
                         source_model: Callable[[Mapping[str, Any]], Any],
                         source_name: str) -> dict[str, Any]:
    """A robust design found on ``model`` (a surrogate) judged by the model it stands for, over the envelope.

    Each model's worst μ over the envelope at the design: the surrogate's as searched
    (:func:`optimize.robust.worst_case_of`), the source's certified where it can be
    (:func:`optimize.robust.certified_worst_case_of`: the physics' exact, at the envelope's worst
    vertex); the friction-force limit judged by the source's.

    Parameters
    ----------
    problem : DesignProblem
        The problem as planned.
    envelope : Envelope
        Where the design must hold.
    design : mapping
        ``balls`` [1], ``groove_angle_deg`` [deg], ``load_N`` [N].
    model, source_model : callable
        The optimized model and its source, ``points -> mu`` [1].
    model_name, source_name : str
        Their names (``"surrogate:<id>"``, ``"physics"``). [-]

    Returns
    -------
    dict
        The fields of :func:`optimize.general.compare_with_source` (``speed_m_s_source`` [m/s] where the
        source's worst case is), ``violated`` (``["max_friction_force_N"]`` when the source breaks it)
        and ``satisfied``, ``resolves`` (0: a robust design is not re-solved) and ``mu_source_certified``.
    """
    mu_model, _ = worst_case_of(model, problem, envelope, design)
    mu_source, where, certified = certified_worst_case_of(source_model, problem, envelope, design)
    load = float(design["load_N"])
    limit = problem.constraints.max_friction_force_N
    violated = ["max_friction_force_N"] if limit is not None and mu_source * load > limit else []
    return {**compare_with_source(model_name, source_name, mu_model, mu_source, where["speed_m_s"], load),
            "violated": violated, "satisfied": not violated, "resolves": 0, "mu_source_certified": certified}
