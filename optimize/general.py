r"""Optimizing any μ model - a surrogate, a calibrated model - by sequential convex approximation.

A model that is not the exact physics (any callable ``mu_model(points) -> mu``
over columnar points keyed by physics parameter names) need not be log-log
convex, so :func:`optimize_model` uses a local method and says so.

Method
------
In log coordinates x = log tan θ, y = log G, for every ball count z and from
several starting points:

1. Fit a local log-log affine (monomial) model of μ at the iterate,
   log μ ≈ f + g_x Δx + g_y Δy, by central differences of the model
   (step 1e-5 in log space).
2. Solve the convex sub-problem (stated in cvxpy by
   :func:`optimize.trust_step.cvxpy_steps`): minimize the model plus an exact
   penalty M·v on the elastic friction-force limit
   f + g·Δ + y + Δy - log F_max <= v, v >= 0, inside the trust region
   |Δx|, |Δy| <= r and subject to the limits that do not depend on the μ
   model, which are exact and convex in (x, y): the box bounds, the minimum
   load, the load per ball, and the peak pressure, which (p0 grows with Q and Q
   with Q0) is equivalent to y + ½ log(1 + e^{2x}) <= log(2 z Q0_max), with
   Q0_max = Q_max - sqrt(2 c Q_max) from Q = (sqrt(2 c Q0 + c²) + c)² / (2c).
3. Evaluate the model at the step; accept it when the merit
   log μ + M max(0, log(μ G / F_max)) drops by at least 10 % of the predicted
   drop, and grow (ratio > 0.75) or shrink (ratio < 0.25, by 4) the radius.
4. Stop when the radius is below 1e-9 or the model predicts no decrease.

All (count, start) pairs are independent: the sub-problem is separable, two
variables per run, and :func:`optimize.trust_step.exact_steps` solves every
run's at once in numpy, exactly (a 1-D convex search to 1e-12 of its interval
beside the closed-form points where the optimum usually is), which tests compare
with the cvxpy statement solved by Clarabel on random sub-problems with the
pressure and friction limits active. The result is a point where no descent step of the local
model exists (a KKT point of the smooth model), verified by evaluating the
model there; it is a local optimum, not a global proof, and the certificate
says so.

Verification by the source model
--------------------------------
A surrogate stands for another model (the physics, or a calibrated model). Given
that ``source_model``, the design found on the surrogate is evaluated by it: μ and
the friction force under both models are reported, every limit is judged by the
source's value (the others do not depend on μ and are exact), and when the source
breaks ``max_friction_force_N`` the problem is re-solved with that limit tightened
by the ratio of the two friction forces and a margin of :data:`RESOLVE_MARGIN`, at
most :data:`MAX_RESOLVES` times; a design still breaking it is returned marked
violating (``satisfied=False``, said in the certificate), never satisfied.

Worst case over a speed range
-----------------------------
μ of the exact physics grows with speed, so its worst case over a range is
the upper end (see :mod:`optimize.problem`); a surrogate or calibrated model
need not be monotone (a calibrated effect on ``speed_m_s`` may fall with
speed). For a speed range [V_lo, V_hi], unless the model declares
``mu_model.mu_grows_with_speed = True`` (as :func:`physics_model` does), the
method minimizes max_V μ(x, V) over :data:`SPEED_GRID_POINTS` equally spaced
speeds from V_lo to V_hi, both ends included, in every model evaluation of the
iterations (the friction-force limit uses the same maximum) and in the final
verification. The result reports the grid speed where the maximum occurs; the
worst case holds on that grid, not proven between its points.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from microbearing import physics

from .dgp import SAFETY_MARGIN, coefficients
from .problem import DesignProblem, constraint_report
from .solve import TIE_TOLERANCE, BallCountResult, InfeasibleDesignError, OptimizationResult, find_conflicts
from .trust_step import TrustStep, exact_steps, log_secant

__all__ = ["optimize_model", "check_exact_limits", "verify_design", "physics_model", "speed_grid_m_s",
           "PENALTY", "SPEED_GRID_POINTS", "MAX_RESOLVES", "RESOLVE_MARGIN"]

#: Exact-penalty weight of the friction-force limit in log space. [1]
PENALTY = 100.0
#: Equally spaced speeds, both ends included, over which a speed range's worst case is taken. [1]
SPEED_GRID_POINTS = 9
_STEP = 1e-5
_MIN_RADIUS = 1e-9
_MAX_RADIUS = 1.0
#: Status of a ball count whose best run converged (no descent step of the local model is left).
LOCAL_OPTIMUM = "local optimum"
#: Status of a ball count whose best run stopped at ``max_iterations`` before converging.
ITERATION_CAP = "iteration cap reached"
#: ``map_calls(fn, arguments, progress) -> list``: runs ``fn(*args)`` for each of ``arguments``. [-]
MapCalls = Callable[[Callable[..., Any], list[tuple], Callable[[float], None] | None], list]

#: Most re-solves with a tightened friction-force limit when the source model breaks it. [1]
MAX_RESOLVES = 3
#: Relative margin by which a re-solve tightens the friction-force limit beyond the models' ratio. [1]
RESOLVE_MARGIN = 1e-3

#: Ball counts per group of runs: the groups are solved independently (in turn, or on an executor). [1]
GROUP_COUNTS = 16

MuModel = Callable[[dict[str, Any]], np.ndarray]


def physics_model(convention: str = physics.DEFAULT_CONVENTION) -> MuModel:
    """The exact physics as a black-box μ model.

    Parameters
    ----------
    convention : str
        A key of :data:`physics.CONVENTIONS`. [-]

    Returns
    -------
    callable
        ``points -> physics.evaluate(convention, **points).mu`` [1], with the
        attribute ``mu_grows_with_speed = True`` (μ of the physics grows with
        speed, so a speed range is evaluated at its upper end only) and
        ``physics_convention`` (it is the physics: μ also grows with the angle,
        :mod:`optimize.robust`).
    """
    def model(points):
        return physics.evaluate(convention=convention, outputs=["mu"], **points).mu

    model.mu_grows_with_speed = True
    model.physics_convention = convention
    return model


def speed_grid_m_s(problem: DesignProblem, mu_model: MuModel) -> np.ndarray:
    """The speeds over which :func:`optimize_model` takes the worst case of μ.

    Parameters
    ----------
    problem : DesignProblem
        Its speed or speed range.
    mu_model : callable
        The μ model; ``mu_model.mu_grows_with_speed = True`` declares μ
        non-decreasing in speed.

    Returns
    -------
    ndarray
        The single speed, the upper end of a range for a model that declares
        μ non-decreasing in speed, or :data:`SPEED_GRID_POINTS` equally spaced
        speeds from the lower to the upper end of the range. [m/s]

    Examples
    --------
    >>> from microbearing.optimize import DesignBounds, DesignProblem
    >>> p = DesignProblem(DesignBounds((4, 6), (40, 60), (0.001, 0.05)), speed_m_s=(0.0, 0.08))
    >>> speed_grid_m_s(p, lambda points: points["load_N"]).round(3).tolist()
    [0.0, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.07, 0.08]
    >>> speed_grid_m_s(p, physics_model()).tolist()
    [0.08]
    """
    speed = problem.speed_m_s
    monotone = getattr(mu_model, "mu_grows_with_speed", False)
    if not isinstance(speed, tuple) or monotone or speed[0] == speed[1]:
        return np.array([problem.design_speed_m_s()])
    return np.linspace(speed[0], speed[1], SPEED_GRID_POINTS)


def _worst_case(problem: DesignProblem, mu_model: MuModel, model_name: str, speeds: np.ndarray, balls,
                theta_deg, load_N) -> tuple[np.ndarray, np.ndarray]:
    """Largest μ over the speeds for each design, and the speed where it occurs. [1], [m/s]"""
    balls, theta_deg, load_N = np.broadcast_arrays(np.atleast_1d(balls), np.atleast_1d(theta_deg),
                                                   np.atleast_1d(load_N))
    n = balls.size
    points = problem.physics_inputs(np.tile(balls, len(speeds)), np.tile(theta_deg, len(speeds)),
                                    np.tile(load_N, len(speeds)), speed_m_s=np.repeat(speeds, n))
    mu = np.asarray(mu_model(points), dtype=float)
    mu = np.broadcast_to(mu, (len(speeds) * n,)).reshape(len(speeds), n)
    if not np.all(np.isfinite(mu) & (mu > 0)):
        raise ValueError(f"{model_name} returned a non-finite or non-positive mu")
    worst = np.argmax(mu, axis=0)
    return mu[worst, np.arange(n)], speeds[worst]


def _contact_load_cap_N(problem: DesignProblem) -> float:
    """Largest Q0 whose peak pressure meets ``max_contact_pressure_Pa`` (inf without it). [N]"""
    limit = problem.constraints.max_contact_pressure_Pa
    if limit is None:
        return np.inf
    coef = coefficients(problem)
    q_max = (limit * (1.0 - SAFETY_MARGIN) / coef.pressure_coefficient) ** 3
    return q_max - np.sqrt(2.0 * coef.adhesion_load_N * q_max)


def optimize_model(problem: DesignProblem, mu_model: MuModel, starts: int = 3, max_iterations: int = 100,
                   progress: Callable[[float], None] | None = None,
                   model_name: str = "model", map_calls: MapCalls | None = None,
                   source_model: MuModel | None = None, source_name: str = "physics") -> OptimizationResult:
    """Minimize any μ model over the design box by sequential convex approximation (a local method).

    Parameters
    ----------
    problem : DesignProblem
        Bounds, limits, speed and fixed parameters (the μ model receives them as columns).
    mu_model : callable
        ``mu_model(points: dict[str, ndarray]) -> ndarray`` of μ [1], with
        the physics parameter names as keys, broadcasting like
        :func:`physics.evaluate`.
    starts : int, default 3
        Starting points per ball count (1 to 9). [1]
    max_iterations : int, default 100
        Iteration cap of the trust-region loop. [1]
    progress : callable, optional
        Called with the fraction of iterations done, 0..1. [1]
    model_name : str, default "model"
        Name of the model in the certificate. [-]
    map_calls : callable, optional
        ``map_calls(fn, arguments, progress) -> [fn(*args) for args in arguments]``, results in
        order, ``progress`` called with the share of calls done: how the groups of
        :data:`GROUP_COUNTS` ball counts (each with its starts) run, e.g. the service's
        ``functools.partial(service.executor.map_chunks, executor)`` on a thread pool or a dask
        cluster (then ``mu_model`` must be serializable). None runs them in turn in this thread,
        with progress within each group. The groups are the same either way, so the result
        does not depend on where they run.
    source_model : callable, optional
        The model ``mu_model`` stands for (a surrogate's physics or calibrated model), same
        signature. The returned design is verified by it: μ and the friction force are
        evaluated by both models, the limits are judged by the source, and a design whose
        friction force breaks ``max_friction_force_N`` under the source is re-solved with the
        limit tightened by the ratio of the two models' forces less :data:`RESOLVE_MARGIN`, at
        most :data:`MAX_RESOLVES` times; one still breaking it is returned with
        ``satisfied=False`` and said so. None: ``mu_model`` is its own source (no verification).
    source_name : str, default "physics"
        Name of ``source_model`` in the report. [-]

    Returns
    -------
    OptimizationResult
        ``method="sequential-convex-approximation"``; ``mu`` is the model at
        the design (for a speed range: its maximum over the grid of
        :func:`speed_grid_m_s`, and ``speed_m_s`` the grid speed where it
        occurs), ``extra["mu_physics"]`` the exact physics there at the upper
        end of the speed range; with a ``source_model``, ``extra["verification"]``
        (:func:`verify_design`) and constraints judged by the source.

    Raises
    ------
    InfeasibleDesignError
        When no ball count admits a design meeting the exact limits (:func:`check_exact_limits`),
        or no iterate meets the friction-force limit under the model.
    ValueError
        For ``starts`` outside 1..9 or ``max_iterations`` < 1, or a model
        returning non-finite or non-positive μ.
    """
    if not 1 <= starts <= 9:
        raise ValueError(f"starts must be in [1, 9]; got {starts!r}")
    if max_iterations < 1:
        raise ValueError(f"max_iterations must be >= 1; got {max_iterations!r}")
    start_time = time.perf_counter()
    solved = problem
    limit = problem.constraints.max_friction_force_N
    # progress: one solve fills the bar; with a source to verify by, each (re-)solve fills the next share
    share = 1.0 if source_model is None else 1.0 / (MAX_RESOLVES + 1)
    for resolves in range(MAX_RESOLVES + 1):
        try:
            result = _optimize_once(solved, mu_model, starts, max_iterations, None if progress is None else (
                lambda f, k=resolves: progress(min(1.0, (k + f) * share))), model_name, map_calls)
        except InfeasibleDesignError:
            if resolves == 0:
                raise
            break  # the tightened limit is out of reach: report the last design, violating
        if source_model is None:
            return dataclasses.replace(result, solve_time_s=time.perf_counter() - start_time)
        report = verify_design(problem, result, mu_model, model_name, source_model, source_name)
        report["resolves"] = resolves
        verified = (result, report)
        if report["satisfied"] or limit is None:
            break
        # the source's force exceeds the model's at the design: ask the model for that much less
        current = solved.constraints.max_friction_force_N
        tightened = current * min(1.0, 1.0 / report["friction_force_ratio"]) * (1.0 - RESOLVE_MARGIN)
        solved = dataclasses.replace(solved, constraints=dataclasses.replace(
            solved.constraints, max_friction_force_N=tightened))
    result, report = verified
    if progress is not None:
        progress(1.0)
    return _with_verification(problem, result, report, time.perf_counter() - start_time)


def check_exact_limits(problem: DesignProblem) -> list[int]:
    """The ball counts that admit a design meeting the limits that do not depend on the μ model.

    Parameters
    ----------
    problem : DesignProblem
        Bounds, pressure, load-per-ball, minimum-load and groove-length limits.

    Returns
    -------
    list of int
        Ball counts whose largest load at the smallest angle reaches the load floor. [1]

    Raises
    ------
    InfeasibleDesignError
        When there is none, naming the same conflicting limits as the certified optimizer
        (:func:`optimize.solve.find_conflicts`): detectable before any evaluation of a model.
    """
    c, b = problem.constraints, problem.bounds
    q0_cap = _contact_load_cap_N(problem)
    g_floor = max(b.load_N[0], c.min_load_capacity_N or 0.0)
    t_lo = np.tan(np.deg2rad(b.groove_angle_deg[0]))
    # a count is feasible for the exact limits iff its largest load at the smallest angle reaches the floor
    counts = [z for z in problem.ball_counts() if min(b.load_N[1], 2 * z * q0_cap / np.sqrt(1 + t_lo**2),
                                                      z * (c.max_load_per_ball_N or np.inf)) >= g_floor]
    if not counts:
        # the exact limits are the DGP's: so are their conflicts
        raise find_conflicts(problem) or InfeasibleDesignError(
            "infeasible: no ball count meets the limits", ["balls"], [])
    return counts


def _optimize_once(problem: DesignProblem, mu_model: MuModel, starts: int, max_iterations: int,
                   progress: Callable[[float], None] | None, model_name: str,
                   map_calls: MapCalls | None) -> OptimizationResult:
    """One run of the method of :func:`optimize_model` on ``problem`` (no verification by a source)."""
    start_time = time.perf_counter()
    c, b = problem.constraints, problem.bounds
    q0_cap = _contact_load_cap_N(problem)
    g_floor = max(b.load_N[0], c.min_load_capacity_N or 0.0)
    counts = check_exact_limits(problem)

    fractions = [(0.5, 0.5), (0.0, 0.9), (1.0, 0.1), (0.0, 0.1), (1.0, 0.9), (0.5, 0.0), (0.5, 1.0),
                 (0.25, 0.75), (0.75, 0.25)][:starts]
    groups = [(problem, mu_model, model_name, counts[i:i + GROUP_COUNTS], fractions, q0_cap, g_floor,
               max_iterations) for i in range(0, len(counts), GROUP_COUNTS)]
    if map_calls is None:
        runs = [_solve_group(*group, progress=None if progress is None else (
                    lambda f, k=k: progress((k + f) / len(groups))))
                for k, group in enumerate(groups)]
    else:
        runs = map_calls(_solve_group, groups, progress)
    z, x, y, done = (np.concatenate([run[k] for run in runs]) for k in range(4))
    return _result(_Task(problem, mu_model, model_name),
                   _Runs(z, counts, fractions, x, y, done, max(run[4] for run in runs)), g_floor, start_time)


def _solve_group(problem, mu_model, model_name, counts, fractions, q0_cap, g_floor, max_iterations,
                 progress=None):
    """The runs (every start of every count of ``counts``): ``(z, x, y, done, iterations)``."""
    c, b = problem.constraints, problem.bounds
    t_lo, t_hi = np.tan(np.deg2rad(b.groove_angle_deg))
    z = np.repeat(np.array(counts, dtype=float), len(fractions))
    f_theta = np.tile([f[0] for f in fractions], len(counts))
    f_load = np.tile([f[1] for f in fractions], len(counts))
    x_lo, x_hi = np.full_like(z, np.log(t_lo)), np.full_like(z, np.log(t_hi))
    y_lo = np.full_like(z, np.log(g_floor))
    y_cap = np.full_like(z, np.log(b.load_N[1]))
    if c.max_load_per_ball_N is not None:
        y_cap = np.minimum(y_cap, np.log(z * c.max_load_per_ball_N * (1.0 - SAFETY_MARGIN)))
    log_pressure_cap = np.log(2 * z * q0_cap) if np.isfinite(q0_cap) else None
    # starts: the angle by its fraction of the log range, then the load by its fraction of the feasible range
    x = x_lo + f_theta * (x_hi - x_lo)
    if log_pressure_cap is not None:
        x_cap = 0.5 * np.log(np.expm1(np.maximum(2 * (log_pressure_cap - y_lo), 1e-300)))
        x = np.minimum(x, x_cap)
    y_hi_start = y_cap if log_pressure_cap is None else np.minimum(y_cap, log_pressure_cap - log_secant(x))
    y = y_lo + f_load * (y_hi_start - y_lo)

    box = _LogBox(x_lo, x_hi, y_lo, y_cap, log_pressure_cap)
    x, y, done, iterations = _iterate(_Task(problem, mu_model, model_name), z, x, y, box, max_iterations,
                                      progress)
    return z, x, y, done, iterations


@dataclass(frozen=True)
class _Task:
    """What every run of :func:`optimize_model` asks: the problem and the model (named for messages)."""

    problem: DesignProblem
    mu_model: MuModel
    model_name: str


@dataclass(frozen=True)
class _LogBox:
    """The runs' box in x = log tan θ and y = log load, and the pressure limit's cap on y + log sec θ (None:
    no limit); arrays, one entry per run."""

    x_lo: np.ndarray
    x_hi: np.ndarray
    y_lo: np.ndarray
    y_cap: np.ndarray
    log_pressure_cap: np.ndarray | None


@dataclass(frozen=True)
class _Runs:
    """Every run of every group: the ball count z, the ends x, y, whether each converged, the starts'
    fractions and the most iterations any took."""

    z: np.ndarray
    counts: list[int]
    fractions: list[tuple[float, float]]
    x: np.ndarray
    y: np.ndarray
    done: np.ndarray
    iterations: int


def _iterate(task: _Task, z: np.ndarray, x: np.ndarray, y: np.ndarray, box: _LogBox, max_iterations: int,
             progress: Callable[[float], None] | None):
    """The trust-region loop of :func:`optimize_model`: (x, y, done, iterations)."""
    problem, mu_model, model_name = task.problem, task.mu_model, task.model_name
    x_lo, x_hi, y_lo, y_cap, log_pressure_cap = box.x_lo, box.x_hi, box.y_lo, box.y_cap, box.log_pressure_cap
    c = problem.constraints

    speeds = speed_grid_m_s(problem, mu_model)

    def evaluate(xs, ys):
        mu, _ = _worst_case(problem, mu_model, model_name, speeds, np.tile(z, len(xs) // len(z)),
                            np.degrees(np.arctan(np.exp(xs))), np.exp(ys))
        return np.log(mu)

    log_friction_max = np.log(c.max_friction_force_N) if c.max_friction_force_N is not None else None

    def merit(log_mu, ys):
        if log_friction_max is None:
            return log_mu
        return log_mu + PENALTY * np.maximum(0.0, log_mu + ys - log_friction_max)

    friction_cap = None if log_friction_max is None else np.full_like(z, log_friction_max)
    log_mu = evaluate(x, y)
    current = merit(log_mu, y)
    radius = np.full_like(z, 0.5)
    done = np.zeros(len(z), dtype=bool)
    iterations = 0
    for iterations in range(1, max_iterations + 1):
        h = _STEP
        stencil = evaluate(np.concatenate([x + h, x - h, x, x]), np.concatenate([y, y, y + h, y - h]))
        n = len(z)
        gx = (stencil[:n] - stencil[n:2 * n]) / (2 * h)
        gy = (stencil[2 * n:3 * n] - stencil[3 * n:]) / (2 * h)
        step_x, step_y = exact_steps(TrustStep(x, y, gx, gy, log_mu, x_lo, x_hi, y_lo, y_cap,
                                               np.where(done, 0.0, radius), PENALTY, friction_cap,
                                               log_pressure_cap))
        x_new, y_new = np.clip(x + step_x, x_lo, x_hi), np.clip(y + step_y, y_lo, y_cap)
        linear = log_mu + gx * (x_new - x) + gy * (y_new - y)
        predicted = current - merit(linear, y_new)
        trial_log_mu = evaluate(x_new, y_new)
        trial = merit(trial_log_mu, y_new)
        ratio = (current - trial) / np.where(predicted > 0, predicted, np.inf)
        accept = ~done & (predicted > 0) & (ratio > 0.1)
        if log_pressure_cap is not None:  # the clipped step must still meet the exact pressure limit
            accept &= y_new + log_secant(x_new) <= log_pressure_cap
        at_edge = np.maximum(np.abs(x_new - x), np.abs(y_new - y)) >= 0.99 * radius
        radius = np.where(ratio > 0.75, np.where(at_edge, np.minimum(2 * radius, _MAX_RADIUS), radius),
                          np.where(ratio < 0.25, radius / 4, radius))
        x, y = np.where(accept, x_new, x), np.where(accept, y_new, y)
        log_mu, current = np.where(accept, trial_log_mu, log_mu), np.where(accept, trial, current)
        done |= (radius < _MIN_RADIUS) | (predicted <= 1e-14)
        if progress is not None:
            progress(iterations / max_iterations)
        if done.all():
            break
    return x, y, done, iterations


def _result(task: _Task, runs: _Runs, g_floor: float, start_time: float) -> OptimizationResult:
    """The :class:`OptimizationResult` of the runs of every group of :func:`optimize_model`."""
    problem, mu_model, model_name = task.problem, task.mu_model, task.model_name
    z, counts, fractions, x, y, done = runs.z, runs.counts, runs.fractions, runs.x, runs.y, runs.done
    iterations = runs.iterations
    c, b = problem.constraints, problem.bounds
    log_friction_max = np.log(c.max_friction_force_N) if c.max_friction_force_N is not None else None
    speeds = speed_grid_m_s(problem, mu_model)
    # the log/exp round trip may cross a bound by an ulp: clip back; re-evaluate the model at what is returned
    theta = np.clip(np.degrees(np.arctan(np.exp(x))), *b.groove_angle_deg)
    load = np.clip(np.exp(y), g_floor, b.load_N[1])
    mu, _ = _worst_case(problem, mu_model, model_name, speeds, z, theta, load)
    meets_friction = np.ones(len(z), dtype=bool) if log_friction_max is None else (
        mu * load <= c.max_friction_force_N)
    rows_by_count: dict[int, BallCountResult] = {}
    for k in range(len(z)):
        zk = int(z[k])
        if not meets_friction[k]:
            continue
        if zk not in rows_by_count or mu[k] < rows_by_count[zk].mu:
            # no solver value separate from the model's, hence no gap; a run stopped by the cap is no optimum
            rows_by_count[zk] = BallCountResult(zk, LOCAL_OPTIMUM if done[k] else ITERATION_CAP,
                                                float(theta[k]), float(load[k]), float(mu[k]))
    fitting = set(problem.ball_counts())
    rows = [rows_by_count.get(zz) or BallCountResult(
        zz, "no feasible local optimum found" if zz in fitting else "does not fit the groove")
        for zz in range(b.balls[0], b.balls[1] + 1)]
    solved = [r for r in rows if r.mu is not None]
    if not solved:
        raise InfeasibleDesignError(
            f"infeasible under {model_name}: no start reached max_friction_force_N="
            f"{c.max_friction_force_N:g} within the exact limits", ["max_friction_force_N"], [])
    best_mu = min(r.mu for r in solved)
    tied = [r for r in solved if r.mu <= best_mu * (1.0 + TIE_TOLERANCE)]
    best = min(tied, key=lambda r: r.balls)
    design_inputs = problem.physics_inputs(best.balls, best.groove_angle_deg, best.load_N)
    # Verify the design by a fresh evaluation of the model at that one point: a batch of every run
    # sums the model's terms in another order (a GP: ~1e-9 relative), and the reported mu must be
    # what a user asking the model about this design (at the worst speed) gets.
    verified, worst_speed = _worst_case(problem, mu_model, model_name, speeds, best.balls,
                                        best.groove_angle_deg, best.load_N)
    verified_mu = float(verified[0])
    # mu_solver: the model in the batch of every run, as the method saw it
    best = dataclasses.replace(best, mu=verified_mu, mu_solver=best.mu,
                               relative_gap=best.mu / verified_mu - 1.0)
    exact = physics.evaluate(convention=problem.convention, **design_inputs)
    unconverged = int(np.count_nonzero(~done))
    found = "Local optimum" if best.status == LOCAL_OPTIMUM else (
        "Best point found, NOT a converged local optimum (its run stopped at the iteration cap),")
    certificate = (
        f"{found} of {model_name} (not a global proof): sequential convex approximation "
        f"(local monomial fits of mu by central differences, trust region in log space, exact-penalty "
        f"friction-force limit; each convex sub-problem solved exactly per run) from {len(fractions)} "
        f"starts for each of the {len(counts)} ball counts "
        f"that meet the exact limits, {iterations} iterations, {unconverged} of {len(z)} runs stopped by "
        f"the iteration cap. The pressure, load-per-ball, minimum-load and box limits are imposed exactly "
        f"(convex in log space); the friction force uses {model_name}. The design was verified by "
        f"evaluating {model_name} there (mu = {best.mu:.6g}); the exact physics gives {float(exact.mu):.6g}. "
        f"A non-convex model may have better optima that no start reached."
    )
    if len(speeds) > 1:
        certificate += (
            f" Speed range [{speeds[0]:g}, {speeds[-1]:g}] m/s: {model_name} need not grow with speed, so "
            f"mu (and the friction force) was taken as the worst case over a grid of {len(speeds)} equally "
            f"spaced speeds, both ends included, in every iteration and in the verification; the worst case "
            f"of the design is at {float(worst_speed[0]):g} m/s. It holds on that grid, not proven between "
            f"grid points.")
    elif isinstance(problem.speed_m_s, tuple):
        lo, hi = problem.speed_m_s
        certificate += (f" Speed range [{lo:g}, {hi:g}] m/s: {model_name} declares mu non-decreasing in "
                        f"speed, so the worst case is the upper end, which was optimized.")
    if len(tied) > 1:
        certificate += f" {len(tied)} counts tie within {TIE_TOLERANCE:g}; the fewest balls are returned."
    return OptimizationResult(
        design={"balls": best.balls, "groove_angle_deg": best.groove_angle_deg, "load_N": best.load_N},
        mu=best.mu, mu_solver=best.mu_solver, relative_gap=best.relative_gap,
        speed_m_s=float(worst_speed[0]),
        constraints=constraint_report(problem, best.balls, best.groove_angle_deg, best.load_N, exact,
                                      best.mu, model_name),
        per_ball_count=rows,
        ties=[{"balls": r.balls, "groove_angle_deg": r.groove_angle_deg, "load_N": r.load_N,
               "load_per_ball_N": r.load_N / r.balls, "mu": r.mu} for r in tied],
        certificate=certificate, solve_time_s=time.perf_counter() - start_time,
        method="sequential-convex-approximation", extra={"mu_physics": float(exact.mu)},
    )


def verify_design(problem: DesignProblem, result: OptimizationResult, mu_model: MuModel, model_name: str,
                  source_model: MuModel, source_name: str) -> dict[str, Any]:
    """Check a design found on ``mu_model`` (a surrogate) with the model it stands for.

    Parameters
    ----------
    problem : DesignProblem
        The problem as asked (its limits, not tightened ones).
    result : OptimizationResult
        The design found on ``mu_model``; its ``mu`` is the model's worst case over the speeds.
    mu_model, source_model : callable
        The optimized model and its source, ``points -> mu`` [1].
    model_name, source_name : str
        Their names. [-]

    Returns
    -------
    dict
        ``source_model``, ``mu_model`` and ``mu_source`` (each model's worst case over its speed
        grid, :func:`speed_grid_m_s`) [1], ``speed_m_s_source`` (where the source's occurs) [m/s],
        ``relative_difference`` (mu_model / mu_source - 1) [1], ``friction_force_N_model`` and
        ``friction_force_N_source`` [N], ``friction_force_ratio`` (source over model) [1],
        ``constraints`` (every bound and limit judged by the source, with the optimized model's
        value beside it), ``violated`` (names of the limits the source breaks) and ``satisfied``.
    """
    design = result.design
    balls, theta, load = design["balls"], design["groove_angle_deg"], design["load_N"]
    mu_source, speed = _worst_case(problem, source_model, source_name, speed_grid_m_s(problem, source_model),
                                   balls, theta, load)
    mu_source = float(mu_source[0])
    exact = physics.evaluate(convention=problem.convention, **problem.physics_inputs(balls, theta, load))
    model_force = result.mu * load
    constraints = [
        dataclasses.replace(c, value_model=model_force) if c.name == "max_friction_force_N"
        else dataclasses.replace(c, value_model=c.value)
        for c in constraint_report(problem, balls, theta, load, exact, mu_source, source_name)]
    violated = [c.name for c in constraints if not c.satisfied]
    return {**compare_with_source(model_name, source_name, result.mu, mu_source, speed[0], load),
            "constraints": constraints, "violated": violated, "satisfied": not violated}


def _with_verification(problem: DesignProblem, result: OptimizationResult, report: dict[str, Any],
                       seconds: float) -> OptimizationResult:
    """``result`` with the limits judged by the source model and the verification in its certificate."""
    source, model = report["source_model"], report["model"]
    text = (f" Verified by {source}, the model {model} stands for: mu = {report['mu_source']:.6g} there "
            f"against {report['mu_model']:.6g} from {model} (relative difference "
            f"{report['relative_difference']:+.3g}); every limit is judged by {source}'s values, "
            f"{model}'s beside them.")
    limit = problem.constraints.max_friction_force_N
    if report["resolves"]:
        text += (f" {source} broke max_friction_force_N={limit:g} N at the first design, so the problem "
                 f"was re-solved {report['resolves']} time(s) with that limit tightened by the ratio of "
                 f"the two models' friction forces and a margin of {RESOLVE_MARGIN:g}.")
    if report["violated"]:
        text += (f" VIOLATING: under {source} the design breaks {', '.join(report['violated'])}; no "
                 f"design meeting every limit under {source} was found.")
    public = {key: value for key, value in report.items() if key != "constraints"}
    return dataclasses.replace(
        result, constraints=report["constraints"], certificate=result.certificate + text,
        solve_time_s=seconds, extra={**result.extra, "mu_source": report["mu_source"],
                                     "source_model": source, "verification": public})


def compare_with_source(model_name: str, source_name: str, mu_model: float, mu_source: float,
                        speed_m_s_source: float, load_N: float) -> dict[str, Any]:
    """How a design found on a model (a surrogate) and the model it stands for compare: the figures every
    verification reports (:func:`verify_design` at a point, :func:`optimize.plan.verify_over_envelope`
    over an envelope).

    Parameters
    ----------
    model_name, source_name : str
        The two models' names. [-]
    mu_model, mu_source : float
        Each one's (worst) μ at the design. [1]
    speed_m_s_source : float
        Where the source's occurs. [m/s]
    load_N : float
        The design's load. [N]

    Returns
    -------
    dict
        ``source_model``, ``model``, ``mu_model`` and ``mu_source`` [1], ``speed_m_s_source`` [m/s],
        ``relative_difference`` (mu_model / mu_source - 1) [1], ``friction_force_N_model`` and
        ``friction_force_N_source`` [N], ``friction_force_ratio`` (source over model) [1].
    """
    model_force, source_force = mu_model * load_N, mu_source * load_N
    return {"source_model": source_name, "model": model_name, "mu_model": float(mu_model),
            "mu_source": float(mu_source), "speed_m_s_source": float(speed_m_s_source),
            "relative_difference": float(mu_model / mu_source - 1.0),
            "friction_force_N_model": float(model_force), "friction_force_N_source": float(source_force),
            "friction_force_ratio": float(source_force / model_force)}
