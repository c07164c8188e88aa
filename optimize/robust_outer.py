"""The outer approximation (cutting planes) for models other than the physics, with its certificates
where the model's parts are bounded over a box (:mod:`optimize.robust`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from microbearing.physics.model import Model

from . import certificates
from .envelope_bound import (
    BoundFailedError,
    BranchAndBound,
    CertifiedMax,
    group_shift,
    interval_floor,
)
from .general import optimize_model
from .over_envelope import (
    Envelope,
    envelope_columns,
    evaluator,
    objective_values,
    shifted_problem,
    vertices_and_centre,
    worst_case_search,
)
from .problem import DESIGN_VARIABLES, DesignProblem, constraint_report
from .proof import (
    GAP_TARGET,
    Proof,
    RobustResult,
    design_of,
    price_of,
    unshift,
    worst_case_dict,
)
from .robust_vertex import (
    design_box_corners,
    point_lower_bound,
)
from .solve import (
    InfeasibleDesignError,
    OptimizationResult,
)

#: A searched worst case above the optimized set's by more than this (relative) adds a point. [1]
ENVELOPE_RTOL = 1e-6
#: Relative bracket to which the nominal design's worst case in the price of robustness is certified (it
#: is stated beside the robust one, not optimized). [1]
NOMINAL_RTOL = 1e-4
#: A round brackets its design's worst case first to this fraction (1 / ROUND_BOX_SHARE) of the box limit:
#: the polishes at 1,000 and 5,000 boxes (optimize.envelope_bound) have found its worst point by then, and a
#: design the rounds leave needs no more; one they end on is bracketed on to the limit. [1]
ROUND_BOX_SHARE = 4
#: Most rounds of the cutting-plane loop for models other than the physics. [1]
MAX_ROUNDS = 6


#: How the certified mu_upper bounds the widening of the interval beyond the data cloud, in words.
_CLOUD_WORDS = (", the widening beyond the data cloud at an upper bound of the distance ratio (the k-th "
                "smallest distance from the data rows to the box's farthest corner, in the cloud's scaled "
                "inputs; the widening is non-decreasing in the ratio)")


class SetModel:
    """The worst case of the objective over a finite set of envelope points, as optimize_model's μ model."""

    def __init__(self, problem: DesignProblem, envelope: Envelope, model: Model, objective: str,
                 points: list[dict[str, Any]], shift: float):
        self.problem, self.envelope, self.model, self.objective = problem, envelope, model, objective
        self.points, self.shift = points, shift

    def __call__(self, columns: Mapping[str, Any]) -> np.ndarray:
        design = {k: np.atleast_1d(np.asarray(columns[k], dtype=float)) for k in DESIGN_VARIABLES}
        n = max(np.size(v) for v in design.values())
        design = {k: np.broadcast_to(v, (n,)) for k, v in design.items()}
        values = objective_values(self.model, self.objective,
                                   envelope_columns(self.problem, self.envelope, design, self.points,
                                                    self.shift),
                                   self.problem.convention)
        return np.max(np.asarray(values, dtype=float).reshape(len(self.points), n), axis=0)


def _certified_proof(problem: DesignProblem, model: Model, bracket: CertifiedMax,
                     points: list[dict[str, Any]], history: list[dict[str, Any]], rounds: int,
                     ending: str) -> tuple[dict[str, Any], float]:
    """The proof of a design whose worst μ is bracketed: the bracket, and the best lower bound at the points.

    ``problem`` is in the nominal angle (the points carry their offsets). Returns the proof and the worst case
    found at the design [1].
    """
    # Groups move every design's mu by one factor at a point naming none (objective mu: sensitivity 1).
    groups = math.exp(group_shift(model.calibrated))
    bounds = [point_lower_bound(problem, model, p, groups) for p in points]
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
        f"({bracket.boxes} boxes{bracket.stopped_words()}) brackets the "
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
    proof = Proof(proven, "outer-approximation-certified", lower, upper, gap, statement, rounds=history,
                  worst_case_boxes=bracket.boxes, worst_case_relative_gap=bracket.relative_gap)
    return proof, bracket.value


@dataclass(frozen=True)
class OuterOptions:
    """How the outer approximation runs (the options of :func:`optimize.robust.optimize_robust`).

    Attributes
    ----------
    starts : int
        Starts per ball count of the local method. [1]
    max_rounds : int
        Most cutting-plane rounds. [1]
    progress : callable or None
        Called with the fraction done, 0..1. [1]
    map_calls : callable or None
        Passed to :func:`optimize.optimize_model` (groups of ball counts on an executor).
    time_limit_s : float
        No new round starts after this much time. [s]
    """

    starts: int = 3
    max_rounds: int = MAX_ROUNDS
    progress: Callable[[float], None] | None = None
    map_calls: Callable | None = None
    time_limit_s: float = math.inf


@dataclass(frozen=True)
class _Rounds:
    """What the rounds of the outer approximation leave: the last design, its worst case and how found."""

    solved: OptimizationResult
    value: float
    where: dict[str, Any]
    bracket: CertifiedMax | None
    certify: Callable | None
    reason: str
    points: list[dict[str, Any]]
    history: list[dict[str, Any]]
    rounds: int
    converged: bool
    timed_out: bool


def _run_rounds(shifted: DesignProblem, envelope: Envelope, model: Model, objective: str,
                options: OuterOptions, points: list[dict[str, Any]], reason: str, start: float) -> _Rounds:
    """The cutting-plane loop: design for the points, bracket (or search) the worst case there, add it."""
    delta = envelope.angle_tolerance_deg
    progress, max_rounds = options.progress, options.max_rounds
    # mu of a calibrated model whose terms are all bounded over a box: the worst case at each design is
    # certified by branch and bound (optimize.envelope_bound), not searched.
    certify, why = certificates.certifier(envelope, model, objective)
    if certify is None and why:
        reason = f"{reason}; nor is its worst case at a design bounded: {why}" if reason else why
    bracket = opened = None
    # Every design a round visits is bracketed first to a share of the boxes (enough to find its worst
    # point, which the next round adds); the design the rounds end on is bracketed to the box limit,
    # continuing the same branch and bound, and so is one a round returns to (optimize.envelope_bound).
    brackets: dict[tuple, BranchAndBound] = {}
    rounds, history, converged, timed_out = 0, [], False, False
    solved = None
    value, where = math.nan, None
    for rounds in range(1, max_rounds + 1):
        set_model = SetModel(shifted, envelope, model, objective, points, delta)
        fraction = 0.8 * (rounds - 1) / max_rounds
        solved = optimize_model(shifted, set_model, starts=options.starts, model_name=model.reference,
                                progress=None if progress is None else (
                                    lambda f, a=fraction: progress(a + 0.8 * f / max_rounds)),
                                map_calls=options.map_calls)
        design = design_of(solved)
        on_set = float(set_model({k: np.array([v]) for k, v in design.items()})[0])
        if certify is not None:
            try:
                key = tuple(sorted((k, float(v)) for k, v in design.items()))
                if key not in brackets:
                    brackets[key] = certify(shifted, design, delta)
                opened = brackets[key]
                bracket = opened.run(opened.max_boxes // ROUND_BOX_SHARE, final=False)
                if bracket.value <= on_set * (1 + ENVELOPE_RTOL):  # the rounds may end here
                    bracket = opened.run()
                value, where = bracket.value, bracket.point
            except BoundFailedError as exc:  # the model breaks the bound's premise: searched, and said so
                certify, bracket, opened = None, None, None
                reason = f"its bound over a box failed a check ({exc})"
        if certify is None:
            evaluate = evaluator(shifted, envelope, model, objective, design, delta)
            value, where, _ = worst_case_search(evaluate, envelope)
        history.append({"round": rounds, "points": len(points), "on_set": on_set, "searched": value})
        if value <= on_set * (1 + ENVELOPE_RTOL):
            value, converged = max(value, on_set), True
            break
        if time.perf_counter() - start > options.time_limit_s:
            timed_out = True
            break
        points = [*points, where]
    if opened is not None and not converged:  # the last round's design, bracketed to the box limit
        try:
            bracket = opened.run()
            value, where = bracket.value, bracket.point
        except BoundFailedError as exc:
            certify, bracket = None, None
            reason = f"its bound over a box failed a check ({exc})"
    return _Rounds(solved, value, where, bracket, certify, reason, points, history, rounds, converged,
                   timed_out)


def _ending(run: _Rounds, time_limit_s: float) -> str:
    """How the rounds ended, in words."""
    if run.converged:
        return f"the last search found {run.value:.10g}, within {ENVELOPE_RTOL:g} of the optimized set"
    when = f"at the time limit of {time_limit_s:g} s after" if run.timed_out else "after"
    return (f"stopped {when} {run.rounds} round(s) with the last search {run.value:.10g} above the optimized "
            f"set's {run.history[-1]['on_set']:.10g}: the design is not the best for the worst case found")


def _local_statement(model: Model, objective: str, run: _Rounds, ending: str, from_vertex: bool) -> str:
    """The statement of a design whose worst case is searched: no proof, and why."""
    start_set = "the vertex where mu is proven worst" if from_vertex else "vertices and centre"
    return (
        f"No proof: {model.reference} is not known to be monotone or log-log convex in the speed, the "
        f"conditions and the angle ({run.reason or 'not a calibrated model'}), and no bound on its "
        "derivatives is known, so its worst case over a box cannot be bounded rigorously. Method: outer "
        f"approximation in {run.rounds} round(s) - the local method minimized the largest {objective} over "
        f"{len(run.points)} envelope point(s) ({start_set}, then the worst points found), and at each design "
        "the whole envelope was searched (a grid of every axis, then L-BFGS-B ascent from the 3 best grid "
        f"points); {ending}. "
        "Best bound found: the worst case at the design as searched (upper_bound)"
        + ("; the design search is local, so no certified lower bound on the best achievable worst case "
           "exists." if objective == "mu" else "."))


def _certified_upper_proof(problem: DesignProblem, model: Model, run: _Rounds, ending: str,
                           from_vertex: bool) -> Proof:
    """The proof of a design whose worst mu_upper is bracketed, with the lower bound at the worst point."""
    bracket, where = run.bracket, run.where
    statement = (
        f"{model.reference}: the worst mu_upper over the envelope at the design is certified by branch "
        "and bound: over any box, the physics' mu and its pivoting share lie between the box's lowest "
        "and highest corner (posynomials), each term between its exact extremes, the composed mu and "
        "each fitted value's finite-difference gradient of log mu by interval arithmetic in closed form, "
        "the parameter variance g'Cg at most its largest value over the box of gradients (a vertex: "
        f"convex){_CLOUD_WORDS if model.calibrated.cloud is not None else ''}, for the model and each "
        f"rival ({bracket.boxes} boxes"
        f"{bracket.stopped_words()}): found {bracket.value:.10g}, "
        "certified "
        f"at most {bracket.upper_bound:.10g} (relative {bracket.relative_gap:.1e}). The design came from "
        f"the outer approximation in {run.rounds} round(s) ({ending}).")
    # Every design's mu_upper at the worst point is at least exp(z noise) times its mu there (the interval
    # is at least the scatter), and its mu there at least the dual bound of the geometric programs.
    # Started from mu's proven worst vertex, that bound is already known (optimize_robust adds it).
    # The data cloud widens every design's interval at the worst point at least by its least distance
    # ratio over the design box there (a lower bound of the k-th nearest distance).
    calibrated = model.calibrated
    least = 1.0
    if calibrated.cloud is not None:
        corners = design_box_corners(problem, model, where)
        ratio = calibrated.cloud_ratio_bound(*corners, (1,), lower=True)
        least = float(calibrated.cloud.widening(ratio)[0])
    scatter = interval_floor(calibrated, float(stats.norm.isf(0.025)), least)
    at_worst = (point_lower_bound(problem, model, where, scatter)
                if not from_vertex and scatter is not None else math.nan)
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
    return Proof(False, "outer-approximation-certified", lower, bracket.upper_bound, gap, statement,
                 rounds=run.history, worst_case_boxes=bracket.boxes,
                 worst_case_relative_gap=bracket.relative_gap)


def _nominal_price(problem: DesignProblem, shifted: DesignProblem, envelope: Envelope, model: Model,
                   objective: str, run: _Rounds, map_calls: Callable | None, value: float) -> dict[str, Any]:
    """The price of robustness: the nominal optimum at the envelope's centre (no tolerance) and its worst
    case beside the robust design's (worst case ``value`` [1])."""
    delta = envelope.angle_tolerance_deg
    solved, certify = run.solved, run.certify
    design = design_of(solved)
    centre = envelope.centre()
    centre_envelope = Envelope(centre["speed_m_s"], centre["conditions"])
    nominal_problem = DesignProblem(problem.bounds, centre["speed_m_s"], problem.constraints, problem.fixed,
                                    problem.convention)
    try:
        nominal = optimize_model(nominal_problem,
                                 SetModel(nominal_problem, centre_envelope, model, objective,
                                          [centre_envelope.point({})], 0.0),
                                 starts=1, model_name=model.reference, map_calls=map_calls)
    except InfeasibleDesignError:  # the local method found no design meeting the limits at the centre
        nominal = solved
    nominal_design = design_of(nominal)
    if nominal is solved:
        nominal_design["groove_angle_deg"] -= delta
    # The nominal design's worst case: certified by the same branch and bound as the robust one's where it
    # applies, to NOMINAL_RTOL (its upper bound then judges the friction limit), else searched.
    nominal_bracket = None
    if certify is not None:
        try:
            nominal_bracket = certify(problem, nominal_design, 0.0, rtol=NOMINAL_RTOL).run()
        except BoundFailedError:
            nominal_bracket = None
    if nominal_bracket is not None:
        nominal_worst, nominal_upper = nominal_bracket.value, nominal_bracket.upper_bound
    else:
        nominal_worst, _, _ = worst_case_search(
            evaluator(problem, envelope, model, objective, nominal_design, 0.0), envelope)
        nominal_upper = None
    limits = constraint_report(shifted, nominal_design["balls"], nominal_design["groove_angle_deg"] + delta,
                               nominal_design["load_N"], mu=nominal_upper or nominal_worst)
    centre_point = envelope.point({"speed_m_s": centre["speed_m_s"],
                                   **{f"conditions.{n}": v for n, v in centre["conditions"].items()}})
    robust_centre = float(evaluator(problem, envelope, model, objective, design, delta)([centre_point])[0])
    nominal_centre = float(evaluator(problem, envelope, model, objective, nominal_design, 0.0)(
        [centre_point])[0])
    return price_of(nominal_design, nominal_centre, nominal_worst,
                    all(c.satisfied for c in limits if not c.name.startswith("groove_angle_deg")),
                    {**design, "groove_angle_deg": design["groove_angle_deg"] - delta}, robust_centre, value,
                    nominal_upper, None if run.bracket is None else run.bracket.upper_bound)


def robust_model(problem: DesignProblem, envelope: Envelope, model: Model, objective: str,
                 options: OuterOptions, reason: str = "",
                 initial_points: list[dict[str, Any]] | None = None) -> RobustResult:
    """The robust design of a model other than the physics by outer approximation, with what is proven
    (the module docstring of :mod:`optimize.robust`); ``problem`` is in the nominal angle."""
    start = time.perf_counter()
    delta = envelope.angle_tolerance_deg
    # Limits that do not depend on the model (the peak pressure) are worst at the angle made high: the
    # optimizer works in θ' = θ + δ, and the model is asked at θ' - δ + offset.
    shifted = shifted_problem(problem, delta, envelope.speed_m_s[1])
    points = initial_points or vertices_and_centre(envelope)
    run = _run_rounds(shifted, envelope, model, objective, options, points, reason, start)
    ending = _ending(run, options.time_limit_s)
    value, where, bracket = run.value, run.where, run.bracket
    statement = _local_statement(model, objective, run, ending, bool(initial_points))
    proof = Proof(False, "outer-approximation-local", None, value, None, statement, rounds=run.history)
    if bracket is not None and objective == "mu":
        proof, value = _certified_proof(problem, model, bracket, [where, *run.points[len(points):]],
                                        run.history, run.rounds, ending)
        statement = proof.statement
    elif bracket is not None:
        proof = _certified_upper_proof(problem, model, run, ending, initial_points is not None)
        statement = proof.statement
    theta = design_of(run.solved)["groove_angle_deg"] - delta
    worst_case = worst_case_dict(objective, value, where, theta)
    price = _nominal_price(problem, shifted, envelope, model, objective, run, options.map_calls, value)
    certificate = (f"{'Proven' if proof.proven else 'Local'} optimum of the worst case over the envelope"
                   f"{'' if proof.proven else ', not proven'}. {statement}")
    result = unshift(dataclasses.replace(run.solved, mu=value, certificate=certificate,
                                         speed_m_s=float(where["speed_m_s"]), method=proof.method,
                                         solve_time_s=time.perf_counter() - start), delta)
    if options.progress is not None:
        options.progress(1.0)
    return RobustResult(result, objective, envelope, worst_case, proof, price)
