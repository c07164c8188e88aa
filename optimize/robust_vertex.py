"""Calibrated models whose terms keep the robust problem a geometric program (:mod:`optimize.robust`).

Each term, read from the effect's declarations (:attr:`physics.effects.Effect.direction`) and at three
designs, is a positive monomial in balls and load at the envelope's worst vertex; the lower bounds at one
envelope point (:func:`point_lower_bound`) use the same reading.
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import cvxpy as cp
import numpy as np

from microbearing import physics
from microbearing.physics.model import Model

from .dgp import LIMIT_NAMES, SAFETY_MARGIN, design_gp
from .envelope_bound import (
    drift_ranges,
    term_pieces,
)
from .over_envelope import (
    Envelope,
    envelope_columns,
    evaluator,
    model_inputs_fn,
    objective_values,
    shifted_problem,
    worst_case_search,
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
from .robust_gp import (
    dual_bound,
)
from .solve import (
    TIE_TOLERANCE,
    BallCountResult,
    OptimizationResult,
    polish_design,
)


def design_box_corners(problem: DesignProblem, model: Model,
                       point: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """The model's points at the design box's lowest and highest corner at one envelope point (each column
    non-decreasing in balls, the nominal angle and the load)."""
    (b_lo, b_hi), (a_lo, a_hi), (l_lo, l_hi) = (problem.bounds.balls, problem.bounds.groove_angle_deg,
                                                problem.bounds.load_N)
    offset, speed = float(point["groove_angle_offset_deg"]), np.array([float(point["speed_m_s"])])
    conditions = {n: np.array([float(v)]) for n, v in point["conditions"].items()}
    low, high = [{**model_inputs_fn(problem, model, np.array([float(b)]), np.array([a]), np.array([g]))(
        offset, speed), **conditions} for b, a, g in ((b_lo, a_lo, l_lo), (b_hi, a_hi, l_hi))]
    return low, high


def point_lower_bound(problem: DesignProblem, model: Model, point: Mapping[str, Any],
                      factor: float = 1.0) -> float:
    """A certified lower bound [1] of the least objective over the designs at one envelope point (NaN: none).

    ``factor`` > 0 is a lower bound of the objective over the model's μ without its groups and discrepancy
    (1 for μ with neither; :func:`optimize.envelope_bound.interval_floor` for ``mu_upper``): the bound is
    factor × exp(the discrepancy's least mean over the design box at the point) × the programs' bound, and
    the friction-force limit on the objective enters the programs divided by that product (a relaxation).

    At a fixed point every effect term is a positive monomial in balls and load_N (read and checked,
    :func:`monomials_at`), so the calibrated μ there is a posynomial and its minimum over the designs, with
    the limits at that point, a geometric program per ball count (the dual bound of each, the least of them).
    The limits at one point are a relaxation of the limits over the envelope, and the worst case of any
    design is at least its μ at the point: the bound holds for the best achievable worst case.
    """
    terms = [(t, v) for t, v in model.calibrated.terms if getattr(t, "kind", None) != "drift"]
    monomials, _ = monomials_at([t for t, _ in terms], [v for _, v in terms], point)
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
        corners = design_box_corners(problem, model, point)
        factor *= math.exp(float(model.calibrated.discrepancy_bound(corners[0], corners[1], (1,))[0][0]))
    if factor != 1.0 and at_point.constraints.max_friction_force_N is not None:
        at_point = DesignProblem(at_point.bounds, at_point.speed_m_s, dataclasses.replace(
            at_point.constraints, max_friction_force_N=at_point.constraints.max_friction_force_N / factor),
            at_point.fixed, at_point.convention)
    bounds = [answer[4] for answer in calibrated_counts(at_point, monomials).values()]
    return math.nan if not bounds or any(math.isnan(b) for b in bounds) else float(min(bounds)) * factor


# --------------------------------------------------------------------------------------------------
# Calibrated models whose terms keep the problem a geometric program


#: Reference designs (balls [1], load [N]) at which a term's monomial form in the design is read, and
#: the one at which it is checked.
_PROBES = ((1.0, 1.0), (2.0, 1.0), (1.0, 2.0), (3.0, 0.37))


@dataclass(frozen=True)
class Monomial:
    """A term at the envelope's worst vertex: ``kind`` "add" (μ + k z^a G^b) or "mul" (μ k z^a G^b)."""

    kind: str
    coefficient: float
    balls_exponent: float
    load_exponent: float


def term_structure(model: Model,
                   envelope: Envelope) -> tuple[dict[str, Any] | None, list[Monomial], str]:
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
    monomials, reason = monomials_at([t for t, _ in terms], [v for _, v in terms], vertex)
    return (vertex if monomials is not None else None), monomials or [], reason


def monomials_at(terms: Sequence[Any], term_values: Sequence[Sequence[float]],
                 point: Mapping[str, Any]) -> tuple[list[Monomial] | None, str]:
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
        monomials.append(Monomial(kind, k, a, b))
    return monomials, ""


def compose_monomials(gp, monomials: list[Monomial]):
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


def calibrated_counts(problem: DesignProblem, monomials: list[Monomial]) -> dict[int, tuple]:
    """Every ball count's DGP optimum of the calibrated μ: (status, value, tan θ, load, lower bound)."""
    limits = frozenset(n for n in problem.constraints.active_limits() if n in LIMIT_NAMES)
    force = problem.constraints.max_friction_force_N
    programs: dict[int, tuple] = {}
    answers = {}
    for z in problem.ball_counts():
        gp, values = design_gp(problem, limits=limits - {"max_friction_force_N"}, balls=z)
        if id(gp) not in programs:
            mu = compose_monomials(gp, monomials)
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


def _vertex_statement(model: Model, envelope: Envelope, terms: int, delta: float, vertex: Mapping[str, Any],
                      bracket: tuple[float | None, float, float | None], mismatch: float,
                      searched: float) -> str:
    """The proof of a calibrated model's robust design at one vertex, in words (the vertex as the request sent
    the envelope: :meth:`Envelope.said`); ``bracket`` is the certified lower bound, the worst case at the
    design and their relative gap [1]."""
    lower, value, gap = bracket
    directions = ", ".join(envelope.said(n, v) for n, v in vertex["conditions"].items()) or "no condition"
    statement = (
        f"{model.reference}: the physics with its fitted values and {terms} term(s), each a "
        "positive "
        "monomial in balls and load_N added to mu or multiplying it (read at three designs, checked at a "
        "fourth), driven by the speed or a condition through a formula monotone in it (physics.effects; "
        "the directions from the fitted parameters' signs), so mu is a posynomial in tan(theta) and load_N "
        "for every ball count and its worst case over the envelope is one vertex: the angle made high "
        f"(+{envelope.said_tolerance(delta)}), {envelope.said('speed_m_s', vertex['speed_m_s'])}, "
        f"{directions}. The robust "
        "problem is then the geometric program of every ball count at that vertex; certified lower bound "
        f"{lower if lower is not None else float('nan'):.10g} (least dual objective over the counts, limits "
        f"exact, less Clarabel's tolerance), worst case at the design {value:.10g} (the model itself), "
        f"relative gap {gap if gap is not None else float('nan'):.2e} (target {GAP_TARGET:g}); solver and "
        f"model agree to {mismatch:.1e} at every count's optimum. A search of the whole envelope at the "
        "design "
        f"(grid and L-BFGS-B) found {searched:.10g}.")
    if searched > value * (1 + 1e-9):
        statement += (" That is above the vertex's value: the monotonicity argument failed here, nothing is "
                      "proven.")
    return statement


def robust_calibrated_gp(problem: DesignProblem, envelope: Envelope, model: Model,
                         progress: Callable[[float], None] | None,
                         bound_only: bool = False) -> RobustResult | str:
    """The robust design of a calibrated model whose terms keep the problem a GP, proven; else why not.

    ``bound_only``: only the design and its certified bound are wanted (no envelope search, no price of
    robustness: their fields repeat the design's own values).
    """
    start = time.perf_counter()
    vertex, monomials, reason = term_structure(model, envelope)
    if vertex is None:
        return reason
    delta = envelope.angle_tolerance_deg
    shifted = shifted_problem(problem, delta, vertex["speed_m_s"])
    answers = calibrated_counts(shifted, monomials)
    solved = {z: a for z, a in answers.items() if a[0] in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)}
    if not solved:
        return "no ball count has a solution of the geometric program"
    box_angle, box_load = shifted.bounds.groove_angle_deg, shifted.bounds.load_N
    counts = sorted(solved)
    theta_p = np.clip(np.degrees(np.arctan([solved[z][2] for z in counts])), *box_angle)
    load = np.clip([solved[z][3] for z in counts], *box_load)
    def exact_at(theta: np.ndarray, load: np.ndarray) -> np.ndarray:
        designs = {"balls": np.array(counts, dtype=float), "groove_angle_deg": theta, "load_N": load}
        return objective_values(model, "mu", envelope_columns(problem, envelope, designs, [vertex], delta),
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
        evaluator(problem, envelope, model, "mu", design, delta), envelope)[:2]
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
    statement = _vertex_statement(model, envelope, len(monomials), delta, vertex, (lower, value, gap),
                                  mismatch, searched)
    proof = Proof(bool(proven), "robust-gp-vertex", lower, value, gap, statement)
    worst_point = vertex if searched <= value * (1 + 1e-9) else where
    worst_case = worst_case_dict("mu", max(value, searched), worst_point, design["groove_angle_deg"] - delta)
    # Price of robustness: the same program at the envelope's centre, no tolerance.
    centre = envelope.centre()
    centre_envelope = Envelope(centre["speed_m_s"], centre["conditions"])
    nominal = (robust_calibrated_gp(problem, centre_envelope, model, None, bound_only=True)
               if envelope.axes() and not bound_only else None)
    if isinstance(nominal, RobustResult):
        nominal_design = design_of(nominal.result)
        nominal_worst = float(evaluator(problem, envelope, model, "mu", nominal_design, 0.0)(
            [{**vertex, "groove_angle_offset_deg": delta}])[0])
        nominal_centre = float(nominal.worst_case["mu"])
        limits = constraint_report(shifted, nominal_design["balls"],
                                   nominal_design["groove_angle_deg"] + delta, nominal_design["load_N"],
                                   mu=nominal_worst)
        nominal_holds = all(c.satisfied for c in limits if not c.name.startswith("groove_angle_deg"))
    else:
        nominal_design, nominal_worst, nominal_centre, nominal_holds = (
            {**design, "groove_angle_deg": design["groove_angle_deg"] - delta}, value, value, True)
    robust_centre = float(evaluator(problem, envelope, model, "mu", design, delta)(
        [envelope.point({"speed_m_s": centre["speed_m_s"],
                         **{f"conditions.{n}": v for n, v in centre["conditions"].items()}})])[0])
    # Both worst cases at the vertex are exact by the monotonicity argument (where the search agreed).
    vertex_holds = searched <= value * (1 + 1e-9)
    price = price_of(nominal_design, nominal_centre, nominal_worst, nominal_holds,
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
    return RobustResult(unshift(result, delta), "mu", envelope, worst_case, proof, price)
