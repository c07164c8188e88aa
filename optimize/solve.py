"""Certified minimum-friction designs: enumerate ball counts, solve one DGP per count, verify.

:func:`optimize_design` solves the DGP of :mod:`optimize.dgp` for every
integer ball count of the bounds that fits the groove, re-evaluates each
optimum with :func:`physics.evaluate`, and returns the best design with its
exact μ, the solver gap, the constraint report, the per-count table, ties and
a certificate stating what is proven. Integers are never left to a solver:
the ball count is a parameter and every count is solved. Infeasible problems
raise :class:`InfeasibleDesignError` naming an irreducible set of conflicting
limits (a deletion filter on the phase-I problem).
"""

from __future__ import annotations

import itertools
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import cvxpy as cp
import numpy as np

from microbearing import physics

from .dgp import SAFETY_MARGIN, BallCountResolver, design_gp
from .problem import DESIGN_VARIABLES, ConstraintStatus, DesignBounds, DesignProblem, constraint_report

__all__ = [
    "TIE_TOLERANCE",
    "InfeasibleDesignError",
    "BallCountResult",
    "OptimizationResult",
    "optimize_design",
    "find_conflicts",
    "polish_design",
]

#: Designs whose exact μ is within this relative distance of the best are ties. [1]
TIE_TOLERANCE = 1e-6
_SOLVER = cp.CLARABEL
#: From this many ball counts on, :class:`BallCountResolver` pays for its three compilations. [1]
_FAST_MIN_COUNTS = 4
_OPTIMAL = (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)
_INFEASIBLE = (cp.INFEASIBLE, cp.INFEASIBLE_INACCURATE)


class InfeasibleDesignError(ValueError):
    """No design meets the bounds and limits.

    Attributes
    ----------
    conflicts : list of str
        Names of limits (fields of :class:`optimize.Constraints`, or ``balls``
        for the ball-count bounds) that cannot hold together within the
        bounds; removing any one of them makes the rest feasible.
    binding_bounds : list of str
        Box bounds, e.g. ``load_N_max``, whose slight widening (one ball, 1 %)
        reduces the least violation of the conflicting limits: the bounds
        that take part in the conflict.
    """

    def __init__(self, message: str, conflicts: list[str], binding_bounds: list[str]):
        super().__init__(message)
        self.conflicts = conflicts
        self.binding_bounds = binding_bounds


@dataclass(frozen=True)
class BallCountResult:
    """The optimum of one ball count.

    Attributes
    ----------
    balls : int
        Ball count z. [1]
    status : str
        ``"optimal"``, ``"optimal_inaccurate"``, ``"infeasible"`` or
        ``"does not fit the groove"``; for :func:`optimize.optimize_model`
        ``"local optimum"``, ``"iteration cap reached"`` (the count's best run
        stopped at ``max_iterations`` unconverged) or ``"no feasible local
        optimum found"``.
    groove_angle_deg, load_N : float or None
        The count's optimal design. [deg], [N]
    mu : float or None
        Exact μ from :func:`physics.evaluate` at that design (the μ model's
        value for :func:`optimize.optimize_model`). [1]
    mu_solver : float or None
        The solver's objective value; None for the local method, which has no
        value apart from the model's. [1]
    relative_gap : float or None
        mu_solver / mu - 1; None when ``mu_solver`` is. [1]
    """

    balls: int
    status: str
    groove_angle_deg: float | None = None
    load_N: float | None = None
    mu: float | None = None
    mu_solver: float | None = None
    relative_gap: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields."""
        return dict(self.__dict__)


@dataclass(frozen=True)
class OptimizationResult:
    """The best design and the evidence for it.

    Attributes
    ----------
    design : dict
        ``balls`` [1], ``groove_angle_deg`` [deg], ``load_N`` [N].
    mu : float
        Exact μ of the design from :func:`physics.evaluate`. [1]
    mu_solver : float
        The model's (DGP or surrogate) value at the design as the solver saw it. [1]
    relative_gap : float
        mu_solver / mu - 1. [1]
    speed_m_s : float
        Speed designed for (the worst case of a range). [m/s]
    constraints : list of ConstraintStatus
        Every bound and limit at the design.
    per_ball_count : list of BallCountResult
        One row per ball count of the bounds.
    ties : list of dict
        Every per-count design whose μ is within ``tie_tolerance`` of the
        best (the returned design included): ``balls``, ``groove_angle_deg``,
        ``load_N``, ``load_per_ball_N``, ``mu``.
    certificate : str
        What is proven about the design, and how.
    solve_time_s : float
        Wall time of the whole optimization. [s]
    method : str
        ``"dgp-enumeration"`` or the method of :mod:`optimize.general`.
    """

    design: dict[str, Any]
    mu: float
    mu_solver: float
    relative_gap: float
    speed_m_s: float
    constraints: list[ConstraintStatus]
    per_ball_count: list[BallCountResult]
    ties: list[dict[str, Any]]
    certificate: str
    solve_time_s: float
    method: str = "dgp-enumeration"
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready nested dict."""
        return {
            "design": dict(self.design), "mu": self.mu, "mu_solver": self.mu_solver,
            "relative_gap": self.relative_gap, "speed_m_s": self.speed_m_s,
            "constraints": [c.to_dict() for c in self.constraints],
            "per_ball_count": [r.to_dict() for r in self.per_ball_count],
            "ties": [dict(t) for t in self.ties], "certificate": self.certificate,
            "solve_time_s": self.solve_time_s, "method": self.method, **self.extra,
        }


def _solve(gp, solver: str = _SOLVER) -> tuple[str, str]:
    """Solve with Clarabel (or ``solver``), falling back to SCS on a numerical failure: (status, solver)."""
    # A phase-I program far from feasible has a log-objective above 709: cvxpy's exp of it is inf,
    # i.e. infeasible (as in BallCountResolver.solve), not an overflow to warn about.
    with warnings.catch_warnings(), np.errstate(over="ignore"):
        # cvxpy warns on inaccurate solutions; the status is checked and reported instead
        warnings.simplefilter("ignore", UserWarning)
        if solver != cp.SCS:
            try:
                gp.problem.solve(gp=True, solver=solver)
                return gp.problem.status, solver
            except cp.SolverError:
                pass
        try:
            gp.problem.solve(gp=True, solver=cp.SCS, eps=1e-9, max_iters=20000)
            return gp.problem.status, cp.SCS
        except cp.SolverError:
            return "solver_error", "none"


class _CountSolver:
    """Solves one DGP per ball count: :class:`BallCountResolver` when it applies, else cvxpy's solve.

    Hold ``gp.lock`` from construction to the last solve.
    """

    def __init__(self, gp, counts: int):
        self.gp = gp
        self.fast = None
        if counts >= _FAST_MIN_COUNTS:
            try:
                self.fast = BallCountResolver(gp)
            except Exception:  # cvxpy internals or the program's structure differ: use the public path
                self.fast = None

    def solve(self, balls: int) -> tuple[str, str, float | None, float | None, float | None]:
        """(status, solver, objective value, tan θ [1], load [N]) for one ball count."""
        if self.fast is not None:
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", UserWarning)
                    status, value, t, g = self.fast.solve(balls)
                if status in (*_OPTIMAL, *_INFEASIBLE):
                    return status, _SOLVER, value, t, g
            except Exception:  # a numerical failure: retry through cvxpy, which also falls back to SCS
                pass
        self.gp.balls.value = balls
        return _solve_count(self.gp)


def _solve_count(gp, solver: str = _SOLVER) -> tuple[str, str, float | None, float | None, float | None]:
    """:func:`_solve` at the count set in ``gp``: (status, solver, objective, tan θ [1], load [N])."""
    status, solver = _solve(gp, solver)
    if status not in _OPTIMAL:
        return status, solver, None, None, None
    return status, solver, float(gp.problem.value), float(gp.tan_theta.value), float(gp.load_N.value)


def _by_structure(problem: DesignProblem, counts: list[int], limits: frozenset[str] | None = None,
                  phase_one: bool = False) -> list[tuple[Any, dict[str, float], list[int]]]:
    """The counts in order, in runs that share one DGP structure: ``(gp, values, run)`` per run.

    A single ball has no neighbour, so its DGP has no ball-ball term (:func:`design_gp`);
    every other count shares one structure.
    """
    runs = itertools.groupby(counts, key=lambda z: physics.bearing.ball_ball_contact(True, z))
    return [(*design_gp(problem, limits, phase_one, balls=run[0]), run) for run in (list(g) for _, g in runs)]


def _solve_counts(problem: DesignProblem, counts: list[int], limits: frozenset[str] | None = None,
                  phase_one: bool = False, done: Callable[[int], None] | None = None,
                  stop: Callable[[tuple], bool] | None = None) -> dict[int, tuple]:
    """:meth:`_CountSolver.solve` of each count in order, one structure at a time, by count.

    ``done(n)`` is called with the number of counts solved after each; ``stop(answer)`` True
    ends the solves early.
    """
    answers: dict[int, tuple] = {}
    for gp, values, run in _by_structure(problem, counts, limits, phase_one):
        with gp.lock:
            gp.assign(values, run[0])
            solver = _CountSolver(gp, len(run))
            for z in run:
                answers[z] = solver.solve(z)
                if done is not None:
                    done(len(answers))
                if stop is not None and stop(answers[z]):
                    return answers
    return answers


def _solver_row(balls: int, status: str, value: float, tan_theta: float, load: float,
                angle_box: tuple[float, float], load_box: tuple[float, float]) -> BallCountResult:
    """A solved count's row, its design clipped back into the box (solvers overshoot by their tolerance)."""
    theta = float(np.clip(np.degrees(np.arctan(tan_theta)), *angle_box))
    return BallCountResult(balls, status, theta, float(np.clip(load, *load_box)), None, value)


def _phase_one_slacks(problem: DesignProblem, limits: frozenset[str], counts: list[int],
                      stop_when_feasible: bool) -> dict[int, float]:
    """Phase-I slack of each count, in order; optionally stopping at the first s <= 1."""
    def feasible(answer: tuple) -> bool:
        return stop_when_feasible and answer[0] in _OPTIMAL and answer[2] <= 1.0

    answers = _solve_counts(problem, counts, limits, phase_one=True, stop=feasible)
    for z, (status, *_) in answers.items():
        if status not in _OPTIMAL:
            raise RuntimeError(f"phase-I problem for balls={z} ended with status {status}")
    return {z: answer[2] for z, answer in answers.items()}


def _phase_one_slack(problem: DesignProblem, limits: frozenset[str], counts: list[int]) -> tuple[float, int]:
    """Smallest phase-I slack over the counts and the count attaining it (stops at the first s <= 1)."""
    slacks = _phase_one_slacks(problem, limits, counts, stop_when_feasible=True)
    z = min(slacks, key=slacks.__getitem__)
    return slacks[z], z


def _widened(problem: DesignProblem) -> dict[str, DesignProblem]:
    """The problem with each box bound in turn widened a little (one ball, 1 %), within the physics' range."""
    b = problem.bounds
    (z_lo, z_hi), (a_lo, a_hi), (g_lo, g_hi) = b.balls, b.groove_angle_deg, b.load_N
    z_range, a_range, g_range = (physics.PARAMETERS[n] for n in DESIGN_VARIABLES)
    boxes = {
        "balls_min": ((max(z_lo - 1, z_range.minimum), z_hi), b.groove_angle_deg, b.load_N),
        "balls_max": ((z_lo, min(z_hi + 1, z_range.maximum)), b.groove_angle_deg, b.load_N),
        "groove_angle_deg_min": (b.balls, (max(0.99 * a_lo, a_range.minimum), a_hi), b.load_N),
        "groove_angle_deg_max": (b.balls, (a_lo, min(a_hi + 0.01 * (90.0 - a_hi), a_range.maximum)),
                                 b.load_N),
        "load_N_min": (b.balls, b.groove_angle_deg, (max(0.99 * g_lo, g_range.minimum), g_hi)),
        "load_N_max": (b.balls, b.groove_angle_deg, (g_lo, min(1.01 * g_hi, g_range.maximum))),
    }
    return {name: replace(problem, bounds=DesignBounds(*box)) for name, box in boxes.items()
            if box != (b.balls, b.groove_angle_deg, b.load_N)}


def find_conflicts(problem: DesignProblem) -> InfeasibleDesignError | None:
    """Name the limits that conflict, or None when the problem is feasible.

    Parameters
    ----------
    problem : DesignProblem
        The problem to analyse.

    Returns
    -------
    InfeasibleDesignError or None
        The error to raise, naming an irreducible infeasible set of limits.

    Notes
    -----
    The phase-I DGP (minimize s with every limit relaxed by the factor s,
    the box hard) is convex in log space, so its optimum over the enumerated
    counts decides feasibility: feasible iff min s <= 1. A deletion filter
    then drops each limit in turn and keeps it out when the rest is still
    infeasible; what remains is irreducible: every one of its limits is needed
    for the conflict. ``groove_length_m`` joins when lifting it (all counts of
    the bounds) makes that set feasible. The bounds taking part are those
    whose widening lowers the least slack.
    """
    counts = problem.ball_counts()
    lo, hi = problem.bounds.balls
    if not counts:
        smallest = problem.groove_fill_m(lo)
        apart = (" and, declared not touching (balls_touching=false, min_ball_gap_m=0), must leave a "
                 "positive clearance" if smallest <= problem.constraints.groove_length_m else "")
        return InfeasibleDesignError(
            f"no ball count in [{lo}, {hi}] fits groove_length_m={problem.constraints.groove_length_m:g} m: "
            f"even {lo} balls need {smallest:g} m per groove{apart}", ["balls", "groove_length_m"],
            ["balls_min"])
    limits = [n for n in problem.constraints.active_limits() if n != "groove_length_m"]
    if not limits or _phase_one_slack(problem, frozenset(limits), counts)[0] <= 1.0:
        return None
    kept = list(limits)
    for name in limits:
        trial = [n for n in kept if n != name]
        if trial and _phase_one_slack(problem, frozenset(trial), counts)[0] > 1.0:
            kept = trial
    conflicts = list(kept)
    all_counts = list(range(lo, hi + 1))
    if len(counts) < len(all_counts) and _phase_one_slack(problem, frozenset(kept), all_counts)[0] <= 1.0:
        conflicts.append("groove_length_m")
    slack, z = _phase_one_slack(problem, frozenset(kept), counts)
    gp, values = design_gp(problem, frozenset(kept), phase_one=True, balls=z)
    with gp.lock:
        gp.assign(values, z)
        _solve(gp)
        theta = float(np.degrees(np.arctan(gp.tan_theta.value)))
        load = float(gp.load_N.value)
    binding = [name for name, wider in _widened(problem).items()
               if wider.ball_counts() and _phase_one_slack(wider, frozenset(kept), wider.ball_counts())[0]
               < slack * (1.0 - 1e-6)]
    limits_text = ", ".join(f"{n}={getattr(problem.constraints, n):g}" for n in conflicts)
    return InfeasibleDesignError(
        f"infeasible: the constraints {limits_text} conflict within the bounds "
        f"(they cannot all hold; the least violation needs them relaxed by a factor {slack:.4g}, "
        f"at balls={z}, groove_angle_deg={theta:.4g}, load_N={load:.4g} ; widening the bounds "
        f"{', '.join(binding) or 'none'} would reduce the violation)", conflicts, binding)


def _upper_excess(problem: DesignProblem, balls, theta, load) -> tuple[np.ndarray, np.ndarray]:
    """Largest log(value / limit) over the upper limits (-inf without any), and the exact μ."""
    r = physics.evaluate(convention=problem.convention, **problem.physics_inputs(balls, theta, load))
    c = problem.constraints
    values = {"max_contact_pressure_Pa": r.max_contact_pressure_Pa,
              "max_friction_force_N": r.friction_force_N, "max_load_per_ball_N": load / balls}
    excess = np.full(np.shape(r.mu), -np.inf)
    for name, value in values.items():
        limit = getattr(c, name)
        if limit is not None:
            excess = np.maximum(excess, np.log(value / limit))
    return excess, r.mu


def polish_design(problem: DesignProblem, balls: np.ndarray, theta: np.ndarray,
                  load: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Move each solver design onto the exact boundary of its binding bounds and limits, when better.

    Parameters
    ----------
    problem : DesignProblem
        The problem.
    balls, theta, load : numpy.ndarray
        Ball counts [1], the solver's groove angles [deg] and loads [N], one per count.

    Returns
    -------
    theta : numpy.ndarray
        Polished groove angles. [deg]
    load : numpy.ndarray
        Polished loads. [N]
    mu : numpy.ndarray
        Exact μ at the polished designs. [1]

    Notes
    -----
    The solver stops within its tolerance (~1e-8 in log space) of a binding
    bound or limit; for a limit this can mean far more than 1e-8 relative in
    the load, because the pressure grows only slowly with G while adhesion
    dominates Q. So: an angle or load within 1e-6 relative of a bound is
    snapped onto it; and since every upper limit (pressure, friction force,
    load per ball) increases with G, regula falsi on log G (the Illinois
    variant, which keeps the bracket) within ±0.1 % of the load finds the
    largest load meeting all of them with the exact physics.
    Each candidate replaces the design only when it meets every limit and
    gives a lower μ, so polishing can only improve a design and never breaks
    a limit.
    """
    floor = max(problem.bounds.load_N[0], problem.constraints.min_load_capacity_N or 0.0)
    ceiling = problem.bounds.load_N[1]
    angle_lo, angle_hi = problem.bounds.groove_angle_deg
    n = len(balls)

    def snap(value, bound):
        return np.where(np.abs(value / bound - 1.0) <= 1e-6, bound, value)

    # the solver's design and its snapped variants, evaluated in one call of the physics
    variants = [(th, g) for th in (theta, snap(theta, angle_lo), snap(theta, angle_hi))
                for g in (load, snap(load, floor), snap(load, ceiling))]
    all_theta = np.concatenate([v[0] for v in variants])
    all_load = np.concatenate([v[1] for v in variants])
    excess, mu_raw = _upper_excess(problem, np.tile(balls, len(variants)), all_theta, all_load)
    ok = ((excess <= 0) & (all_load >= floor) & (all_load <= ceiling) & (all_theta >= angle_lo)
          & (all_theta <= angle_hi)).reshape(len(variants), n)
    mu_raw = mu_raw.reshape(len(variants), n)
    mu_all = np.where(ok, mu_raw, np.inf)
    pick = np.argmin(mu_all, axis=0)
    columns = np.arange(n)
    found = np.isfinite(mu_all[pick, columns])
    best_theta = np.where(found, all_theta.reshape(len(variants), n)[pick, columns], theta)
    best_load = np.where(found, all_load.reshape(len(variants), n)[pick, columns], load)
    best_mu = mu_all[pick, columns]

    # the largest load meeting every upper limit near the solver's, by regula falsi (Illinois) on log G
    low = np.log(np.clip(load * (1.0 - 1e-3), floor, ceiling))
    high = np.log(np.clip(load * (1.0 + 1e-3), floor, ceiling))
    f_low = _upper_excess(problem, balls, best_theta, np.exp(low))[0]
    f_high = _upper_excess(problem, balls, best_theta, np.exp(high))[0]
    active = (f_low <= 0) & (f_high > 0)
    if active.any():
        idx = np.flatnonzero(active)
        lo_y, hi_y, f_lo, f_hi = low[idx], high[idx], f_low[idx], f_high[idx]
        excess_lo = f_lo.copy()  # the true excess at the feasible end (f_lo is halved by Illinois)
        for _ in range(30):
            width = hi_y - lo_y
            # done when the feasible end sits on the limit to 1e-13 (log) or the bracket has closed
            if np.all((width <= 1e-13) | (excess_lo >= -1e-13)):
                break
            trial = np.clip(lo_y - f_lo * width / (f_hi - f_lo), lo_y + 1e-3 * width, hi_y - 1e-3 * width)
            f_trial = _upper_excess(problem, balls[idx], best_theta[idx], np.exp(trial))[0]
            below = f_trial <= 0
            # Illinois: halve the value kept at an end that did not move, so both ends converge
            f_hi = np.where(below, 0.5 * f_hi, f_trial)
            f_lo = np.where(below, f_trial, 0.5 * f_lo)
            excess_lo = np.where(below, f_trial, excess_lo)
            lo_y, hi_y = np.where(below, trial, lo_y), np.where(below, hi_y, trial)
        candidate = np.exp(lo_y)  # the feasible end of the bracket
        c_excess, c_mu = _upper_excess(problem, balls[idx], best_theta[idx], candidate)
        better = (c_excess <= 0) & (candidate >= floor) & (candidate <= ceiling) & (c_mu < best_mu[idx])
        best_load[idx] = np.where(better, candidate, best_load[idx])
        best_mu[idx] = np.where(better, c_mu, best_mu[idx])
        found[idx] |= better
    # nothing feasible found: report the solver's point (variant 0) as it is
    return (np.where(found, best_theta, theta), np.where(found, best_load, load),
            np.where(found, best_mu, mu_raw[0]))


def _polished(problem: DesignProblem, solved: list[BallCountResult]) -> dict[int, BallCountResult]:
    """The solved rows after :func:`polish_design`, with the exact μ and the solver's gap, by count."""
    balls = np.array([r.balls for r in solved])
    theta, load, mu = polish_design(problem, balls, np.array([r.groove_angle_deg for r in solved]),
                                    np.array([r.load_N for r in solved]))
    return {r.balls: BallCountResult(r.balls, r.status, float(theta[k]), float(load[k]), float(mu[k]),
                                     r.mu_solver, r.mu_solver / float(mu[k]) - 1.0)
            for k, r in enumerate(solved)}


def _breaks_limit(problem: DesignProblem, row: BallCountResult, rtol: float = 1e-9) -> bool:
    """Whether the exact physics at the row's design breaks a limit by more than ``rtol`` relative."""
    return any(
        (c.value > c.limit * (1 + rtol) if c.sense == "<=" else c.value < c.limit * (1 - rtol))
        for c in constraint_report(problem, row.balls, row.groove_angle_deg, row.load_N))


def _certificate(problem: DesignProblem, rows: list[BallCountResult], best: BallCountResult,
                 ties: list[dict[str, Any]], fallback: list[int]) -> str:
    counts = [r for r in rows if r.status.startswith("optimal")]
    infeasible = [r.balls for r in rows if r.status == "infeasible"]
    excluded = [r.balls for r in rows if r.status == "does not fit the groove"]
    inaccurate = [r.balls for r in rows if r.status == "optimal_inaccurate"]
    worst_gap = max(abs(r.relative_gap) for r in counts)
    lo, hi = problem.bounds.balls
    speed = problem.speed_m_s
    parts = [
        f"Global optimum of mu over integer balls in [{lo}, {hi}], groove_angle_deg in "
        f"[{problem.bounds.groove_angle_deg[0]:g}, {problem.bounds.groove_angle_deg[1]:g}] and load_N in "
        f"[{problem.bounds.load_N[0]:g}, {problem.bounds.load_N[1]:g}] under the stated limits.",
        "Proof: for each ball count the problem is a disciplined geometric program (cvxpy "
        "is_dgp(dpp=True) and is_dpp('dgp') checked, variables tan(theta) and load_N, the physics "
        "equations exactly, no approximation), i.e. convex after the change of variables to logarithms, "
        f"so the solver's optimum is the global optimum for that count; all {hi - lo + 1} counts were "
        "enumerated (the integer is never left to the solver), so the best of them is global.",
        f"Solved: {len(counts)} counts; infeasible (confirmed by phase-I, min slack > 1): "
        f"{infeasible or 'none'}; excluded by groove_length_m: {excluded or 'none'}.",
        f"Verification: each count's optimum re-evaluated with physics.evaluate; largest relative gap "
        f"between solver and physics {worst_gap:.2e} (the returned design: {best.relative_gap:.2e}); "
        f"Clarabel stops at relative tolerance 1e-8; limits were tightened by {SAFETY_MARGIN:g} relative "
        "in the DGP, then each design was moved onto the exact boundary of its binding bounds and limits "
        "(snapping, bisection on the physics; only when that lowers mu), so the exact physics meets "
        "every limit.",
    ]
    if fallback:
        parts.append(f"Clarabel failed numerically for counts {sorted(set(fallback))} (an error, or a design "
                     "the exact physics found breaking a limit), solved by SCS (eps 1e-9) instead.")
    unsolved = [r.balls for r in rows if r.status == "solver_error"]
    if unsolved:
        parts.append(f"Counts {unsolved}: neither Clarabel nor SCS returned a design meeting the limits; "
                     "they are left out, so the optimum is global over the other counts only.")
    if inaccurate:
        parts.append(f"Counts {inaccurate} were solved only to reduced accuracy (status optimal_inaccurate); "
                     "their optimality holds only to that accuracy.")
    if isinstance(speed, tuple):
        parts.append(f"Speed range [{speed[0]:g}, {speed[1]:g}] m/s: mu and the friction force increase "
                     "with speed (only F_R ~ V^0.66 depends on it), so the worst case is the upper end, "
                     "which was optimized.")
    if len(ties) > 1:
        parts.append(f"{len(ties)} designs tie within {TIE_TOLERANCE:g} relative (mu depends on load and "
                     "ball count only through the load per ball); the one with the fewest balls is returned.")
    return " ".join(parts)


def optimize_design(problem: DesignProblem, progress: Callable[[float], None] | None = None,
                    tie_tolerance: float = TIE_TOLERANCE) -> OptimizationResult:
    """Minimize the exact μ over the design box, globally, with a certificate.

    Parameters
    ----------
    problem : DesignProblem
        Bounds, limits, speed and fixed physics parameters.
    progress : callable, optional
        Called with the fraction of ball counts done, 0..1. [1]
    tie_tolerance : float, default :data:`TIE_TOLERANCE`
        Relative μ distance within which designs count as ties. [1]

    Returns
    -------
    OptimizationResult
        The best design (fewest balls among ties) re-evaluated with the physics.

    Raises
    ------
    InfeasibleDesignError
        When no design meets the limits, naming the conflicting ones.
    RuntimeError
        When a solver ends with an unexpected status.
    ValueError
        For a ``tie_tolerance`` outside [0, 1).
    """
    if not 0.0 <= tie_tolerance < 1.0:
        raise ValueError(f"tie_tolerance must be in [0, 1); got {tie_tolerance!r}")
    start = time.perf_counter()
    fitting = set(problem.ball_counts())
    lo, hi = problem.bounds.balls
    angle_box = problem.bounds.groove_angle_deg
    load_box = (max(problem.bounds.load_N[0], problem.constraints.min_load_capacity_N or 0.0),
                problem.bounds.load_N[1])
    rows: list[BallCountResult] = []
    unconfirmed: list[int] = []
    fallback: list[int] = []
    counts = sorted(fitting)
    answers = _solve_counts(problem, counts, done=None if progress is None else (
        lambda solved: progress(solved / len(counts))))
    for z in range(lo, hi + 1):
        if z not in fitting:
            rows.append(BallCountResult(z, "does not fit the groove"))
            continue
        status, solver, value, tan_theta, load = answers[z]
        if solver != _SOLVER:
            fallback.append(z)
        if status in _OPTIMAL:
            rows.append(_solver_row(z, status, value, tan_theta, load, angle_box, load_box))
        elif status in (*_INFEASIBLE, "solver_error"):
            # decided by the phase-I problem below, which is always feasible
            rows.append(BallCountResult(z, "infeasible"))
            unconfirmed.append(z)
        else:
            raise RuntimeError(f"the DGP for balls={z} ended with status {status!r}")
    limits = frozenset(n for n in problem.constraints.active_limits() if n != "groove_length_m")
    confirmed = _phase_one_slacks(problem, limits, unconfirmed, stop_when_feasible=False) if (
        limits and unconfirmed) else dict.fromkeys(unconfirmed, 0.0)
    for z, slack in confirmed.items():
        if slack <= 1.0:
            raise RuntimeError(f"solver failed or said infeasible for balls={z}, but phase-I slack is "
                               f"{slack:.6g} <= 1")
    solved = [r for r in rows if r.status in _OPTIMAL]
    if not solved:
        raise find_conflicts(problem) or RuntimeError("no count solved, yet phase-I says feasible")

    rows_by_count = {r.balls: r for r in rows}
    rows_by_count.update(_polished(problem, solved))
    # An interior-point solver can call a degenerate program (e.g. a limit leaving one feasible
    # point) optimal at a design that breaks the limit: such counts are re-solved by SCS, and
    # dropped (said in the certificate) if the exact physics still finds a limit broken.
    broken = [r.balls for r in rows_by_count.values() if r.status in _OPTIMAL and _breaks_limit(problem, r)]
    for z in broken:
        gp, values = design_gp(problem, balls=z)
        with gp.lock:
            gp.assign(values, z)
            status, _, value, tan_theta, load = _solve_count(gp, solver=cp.SCS)
        rows_by_count[z] = BallCountResult(z, "solver_error")
        if status in _OPTIMAL:
            solver_row = _solver_row(z, status, value, tan_theta, load, angle_box, load_box)
            row = _polished(problem, [solver_row])[z]
            fallback.append(z)
            if not _breaks_limit(problem, row):
                rows_by_count[z] = row
    rows = [rows_by_count[z] for z in range(lo, hi + 1)]
    solved = [r for r in rows if r.status in _OPTIMAL]
    if not solved:
        raise RuntimeError(f"the solvers' designs for balls={broken} break a limit and no other count is "
                           "feasible")
    best_mu = min(r.mu for r in solved)
    tied = [r for r in solved if r.mu <= best_mu * (1.0 + tie_tolerance)]
    best = min(tied, key=lambda r: r.balls)
    ties = [{"balls": r.balls, "groove_angle_deg": r.groove_angle_deg, "load_N": r.load_N,
             "load_per_ball_N": r.load_N / r.balls, "mu": r.mu} for r in tied]
    return OptimizationResult(
        design={"balls": best.balls, "groove_angle_deg": best.groove_angle_deg, "load_N": best.load_N},
        mu=best.mu, mu_solver=best.mu_solver, relative_gap=best.relative_gap,
        speed_m_s=problem.design_speed_m_s(),
        constraints=constraint_report(problem, best.balls, best.groove_angle_deg, best.load_N),
        per_ball_count=rows, ties=ties, certificate=_certificate(problem, rows, best, ties, fallback),
        solve_time_s=time.perf_counter() - start, extra={"mu_physics": best.mu},
    )
