"""Certificates of a robust design: the worst case at a design bracketed by branch and bound, and the
lower bounds over the designs of ``mu_upper`` (:mod:`optimize.envelope_bound`, :mod:`optimize.design_bound`).
"""

from __future__ import annotations

import dataclasses
import math
import time
import types
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from microbearing import physics
from microbearing.physics.model import Model

from .design_bound import DesignPoints, design_lower_bound, kth_distance_to_boxes
from .envelope_bound import (
    BOUND_RTOL,
    MAX_BOXES,
    BoundFailedError,
    BranchAndBound,
    CertifiedMax,
    mu_box_bound,
    term_pieces,
)
from .interval_bound import (
    INTERVAL_OUTPUTS,
    INTERVAL_RTOL,
    interval_structures,
    mu_upper_box_bound,
)
from .over_envelope import (
    Envelope,
    envelope_columns,
    evaluator,
    model_inputs_fn,
    objective_values,
    shifted_problem,
    vertices_and_centre,
    worst_case_search,
)
from .problem import DESIGN_VARIABLES, DesignProblem, constraint_report
from .proof import (
    GAP_TARGET,
    RobustResult,
    design_of,
    worst_case_dict,
)
from .robust_vertex import (
    design_box_corners,
    monomials_at,
)


def least_widening(problem: DesignProblem, model: Model, point: Mapping[str, Any]) -> float:
    """A lower bound [1] of the data cloud's widening of the interval at an envelope point over the design
    box (1 without a cloud): the widening at the least distance ratio there (non-decreasing)."""
    calibrated = getattr(model, "calibrated", None)
    if getattr(calibrated, "cloud", None) is None:
        return 1.0
    ratio = calibrated.cloud_ratio_bound(*design_box_corners(problem, model, point), (1,), lower=True)
    return max(float(calibrated.cloud.widening(ratio)[0]), 1.0)


def with_interval_bound(result: RobustResult, mu_result: RobustResult, noise_std_log: float,
                        widening: float = 1.0) -> RobustResult:
    """A mu_upper result with the certified lower bound that the proven mu problem gives.

    A calibrated model's upper bound is mu exp(z sigma) with sigma^2 = g'Cg + (noise W)^2 >= (noise W)^2 (C
    positive semi-definite, no discrepancy) and W >= ``widening`` the data cloud's widening at mu's worst
    vertex (over the design box), so every design's worst mu_upper is at least exp(z noise W) times its mu
    there, its worst mu, hence at least that factor times the certified lower bound of the mu problem (whose
    friction limit on mu is a relaxation of the one on mu_upper).
    """
    z = float(stats.norm.isf(0.025))
    upper = result.proof.upper_bound
    lower = min(max(mu_result.proof.lower_bound * math.exp(z * noise_std_log * widening),
                    result.proof.lower_bound or 0.0), upper)
    gap = (upper - lower) / upper
    cloud = f" x {widening:.4g}, the data cloud's least widening there" if widening > 1.0 else ""
    statement = (f" Certified lower bound {lower:.10g}: mu_upper >= mu exp(1.96 x {noise_std_log:.4g}"
                 f"{cloud}) (the interval is at least the measurement scatter) and the worst mu over the "
                 "envelope is "
                 f"proven at least {mu_result.proof.lower_bound:.10g} (geometric programming, as for "
                 f"objective mu); relative gap to the worst case's upper bound {gap:.2e}: the parameters' "
                 "share of "
                 f"the interval. {'Not proven: the gap is above the target.' if gap > GAP_TARGET else ''}")
    proof = dataclasses.replace(result.proof.with_statement(statement), lower_bound=lower, relative_gap=gap)
    certificate = result.result.certificate + statement
    return dataclasses.replace(result, proof=proof,
                               result=dataclasses.replace(result.result, certificate=certificate))


#: Envelope points whose mu_upper at the returned design is within this of its worst case (relative) join the
#: worst point in the lower bound over the designs. [1]
_ACTIVE_RTOL = 1e-3
#: Relative gap to which the worst mu_upper at a design is bracketed (with the lower bound over the designs,
#: within the gap target of a proof). [1]
BRACKET_RTOL = 1e-7
#: Most boxes of a mu_upper bracket at a design: twice mu's (:data:`optimize.envelope_bound.MAX_BOXES`), as
#: its bound composes more enclosures, each first order in the box's width (the fitted values' gradient, a
#: GP's mean and variance); with a GP discrepancy alone the bench's bracket closes to 1e-7 after 26,445
#: boxes, where 20,000 left it at 7.3e-6 (bench/optimize.py --kinds). [1]
UPPER_MAX_BOXES = 2 * MAX_BOXES
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


def _load_term(piece: Any) -> bool:
    """Whether a term is one of the load alone that declares where its extremes over an interval lie (monotone
    in it, or at its declared stationary point; :class:`physics.effects.Effect`) and how mu moves with each
    fitted value (its value forms, whose extremes lie at the interval's ends or the data's centre): its
    range and its gradient's over a box of loads are then exact at those loads (:mod:`optimize.design_bound`),
    monomial or not (a ``generic_quadratic`` on the load)."""
    effect = piece.term.effect
    return (tuple(piece.term.drivers) == ("load_N",) and effect.enters in ("add", "mul")
            and (effect.monotone or effect.stationary is not None)
            and all(piece.value_form(i) is not None for i in range(len(piece.values))))


def _monomial_everywhere(structures: Sequence[Any], point: Mapping[str, Any]) -> str:
    """Why some term of the model or a rival is neither a positive monomial in balls and load at the point
    (also with each fitted value stepped, as the gradient takes it) nor a term of the load declaring its
    extremes (:func:`_load_term`), or "" when every one is."""
    for s in structures:
        # drifts: in the physics; terms of the load alone: bounded from their declarations
        effects = [piece for piece in s.pieces if piece.kind != "drift" and not _load_term(piece)]
        terms = [piece.term for piece in effects]
        values = [list(piece.values) for piece in effects]
        variants = [values] + [[*values[:k], [*v[:i], x + 1.0, *v[i + 1:]], *values[k + 1:]]
                               for k, v in enumerate(values) for i, x in enumerate(v)]
        for each in variants:
            monomials, reason = monomials_at(terms, each, point)
            if monomials is None:
                return reason or "a term is not a positive monomial in balls and load_N at a point"
    return ""


def _design_bound_points(problem: DesignProblem, envelope: Envelope, model: Model, result: RobustResult,
                         structures: Sequence[Any]) -> list[dict[str, Any]] | str:
    """The envelope points the lower bound over the designs is taken at (the worst one at the design, and
    the vertices and centre within :data:`_ACTIVE_RTOL` of it), or why it cannot be."""
    # The design boxes' bound composes the physics (with drifted parameters at the point), additions,
    # factors, groups (at a point naming none) and a Gaussian-process discrepancy (its least mean and
    # variance over the box); a drift's driver must be fixed at the point.
    for s in structures:
        for piece in s.pieces:
            if piece.kind == "drift" and piece.term.driver not in ("speed_m_s", *envelope.conditions):
                return (f"its term {piece.term.label!r} drifts a physics parameter with "
                        f"{piece.term.driver}, which the bound over design boxes does not take")
    design = design_of(result.result)
    worst = result.worst_case
    offset = worst["groove_angle_deg"] - design["groove_angle_deg"]
    points = [envelope.point({"speed_m_s": worst["speed_m_s"], "groove_angle_offset_deg": offset,
                              **{f"conditions.{n}": v for n, v in worst["conditions"].items()}})]
    candidates = vertices_and_centre(envelope)
    at = evaluator(problem, envelope, model, "mu_upper", design, 0.0)(candidates)
    top = max(float(np.max(at)), float(worst["mu_upper"]))
    points += [p for p, v in zip(candidates, at, strict=True)
               if v >= top * (1.0 - _ACTIVE_RTOL) and p != points[0]]
    for point in points:
        reason = _monomial_everywhere(structures, point)
        if reason:
            return reason
    return points


def _design_passes(problem: DesignProblem, envelope: Envelope, model: Model, result: RobustResult,
                   structures: Sequence[Any], points: list[dict[str, Any]], widened: bool,
                   deadline: float, progress: Callable[[float], None] | None = None) -> tuple[Any, int]:
    """The lower bound over the designs at the points, with up to :data:`_DESIGN_PASSES` passes (each adding
    the worst point of a design lower than the returned one there); ``points`` grows. Returns it and the
    points added."""
    design = design_of(result.result)
    worst = result.worst_case
    z_quantile = float(stats.norm.isf(0.025))

    def evaluate(designs: Mapping[str, np.ndarray]) -> np.ndarray:
        return objective_values(model, "mu_upper", envelope_columns(problem, envelope, designs, points, 0.0),
                                problem.convention)

    fitted_names = {name for s in structures for name in s.fitted}
    added = 0
    for _ in range(_DESIGN_PASSES):
        widening = [cloud_widening(problem, envelope, model, p, design, fitted_names)
                    if widened else None for p in points]
        at = DesignPoints(problem, structures, model.calibrated.fixed, points, envelope.angle_tolerance_deg,
                          z_quantile, widening)
        found = design_lower_bound(at, design, evaluate, time_limit_s=deadline - time.perf_counter(),
                                   progress=progress)
        enough = found.lower_bound >= float(worst["mu_upper"]) * (1.0 - GAP_TARGET + BRACKET_RTOL)
        if enough or not (found.improved and found.complete) or time.perf_counter() > deadline:
            break
        # A design lower than the returned one at the points: its worst point joins them.
        _, where, _ = worst_case_search(evaluator(problem, envelope, model, "mu_upper",
                                                  found.incumbent_design, 0.0), envelope)
        if _monomial_everywhere(structures, where):
            break
        points.append(where)
        added += 1
    return found, added


@dataclass(frozen=True)
class _DesignBoundEvidence:
    """The figures the statement of a lower bound over the designs is written from."""

    found: Any
    lower: float
    upper: float
    value: float
    gap: float
    proven: bool
    certified: bool
    widened: bool
    counts: int
    points: int
    added: int
    parts: str
    swapped: str


def _design_bound_statement(e: _DesignBoundEvidence, envelope: Envelope) -> str:
    """The lower bound over the designs and the gap, in words (a design in the request's keys and units,
    :meth:`Envelope.said_design`)."""
    found = e.found
    stopped = "" if found.complete else ", stopped at the time or box limit: the bound found so far"
    extra = f", and {e.added} worst point(s) of designs lower there" if e.added else ""
    cloud = (", the data cloud's widening of sigma at least the k-th nearest row's distance to the box over "
             "the cloud's threshold" if e.widened else "")
    statement = (
        f" Certified lower bound {e.lower:.10g} on the best achievable worst case, by branch and bound over "
        f"the designs ({found.boxes} boxes of groove angle and load over {e.counts} ball count(s){stopped}): "
        f"at {e.points} envelope point(s) (the worst one at the design, the vertices within "
        f"{_ACTIVE_RTOL:g} of it{extra}) no design's mu_upper is below its box's bound - the physics' "
        "friction force grows with the angle and the load (its posynomial form), each term is a positive "
        "monomial in balls and load there (read and checked) or a term of the load at its ends and where "
        "it declares an extreme (its stationary point, its data's centre), the composed mu and each fitted "
        "value's "
        "gradient of log mu by interval arithmetic, the least parameter variance g'Cg over the box of "
        "gradients from convexity (coordinate descent and its Frank-Wolfe gap), for the model and each "
        f"rival{cloud}{e.parts}; boxes where a limit is certainly broken are "
        "dropped. ")
    if e.certified:
        statement += ("Upper end certified by branch and bound over the envelope at the design: "
                      f"{e.upper:.10g}. ")
    else:
        why_searched = "the data cloud widens the interval" if e.widened else "see above"
        statement += (f"Upper end {e.upper:.10g} searched, not certified (no bound over a box of the "
                      f"envelope: {why_searched}). ")
    statement += f"Relative gap {e.gap:.2e} (target {GAP_TARGET:g})"
    if e.proven:
        statement += ": proven."
    else:
        statement += ": not proven ({}).".format(
            "the gap is above the target" if e.gap > GAP_TARGET else
            "the search stopped at its limit" if not found.complete else
            "the worst case at the design is not certified")
    statement += e.swapped
    if found.incumbent < e.value * (1.0 - 1e-9):
        better = found.incumbent_design
        statement += (f" A design lower at the points by {1.0 - found.incumbent / e.value:.1e} relative was "
                      f"found ({envelope.said_design(better)}: {found.incumbent:.10g}); the gap includes it.")
    return statement


def with_design_bound(problem: DesignProblem, envelope: Envelope, model: Model, result: RobustResult,
                      deadline: float, progress: Callable[[float], None] | None = None) -> RobustResult | str:
    """A mu_upper result with the certified lower bound over the designs (:mod:`optimize.design_bound`), and
    the best design at the points in place of the returned one where only that closes the gap; else why not.

    ``problem`` is in the nominal angle, with the model's values held; ``deadline`` is a
    :func:`time.perf_counter` instant after which no new batch of boxes starts; ``progress`` is told each
    pass's share of its box or time limit (:func:`optimize.design_bound.design_lower_bound`).
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
    points = _design_bound_points(problem, envelope, model, result, structures)
    if isinstance(points, str):
        return points
    try:
        found, added = _design_passes(problem, envelope, model, result, structures, points, widened, deadline,
                                      progress)
    except BoundFailedError as exc:
        return f"its bound over a design box failed a check ({exc})"
    if not found.design_meets_limits:
        return "the returned design does not meet the limits (exactly) at the worst points"
    certified = result.proof.method == "outer-approximation-certified"
    swapped = ""
    # Where the gap is above the target only by the returned design's distance from the best at the points,
    # that best design is tried (a bracket stopped at its box limit at the design would stop beside it too).
    closed = (result.proof.worst_case_relative_gap or 0.0) <= BRACKET_RTOL
    short = found.lower_bound < result.proof.upper_bound * (1.0 - GAP_TARGET)
    lower_found = found.incumbent < float(result.worst_case["mu_upper"]) * (1.0 - 1e-9)
    if certified and closed and short and lower_found:
        better = certified_design(problem, envelope, model, result, found.incumbent_design, deadline)
        if better is not None:
            swapped = (f" The design returned is the lower bound's best at the points (a box's centre), its "
                       f"worst case certified at most {better.proof.upper_bound:.10g}, below the outer "
                       f"approximation's design's {result.proof.upper_bound:.10g} (whose local method "
                       "keeps 1e-7 inside every limit; the limits here hold exactly).")
            result = better
    proof = result.proof
    upper, value = proof.upper_bound, float(result.worst_case["mu_upper"])
    lower = min(found.lower_bound, upper)
    gap = max(0.0, (upper - lower) / upper)
    proven = bool(certified and found.complete and gap <= GAP_TARGET)
    statement = _design_bound_statement(_DesignBoundEvidence(
        found, lower, upper, value, gap, proven, certified, widened, len(problem.ball_counts()), len(points),
        added, _design_bound_parts(structures), swapped), envelope)
    proof = dataclasses.replace(proof.with_statement(statement), proven=proven, lower_bound=lower,
                                relative_gap=gap, lower_bound_boxes=found.boxes,
                                upper_bound_certified=certified)
    certificate = (f"Proven optimum of the worst mu_upper over the envelope, to a relative gap of {gap:.1e}. "
                   f"{proof.statement}" if proven else result.result.certificate + statement)
    return dataclasses.replace(result, proof=proof, result=dataclasses.replace(result.result,
                                                                               certificate=certificate))


def cloud_widening(problem: DesignProblem, envelope: Envelope, model: Model, point: Mapping[str, Any],
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
    columns = {k: v for k, v in envelope_columns(problem, envelope, one, [point], 0.0).items()
               if k not in held}
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


def certified_design(problem: DesignProblem, envelope: Envelope, model: Model, result: RobustResult,
                     candidate: Mapping[str, float], deadline: float) -> RobustResult | None:
    """The result with ``candidate`` (nominal angle) as its design where its worst mu_upper over the envelope,
    certified by branch and bound, is below the result's and every limit holds there; else None."""
    structures, _ = interval_structures(model)
    if structures is None:
        return None
    design = {"balls": round(candidate["balls"]), "groove_angle_deg": float(candidate["groove_angle_deg"]),
              "load_N": float(candidate["load_N"])}
    try:
        bracket = certified_upper_search(problem, envelope, model, structures, design, 0.0,
                                          rtol=BRACKET_RTOL,
                                          time_limit_s=max(0.0, deadline - time.perf_counter()))
    except BoundFailedError:
        return None
    if not bracket.complete or bracket.upper_bound >= result.proof.upper_bound:
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
    at_centre = float(evaluator(problem, envelope, model, "mu_upper", design, 0.0)([centre_point])[0])
    price = dict(result.price_of_robustness)
    price["robust"] = {**price["robust"], "design": dict(design), "at_centre": at_centre,
                       "worst_case": bracket.value}
    price["ratio"] = float(price["nominal"]["worst_case"] / bracket.value)
    proof = dataclasses.replace(result.proof, upper_bound=bracket.upper_bound, worst_case_boxes=bracket.boxes,
                                worst_case_relative_gap=bracket.relative_gap)
    solved = dataclasses.replace(result.result, design={**result.result.design, **design}, mu=bracket.value,
                                 relative_gap=result.result.mu_solver / bracket.value - 1.0,
                                 constraints=report, speed_m_s=float(bracket.point["speed_m_s"]))
    return dataclasses.replace(result, result=solved, proof=proof, price_of_robustness=price,
                               worst_case=worst_case_dict("mu_upper", bracket.value, bracket.point,
                                                           design["groove_angle_deg"]))


def certifier(envelope: Envelope, model: Model, objective: str
              ) -> tuple[Callable[[DesignProblem, Mapping[str, Any], float], BranchAndBound] | None, str]:
    """What opens the bracket of the worst objective at a design (problem, design in θ', shift; ``rtol``
    optional: its :meth:`BranchAndBound.run` brackets it), or None and why not."""
    if objective == "mu":
        pieces, why = term_pieces(model)
        if pieces is None:
            return None, why
        return (lambda problem, design, shift, **rtol: mu_bracket(problem, envelope, model, pieces,
                                                                   design, shift, **rtol)), ""
    structures, why = interval_structures(model)
    if structures is None:
        return None, why
    return (lambda problem, design, shift, **options: upper_bracket(
        problem, envelope, model, structures, design, shift, **{"rtol": BRACKET_RTOL, **options})), ""


def certified_upper_search(problem: DesignProblem, envelope: Envelope, model: Model, structures: list,
                           design: Mapping[str, Any], shift: float, rtol: float | None = None,
                           time_limit_s: float = math.inf) -> CertifiedMax:
    """The worst mu_upper over the envelope at a design (angle θ' = θ + ``shift``), bracketed."""
    return upper_bracket(problem, envelope, model, structures, design, shift, rtol).run(
        time_limit_s=time_limit_s)


def upper_bracket(problem: DesignProblem, envelope: Envelope, model: Model, structures: list,
                  design: Mapping[str, Any], shift: float, rtol: float | None = None) -> BranchAndBound:
    """The branch and bound of :func:`certified_upper_search`, opened (:meth:`BranchAndBound.run` runs it)."""
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
                               model_inputs_fn(problem, model, balls, theta, load), {**problem.fixed})
    return BranchAndBound(bound, evaluator(problem, envelope, model, "mu_upper", design, shift), envelope,
                          rtol=rtol or INTERVAL_RTOL, max_boxes=UPPER_MAX_BOXES)


def certified_search(problem: DesignProblem, envelope: Envelope, model: Model, pieces: list,
                     design: Mapping[str, Any], shift: float, rtol: float | None = None) -> CertifiedMax:
    """The worst μ over the envelope at a design (angle θ' = θ + ``shift``), bracketed by branch and bound."""
    return mu_bracket(problem, envelope, model, pieces, design, shift, rtol).run()


def mu_bracket(problem: DesignProblem, envelope: Envelope, model: Model, pieces: list,
               design: Mapping[str, Any], shift: float, rtol: float | None = None) -> BranchAndBound:
    """The branch and bound of :func:`certified_search`, opened (:meth:`BranchAndBound.run` runs it)."""
    balls, load = float(design["balls"]), float(design["load_N"])
    theta = float(design["groove_angle_deg"]) - shift

    def physics_mu(offset: np.ndarray, speed: np.ndarray, **parameters: np.ndarray) -> np.ndarray:
        with np.errstate(all="ignore"):
            return physics.evaluate(convention=problem.convention, outputs=["mu"], **{
                **problem.physics_inputs(balls, theta + offset, load, speed_m_s=speed), **parameters}).mu

    # The values the drifts start from: the model's own (in problem.fixed, with_model_values), else defaults.
    base = {**physics.defaults(), **problem.fixed}
    return BranchAndBound(mu_box_bound(pieces, physics_mu, envelope, {"balls": balls, "load_N": load},
                                       model.calibrated, base,
                                       model_inputs_fn(problem, model, balls, theta, load)),
                          evaluator(problem, envelope, model, "mu", design, shift), envelope,
                          rtol=rtol or BOUND_RTOL)
