r"""Designs that hold over an operating envelope, on any model, with what is proven about them.

A designer knows the bearing will run over a range of speeds and conditions (a calibrated model's
relative humidity, temperature, ...) and that the groove angle is made to a tolerance. An
:class:`Envelope` states them; :func:`optimize_robust` finds the design whose **worst case** of the
objective over the envelope (``mu``, or ``mu_upper``: the 95 % upper bound of a calibrated or
surrogate model) is lowest, with every limit holding over the whole envelope, and says what is
proven: the worst case at the returned design and where it occurs, a certified lower bound on the
best achievable worst case and the gap between them, and the price of robustness (the nominal
optimum at the envelope's centre beside the robust one, each with its worst case).

The physics: a proof by geometric programming
---------------------------------------------
For a fixed ball count every term of the physics' μ is a posynomial, with positive coefficients and
exponents, in t = tan θ and in the speed V (:mod:`optimize.dgp`; V enters only through Houpert's
rolling force, k V^0.66), and so are the peak pressure and the friction force μ G. Hence μ, the
pressure and the friction force are non-decreasing in θ on (0°, 90°) and in V, and the physics reads
no condition column: over an envelope of speeds [V_lo, V_hi] and an angle made to θ ± δ, the worst
case of every one of them is at (θ + δ, V_hi), one vertex. Minimizing the worst case over nominal
angles θ in [θ_lo, θ_hi] is therefore minimizing μ at θ' = θ + δ over [θ_lo + δ, θ_hi + δ] and V_hi:
the geometric program of :func:`optimize.optimize_design` on a shifted box, solved for every ball
count (the global optimum per count, all counts enumerated). The certified lower bound is the least,
over the counts, of the dual objective of each count's conic program (weak duality; limits taken
exactly, without the solver's safety margin), less the solver's tolerance; the upper bound is the
exact physics' worst case at the returned design. ``tests/test_optimize_robust.py`` checks the
monotonicity on the exact physics and the optimum against brute force.

:func:`robust_gp` is the same argument for any geometric program whose constants are uncertain
within a box: a posynomial is log-log convex in its positive constants too, so its maximum over a
box of them is at one of the box's vertices, and the worst case over the box of a maximum of
posynomials is a geometric program over the vertices (a robust GP; the cantilever beam of Dakota's
examples is checked with it).

Calibrated models whose terms keep it a geometric program
---------------------------------------------------------
A calibrated model is the physics with fitted values and terms applied in order. When every term is
a positive monomial in balls and load (read at three designs, checked at a fourth) added to μ or
multiplying it, driven by the speed or a condition through a formula monotone in it (the directions
each effect declares, :attr:`physics.effects.Effect.direction`, at its fitted values), and the model
has no Gaussian-process discrepancy and no drift of a physics parameter, μ is a posynomial in tan θ
and G for every ball count, monotone in every envelope axis: its worst case is one vertex, and the
robust problem one GP per ball count, proven as for the physics (objective ``mu``).

Calibrated models with other effect terms (objective ``mu``): an outer approximation, certified
-----------------------------------------------------------------------------------------------
A term that is not monotone (a log-quadratic in temperature may peak inside the range) or falls where
the physics rises (a Stribeck term in speed) leaves no single worst vertex, but still a rigorous bound:
at a design, μ over any box of the envelope is at most the composition of the physics' maximum (its
highest angle and speed) and each term's maximum over its driver's interval
(:mod:`optimize.envelope_bound`), and branch and bound brackets the worst case to 1e-7. The design
comes from the outer approximation below, with that bracket in place of the search; the certified
lower bound on the best achievable worst case is the largest, over the worst points found, of the
least μ over the designs at that point (there every term is a positive monomial in balls and load,
so a geometric program per ball count, bounded by its dual). A gap within :data:`GAP_TARGET` is a
proof; otherwise both bounds are stated and the result says it is not proven. The same holds with a
drifting physics parameter (the drifted value fixed at the point), groups (a constant factor at a
point naming none) and a Gaussian-process discrepancy (its least mean over the design box at the
point), each bounded over a box as :mod:`optimize.envelope_bound` says; ``mu_upper``'s bracket also
bounds the data cloud's widening of the interval. The nominal design's worst case in the price of
robustness is bracketed the same way (``worst_case_certified``, ``worst_case_upper_bound``).

The 95 % upper bound of a calibrated model: a lower bound over the designs
--------------------------------------------------------------------------
For ``mu_upper`` the worst case at a design is bracketed the same way (interval arithmetic on its closed
form, :func:`optimize.envelope_bound.mu_upper_box_bound`), and the best achievable worst case is bounded
below by branch and bound over the designs at the worst envelope points (:mod:`optimize.design_bound`):
min over designs of the largest ``mu_upper`` at fixed points is at most the best achievable worst case,
and each box of designs gets a certified lower bound of it (drifted parameters at their law's value at the
point, groups and a Gaussian-process discrepancy at their least over the box included). Both ends within
:data:`GAP_TARGET` are a proof; a model whose interval widens off its data cloud has its worst case at a
design searched (the lower bound leaves the widening out and stays valid), so it gets a tight lower bound
and no proof.

Other models: an outer approximation, said to be unproven
---------------------------------------------------------
A surrogate, or a part of a calibrated model :mod:`optimize.envelope_bound` has no box bound for (a
drift of the adhesion energy or a modulus in the interval, a scatter that depends on an input, a
fitted value whose effect on μ has no closed form), has no known bound on its derivatives, so no
rigorous bound over a box exists for it
here. The method is a cutting-plane (outer-approximation) loop: the local method of
:func:`optimize.optimize_model` minimizes the largest objective over a finite set of envelope points
(its vertices and centre, or the vertex where μ is proven worst, to begin with); at the design
found, the worst case over the whole envelope is searched (a grid of every axis, then a bounded
quasi-Newton ascent from the best grid points); a point worse than the set by more than
:data:`ENVELOPE_RTOL` relative is added and the design re-optimized, at most :data:`MAX_ROUNDS`
times. The result says ``proven: false`` with the best bound found: the worst case found at the
returned design, and a certified lower bound only for ``mu_upper`` of a calibrated model (above; or,
where that cannot be built and the ``mu`` problem is a GP, mu_upper >= μ exp(1.96 σ_noise), so that
factor times the proven bound of the ``mu`` problem, a gap of the parameters' share of the interval).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
import types
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import cvxpy as cp
import numpy as np
from scipy import optimize as sciopt
from scipy import stats

from microbearing import physics
from microbearing.physics.model import Model

from .design_bound import design_lower_bound, kth_distance_to_boxes
from .dgp import LIMIT_NAMES, SAFETY_MARGIN, design_gp
from .envelope_bound import (
    BOUND_RTOL,
    INTERVAL_OUTPUTS,
    INTERVAL_RTOL,
    BoundFailedError,
    CertifiedMax,
    certified_max,
    drift_ranges,
    group_shift,
    interval_floor,
    interval_structures,
    mu_box_bound,
    mu_upper_box_bound,
    term_pieces,
)
from .general import optimize_model
from .problem import DESIGN_VARIABLES, DesignBounds, DesignProblem, constraint_report
from .solve import (
    TIE_TOLERANCE,
    BallCountResult,
    InfeasibleDesignError,
    OptimizationResult,
    optimize_design,
    polish_design,
)

__all__ = ["ENVELOPE_RTOL", "GAP_TARGET", "MAX_ROUNDS", "OBJECTIVES", "TOLERANCE_NAMES", "Envelope",
           "RobustGPResult", "RobustResult", "certified_worst_case_of", "check_model", "dual_bound",
           "optimize_robust", "robust_gp", "shifted_problem", "worst_case_of", "worst_case_search"]

#: The objectives a design may minimize the worst case of.
OBJECTIVES = ("mu", "mu_upper")
#: Design variables a tolerance may be given for (the angle: μ is monotone in it, see the module docstring).
TOLERANCE_NAMES = ("groove_angle_deg",)
#: Relative gap between the certified lower bound and the worst case that counts as closed. [1]
GAP_TARGET = 1e-6
#: A searched worst case above the optimized set's by more than this (relative) adds a point. [1]
ENVELOPE_RTOL = 1e-6
#: Relative bracket to which the nominal design's worst case in the price of robustness is certified (it
#: is stated beside the robust one, not optimized). [1]
NOMINAL_RTOL = 1e-4
#: Most rounds of the cutting-plane loop for models other than the physics. [1]
MAX_ROUNDS = 6
#: Clarabel's stopping tolerances (gap and feasibility, its defaults), taken off the dual bound. [1]
_SOLVER_TOL = 1e-8
_ANGLE = physics.PARAMETERS["groove_angle_deg"]
#: How the certified mu_upper bounds the widening of the interval beyond the data cloud, in words.
_CLOUD_WORDS = (", the widening beyond the data cloud at an upper bound of the distance ratio (the k-th "
                "smallest distance from the data rows to the box's farthest corner, in the cloud's scaled "
                "inputs; the widening is non-decreasing in the ratio)")
_SPEED = physics.PARAMETERS["speed_m_s"]


def _range(field_name: str, value: Any, minimum: float | None = None) -> tuple[float, float]:
    """A [low, high] pair (a number is a range of one point), finite and ordered, or a ValueError."""
    if isinstance(value, list | tuple):
        if len(value) != 2:
            raise ValueError(f"{field_name} must be a number or a pair [low, high]; got {value!r}")
        lo, hi = value
    else:
        lo = hi = value
    try:
        lo, hi = float(lo), float(hi)
    except (TypeError, ValueError):
        raise ValueError(f"{field_name} must be a number or a pair [low, high]; got {value!r}") from None
    if isinstance(value, bool) or not (math.isfinite(lo) and math.isfinite(hi)):
        raise ValueError(f"{field_name} must hold finite numbers; got {value!r}")
    if lo > hi:
        raise ValueError(f"{field_name} must have low <= high; got [{lo:g}, {hi:g}]")
    if minimum is not None and lo < minimum:
        raise ValueError(f"{field_name} must be >= {minimum:g}; got {lo:g}")
    return lo, hi


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

    Raises
    ------
    ValueError
        Naming the field (``speed_m_s``, ``conditions.<name>``, ``tolerances.<name>``).
    """

    speed_m_s: float | tuple[float, float]
    conditions: Mapping[str, Any] = field(default_factory=dict)
    tolerances: Mapping[str, float] = field(default_factory=dict)

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

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields: ranges as [low, high]."""
        return {"speed_m_s": list(self.speed_m_s),
                "conditions": {n: list(r) for n, r in self.conditions.items()},
                "tolerances": dict(self.tolerances)}


# --------------------------------------------------------------------------------------------------
# Certified bounds of geometric programs


def dual_bound(problem: cp.Problem) -> tuple[str, float, float]:
    """Solve a DGP with Clarabel and return (status, primal value, certified lower bound).

    The lower bound is the dual objective of the conic program (weak duality), less Clarabel's
    stopping tolerance (1e-8 absolute and relative, in the logarithm of the objective).

    Parameters
    ----------
    problem : cvxpy.Problem
        A disciplined geometric program (minimization); parameters already assigned.

    Returns
    -------
    status : str
        Clarabel's status (``"Solved"``, ``"AlmostSolved"``, ``"PrimalInfeasible"``, ...).
    value : float
        The primal objective (NaN unless solved). [unit of the objective]
    lower_bound : float
        The certified lower bound (NaN unless solved; +inf when proven infeasible). [unit of the objective]
    """
    data, chain, _ = problem.get_problem_data(cp.CLARABEL, gp=True)
    offset = float(data["param_prob"].apply_parameters()[1])
    raw = chain.solver.solve_via_data(data, False, False, {})
    status = str(raw.status)
    if status == "PrimalInfeasible":
        return status, math.nan, math.inf
    if status not in ("Solved", "AlmostSolved"):
        return status, math.nan, math.nan
    primal, dual = float(raw.obj_val) + offset, float(raw.obj_val_dual) + offset
    slack = _SOLVER_TOL * (1.0 + abs(dual))
    return status, math.exp(primal), math.exp(min(dual, primal) - slack)


@dataclass(frozen=True)
class RobustGPResult:
    """The optimum of a robust geometric program and its certificate.

    Attributes
    ----------
    value : float
        The worst case over the box of the objective at the optimum. [unit of the objective]
    lower_bound : float
        Certified lower bound on the best achievable worst case (:func:`dual_bound`). [same unit]
    relative_gap : float
        (value - lower_bound) / value. [1]
    variables : dict of str to float
        The optimal variables. [their units]
    worst_vertex : dict of str to float
        The vertex of the box where the objective is largest at the optimum. [their units]
    vertices : int
        Vertices of the box enumerated. [1]
    """

    value: float
    lower_bound: float
    relative_gap: float
    variables: dict[str, float]
    worst_vertex: dict[str, float]
    vertices: int


def robust_gp(variables: Mapping[str, cp.Variable],
              objective: Callable[[Mapping[str, float]], cp.Expression],
              constraints: Callable[[Mapping[str, float]], Sequence[cp.Constraint]],
              box: Mapping[str, tuple[float, float]]) -> RobustGPResult:
    """Minimize the worst case over a box of positive constants, subject to constraints at all of them.

    Every expression must be a posynomial (log-log convex) in the variables and the constants alike,
    so that its maximum over the box is at a vertex (see the module docstring): the program is
    min s subject to objective(v) <= s and constraints(v) for every vertex v, still a geometric
    program, solved once with a certified lower bound.

    Parameters
    ----------
    variables : mapping of str to cvxpy.Variable
        Positive variables (``pos=True``) by name.
    objective : callable
        The objective at the constants ``{name: value}`` of a vertex.
    constraints : callable
        The constraints at the constants of a vertex.
    box : mapping of str to (float, float)
        [low, high] of each uncertain constant, both > 0. [their units]

    Returns
    -------
    RobustGPResult

    Raises
    ------
    ValueError
        For an empty or non-positive box, a program that is not a DGP, or no solution.
    """
    names = list(box)
    for name in names:
        lo, hi = box[name]
        if not 0 < lo <= hi:
            raise ValueError(f"box.{name} must be 0 < low <= high; got [{lo:g}, {hi:g}]")
    corners = itertools.product(*(box[n] for n in names))
    vertices = [dict(zip(names, corner, strict=True)) for corner in corners]
    bound = cp.Variable(pos=True, name="worst_case")
    cons = [objective(v) <= bound for v in vertices]
    for v in vertices:
        cons += list(constraints(v))
    program = cp.Problem(cp.Minimize(bound), cons)
    if not program.is_dgp():
        raise ValueError("the robust program is not a disciplined geometric program")
    status, _, lower = dual_bound(program)
    if status not in ("Solved", "AlmostSolved"):
        raise ValueError(f"the robust geometric program has no solution (Clarabel: {status})")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        program.solve(gp=True, solver=cp.CLARABEL)
    values = {name: float(var.value) for name, var in variables.items()}
    # The worst case at the optimum, from the objective itself at each vertex.
    at = [float(objective(v).value) for v in vertices]
    worst = int(np.argmax(at))
    value = at[worst]
    lower = min(lower, value)
    return RobustGPResult(value, lower, (value - lower) / value, values, vertices[worst], len(vertices))


# --------------------------------------------------------------------------------------------------
# Worst case over an envelope


def _objective_values(model: Model | None, objective: str, columns: dict[str, Any],
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
        if predict is not None:  # a calibrated model: its prediction, without the physics' other outputs
            return np.asarray(predict(columns).mu_upper, dtype=float)
        return np.asarray(model.evaluate(columns, [objective]).values[objective], dtype=float)


def _columns(problem: DesignProblem, envelope: Envelope, design: Mapping[str, Any],
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
            return np.asarray(mu_model(_columns(problem, envelope, design, points, 0.0)), dtype=float)

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
    columns = _columns(problem, envelope, {k: np.array([float(design[k])]) for k in DESIGN_VARIABLES},
                       [vertex], 0.0)
    with np.errstate(all="ignore"):
        value = float(np.asarray(mu_model(columns), dtype=float)[0])
    # The search at the design is a check of the argument: nothing it finds may be above the vertex.
    if searched > value * (1 + 1e-12):
        return searched, where, False
    return value, vertex, True


def _vertices_and_centre(envelope: Envelope) -> list[dict[str, Any]]:
    axes = envelope.axes()
    names = list(axes)
    corners = [dict(zip(names, c, strict=True)) for c in itertools.product(*(axes[n] for n in names))]
    centre = {n: 0.5 * (lo + hi) for n, (lo, hi) in axes.items()}
    return [envelope.point(c) for c in [centre, *corners]]


# --------------------------------------------------------------------------------------------------
# The robust optimization


@dataclass(frozen=True)
class RobustResult:
    """The robust design, its worst case, what is proven and the price of robustness.

    Attributes
    ----------
    result : OptimizationResult
        The design (nominal groove angle), with ``mu`` the worst case of the objective over the
        envelope, its constraint report (the limits at their worst over the envelope) and per-count table.
    objective : str
        ``"mu"`` or ``"mu_upper"``.
    envelope : Envelope
        The envelope designed for.
    worst_case : dict
        ``{objective: value [1], "speed_m_s" [m/s], "groove_angle_deg" [deg] (the angle made),
        "conditions": {...}}``: where the worst case occurs at the returned design.
    proof : dict
        ``proven`` (bool), ``method``, ``lower_bound`` [1] (certified, or None), ``upper_bound`` [1]
        (the worst case at the design: exact, certified by branch and bound, or as searched when the
        method says no bound), ``relative_gap`` [1] (or None), ``gap_target`` [1],
        ``statement``.
    price_of_robustness : dict
        ``nominal`` and ``robust``: each a design with its objective at the envelope's centre and its
        worst case over the envelope; ``ratio`` [1], the nominal design's worst case over the robust one's.
    """

    result: OptimizationResult
    objective: str
    envelope: Envelope
    worst_case: dict[str, Any]
    proof: dict[str, Any]
    price_of_robustness: dict[str, Any]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready nested dict: the fields of :meth:`OptimizationResult.to_dict` and the robust ones."""
        return {**self.result.to_dict(), "objective": self.objective, "envelope": self.envelope.to_dict(),
                "worst_case": dict(self.worst_case), "proof": dict(self.proof),
                "price_of_robustness": dict(self.price_of_robustness)}


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


def _unshift(result: OptimizationResult, delta: float,
             extra: dict[str, Any] | None = None) -> OptimizationResult:
    """The result with every angle moved back from θ' to the nominal θ = θ' - δ."""
    if delta == 0 and not extra:
        return result
    design = {**result.design, "groove_angle_deg": result.design["groove_angle_deg"] - delta}
    rows = [dataclasses.replace(r, groove_angle_deg=None if r.groove_angle_deg is None
                                else r.groove_angle_deg - delta) for r in result.per_ball_count]
    ties = [{**t, "groove_angle_deg": t["groove_angle_deg"] - delta} for t in result.ties]
    constraints = [dataclasses.replace(c, value=c.value - delta, limit=c.limit - delta)
                   if c.name.startswith("groove_angle_deg") else c for c in result.constraints]
    return dataclasses.replace(result, design=design, per_ball_count=rows, ties=ties, constraints=constraints,
                               extra={**result.extra, **(extra or {})})


def _physics_lower_bound(problem: DesignProblem,
                         result: OptimizationResult) -> tuple[float | None, list[int]]:
    """The least certified lower bound over the ball counts, with the limits exact (no safety margin).

    Returns the bound [1] (None when a count could not be bounded) and the counts that could not.
    """
    bounds, unbounded = [], []
    for row in result.per_ball_count:
        if row.status in ("does not fit the groove", "infeasible"):
            continue  # no design of this count (the infeasible ones proven by phase I)
        gp, values = design_gp(problem, balls=row.balls)
        relaxed = {n: (v / (1.0 - SAFETY_MARGIN) if LIMIT_NAMES.get(n) == "max" else v)
                   for n, v in values.items()}
        with gp.lock:
            gp.assign(relaxed, row.balls)
            _, _, lower = dual_bound(gp.problem)
        if math.isnan(lower):
            unbounded.append(row.balls)
        else:
            bounds.append(lower)
    return (min(bounds) if bounds and not unbounded else None), unbounded


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
    known = set(required) | set(getattr(model, "unread_conditions", {}))
    unknown = [n for n in envelope.conditions if n not in known]
    if unknown:
        raise ValueError(f"conditions.{unknown[0]} is not a condition of {model.reference}; its "
                         f"conditions are {', '.join(sorted(known)) or 'none'}")


def _with_model_values(problem: DesignProblem, model: Model | None) -> DesignProblem:
    """The problem with the values the model holds (a calibration's fixed and fitted ones) in ``fixed``."""
    if model is None:
        return problem
    held = {k: v for k, v in {**model.fixed, **model.fitted}.items()
            if k in physics.PARAMETERS and k not in DESIGN_VARIABLES and k != "speed_m_s"}
    if not held and problem.convention == model.convention:
        return problem
    return DesignProblem(problem.bounds, problem.speed_m_s, problem.constraints, {**problem.fixed, **held},
                         model.convention)


def _evaluator(problem: DesignProblem, envelope: Envelope, model: Model | None, objective: str,
               design: Mapping[str, Any], shift: float) -> Callable[[list[dict[str, Any]]], np.ndarray]:
    def evaluate(points: list[dict[str, Any]]) -> np.ndarray:
        return _objective_values(model, objective, _columns(problem, envelope, design, points, shift),
                                 problem.convention)
    return evaluate


def _worst_case_dict(objective: str, value: float, point: Mapping[str, Any],
                     nominal_deg: float) -> dict[str, Any]:
    return {objective: float(value), "speed_m_s": float(point["speed_m_s"]),
            "groove_angle_deg": float(nominal_deg + point["groove_angle_offset_deg"]),
            "conditions": {n: float(v) for n, v in point["conditions"].items()}}


def _design_of(result: OptimizationResult) -> dict[str, Any]:
    return {k: result.design[k] for k in ("balls", "groove_angle_deg", "load_N")}


def optimize_robust(problem: DesignProblem, envelope: Envelope, model: Model | None = None,
                    objective: str = "mu", starts: int = 3, max_rounds: int = MAX_ROUNDS,
                    progress: Callable[[float], None] | None = None,
                    map_calls: Callable | None = None, time_limit_s: float = math.inf) -> RobustResult:
    """The design whose worst case of the objective over the envelope is lowest, with its proof.

    Parameters
    ----------
    problem : DesignProblem
        Bounds (nominal groove angle), limits and fixed values; its speed is replaced by the
        envelope's. For a model, the values the model holds (fixed, fitted) take precedence.
    envelope : Envelope
        Speeds, conditions and tolerances the design must hold over.
    model : physics.model.Model, optional
        The model; None (or a :class:`physics.model.PhysicsModel`) for the physics.
    objective : {"mu", "mu_upper"}, default "mu"
        μ, or the 95 % upper bound of a calibrated or surrogate model. [1]
    starts : int, default 3
        Starts per ball count of the local method (models other than the physics). [1]
    max_rounds : int, default :data:`MAX_ROUNDS`
        Most cutting-plane rounds (models other than the physics). [1]
    progress : callable, optional
        Called with the fraction done, 0..1. [1]
    map_calls : callable, optional
        Passed to :func:`optimize.optimize_model` (groups of ball counts on an executor).
    time_limit_s : float, default inf
        No new round of the outer approximation starts after this much time; the result then says
        so, with the worst case found. [s]

    Returns
    -------
    RobustResult

    Raises
    ------
    ValueError
        Naming the field: an objective the model has no value for, missing or unknown conditions,
        a tolerance taking the angle out of the physics' range.
    InfeasibleDesignError
        When no design meets the limits over the envelope.
    """
    start = time.perf_counter()
    check_model(model, envelope, objective)
    if model is not None and model.kind == "physics":
        problem = DesignProblem(problem.bounds, problem.speed_m_s, problem.constraints, problem.fixed,
                                model.convention)
        model = None
    problem = _with_model_values(problem, model)
    if model is None:
        return _robust_physics(problem, envelope, progress)
    reason = "the objective is mu_upper, whose interval is not log-log convex"
    vertex = None
    if objective == "mu":
        proven = _robust_calibrated_gp(problem, envelope, model, progress)
        if isinstance(proven, RobustResult):
            return proven
        reason = proven
    else:
        # Where mu is proven worst (its terms monotone) is where its upper bound is likely worst too: the
        # outer approximation starts from that vertex alone (the search adds any other point that is worse).
        vertex = _term_structure(model, envelope)[0]
    result = _robust_model(problem, envelope, model, objective, starts, max_rounds, progress, map_calls,
                           reason, None if vertex is None else [vertex], time_limit_s)
    if objective == "mu":
        return result
    bounded = _with_design_bound(problem, envelope, model, result, start + time_limit_s)
    if isinstance(bounded, RobustResult):
        return bounded
    result = dataclasses.replace(result, proof={
        **result.proof, "statement": f"{result.proof['statement']} No lower bound over the designs by branch "
                                     f"and bound: {bounded}."})
    noise = getattr(getattr(model, "calibrated", None), "noise_std_log", None)
    proven = _robust_calibrated_gp(problem, envelope, model, None, bound_only=True) if vertex else None
    if isinstance(proven, RobustResult) and proven.proof["lower_bound"] and noise:
        result = _with_interval_bound(result, proven, float(noise), _least_widening(problem, model, vertex))
    return result


def _least_widening(problem: DesignProblem, model: Model, point: Mapping[str, Any]) -> float:
    """A lower bound [1] of the data cloud's widening of the interval at an envelope point over the design
    box (1 without a cloud): the widening at the least distance ratio there (non-decreasing)."""
    calibrated = getattr(model, "calibrated", None)
    if getattr(calibrated, "cloud", None) is None:
        return 1.0
    ratio = calibrated.cloud_ratio_bound(*_design_box_corners(problem, model, point), (1,), lower=True)
    return max(float(calibrated.cloud.widening(ratio)[0]), 1.0)


def _with_interval_bound(result: RobustResult, mu_result: RobustResult, noise_std_log: float,
                         widening: float = 1.0) -> RobustResult:
    """A mu_upper result with the certified lower bound that the proven mu problem gives.

    A calibrated model's upper bound is mu exp(z sigma W) with sigma^2 = g'Cg + noise^2 >= noise^2 (C positive
    semi-definite, no discrepancy) and W >= ``widening`` the data cloud's widening at mu's worst vertex (over
    the design box), so every design's worst mu_upper is at least exp(z noise W) times its mu there, its worst
    mu, hence at least that factor times the certified lower bound of the mu problem (whose friction limit
    on mu is a relaxation of the one on mu_upper).
    """
    z = float(stats.norm.isf(0.025))
    upper = result.proof["upper_bound"]
    lower = min(max(mu_result.proof["lower_bound"] * math.exp(z * noise_std_log * widening),
                    result.proof["lower_bound"] or 0.0), upper)
    gap = (upper - lower) / upper
    cloud = f" x {widening:.4g}, the data cloud's least widening there" if widening > 1.0 else ""
    statement = (f" Certified lower bound {lower:.10g}: mu_upper >= mu exp(1.96 x {noise_std_log:.4g}"
                 f"{cloud}) (the interval is at least the measurement scatter) and the worst mu over the "
                 "envelope is "
                 f"proven at least {mu_result.proof['lower_bound']:.10g} (geometric programming, as for "
                 f"objective mu); relative gap to the worst case's upper bound {gap:.2e}: the parameters' "
                 "share of "
                 f"the interval. {'Not proven: the gap is above the target.' if gap > GAP_TARGET else ''}")
    proof = {**result.proof, "lower_bound": lower, "relative_gap": gap,
             "statement": result.proof["statement"] + statement}
    certificate = result.result.certificate + statement
    return dataclasses.replace(result, proof=proof,
                               result=dataclasses.replace(result.result, certificate=certificate))


#: Envelope points whose mu_upper at the returned design is within this of its worst case (relative) join the
#: worst point in the lower bound over the designs. [1]
_ACTIVE_RTOL = 1e-3
#: Relative gap to which the worst mu_upper at a design is bracketed (with the lower bound over the designs,
#: within the gap target of a proof). [1]
_BRACKET_RTOL = 1e-7
#: Most passes of the lower bound over the designs; each after the first adds the worst point of a design that
#: was lower than the returned one at the points. [1]
_DESIGN_PASSES = 3


def _design_bound_parts(structures: Sequence[Any]) -> str:
    """What the bound over design boxes takes besides the terms, for the statement."""
    parts = []
    if any(piece.kind == "drift" for s in structures for piece in s.pieces):
        parts.append("each drifted physics parameter at its law's value at the point, its coefficient's "
                     "share of the gradient by interval arithmetic")
    if any(s.groups for s in structures):
        parts.append("the groups' least shift s b0 and new-group variance at a point naming no group")
    if any(getattr(s.model, "discrepancy", None) is not None for s in structures):
        parts.append("the discrepancy's least mean and latent variance over the box")
    return "".join(f", {p}" for p in parts)


def _with_design_bound(problem: DesignProblem, envelope: Envelope, model: Model, result: RobustResult,
                       deadline: float) -> RobustResult | str:
    """A mu_upper result with the certified lower bound over the designs (:mod:`optimize.design_bound`), and
    the best design at the points in place of the returned one where only that closes the gap; else why not.

    ``problem`` is in the nominal angle, with the model's values held; ``deadline`` is a
    :func:`time.perf_counter` instant after which no new batch of boxes starts.
    """
    calibrated = getattr(model, "calibrated", None)
    if calibrated is None or not dataclasses.is_dataclass(calibrated):
        return f"{model.reference} is not a calibrated model"
    # The data cloud only widens the interval (sigma times a ratio of at least 1): left out, a lower bound.
    widened = hasattr(calibrated, "cloud") and calibrated.cloud is not None
    held = types.SimpleNamespace(reference=model.reference, calibrated=dataclasses.replace(
        calibrated, cloud=None) if widened else calibrated)
    structures, why = interval_structures(held)
    if structures is None:
        return why
    # The design boxes' bound composes the physics (with drifted parameters at the point), additions,
    # factors, groups (at a point naming none) and a Gaussian-process discrepancy (its least mean and
    # variance over the box); a drift's driver must be fixed at the point.
    for s in structures:
        for piece in s.pieces:
            if piece.kind == "drift" and piece.term.driver not in ("speed_m_s", *envelope.conditions):
                return (f"its term {piece.term.label!r} drifts a physics parameter with "
                        f"{piece.term.driver}, which the bound over design boxes does not take")
    design = _design_of(result.result)
    worst = result.worst_case
    offset = worst["groove_angle_deg"] - design["groove_angle_deg"]
    points = [envelope.point({"speed_m_s": worst["speed_m_s"], "groove_angle_offset_deg": offset,
                              **{f"conditions.{n}": v for n, v in worst["conditions"].items()}})]
    candidates = _vertices_and_centre(envelope)
    at = _evaluator(problem, envelope, model, "mu_upper", design, 0.0)(candidates)
    top = max(float(np.max(at)), float(worst["mu_upper"]))
    points += [p for p, v in zip(candidates, at, strict=True)
               if v >= top * (1.0 - _ACTIVE_RTOL) and p != points[0]]

    def monomial_everywhere(point: Mapping[str, Any]) -> str:
        for s in structures:
            effects = [piece for piece in s.pieces if piece.kind != "drift"]  # drifts: in the physics
            terms = [piece.term for piece in effects]
            values = [list(piece.values) for piece in effects]
            variants = [values] + [[*values[:k], [*v[:i], x + 1.0, *v[i + 1:]], *values[k + 1:]]
                                   for k, v in enumerate(values) for i, x in enumerate(v)]
            for each in variants:
                monomials, reason = _monomials_at(terms, each, point)
                if monomials is None:
                    return reason or "a term is not a positive monomial in balls and load_N at a point"
        return ""

    for point in points:
        reason = monomial_everywhere(point)
        if reason:
            return reason
    z_quantile = float(stats.norm.isf(0.025))

    def evaluate(designs: Mapping[str, np.ndarray]) -> np.ndarray:
        return _objective_values(model, "mu_upper", _columns(problem, envelope, designs, points, 0.0),
                                 problem.convention)

    fitted_names = {name for s in structures for name in s.fitted}
    added = 0
    try:
        for _ in range(_DESIGN_PASSES):
            widening = [_cloud_widening(problem, envelope, model, p, design, fitted_names)
                        if widened else None for p in points]
            found = design_lower_bound(problem, structures, calibrated.fixed, points,
                                       envelope.angle_tolerance_deg, design, evaluate, z_quantile,
                                       time_limit_s=deadline - time.perf_counter(), widening=widening)
            enough = found.lower_bound >= float(worst["mu_upper"]) * (1.0 - GAP_TARGET + _BRACKET_RTOL)
            if enough or not (found.improved and found.complete) or time.perf_counter() > deadline:
                break
            # A design lower than the returned one at the points: its worst point joins them.
            _, where, _ = worst_case_search(_evaluator(problem, envelope, model, "mu_upper",
                                                       found.incumbent_design, 0.0), envelope)
            if monomial_everywhere(where):
                break
            points.append(where)
            added += 1
    except BoundFailedError as exc:
        return f"its bound over a design box failed a check ({exc})"
    if not found.design_meets_limits:
        return "the returned design does not meet the limits (exactly) at the worst points"
    certified = result.proof["method"] == "outer-approximation-certified"
    swapped = ""
    # Where the gap is above the target only by the returned design's distance from the best at the points,
    # that best design is tried (a bracket stopped at its box limit at the design would stop beside it too).
    closed = (result.proof.get("worst_case_relative_gap") or 0.0) <= _BRACKET_RTOL
    short = found.lower_bound < result.proof["upper_bound"] * (1.0 - GAP_TARGET)
    if certified and closed and short and found.incumbent < float(worst["mu_upper"]) * (1.0 - 1e-9):
        better = _certified_design(problem, envelope, model, result, found.incumbent_design, deadline)
        if better is not None:
            swapped = (f" The design returned is the lower bound's best at the points (a box's centre), its "
                       f"worst case certified at most {better.proof['upper_bound']:.10g}, below the outer "
                       f"approximation's design's {result.proof['upper_bound']:.10g} (whose local method "
                       "keeps 1e-7 inside every limit; the limits here hold exactly).")
            result = better
    proof = dict(result.proof)
    upper, value = proof["upper_bound"], float(result.worst_case["mu_upper"])
    lower = min(found.lower_bound, upper)
    gap = max(0.0, (upper - lower) / upper)
    proven = bool(certified and found.complete and gap <= GAP_TARGET)
    counts = len(problem.ball_counts())
    stopped = "" if found.complete else ", stopped at the time or box limit: the bound found so far"
    extra = f", and {added} worst point(s) of designs lower there" if added else ""
    cloud = (", the data cloud's widening of sigma at least the k-th nearest row's distance to the box over "
             "the cloud's threshold" if widened else "")
    statement = (
        f" Certified lower bound {lower:.10g} on the best achievable worst case, by branch and bound over "
        f"the designs ({found.boxes} boxes of groove angle and load over {counts} ball count(s){stopped}): "
        f"at {len(points)} envelope point(s) (the worst one at the design, the vertices within "
        f"{_ACTIVE_RTOL:g} of it{extra}) no design's mu_upper is below its box's bound - the physics' "
        "friction force grows with the angle and the load (its posynomial form), each term is a positive "
        "monomial in balls and load there (read and checked), the composed mu and each fitted value's "
        "gradient of log mu by interval arithmetic, the least parameter variance g'Cg over the box of "
        "gradients from convexity (coordinate descent and its Frank-Wolfe gap), for the model and each "
        f"rival{cloud}{_design_bound_parts(structures)}; boxes where a limit is certainly broken are "
        "dropped. ")
    if certified:
        statement += ("Upper end certified by branch and bound over the envelope at the design: "
                      f"{upper:.10g}. ")
    else:
        why_searched = "the data cloud widens the interval" if widened else "see above"
        statement += (f"Upper end {upper:.10g} searched, not certified (no bound over a box of the envelope: "
                      f"{why_searched}). ")
    statement += f"Relative gap {gap:.2e} (target {GAP_TARGET:g})"
    if proven:
        statement += ": proven."
    else:
        statement += ": not proven ({}).".format(
            "the gap is above the target" if gap > GAP_TARGET else
            "the search stopped at its limit" if not found.complete else
            "the worst case at the design is not certified")
    statement += swapped
    if found.incumbent < value * (1.0 - 1e-9):
        better = found.incumbent_design
        statement += (f" A design lower at the points by {1.0 - found.incumbent / value:.1e} relative was "
                      f"found ({better['balls']:g} balls, {better['groove_angle_deg']:.7f} deg, "
                      f"{better['load_N']:.7g} N: {found.incumbent:.10g}); the gap includes it.")
    proof.update(proven=proven, lower_bound=lower, relative_gap=gap, statement=proof["statement"] + statement,
                 lower_bound_boxes=found.boxes, upper_bound_certified=certified)
    certificate = (f"Proven optimum of the worst mu_upper over the envelope, to a relative gap of {gap:.1e}. "
                   f"{proof['statement']}" if proven else result.result.certificate + statement)
    return dataclasses.replace(result, proof=proof, result=dataclasses.replace(result.result,
                                                                               certificate=certificate))


def _cloud_widening(problem: DesignProblem, envelope: Envelope, model: Model, point: Mapping[str, Any],
                    design: Mapping[str, Any], fitted_names: set[str]) -> Callable | None:
    """A lower bound over boxes of designs of the factor the data cloud widens σ by at ``point``, or None.

    The model widens σ by max(1, d_k / threshold, departure), d_k the distance of the point (its columns
    scaled as the cloud's) to its k-th nearest row and departure its distance from the lines of columns
    moving together over theirs (:class:`calibrate.domain.DataCloud`); over a box of designs d_k is at
    least the k-th smallest distance from the box to the rows, and the departure, linear in two columns,
    at least its least value at the box's corners (0 where the box crosses the line). None where the cloud
    reads a fitted value (a rival's would differ) or fewer than two of its columns.
    """
    cloud = model.calibrated.cloud
    held = {*model.fixed, *model.fitted}
    one = {k: np.array([float(design[k])]) for k in DESIGN_VARIABLES}
    columns = {k: v for k, v in _columns(problem, envelope, one, [point], 0.0).items() if k not in held}
    columns = {k: v for k, v in model.calibrated.columns_at(columns).items()
               if k in columns or k in physics.PARAMETERS}
    given = [c for c in cloud.columns if c in columns]
    if len(given) < 2 or fitted_names & set(given):
        return None
    space = cloud.space(given)
    rows = cloud.rows[:, list(space.index)]
    offset = float(point["groove_angle_offset_deg"])
    scaled = cloud.scaled

    def ratio(z: np.ndarray, tl: np.ndarray, th: np.ndarray, gl: np.ndarray, gh: np.ndarray) -> np.ndarray:
        ends = {"balls": (z, z), "groove_angle_deg": (tl + offset, th + offset), "load_N": (gl, gh)}
        lo, hi = [], []
        for column in given:
            a, b = ends.get(column, (np.full(len(z), float(np.ravel(columns[column])[0])),) * 2)
            lo.append(scaled(column, a))
            hi.append(scaled(column, b))
        low, high = np.column_stack(lo), np.column_stack(hi)
        distance = kth_distance_to_boxes(rows, low, high, space.k)
        # and the departure from a line of columns moving together: exact over the box (linear in two)
        departure = cloud.line_ratio(given, low, high, lower=True)
        return np.maximum(distance / max(space.threshold, 1e-12), departure)

    return ratio


def _certified_design(problem: DesignProblem, envelope: Envelope, model: Model, result: RobustResult,
                       candidate: Mapping[str, float], deadline: float) -> RobustResult | None:
    """The result with ``candidate`` (nominal angle) as its design where its worst mu_upper over the envelope,
    certified by branch and bound, is below the result's and every limit holds there; else None."""
    structures, _ = interval_structures(model)
    if structures is None:
        return None
    design = {"balls": round(candidate["balls"]), "groove_angle_deg": float(candidate["groove_angle_deg"]),
              "load_N": float(candidate["load_N"])}
    try:
        bracket = _certified_upper_search(problem, envelope, model, structures, design, 0.0,
                                          rtol=_BRACKET_RTOL,
                                          time_limit_s=max(0.0, deadline - time.perf_counter()))
    except BoundFailedError:
        return None
    if not bracket.complete or bracket.upper_bound >= result.proof["upper_bound"]:
        return None
    delta = envelope.angle_tolerance_deg
    # The limits at their worst over the envelope: the angle made high, the friction force at the worst case.
    report = constraint_report(shifted_problem(problem, delta, envelope.speed_m_s[1]), design["balls"],
                               design["groove_angle_deg"] + delta, design["load_N"], mu=bracket.upper_bound,
                               mu_name=model.reference)
    if not all(c.satisfied for c in report):
        return None
    report = [dataclasses.replace(c, value=c.value - delta, limit=c.limit - delta)
              if c.name.startswith("groove_angle_deg") else c for c in report]
    centre = envelope.centre()
    centre_point = envelope.point({"speed_m_s": centre["speed_m_s"],
                                   **{f"conditions.{n}": v for n, v in centre["conditions"].items()}})
    at_centre = float(_evaluator(problem, envelope, model, "mu_upper", design, 0.0)([centre_point])[0])
    price = dict(result.price_of_robustness)
    price["robust"] = {**price["robust"], "design": dict(design), "at_centre": at_centre,
                       "worst_case": bracket.value}
    price["ratio"] = float(price["nominal"]["worst_case"] / bracket.value)
    proof = {**result.proof, "upper_bound": bracket.upper_bound, "worst_case_boxes": bracket.boxes,
             "worst_case_relative_gap": bracket.relative_gap}
    solved = dataclasses.replace(result.result, design={**result.result.design, **design}, mu=bracket.value,
                                 relative_gap=result.result.mu_solver / bracket.value - 1.0,
                                 constraints=report, speed_m_s=float(bracket.point["speed_m_s"]))
    return dataclasses.replace(result, result=solved, proof=proof, price_of_robustness=price,
                               worst_case=_worst_case_dict("mu_upper", bracket.value, bracket.point,
                                                           design["groove_angle_deg"]))


def _robust_physics(problem: DesignProblem, envelope: Envelope,
                    progress: Callable[[float], None] | None) -> RobustResult:
    start = time.perf_counter()
    delta = envelope.angle_tolerance_deg
    v_hi = envelope.speed_m_s[1]
    shifted = shifted_problem(problem, delta, v_hi)
    solved = optimize_design(shifted, progress=None if progress is None else (lambda f: progress(0.6 * f)))
    lower, unbounded = _physics_lower_bound(shifted, solved)
    design = _design_of(solved)
    theta = design["groove_angle_deg"] - delta
    # Where the worst case occurs, and a check of the vertex argument on the exact physics: no other
    # vertex or the centre is worse.
    evaluate = _evaluator(problem, envelope, None, "mu", design, delta)
    vertices = _vertices_and_centre(envelope)
    at = evaluate(vertices)
    worst = vertices[int(np.argmax(at))]
    predicted = envelope.point({"speed_m_s": v_hi, "groove_angle_offset_deg": delta})
    value = float(evaluate([predicted])[0])
    gap = None if lower is None else max(0.0, (value - lower) / value)
    proven = lower is not None and gap <= GAP_TARGET
    statement = (
        "The physics' mu, peak pressure and friction force are posynomials in tan(theta) and in the speed "
        "with "
        "positive coefficients (the rolling force ~ V^0.66 is the only speed term), so over the envelope "
        f"their worst case is at the angle made high (nominal + {delta:g} deg) and the highest speed "
        f"{v_hi:g} m/s; the physics reads no condition column. The robust problem is the geometric program "
        f"of every ball count on the angle box moved by {delta:g} deg at {v_hi:g} m/s, solved per count; "
        f"certified lower bound {lower if lower is not None else float('nan'):.10g} (least dual objective "
        f"over the counts, limits exact, less Clarabel's 1e-8 tolerance), worst case at the design "
        f"{value:.10g} (exact physics), relative gap {gap if gap is not None else float('nan'):.2e} "
        f"(target {GAP_TARGET:g}). The {len(vertices)} vertices and centre of the envelope checked on the "
        f"exact physics: largest {float(np.max(at)):.10g}.")
    if unbounded:
        statement += f" Counts {unbounded} could not be bounded by the solver: no certified bound."
    if lower is not None and gap > GAP_TARGET:
        statement += " The gap is above the target: the optimum is proven only to that gap."
    proof = {"proven": bool(proven), "method": "robust-gp-vertex", "lower_bound": lower, "upper_bound": value,
             "relative_gap": gap, "gap_target": GAP_TARGET, "statement": statement}
    vertex_holds = float(np.max(at)) <= value * (1 + 1e-12)
    if not vertex_holds:
        proof["proven"] = False
        proof["statement"] += (f" But a vertex or the centre gave {float(np.max(at)):.10g} > the predicted "
                               "worst case: the monotonicity argument failed here, nothing is proven.")
        value = float(np.max(at))
        predicted = worst
    worst_case = _worst_case_dict("mu", value, predicted, theta)
    # Price of robustness: the nominal optimum at the envelope's centre and its worst case.
    centre_speed = envelope.centre()["speed_m_s"]
    nominal = optimize_design(DesignProblem(problem.bounds, centre_speed, problem.constraints, problem.fixed,
                                            problem.convention))
    nominal_design = _design_of(nominal)
    nominal_eval = _evaluator(problem, envelope, None, "mu", nominal_design, 0.0)
    nominal_worst = float(nominal_eval([predicted | {"groove_angle_offset_deg": delta}])[0])
    nominal_limits = constraint_report(shifted, nominal_design["balls"],
                                       nominal_design["groove_angle_deg"] + delta,
                                       nominal_design["load_N"])
    robust_centre = float(_evaluator(problem, envelope, None, "mu", design, delta)(
        [envelope.point({"speed_m_s": centre_speed})])[0])
    # Both worst cases at the vertex are exact where the monotonicity held on the checked points.
    price = _price(nominal_design, nominal.mu, nominal_worst,
                   all(c.satisfied for c in nominal_limits if not c.name.startswith("groove_angle_deg")),
                   {**design, "groove_angle_deg": theta}, robust_centre, value,
                   nominal_worst if vertex_holds else None, value if vertex_holds else None)
    certificate = (solved.certificate + " Envelope: " + statement)
    result = _unshift(dataclasses.replace(solved, mu=value, certificate=certificate,
                                          speed_m_s=v_hi, solve_time_s=time.perf_counter() - start), delta)
    if progress is not None:
        progress(1.0)
    return RobustResult(result, "mu", envelope, worst_case, proof, price)


def _price(nominal_design: dict[str, Any], nominal_centre: float, nominal_worst: float, nominal_holds: bool,
           robust_design: dict[str, Any], robust_centre: float, robust_worst: float,
           nominal_upper: float | None = None, robust_upper: float | None = None) -> dict[str, Any]:
    """Both designs; ``*_upper``: a certified upper bound of each worst case [1] (None: searched only)."""
    def certified(upper: float | None) -> dict[str, Any]:
        return {"worst_case_certified": upper is not None,
                "worst_case_upper_bound": None if upper is None else float(upper)}

    return {
        "nominal": {"design": dict(nominal_design), "at_centre": float(nominal_centre),
                    "worst_case": float(nominal_worst), "limits_hold_over_envelope": bool(nominal_holds),
                    **certified(nominal_upper)},
        "robust": {"design": dict(robust_design), "at_centre": float(robust_centre),
                   "worst_case": float(robust_worst), "limits_hold_over_envelope": True,
                   **certified(robust_upper)},
        "ratio": float(nominal_worst / robust_worst),
    }


class _SetModel:
    """The worst case of the objective over a finite set of envelope points, as optimize_model's μ model."""

    def __init__(self, problem: DesignProblem, envelope: Envelope, model: Model, objective: str,
                 points: list[dict[str, Any]], shift: float):
        self.problem, self.envelope, self.model, self.objective = problem, envelope, model, objective
        self.points, self.shift = points, shift

    def __call__(self, columns: Mapping[str, Any]) -> np.ndarray:
        design = {k: np.atleast_1d(np.asarray(columns[k], dtype=float)) for k in DESIGN_VARIABLES}
        n = max(np.size(v) for v in design.values())
        design = {k: np.broadcast_to(v, (n,)) for k, v in design.items()}
        values = _objective_values(self.model, self.objective,
                                   _columns(self.problem, self.envelope, design, self.points, self.shift),
                                   self.problem.convention)
        return np.max(np.asarray(values, dtype=float).reshape(len(self.points), n), axis=0)


def _certifier(envelope: Envelope, model: Model, objective: str
               ) -> tuple[Callable[[DesignProblem, Mapping[str, Any], float], CertifiedMax] | None, str]:
    """What brackets the worst objective at a design (problem, design in θ', shift; ``rtol`` optional), or
    None and why not."""
    if objective == "mu":
        pieces, why = term_pieces(model)
        if pieces is None:
            return None, why
        return (lambda problem, design, shift, **rtol: _certified_search(problem, envelope, model, pieces,
                                                                         design, shift, **rtol)), ""
    structures, why = interval_structures(model)
    if structures is None:
        return None, why
    return (lambda problem, design, shift, **options: _certified_upper_search(
        problem, envelope, model, structures, design, shift, **{"rtol": _BRACKET_RTOL, **options})), ""


def _certified_upper_search(problem: DesignProblem, envelope: Envelope, model: Model, structures: list,
                            design: Mapping[str, Any], shift: float, rtol: float | None = None,
                            time_limit_s: float = math.inf) -> CertifiedMax:
    """The worst mu_upper over the envelope at a design (angle θ' = θ + ``shift``), bracketed."""
    balls, load = float(design["balls"]), float(design["load_N"])
    theta = float(design["groove_angle_deg"]) - shift
    calibrated = model.calibrated
    outputs = list(INTERVAL_OUTPUTS)

    def physics_fn(offset: np.ndarray, speed: np.ndarray,
                   fitted: Mapping[str, float]) -> dict[str, np.ndarray]:
        columns = problem.physics_inputs(balls, theta + offset, load, speed_m_s=speed)
        inputs = {k: v for k, v in columns.items() if k not in calibrated.fitted}
        with np.errstate(all="ignore"):
            result = physics.evaluate(convention=problem.convention, outputs=outputs,
                                      **{**inputs, **calibrated.fixed, **fitted})
        return {name: np.asarray(getattr(result, name), dtype=float) for name in outputs}

    bound = mu_upper_box_bound(structures, physics_fn, envelope, {"balls": balls, "load_N": load},
                               float(stats.norm.isf(0.025)), calibrated,
                               _inputs_fn(problem, model, balls, theta, load), {**problem.fixed})
    return certified_max(bound, _evaluator(problem, envelope, model, "mu_upper", design, shift), envelope,
                         rtol=rtol or INTERVAL_RTOL, time_limit_s=time_limit_s)


def _inputs_fn(problem: DesignProblem, model: Model, balls: Any, theta: Any,
               load: Any) -> Callable[[np.ndarray, np.ndarray], dict[str, Any]]:
    """``(angle offset [deg], speed [m/s]) -> the physics inputs the model is given at a design``, as
    :func:`_objective_values` gives them (without the values the model holds)."""
    held = {*model.fixed, *model.fitted}

    def inputs_fn(offset: np.ndarray, speed: np.ndarray) -> dict[str, Any]:
        columns = problem.physics_inputs(balls, theta + offset, load, speed_m_s=speed)
        return {k: v for k, v in columns.items() if k not in held}

    return inputs_fn


def _certified_search(problem: DesignProblem, envelope: Envelope, model: Model, pieces: list,
                      design: Mapping[str, Any], shift: float, rtol: float | None = None) -> CertifiedMax:
    """The worst μ over the envelope at a design (angle θ' = θ + ``shift``), bracketed by branch and bound."""
    balls, load = float(design["balls"]), float(design["load_N"])
    theta = float(design["groove_angle_deg"]) - shift

    def physics_mu(offset: np.ndarray, speed: np.ndarray, **parameters: np.ndarray) -> np.ndarray:
        with np.errstate(all="ignore"):
            return physics.evaluate(convention=problem.convention, outputs=["mu"], **{
                **problem.physics_inputs(balls, theta + offset, load, speed_m_s=speed), **parameters}).mu

    # The values the drifts start from: the model's own (in problem.fixed, _with_model_values), else defaults.
    base = {**physics.defaults(), **problem.fixed}
    return certified_max(mu_box_bound(pieces, physics_mu, envelope, {"balls": balls, "load_N": load},
                                      model.calibrated, base, _inputs_fn(problem, model, balls, theta, load)),
                         _evaluator(problem, envelope, model, "mu", design, shift), envelope,
                         rtol=rtol or BOUND_RTOL)


def _design_box_corners(problem: DesignProblem, model: Model,
                        point: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """The model's points at the design box's lowest and highest corner at one envelope point (each column
    non-decreasing in balls, the nominal angle and the load)."""
    (b_lo, b_hi), (a_lo, a_hi), (l_lo, l_hi) = (problem.bounds.balls, problem.bounds.groove_angle_deg,
                                                problem.bounds.load_N)
    offset, speed = float(point["groove_angle_offset_deg"]), np.array([float(point["speed_m_s"])])
    conditions = {n: np.array([float(v)]) for n, v in point["conditions"].items()}
    low, high = [{**_inputs_fn(problem, model, np.array([float(b)]), np.array([a]), np.array([g]))(
        offset, speed), **conditions} for b, a, g in ((b_lo, a_lo, l_lo), (b_hi, a_hi, l_hi))]
    return low, high


def _point_lower_bound(problem: DesignProblem, model: Model, point: Mapping[str, Any],
                       factor: float = 1.0) -> float:
    """A certified lower bound [1] of the least objective over the designs at one envelope point (NaN: none).

    ``factor`` > 0 is a lower bound of the objective over the model's μ without its groups and discrepancy
    (1 for μ with neither; :func:`optimize.envelope_bound.interval_floor` for ``mu_upper``): the bound is
    factor × exp(the discrepancy's least mean over the design box at the point) × the programs' bound, and
    the friction-force limit on the objective enters the programs divided by that product (a relaxation).

    At a fixed point every effect term is a positive monomial in balls and load_N (read and checked,
    :func:`_monomials_at`), so the calibrated μ there is a posynomial and its minimum over the designs, with
    the limits at that point, a geometric program per ball count (the dual bound of each, the least of them).
    The limits at one point are a relaxation of the limits over the envelope, and the worst case of any
    design is at least its μ at the point: the bound holds for the best achievable worst case.
    """
    terms = [(t, v) for t, v in model.calibrated.terms if getattr(t, "kind", None) != "drift"]
    monomials, _ = _monomials_at([t for t, _ in terms], [v for _, v in terms], point)
    if monomials is None:
        return math.nan
    try:
        at_point = shifted_problem(problem, float(point["groove_angle_offset_deg"]),
                                   float(point["speed_m_s"]))
    except ValueError:
        return math.nan
    # A drift fixes its parameter at the point: the drifted value, in the program's fixed values.
    drifts, _ = term_pieces(model)
    drifted = drift_ranges([p for p in drifts or [] if p.kind == "drift"],
                           {**physics.defaults(), **problem.fixed},
                           lambda driver: (np.atleast_1d(point["conditions"][driver]),) * 2 + (None,), 1)
    if drifted:
        at_point = DesignProblem(at_point.bounds, at_point.speed_m_s, at_point.constraints,
                                 {**at_point.fixed, **{n: float(lo[0]) for n, (lo, _) in drifted.items()}},
                                 at_point.convention)
    if model.calibrated.discrepancy is not None:
        corners = _design_box_corners(problem, model, point)
        factor *= math.exp(float(model.calibrated.discrepancy_bound(corners[0], corners[1], (1,))[0][0]))
    if factor != 1.0 and at_point.constraints.max_friction_force_N is not None:
        at_point = DesignProblem(at_point.bounds, at_point.speed_m_s, dataclasses.replace(
            at_point.constraints, max_friction_force_N=at_point.constraints.max_friction_force_N / factor),
            at_point.fixed, at_point.convention)
    bounds = [answer[4] for answer in _calibrated_counts(at_point, monomials).values()]
    return math.nan if not bounds or any(math.isnan(b) for b in bounds) else float(min(bounds)) * factor


def _certified_proof(problem: DesignProblem, model: Model, bracket: CertifiedMax,
                     points: list[dict[str, Any]], history: list[dict[str, Any]], rounds: int,
                     ending: str) -> tuple[dict[str, Any], float]:
    """The proof of a design whose worst μ is bracketed: the bracket, and the best lower bound at the points.

    ``problem`` is in the nominal angle (the points carry their offsets). Returns the proof and the worst case
    found at the design [1].
    """
    # Groups move every design's mu by one factor at a point naming none (objective mu: sensitivity 1).
    groups = math.exp(group_shift(model.calibrated))
    bounds = [_point_lower_bound(problem, model, p, groups) for p in points]
    known = [b for b in bounds if not math.isnan(b)]
    upper = bracket.upper_bound
    lower = min(max(known), upper) if known else None
    gap = None if lower is None else max(0.0, (upper - lower) / upper)
    proven = bool(gap is not None and gap <= GAP_TARGET)
    statement = (
        f"{model.reference}: the physics with its fitted values and its effect terms, each added to mu or "
        "multiplying it and each a function of one driver; the physics' mu is non-decreasing in the angle "
        "made and the speed (a posynomial), each term monotone in its driver or log-quadratic (its maximum "
        "over an interval at an end or at its stationary point), so over any box of the envelope mu is at "
        "most the composition of those maxima. Branch and bound over the envelope at the design "
        f"({bracket.boxes} boxes{'' if bracket.complete else ', stopped at the box limit'}) brackets the "
        "worst "
        f"case: found {bracket.value:.10g}, certified at most {upper:.10g} (relative "
        f"{bracket.relative_gap:.1e}). The design came from the outer approximation in {rounds} round(s) "
        f"({ending}). Certified lower bound on the best achievable worst case "
        f"{lower if lower is not None else float('nan'):.10g}: at {len(points)} envelope point(s) (the worst "
        "one at the design first) mu is a posynomial in tan(theta) and load_N for every ball count (each "
        "term "
        "a positive monomial there, read and checked), and the least dual objective of those geometric "
        "programs bounds every design's mu at that point; the largest such bound is taken. Relative gap "
        f"{gap if gap is not None else float('nan'):.2e} (target {GAP_TARGET:g})")
    statement += (": proven." if proven else
                  ": not proven (the gap is above the target: the best bound found is stated).")
    proof = {"proven": proven, "method": "outer-approximation-certified", "lower_bound": lower,
             "upper_bound": upper, "relative_gap": gap, "gap_target": GAP_TARGET, "statement": statement,
             "rounds": history, "worst_case_boxes": bracket.boxes,
             "worst_case_relative_gap": bracket.relative_gap}
    return proof, bracket.value


def _robust_model(problem: DesignProblem, envelope: Envelope, model: Model, objective: str, starts: int,
                  max_rounds: int, progress: Callable[[float], None] | None,
                  map_calls: Callable | None, reason: str = "",
                  initial_points: list[dict[str, Any]] | None = None,
                  time_limit_s: float = math.inf) -> RobustResult:
    start = time.perf_counter()
    delta = envelope.angle_tolerance_deg
    v_hi = envelope.speed_m_s[1]
    # Limits that do not depend on the model (the peak pressure) are worst at the angle made high: the
    # optimizer works in θ' = θ + δ, and the model is asked at θ' - δ + offset.
    shifted = shifted_problem(problem, delta, v_hi)
    points = initial_points or _vertices_and_centre(envelope)
    initial_count = len(points)
    # mu of a calibrated model whose terms are all bounded over a box: the worst case at each design is
    # certified by branch and bound (optimize.envelope_bound), not searched.
    certify, why = _certifier(envelope, model, objective)
    if certify is None and why:
        reason = f"{reason}; nor is its worst case at a design bounded: {why}" if reason else why
    bracket = None
    rounds, history, converged, timed_out = 0, [], False, False
    solved = None
    value, where = math.nan, None
    for rounds in range(1, max_rounds + 1):
        set_model = _SetModel(shifted, envelope, model, objective, points, delta)
        fraction = 0.8 * (rounds - 1) / max_rounds
        solved = optimize_model(shifted, set_model, starts=starts, model_name=model.reference,
                                progress=None if progress is None else (
                                    lambda f, a=fraction: progress(a + 0.8 * f / max_rounds)),
                                map_calls=map_calls)
        design = _design_of(solved)
        on_set = float(set_model({k: np.array([v]) for k, v in design.items()})[0])
        if certify is not None:
            try:
                bracket = certify(shifted, design, delta)
                value, where = bracket.value, bracket.point
            except BoundFailedError as exc:  # the model breaks the bound's premise: searched, and said so
                certify, bracket = None, None
                reason = f"its bound over a box failed a check ({exc})"
        if certify is None:
            evaluate = _evaluator(shifted, envelope, model, objective, design, delta)
            value, where, _ = worst_case_search(evaluate, envelope)
        history.append({"round": rounds, "points": len(points), "on_set": on_set, "searched": value})
        if value <= on_set * (1 + ENVELOPE_RTOL):
            value, converged = max(value, on_set), True
            break
        if time.perf_counter() - start > time_limit_s:
            timed_out = True
            break
        points = [*points, where]
    design = _design_of(solved)
    if converged:
        ending = f"the last search found {value:.10g}, within {ENVELOPE_RTOL:g} of the optimized set"
    else:
        when = f"at the time limit of {time_limit_s:g} s after" if timed_out else "after"
        ending = (f"stopped {when} {rounds} round(s) with the last search {value:.10g} above the optimized "
                  f"set's {history[-1]['on_set']:.10g}: the design is not the best for the worst case found")
    theta = design["groove_angle_deg"] - delta
    start_set = "the vertex where mu is proven worst" if initial_points else "vertices and centre"
    statement = (
        f"No proof: {model.reference} is not known to be monotone or log-log convex in the speed, the "
        f"conditions and the angle ({reason or 'not a calibrated model'}), and no bound on its derivatives "
        "is known, so its worst case over a box cannot be bounded rigorously. Method: outer approximation in "
        f"{rounds} round(s) - the local method minimized the largest {objective} over {len(points)} envelope "
        f"point(s) ({start_set}, then the worst points found), and at each design the whole envelope was "
        f"searched (a grid of every axis, then L-BFGS-B ascent from the 3 best grid points); {ending}. "
        "Best bound found: the worst case at the design as searched (upper_bound)"
        + ("; the design search is local, so no certified lower bound on the best achievable worst case "
           "exists." if objective == "mu" else "."))
    proof = {"proven": False, "method": "outer-approximation-local", "lower_bound": None,
             "upper_bound": value,
             "relative_gap": None, "gap_target": GAP_TARGET, "statement": statement, "rounds": history}
    if bracket is not None and objective == "mu":
        proof, value = _certified_proof(problem, model, bracket, [where, *points[initial_count:]], history,
                                        rounds, ending)
        statement = proof["statement"]
    elif bracket is not None:
        statement = (
            f"{model.reference}: the worst mu_upper over the envelope at the design is certified by branch "
            "and bound: over any box, the physics' mu and its pivoting share lie between the box's lowest "
            "and highest corner (posynomials), each term between its exact extremes, the composed mu and "
            "each fitted value's finite-difference gradient of log mu by interval arithmetic in closed form, "
            "the parameter variance g'Cg at most its largest value over the box of gradients (a vertex: "
            f"convex){_CLOUD_WORDS if model.calibrated.cloud is not None else ''}, for the model and each "
            f"rival ({bracket.boxes} boxes"
            f"{'' if bracket.complete else ', stopped at the box limit'}): found {bracket.value:.10g}, "
            "certified "
            f"at most {bracket.upper_bound:.10g} (relative {bracket.relative_gap:.1e}). The design came from "
            f"the outer approximation in {rounds} round(s) ({ending}).")
        # Every design's mu_upper at the worst point is at least exp(z noise) times its mu there (the interval
        # is at least the scatter), and its mu there at least the dual bound of the geometric programs.
        # Started from mu's proven worst vertex, that bound is already known (optimize_robust adds it).
        # The data cloud widens every design's interval at the worst point at least by its least distance
        # ratio over the design box there (a lower bound of the k-th nearest distance).
        calibrated = model.calibrated
        least = 1.0
        if calibrated.cloud is not None:
            corners = _design_box_corners(problem, model, where)
            ratio = calibrated.cloud_ratio_bound(*corners, (1,), lower=True)
            least = float(calibrated.cloud.widening(ratio)[0])
        scatter = interval_floor(calibrated, float(stats.norm.isf(0.025)), least)
        at_worst = (_point_lower_bound(problem, model, where, scatter)
                    if initial_points is None and scatter is not None else math.nan)
        lower = None
        if not math.isnan(at_worst):
            lower = min(at_worst, bracket.upper_bound)
            statement += (f" Certified lower bound {lower:.10g}: at the worst point every design's mu_upper "
                          f"is at least {scatter:.10g} (exp(1.96 x the measurement scatter), with the "
                          "groups' offset and spread where the model has groups, times the data cloud's "
                          f"least widening over the designs there, {least:.4g}) times its mu there, and "
                          "that mu at least the dual bound of geometric programs per ball count there (as "
                          "for objective mu; a discrepancy's least mean over the designs there multiplies "
                          "it).")
        gap = None if lower is None else (bracket.upper_bound - lower) / bracket.upper_bound
        proof = {"proven": False, "method": "outer-approximation-certified", "lower_bound": lower,
                 "upper_bound": bracket.upper_bound, "relative_gap": gap, "gap_target": GAP_TARGET,
                 "statement": statement, "rounds": history, "worst_case_boxes": bracket.boxes,
                 "worst_case_relative_gap": bracket.relative_gap}
    worst_case = _worst_case_dict(objective, value, where, theta)
    # Price of robustness: the nominal optimum at the envelope's centre (no tolerance) and its worst case.
    centre = envelope.centre()
    centre_envelope = Envelope(centre["speed_m_s"], centre["conditions"])
    nominal_problem = DesignProblem(problem.bounds, centre["speed_m_s"], problem.constraints, problem.fixed,
                                    problem.convention)
    try:
        nominal = optimize_model(nominal_problem,
                                 _SetModel(nominal_problem, centre_envelope, model, objective,
                                           [centre_envelope.point({})], 0.0),
                                 starts=1, model_name=model.reference, map_calls=map_calls)
    except InfeasibleDesignError:  # the local method found no design meeting the limits at the centre
        nominal = solved
    nominal_design = _design_of(nominal)
    if nominal is solved:
        nominal_design["groove_angle_deg"] -= delta
    # The nominal design's worst case: certified by the same branch and bound as the robust one's where it
    # applies, to NOMINAL_RTOL (its upper bound then judges the friction limit), else searched.
    nominal_bracket = None
    if certify is not None:
        try:
            nominal_bracket = certify(problem, nominal_design, 0.0, rtol=NOMINAL_RTOL)
        except BoundFailedError:
            nominal_bracket = None
    if nominal_bracket is not None:
        nominal_worst, nominal_upper = nominal_bracket.value, nominal_bracket.upper_bound
    else:
        nominal_worst, _, _ = worst_case_search(
            _evaluator(problem, envelope, model, objective, nominal_design, 0.0), envelope)
        nominal_upper = None
    limits = constraint_report(shifted, nominal_design["balls"], nominal_design["groove_angle_deg"] + delta,
                               nominal_design["load_N"], mu=nominal_upper or nominal_worst)
    centre_point = envelope.point({"speed_m_s": centre["speed_m_s"],
                                   **{f"conditions.{n}": v for n, v in centre["conditions"].items()}})
    robust_centre = float(_evaluator(problem, envelope, model, objective, design, delta)([centre_point])[0])
    nominal_centre = float(_evaluator(problem, envelope, model, objective, nominal_design, 0.0)(
        [centre_point])[0])
    price = _price(nominal_design, nominal_centre, nominal_worst,
                   all(c.satisfied for c in limits if not c.name.startswith("groove_angle_deg")),
                   {**design, "groove_angle_deg": theta}, robust_centre, value, nominal_upper,
                   None if bracket is None else bracket.upper_bound)
    certificate = (f"{'Proven' if proof['proven'] else 'Local'} optimum of the worst case over the envelope"
                   f"{'' if proof['proven'] else ', not proven'}. {statement}")
    result = _unshift(dataclasses.replace(solved, mu=value, certificate=certificate,
                                          speed_m_s=float(where["speed_m_s"]),
                                          method=proof["method"],
                                          solve_time_s=time.perf_counter() - start), delta)
    if progress is not None:
        progress(1.0)
    return RobustResult(result, objective, envelope, worst_case, proof, price)


# --------------------------------------------------------------------------------------------------
# Calibrated models whose terms keep the problem a geometric program


#: Reference designs (balls [1], load [N]) at which a term's monomial form in the design is read, and
#: the one at which it is checked.
_PROBES = ((1.0, 1.0), (2.0, 1.0), (1.0, 2.0), (3.0, 0.37))


@dataclass(frozen=True)
class _Monomial:
    """A term at the envelope's worst vertex: ``kind`` "add" (μ + k z^a G^b) or "mul" (μ k z^a G^b)."""

    kind: str
    coefficient: float
    balls_exponent: float
    load_exponent: float


def _term_structure(model: Model,
                    envelope: Envelope) -> tuple[dict[str, Any] | None, list[_Monomial], str]:
    """The worst vertex and each term as a monomial in the design there, or None and why not.

    The worst vertex follows from the directions each effect declares
    (:attr:`physics.effects.Effect.direction`, at the fitted values) and the physics' μ, which grows with
    speed and angle; each term's form in (balls, load) is read at three designs and checked at a fourth,
    so a term whose form the declarations do not describe is refused, not guessed.
    """
    calibrated = getattr(model, "calibrated", None)
    if calibrated is None:
        return None, [], f"{model.reference} is not a calibrated model"
    if getattr(calibrated, "discrepancy", None) is not None:
        return None, [], "its Gaussian-process discrepancy is not log-log convex"
    directions: dict[str, set[int]] = {"speed_m_s": {1}}
    terms = []
    for term, values in calibrated.terms:
        if getattr(term, "kind", None) != "effect" or term.effect.direction is None:
            return None, [], f"its term {getattr(term, 'label', term)!r} is not one known to be monotone"
        driver = term.drivers[0]
        if driver == "groove_angle_deg" or (driver not in ("speed_m_s", "load_N", "balls")
                                            and driver not in envelope.conditions):
            return None, [], f"its term {term.label} is driven by {driver}"
        if driver not in ("load_N", "balls"):
            directions.setdefault(driver, set()).add(term.effect.direction(values))
        terms.append((term, values))
    worst: dict[str, float] = {}
    for axis, signs in directions.items():
        signs.discard(0)
        if len(signs) > 1:
            return None, [], f"mu rises and falls with {axis} (terms of opposite directions)"
        rising = not signs or signs == {1}
        lo, hi = envelope.speed_m_s if axis == "speed_m_s" else envelope.conditions[axis]
        worst[axis] = hi if rising else lo
    conditions = {n: worst.get(n, lo) for n, (lo, _) in envelope.conditions.items()}
    vertex = {"speed_m_s": worst["speed_m_s"], "conditions": conditions,
              "groove_angle_offset_deg": envelope.angle_tolerance_deg}
    monomials, reason = _monomials_at([t for t, _ in terms], [v for _, v in terms], vertex)
    return (vertex if monomials is not None else None), monomials or [], reason


def _monomials_at(terms: Sequence[Any], term_values: Sequence[Sequence[float]],
                  point: Mapping[str, Any]) -> tuple[list[_Monomial] | None, str]:
    """Each effect term at one envelope point as a positive monomial in (balls, load_N), or None and why.

    Read at three designs and checked at a fourth (:data:`_PROBES`): a term the reading does not fit
    is refused, not guessed.
    """
    monomials = []
    conditions = point["conditions"]
    z = np.array([p[0] for p in _PROBES])
    g = np.array([p[1] for p in _PROBES])
    columns = {"balls": z, "load_N": g, "speed_m_s": np.full(z.shape, point["speed_m_s"]),
               **{n: np.full(z.shape, v) for n, v in conditions.items()}}
    for term, values in zip(terms, term_values, strict=True):
        effect = term.effect
        params = dict(zip(effect.parameter_names, values, strict=True))
        with np.errstate(all="ignore"):
            try:
                at = [effect.apply(np.full(z.shape, m), columns, params, term.drivers, term.constants)
                      for m in (0.0, 0.7, 1.0)]
            except ValueError as exc:
                return None, str(exc)
        added = at[0]
        if np.allclose(at[1], 0.7 + added, rtol=1e-12, atol=0.0) and np.all(added >= 0):
            kind, amount = "add", added
        elif np.allclose(at[1], 0.7 * at[2], rtol=1e-12, atol=0.0) and np.all(at[2] > 0):
            kind, amount = "mul", at[2]
        else:
            return None, f"its term {term.label} is neither a positive addition nor a positive factor"
        if kind == "add" and np.all(amount == 0):
            continue
        if not np.all(amount > 0):
            return None, f"its term {term.label} vanishes at some designs only"
        a = float(np.log2(amount[1] / amount[0]))
        b = float(np.log2(amount[2] / amount[0]))
        k = float(amount[0])
        if not math.isclose(k * 3.0**a * 0.37**b, float(amount[3]), rel_tol=1e-9):
            return None, f"its term {term.label} is not a monomial in balls and load_N"
        monomials.append(_Monomial(kind, k, a, b))
    return monomials, ""


def _compose(gp, monomials: list[_Monomial]):
    """The calibrated μ as a DGP expression of the physics' one and the terms, in their order."""
    mu = gp.expressions["mu"]
    for m in monomials:
        piece = m.coefficient
        if m.balls_exponent:
            piece = piece * gp.balls**m.balls_exponent
        if m.load_exponent:
            piece = piece * gp.load_N**m.load_exponent
        mu = mu + piece if m.kind == "add" else mu * piece
    return mu


def _calibrated_counts(problem: DesignProblem, monomials: list[_Monomial]) -> dict[int, tuple]:
    """Every ball count's DGP optimum of the calibrated μ: (status, value, tan θ, load, lower bound)."""
    limits = frozenset(n for n in problem.constraints.active_limits() if n in LIMIT_NAMES)
    force = problem.constraints.max_friction_force_N
    programs: dict[int, tuple] = {}
    answers = {}
    for z in problem.ball_counts():
        gp, values = design_gp(problem, limits=limits - {"max_friction_force_N"}, balls=z)
        if id(gp) not in programs:
            mu = _compose(gp, monomials)
            cons = [c for name, c in gp.constraints.items() if name != "max_friction_force_N"]
            limit = cp.Parameter(pos=True, name="friction_limit")
            if force is not None:
                cons.append(mu * gp.load_N <= limit)
            programs[id(gp)] = (cp.Problem(cp.Minimize(mu), cons), limit)
        program, limit = programs[id(gp)]
        relaxed = {n: (v / (1.0 - SAFETY_MARGIN) if LIMIT_NAMES.get(n) == "max" else v)
                   for n, v in values.items()}
        with gp.lock:
            gp.assign(values, z)
            limit.value = (force or 1.0) * (1.0 - SAFETY_MARGIN)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)
                try:
                    program.solve(gp=True, solver=cp.CLARABEL)
                    status = program.status
                except cp.SolverError:
                    status = "solver_error"
            solved = status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)
            value = float(program.value) if solved else math.nan
            t = float(gp.tan_theta.value) if solved else math.nan
            g = float(gp.load_N.value) if solved else math.nan
            gp.assign(relaxed, z)
            limit.value = force or 1.0
            _, _, lower = dual_bound(program)
        answers[z] = (status, value, t, g, lower)
    return answers


def _robust_calibrated_gp(problem: DesignProblem, envelope: Envelope, model: Model,
                          progress: Callable[[float], None] | None,
                          bound_only: bool = False) -> RobustResult | str:
    """The robust design of a calibrated model whose terms keep the problem a GP, proven; else why not.

    ``bound_only``: only the design and its certified bound are wanted (no envelope search, no price of
    robustness: their fields repeat the design's own values).
    """
    start = time.perf_counter()
    vertex, monomials, reason = _term_structure(model, envelope)
    if vertex is None:
        return reason
    delta = envelope.angle_tolerance_deg
    shifted = shifted_problem(problem, delta, vertex["speed_m_s"])
    answers = _calibrated_counts(shifted, monomials)
    solved = {z: a for z, a in answers.items() if a[0] in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)}
    if not solved:
        return "no ball count has a solution of the geometric program"
    box_angle, box_load = shifted.bounds.groove_angle_deg, shifted.bounds.load_N
    counts = sorted(solved)
    theta_p = np.clip(np.degrees(np.arctan([solved[z][2] for z in counts])), *box_angle)
    load = np.clip([solved[z][3] for z in counts], *box_load)
    def exact_at(theta: np.ndarray, load: np.ndarray) -> np.ndarray:
        designs = {"balls": np.array(counts, dtype=float), "groove_angle_deg": theta, "load_N": load}
        return _objective_values(model, "mu", _columns(problem, envelope, designs, [vertex], delta),
                                 problem.convention)

    exact = exact_at(theta_p, load)
    if shifted.constraints.max_friction_force_N is None:
        # The solver stops within its tolerance of a binding limit: moved onto the exact boundary with the
        # physics (optimize.solve.polish_design), kept only where the model's mu is lower there.
        theta_q, load_q, _ = polish_design(shifted, np.array(counts), theta_p, load)
        polished = exact_at(theta_q, load_q)
        better = polished < exact
        theta_p, load = np.where(better, theta_q, theta_p), np.where(better, load_q, load)
        exact = np.where(better, polished, exact)
    # The fewest balls among the designs within 1e-6 of the best (mu depends on the load per ball).
    best_index = min(np.flatnonzero(exact <= exact.min() * (1 + TIE_TOLERANCE)), key=lambda k: counts[k])
    z_best = counts[best_index]
    design = {"balls": z_best, "groove_angle_deg": float(theta_p[best_index]),
              "load_N": float(load[best_index])}
    value = float(exact[best_index])
    mu_solver = solved[z_best][1]
    mismatch = max(abs(solved[z][1] / float(exact[k]) - 1) for k, z in enumerate(counts))
    if mismatch > 1e-6:
        return (f"the geometric program and the model differ by {mismatch:.1e} relative at the counts' "
                "optima (a term the translation does not capture)")
    bounds = [a[4] for a in answers.values()]
    lower = None if any(math.isnan(b) for b in bounds) else min(min(bounds), value)
    gap = None if lower is None else max(0.0, (value - lower) / value)
    # Cross-check of the vertex argument at the design: a search of the whole envelope finds nothing worse.
    searched, where = (value, vertex) if bound_only else worst_case_search(
        _evaluator(problem, envelope, model, "mu", design, delta), envelope)[:2]
    proven = lower is not None and gap <= GAP_TARGET and searched <= value * (1 + 1e-9)
    rows = [BallCountResult(z, "does not fit the groove") for z in range(shifted.bounds.balls[0],
                                                                         shifted.bounds.balls[1] + 1)
            if z not in answers]
    rows += [BallCountResult(z, answers[z][0] if z not in solved else solved[z][0])
             if z not in solved else
             BallCountResult(z, solved[z][0], float(theta_p[counts.index(z)]), float(load[counts.index(z)]),
                             float(exact[counts.index(z)]), solved[z][1],
                             solved[z][1] / float(exact[counts.index(z)]) - 1.0)
             for z in answers]
    rows.sort(key=lambda r: r.balls)
    directions = ", ".join(f"{n} at {v:g}" for n, v in vertex["conditions"].items()) or "no condition"
    statement = (
        f"{model.reference}: the physics with its fitted values and {len(monomials)} term(s), each a "
        "positive "
        "monomial in balls and load_N added to mu or multiplying it (read at three designs, checked at a "
        "fourth), driven by the speed or a condition through a formula monotone in it (physics.effects; "
        "the directions from the fitted parameters' signs), so mu is a posynomial in tan(theta) and load_N "
        "for every ball count and its worst case over the envelope is one vertex: the angle made high "
        f"(+{delta:g} deg), speed {vertex['speed_m_s']:g} m/s, {directions}. The robust problem is then the "
        "geometric program of every ball count at that vertex; certified lower bound "
        f"{lower if lower is not None else float('nan'):.10g} (least dual objective over the counts, limits "
        f"exact, less Clarabel's tolerance), worst case at the design {value:.10g} (the model itself), "
        f"relative gap {gap if gap is not None else float('nan'):.2e} (target {GAP_TARGET:g}); solver and "
        f"model agree to {mismatch:.1e} at every count's optimum. A search of the whole envelope at the "
        "design "
        f"(grid and L-BFGS-B) found {searched:.10g}.")
    if searched > value * (1 + 1e-9):
        statement += (" That is above the vertex's value: the monotonicity argument failed here, nothing is "
                      "proven.")
    proof = {"proven": bool(proven), "method": "robust-gp-vertex", "lower_bound": lower, "upper_bound": value,
             "relative_gap": gap, "gap_target": GAP_TARGET, "statement": statement}
    worst_point = vertex if searched <= value * (1 + 1e-9) else where
    worst_case = _worst_case_dict("mu", max(value, searched), worst_point, design["groove_angle_deg"] - delta)
    # Price of robustness: the same program at the envelope's centre, no tolerance.
    centre = envelope.centre()
    centre_envelope = Envelope(centre["speed_m_s"], centre["conditions"])
    nominal = (_robust_calibrated_gp(problem, centre_envelope, model, None, bound_only=True)
               if envelope.axes() and not bound_only else None)
    if isinstance(nominal, RobustResult):
        nominal_design = _design_of(nominal.result)
        nominal_worst = float(_evaluator(problem, envelope, model, "mu", nominal_design, 0.0)(
            [{**vertex, "groove_angle_offset_deg": delta}])[0])
        nominal_centre = float(nominal.worst_case["mu"])
        limits = constraint_report(shifted, nominal_design["balls"],
                                   nominal_design["groove_angle_deg"] + delta, nominal_design["load_N"],
                                   mu=nominal_worst)
        nominal_holds = all(c.satisfied for c in limits if not c.name.startswith("groove_angle_deg"))
    else:
        nominal_design, nominal_worst, nominal_centre, nominal_holds = (
            {**design, "groove_angle_deg": design["groove_angle_deg"] - delta}, value, value, True)
    robust_centre = float(_evaluator(problem, envelope, model, "mu", design, delta)(
        [envelope.point({"speed_m_s": centre["speed_m_s"],
                         **{f"conditions.{n}": v for n, v in centre["conditions"].items()}})])[0])
    # Both worst cases at the vertex are exact by the monotonicity argument (where the search agreed).
    vertex_holds = searched <= value * (1 + 1e-9)
    price = _price(nominal_design, nominal_centre, nominal_worst, nominal_holds,
                   {**design, "groove_angle_deg": design["groove_angle_deg"] - delta}, robust_centre, value,
                   nominal_worst if vertex_holds else None, value if vertex_holds else None)
    best_mu = value
    ties = [{"balls": r.balls, "groove_angle_deg": r.groove_angle_deg, "load_N": r.load_N,
             "load_per_ball_N": r.load_N / r.balls, "mu": r.mu}
            for r in rows if r.mu is not None and r.mu <= best_mu * (1 + TIE_TOLERANCE)]
    certificate = ("Global optimum of the worst case of mu over the envelope, by geometric programming per "
                   f"ball count (all {len(rows)} counts enumerated). {statement}")
    result = OptimizationResult(
        design=design, mu=value, mu_solver=mu_solver, relative_gap=mu_solver / value - 1.0,
        speed_m_s=float(vertex["speed_m_s"]),
        constraints=constraint_report(shifted, z_best, design["groove_angle_deg"], design["load_N"],
                                      mu=value, mu_name=model.reference),
        per_ball_count=rows, ties=ties, certificate=certificate, solve_time_s=time.perf_counter() - start,
        method="robust-gp-vertex")
    if progress is not None:
        progress(1.0)
    return RobustResult(_unshift(result, delta), "mu", envelope, worst_case, proof, price)
