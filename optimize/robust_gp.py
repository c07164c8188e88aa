"""Robust geometric programs with a certified dual bound, and the robust design of the physics itself.

The proofs are those of :mod:`optimize.robust` ("The physics: a proof by geometric programming").
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from .dgp import LIMIT_NAMES, SAFETY_MARGIN, design_gp
from .over_envelope import (
    Envelope,
    evaluator,
    shifted_problem,
    vertices_and_centre,
)
from .problem import DesignProblem, constraint_report
from .proof import (
    GAP_TARGET,
    Proof,
    RobustResult,
    design_of,
    price_of,
    unshift,
    worst_case_dict,
)
from .solve import (
    OptimizationResult,
    optimize_design,
)

#: Clarabel's stopping tolerances (gap and feasibility, its defaults), taken off the dual bound. [1]
_SOLVER_TOL = 1e-8


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


def physics_lower_bound(problem: DesignProblem,
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


def robust_physics(problem: DesignProblem, envelope: Envelope,
                   progress: Callable[[float], None] | None) -> RobustResult:
    """The robust design of the physics: one geometric program per ball count at the envelope's worst
    vertex, proven by the dual bound (the module docstring of :mod:`optimize.robust`)."""
    start = time.perf_counter()
    delta = envelope.angle_tolerance_deg
    v_hi = envelope.speed_m_s[1]
    shifted = shifted_problem(problem, delta, v_hi)
    solved = optimize_design(shifted, progress=None if progress is None else (lambda f: progress(0.6 * f)))
    lower, unbounded = physics_lower_bound(shifted, solved)
    design = design_of(solved)
    theta = design["groove_angle_deg"] - delta
    # Where the worst case occurs, and a check of the vertex argument on the exact physics: no other
    # vertex or the centre is worse.
    evaluate = evaluator(problem, envelope, None, "mu", design, delta)
    vertices = vertices_and_centre(envelope)
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
        f"their worst case is at the angle made high (nominal + {envelope.said_tolerance(delta)}) and the "
        "highest speed, "
        f"{envelope.said('speed_m_s', v_hi)}; the physics reads no condition column. The robust problem is "
        "the geometric program of every ball count on the angle box moved by "
        f"{envelope.said_tolerance(delta)} at that speed, "
        "solved per count; "
        f"certified lower bound {lower if lower is not None else float('nan'):.10g} (least dual objective "
        f"over the counts, limits exact, less Clarabel's 1e-8 tolerance), worst case at the design "
        f"{value:.10g} (exact physics), relative gap {gap if gap is not None else float('nan'):.2e} "
        f"(target {GAP_TARGET:g}). The {len(vertices)} vertices and centre of the envelope checked on the "
        f"exact physics: largest {float(np.max(at)):.10g}.")
    if unbounded:
        statement += f" Counts {unbounded} could not be bounded by the solver: no certified bound."
    if lower is not None and gap > GAP_TARGET:
        statement += " The gap is above the target: the optimum is proven only to that gap."
    proof = Proof(bool(proven), "robust-gp-vertex", lower, value, gap, statement)
    vertex_holds = float(np.max(at)) <= value * (1 + 1e-12)
    if not vertex_holds:
        proof = dataclasses.replace(proof.with_statement(
            f" But a vertex or the centre gave {float(np.max(at)):.10g} > the predicted worst case: the "
            "monotonicity argument failed here, nothing is proven."), proven=False)
        value = float(np.max(at))
        predicted = worst
    worst_case = worst_case_dict("mu", value, predicted, theta)
    # Price of robustness: the nominal optimum at the envelope's centre and its worst case.
    centre_speed = envelope.centre()["speed_m_s"]
    nominal = optimize_design(DesignProblem(problem.bounds, centre_speed, problem.constraints, problem.fixed,
                                            problem.convention))
    nominal_design = design_of(nominal)
    nominal_eval = evaluator(problem, envelope, None, "mu", nominal_design, 0.0)
    nominal_worst = float(nominal_eval([predicted | {"groove_angle_offset_deg": delta}])[0])
    nominal_limits = constraint_report(shifted, nominal_design["balls"],
                                       nominal_design["groove_angle_deg"] + delta,
                                       nominal_design["load_N"])
    robust_centre = float(evaluator(problem, envelope, None, "mu", design, delta)(
        [envelope.point({"speed_m_s": centre_speed})])[0])
    # Both worst cases at the vertex are exact where the monotonicity held on the checked points.
    price = price_of(nominal_design, nominal.mu, nominal_worst,
                   all(c.satisfied for c in nominal_limits if not c.name.startswith("groove_angle_deg")),
                   {**design, "groove_angle_deg": theta}, robust_centre, value,
                   nominal_worst if vertex_holds else None, value if vertex_holds else None)
    certificate = (solved.certificate + " Envelope: " + statement)
    result = unshift(dataclasses.replace(solved, mu=value, certificate=certificate,
                                          speed_m_s=v_hi, solve_time_s=time.perf_counter() - start), delta)
    if progress is not None:
        progress(1.0)
    return RobustResult(result, "mu", envelope, worst_case, proof, price)
