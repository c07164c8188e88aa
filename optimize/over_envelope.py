"""The operating envelope and the worst case of an objective over it, as the robust design reads them.

An :class:`Envelope` states the speeds, conditions and tolerances a design must hold over; the functions
here ask a model for its objective at (design, envelope point) pairs (:func:`evaluator`), search the
worst case over the envelope (:func:`worst_case_search`) and check what a model can be asked
(:func:`check_model`). :mod:`optimize.robust` says how the worst case is proven.
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy import optimize as sciopt

from microbearing import physics
from microbearing.physics.model import Model
from microbearing.physics.spans import read_span

from .problem import DESIGN_VARIABLES, DesignBounds, DesignProblem

#: The objectives a design may minimize the worst case of.
OBJECTIVES = ("mu", "mu_upper")
#: Design variables a tolerance may be given for (the angle: μ is monotone in it, see the module docstring).
TOLERANCE_NAMES = ("groove_angle_deg",)


_ANGLE = physics.PARAMETERS["groove_angle_deg"]


def _range(field_name: str, value: Any, minimum: float | None = None) -> tuple[float, float]:
    """A range, [low, high] or {low, high} (a number is a range of one point), finite and ordered, as every
    route reads it (:func:`physics.spans.read_span`), or a ValueError."""
    span = read_span(field_name, value)
    if not span.is_range and len(span.values) > 1:
        raise ValueError(f"{field_name}: a set of values has no worst case over a range; give [low, high]")
    if minimum is not None and span.low < minimum:
        raise ValueError(f"{field_name} must be >= {minimum:g}; got {span.low:g}")
    return span.low, span.high


@dataclass(frozen=True)
class Envelope:
    """Where a design must hold: ranges of speed and conditions, tolerances of design variables.

    Parameters
    ----------
    speed_m_s : float or tuple of float
        Slider speed, or [low, high]. [m/s]
    conditions : mapping of str to float or tuple of float, optional
        Condition columns a calibrated model reads (e.g. ``relative_humidity`` [fraction or as in the
        calibration data], ``temperature_C`` [degC]): a value or [low, high], in the data's unit.
    tolerances : mapping of str to float, optional
        Half-widths δ of design variables made to a tolerance: the design must hold anywhere within
        nominal ± δ. Only ``groove_angle_deg`` [deg].
    readings : mapping of str to physics.columns.Reading, optional
        How ``speed_m_s``, each condition and each design variable's bounds (``groove_angle_deg``,
        ``load_N``) were sent (the key and unit of a request), and each tolerance under
        ``tolerances.<name>`` (``groove angle [rad]``), for the words of a proof (:meth:`said`,
        :meth:`said_design`, :meth:`said_tolerance`); the figures stay in the model's units. Not compared.

    Raises
    ------
    ValueError
        Naming the field (``speed_m_s``, ``conditions.<name>``, ``tolerances.<name>``).
    """

    speed_m_s: float | tuple[float, float]
    conditions: Mapping[str, Any] = field(default_factory=dict)
    tolerances: Mapping[str, float] = field(default_factory=dict)
    readings: Mapping[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        lo, hi = _range("speed_m_s", self.speed_m_s)
        for v in (lo, hi):
            try:
                physics.validate("speed_m_s", v)
            except ValueError as exc:
                raise ValueError(f"speed_m_s: {exc}") from None
        object.__setattr__(self, "speed_m_s", (lo, hi))
        object.__setattr__(self, "conditions", {str(name): _range(f"conditions.{name}", value)
                                                for name, value in dict(self.conditions).items()})
        tolerances = {}
        for name, value in dict(self.tolerances).items():
            if name not in TOLERANCE_NAMES:
                raise ValueError(f"tolerances.{name}: a tolerance is taken on {', '.join(TOLERANCE_NAMES)} "
                                 "only")
            if isinstance(value, bool) or not isinstance(value, int | float) or not (
                    math.isfinite(value) and 0 <= value <= 10):
                raise ValueError(f"tolerances.{name} must be a number in [0, 10] [deg]; got {value!r}")
            tolerances[name] = float(value)
        object.__setattr__(self, "tolerances", tolerances)

    @property
    def angle_tolerance_deg(self) -> float:
        """δ of the groove angle (0 without a tolerance). [deg]"""
        return self.tolerances.get("groove_angle_deg", 0.0)

    def axes(self) -> dict[str, tuple[float, float]]:
        """Every dimension of the envelope that is a range: ``speed_m_s``, the conditions, and
        ``groove_angle_offset_deg`` (the offset from the nominal angle, [-δ, δ]). [their units]"""
        axes = {}
        if self.speed_m_s[0] < self.speed_m_s[1]:
            axes["speed_m_s"] = self.speed_m_s
        axes.update({f"conditions.{n}": r for n, r in self.conditions.items() if r[0] < r[1]})
        if self.angle_tolerance_deg > 0:
            axes["groove_angle_offset_deg"] = (-self.angle_tolerance_deg, self.angle_tolerance_deg)
        return axes

    def centre(self) -> dict[str, Any]:
        """The envelope's centre: ``speed_m_s`` [m/s] and ``conditions`` (midpoints), no angle offset."""
        return {"speed_m_s": 0.5 * sum(self.speed_m_s),
                "conditions": {n: 0.5 * (lo + hi) for n, (lo, hi) in self.conditions.items()}}

    def point(self, values: Mapping[str, float]) -> dict[str, Any]:
        """A point of the envelope from axis values (the other dimensions at their single value)."""
        conditions = {n: float(values.get(f"conditions.{n}", lo)) for n, (lo, _) in self.conditions.items()}
        return {"speed_m_s": float(values.get("speed_m_s", self.speed_m_s[0])), "conditions": conditions,
                "groove_angle_offset_deg": float(values.get("groove_angle_offset_deg", 0.0))}

    def said(self, name: str, value: float) -> str:
        """A value of ``speed_m_s`` or a condition (in the model's unit) as a proof's words give it: under
        the key it was sent as, in that unit, the column's value in brackets (:meth:`physics.columns.Reading.
        said`: ``T [degF] at 70 (temperature_K 294.261)``); ``speed 0.05 m/s`` or ``relative_humidity at
        0.6`` when it was sent so."""
        reading = self.readings.get(name)
        if reading is not None:
            return reading.said(value)
        return f"speed {value:g} m/s" if name == "speed_m_s" else f"{name} at {value:g}"

    def said_tolerance(self, delta: float) -> str:
        """The groove angle's tolerance ``delta`` [deg] (or the angle moved by it) as a proof's words give
        it: in the unit its key was sent in, the value in deg in brackets (``0.01 rad (0.572958 deg)`` for
        ``groove angle [rad]``: 0.01); ``0.5 deg`` when it was sent in deg.

        >>> from microbearing.physics.columns import read_name
        >>> Envelope(0.05, tolerances={"groove_angle_deg": 0.5729577951308232},
        ...          readings={"tolerances.groove_angle_deg": read_name("groove angle [rad]")}
        ...          ).said_tolerance(0.5729577951308232)
        '0.01 rad (0.572958 deg)'
        """
        reading = self.readings.get("tolerances.groove_angle_deg")
        if reading is None or not reading.reading or reading.offset:  # a half-width is scaled, never offset
            return f"{delta:g} deg"
        return f"{reading.set_point(delta):g} {reading.sent_unit} ({delta:g} deg)"

    def said_design(self, design: Mapping[str, Any]) -> str:
        """A design (``balls``, ``groove_angle_deg`` [deg], ``load_N`` [N]) as a proof's words give it: the
        angle and load under the bounds' keys as sent, in their units, the column's value in brackets
        (``groove angle [rad] at 0.8901179 (groove_angle_deg 51.0000000)``); ``51.0000000 deg`` and
        ``0.01 N`` when they were sent so."""
        words = [f"{float(design['balls']):g} balls"]
        for name, unit, digits in (("groove_angle_deg", "deg", ".7f"), ("load_N", "N", ".7g")):
            value = float(design[name])
            reading = self.readings.get(name)
            if reading is None:
                words.append(f"{value:{digits}} {unit}")
            elif not reading.reading:
                words.append(f"{reading.sent} at {value:{digits}}")
            else:
                words.append(f"{reading.sent} at {reading.set_point(value):.7g} ({name} {value:{digits}})")
        return ", ".join(words)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields: ranges as [low, high]."""
        return {"speed_m_s": list(self.speed_m_s),
                "conditions": {n: list(r) for n, r in self.conditions.items()},
                "tolerances": dict(self.tolerances)}


# Worst case over an envelope


def objective_values(model: Model | None, objective: str, columns: dict[str, Any],
                     convention: str) -> np.ndarray:
    """The objective at columnar points: the physics' μ, a model's μ or its ``mu_upper``. [1]"""
    with np.errstate(all="ignore"):
        if model is None:
            return physics.evaluate(convention=convention, outputs=["mu"], **columns).mu
        # The values a model holds are its own: given as columns, a calibrated model would read a fitted
        # value as known and leave its uncertainty out of the interval.
        held = {*model.fixed, *model.fitted}
        columns = {name: value for name, value in columns.items() if name not in held}
        if objective == "mu":
            return np.asarray(model(columns), dtype=float)
        predict = getattr(model, "predict", None)
        if predict is not None:  # a calibrated model: its interval, without the physics' other outputs
            return np.asarray(predict(columns, domain=False).mu_upper, dtype=float)
        return np.asarray(model.evaluate(columns, [objective]).values[objective], dtype=float)


def envelope_columns(problem: DesignProblem, envelope: Envelope, design: Mapping[str, Any],
                     points: Sequence[Mapping[str, Any]], angle_shift: float) -> dict[str, Any]:
    """Columns of every (design, envelope point) pair, designs varying fastest.

    ``design`` holds arrays of n designs (the angle being the optimizer's θ' = θ + ``angle_shift``);
    ``points`` are m envelope points; the result has m n values per column.
    """
    n = int(np.size(design["balls"]))
    m = len(points)
    offsets = np.repeat([p["groove_angle_offset_deg"] for p in points], n)
    theta = np.tile(np.broadcast_to(design["groove_angle_deg"], (n,)), m) - angle_shift + offsets
    cols = problem.physics_inputs(np.tile(np.broadcast_to(design["balls"], (n,)), m), theta,
                                  np.tile(np.broadcast_to(design["load_N"], (n,)), m),
                                  speed_m_s=np.repeat([p["speed_m_s"] for p in points], n))
    for name in envelope.conditions:
        cols[name] = np.repeat([p["conditions"][name] for p in points], n)
    return cols


def worst_case_search(evaluate: Callable[[list[dict[str, Any]]], np.ndarray], envelope: Envelope,
                      levels: int | None = None, polish: int = 3) -> tuple[float, dict[str, Any], int]:
    """The largest value of a function over the envelope: a grid of every axis, then local ascent.

    Parameters
    ----------
    evaluate : callable
        Values at a list of envelope points (:meth:`Envelope.point`). [1]
    envelope : Envelope
        The envelope.
    levels : int, optional
        Grid levels per axis (both ends included); by default 9 for up to 2 axes, 5 for 3-4, 3 above.
    polish : int, default 3
        Best grid points from which a bounded quasi-Newton ascent (L-BFGS-B) starts. [1]

    Returns
    -------
    value : float
        The largest value found. [1]
    point : dict
        Where it occurs (:meth:`Envelope.point`).
    evaluations : int
        Points evaluated. [1]
    """
    axes = envelope.axes()
    names = list(axes)
    if not names:
        point = envelope.point({})
        return float(evaluate([point])[0]), point, 1
    k = len(names)
    levels = levels or (9 if k <= 2 else 5 if k <= 4 else 3)
    grid = np.array(list(itertools.product(np.linspace(0.0, 1.0, levels), repeat=k)))
    lo = np.array([axes[n][0] for n in names])
    span = np.array([axes[n][1] - axes[n][0] for n in names])

    def points_of(unit: np.ndarray) -> list[dict[str, Any]]:
        return [envelope.point(dict(zip(names, lo + span * u, strict=True))) for u in unit]

    values = np.asarray(evaluate(points_of(grid)), dtype=float)
    count = len(grid)
    best = int(np.nanargmax(values))
    best_value, best_unit = float(values[best]), grid[best]
    step = 1e-7
    calls = 0

    def negative(u: np.ndarray) -> tuple[float, np.ndarray]:
        # The value and a forward-difference gradient (backward at the upper edge) in one call of the model.
        nonlocal calls
        sign = np.where(u + step <= 1.0, 1.0, -1.0)
        at = np.vstack([u, u + np.diag(sign * step)])
        f = -np.asarray(evaluate(points_of(at)), dtype=float)
        calls += len(at)
        return float(f[0]), (f[1:] - f[0]) / (sign * step)

    for start in np.argsort(-np.nan_to_num(values, nan=-np.inf))[:polish]:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            found = sciopt.minimize(negative, grid[start], jac=True, method="L-BFGS-B",
                                    bounds=[(0.0, 1.0)] * k, options={"maxiter": 50})
        if np.isfinite(found.fun) and -found.fun > best_value:
            best_value, best_unit = float(-found.fun), np.clip(found.x, 0.0, 1.0)
    return best_value, points_of(best_unit[None, :])[0], count + calls


def worst_case_of(mu_model: Callable[[Mapping[str, Any]], Any], problem: DesignProblem, envelope: Envelope,
                  design: Mapping[str, Any]) -> tuple[float, dict[str, Any]]:
    """The largest value of any ``mu_model(points)`` callable over the envelope at a design, as searched.

    What verifies a surrogate's robust design by the model it stands for (:func:`worst_case_search`;
    not a bound).

    Parameters
    ----------
    mu_model : callable
        ``points -> mu`` [1] over columnar physics inputs and condition columns.
    problem : DesignProblem
        Its fixed values and convention.
    envelope : Envelope
        The envelope.
    design : mapping
        ``balls`` [1], ``groove_angle_deg`` (nominal) [deg], ``load_N`` [N].

    Returns
    -------
    value : float
        The largest value found. [1]
    point : dict
        Where (:meth:`Envelope.point`).
    """
    design = {k: np.array([float(design[k])]) for k in DESIGN_VARIABLES}

    def evaluate(points: list[dict[str, Any]]) -> np.ndarray:
        with np.errstate(all="ignore"):
            return np.asarray(mu_model(envelope_columns(problem, envelope, design, points, 0.0)), dtype=float)

    value, point, _ = worst_case_search(evaluate, envelope)
    return value, point


def certified_worst_case_of(mu_model: Callable[[Mapping[str, Any]], Any], problem: DesignProblem,
                            envelope: Envelope,
                            design: Mapping[str, Any]) -> tuple[float, dict[str, Any], bool]:
    """The largest μ of a ``mu_model(points)`` callable over the envelope at a design, certified if it can be.

    The physics (a callable of :func:`optimize.general.physics_model`, which carries ``physics_convention``)
    grows with the angle made and the speed (its posynomial form, module docstring), and reads no
    condition: its worst case is exactly its value at the angle made high and the highest speed. Any other
    callable is searched (:func:`worst_case_of`), not bounded.

    Parameters
    ----------
    mu_model : callable
        ``points -> mu`` [1].
    problem : DesignProblem
        Its fixed values and convention.
    envelope : Envelope
        The envelope.
    design : mapping
        ``balls`` [1], ``groove_angle_deg`` (nominal) [deg], ``load_N`` [N].

    Returns
    -------
    value : float
        The worst case (exact for the physics; the largest found otherwise). [1]
    point : dict
        Where (:meth:`Envelope.point`).
    certified : bool
        Whether ``value`` is the proven maximum.
    """
    searched, where = worst_case_of(mu_model, problem, envelope, design)
    if getattr(mu_model, "physics_convention", None) is None or envelope.conditions:
        return searched, where, False
    vertex = envelope.point({"speed_m_s": envelope.speed_m_s[1],
                             "groove_angle_offset_deg": envelope.angle_tolerance_deg})
    columns = envelope_columns(problem, envelope, {k: np.array([float(design[k])]) for k in DESIGN_VARIABLES},
                       [vertex], 0.0)
    with np.errstate(all="ignore"):
        value = float(np.asarray(mu_model(columns), dtype=float)[0])
    # The search at the design is a check of the argument: nothing it finds may be above the vertex.
    if searched > value * (1 + 1e-12):
        return searched, where, False
    return value, vertex, True


def vertices_and_centre(envelope: Envelope) -> list[dict[str, Any]]:
    """The envelope's centre and every vertex of its axes, as points (:meth:`Envelope.point`)."""
    axes = envelope.axes()
    names = list(axes)
    corners = [dict(zip(names, c, strict=True)) for c in itertools.product(*(axes[n] for n in names))]
    centre = {n: 0.5 * (lo + hi) for n, (lo, hi) in axes.items()}
    return [envelope.point(c) for c in [centre, *corners]]


def shifted_problem(problem: DesignProblem, delta: float, speed: float) -> DesignProblem:
    """The problem in θ' = θ + δ at one speed [m/s]: the angle box moved by δ [deg].

    Raises
    ------
    ValueError
        ``tolerances.groove_angle_deg: ...`` when the angles made leave the physics' range.
    """
    lo, hi = problem.bounds.groove_angle_deg
    if lo - delta <= _ANGLE.minimum or hi + delta >= _ANGLE.maximum:
        raise ValueError("tolerances.groove_angle_deg: the angles made, "
                         f"[{lo - delta:g}, {hi + delta:g}] deg, "
                         f"must stay within the physics' range {_ANGLE.range_text()}")
    bounds = DesignBounds(problem.bounds.balls, (lo + delta, hi + delta), problem.bounds.load_N)
    return DesignProblem(bounds, speed, problem.constraints, problem.fixed, problem.convention)


#: Why a factor column (group labels) has no place in an operating envelope, whatever its value.
GROUP_LABEL_OVER_ENVELOPE = ("a group label is taken by a design at one point only; over an operating "
                             "envelope the design holds for a new group (the spread between groups is in its "
                             "interval): leave it out")


def check_model(model: Model | None, envelope: Envelope, objective: str) -> None:
    """Refuse what a model cannot be asked over an envelope (the checks :func:`optimize_robust` makes first).

    Raises
    ------
    ValueError
        Naming the field: ``objective`` (mu_upper without an interval), ``conditions`` (a condition for
        the physics, a missing or unknown one for a calibrated model).
    """
    if objective not in OBJECTIVES:
        raise ValueError(f"objective must be one of {', '.join(OBJECTIVES)}; got {objective!r}")
    if model is None or model.kind == "physics":
        if objective != "mu":
            raise ValueError("objective: mu_upper is the 95 % upper bound of a calibrated or surrogate "
                             "model; "
                             "the physics has no interval")
        if envelope.conditions:
            raise ValueError("conditions: condition columns are read by calibrated models only")
        return
    if objective == "mu_upper" and not model.has_interval:
        raise ValueError(f"objective: {model.reference} has no interval")
    required = list(model.required_columns)
    missing = [n for n in required if n not in envelope.conditions]
    if missing:
        raise ValueError(f"conditions.{missing[0]}: {model.reference} reads {', '.join(required)}; give each "
                         "a value or a range [low, high]")
    factors = [n for n, spec in model.inputs.items() if spec.kind == "label" and n in envelope.conditions]
    if factors:
        raise ValueError(f"conditions.{factors[0]}: {GROUP_LABEL_OVER_ENVELOPE}")
    known = set(required) | set(getattr(model, "unread_conditions", {}))
    unknown = [n for n in envelope.conditions if n not in known]
    if unknown:
        raise ValueError(f"conditions.{unknown[0]} is not a condition of {model.reference}; its "
                         f"conditions are {', '.join(sorted(known)) or 'none'}")


def with_column_defaults(envelope: Envelope, model: Model | None) -> Envelope:
    """The envelope with each condition column the model fills when a point does not give it (a calibrated
    model's ``column_defaults``: the session column of an instrument's drift, where the reading is taken
    as true) held at that value: the design is for the bearing, not for a reading."""
    defaults = {k: v for k, v in dict(getattr(model, "column_defaults", None) or {}).items()
                if k not in envelope.conditions}
    if not defaults:
        return envelope
    return replace(envelope, conditions={**envelope.conditions, **defaults})


def with_model_values(problem: DesignProblem, model: Model | None) -> DesignProblem:
    """The problem with the values the model holds (a calibration's fixed and fitted ones) in ``fixed``."""
    if model is None:
        return problem
    held = {k: v for k, v in {**model.fixed, **model.fitted}.items()
            if k in physics.PARAMETERS and k not in DESIGN_VARIABLES and k != "speed_m_s"}
    if not held and problem.convention == model.convention:
        return problem
    return DesignProblem(problem.bounds, problem.speed_m_s, problem.constraints, {**problem.fixed, **held},
                         model.convention)


def evaluator(problem: DesignProblem, envelope: Envelope, model: Model | None, objective: str,
              design: Mapping[str, Any], shift: float) -> Callable[[list[dict[str, Any]]], np.ndarray]:
    """``points -> values`` [1] of the objective at one design (arrays of designs allowed; its angle θ' = θ +
    ``shift``) over a list of envelope points, as :func:`objective_values` gives them."""
    def evaluate(points: list[dict[str, Any]]) -> np.ndarray:
        return objective_values(model, objective, envelope_columns(problem, envelope, design, points, shift),
                                 problem.convention)
    return evaluate


def model_inputs_fn(problem: DesignProblem, model: Model, balls: Any, theta: Any,
                    load: Any) -> Callable[[np.ndarray, np.ndarray], dict[str, Any]]:
    """``(angle offset [deg], speed [m/s]) -> the physics inputs the model is given at a design``, as
    :func:`objective_values` gives them (without the values the model holds)."""
    held = {*model.fixed, *model.fitted}

    def inputs_fn(offset: np.ndarray, speed: np.ndarray) -> dict[str, Any]:
        columns = problem.physics_inputs(balls, theta + offset, load, speed_m_s=speed)
        return {k: v for k, v in columns.items() if k not in held}

    return inputs_fn
