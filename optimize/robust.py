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
drift of a modulus in the interval, a scatter that depends on an input, a
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

Where each method lives
-----------------------
:func:`optimize_robust` checks the request and dispatches; the methods are one module each:
:mod:`optimize.robust_gp` (robust geometric programs, the physics), :mod:`optimize.robust_vertex`
(calibrated models at one vertex), :mod:`optimize.robust_outer` (the outer approximation),
:mod:`optimize.certificates` (brackets at a design, lower bounds over the designs). The envelope and the
worst-case search are :mod:`optimize.over_envelope`; what is proven is a :class:`Proof`
(:mod:`optimize.proof`), whose ``statement`` each method's formatter writes from its figures.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable

from threadpoolctl import threadpool_limits

from microbearing.physics.model import Model

from . import certificates
from .over_envelope import (
    OBJECTIVES,
    TOLERANCE_NAMES,
    Envelope,
    certified_worst_case_of,
    check_model,
    shifted_problem,
    with_column_defaults,
    with_model_values,
    worst_case_of,
    worst_case_search,
)
from .problem import DesignProblem
from .proof import GAP_TARGET, Proof, RobustResult
from .robust_gp import RobustGPResult, dual_bound, robust_gp, robust_physics
from .robust_outer import ENVELOPE_RTOL, MAX_ROUNDS, OuterOptions, robust_model
from .robust_vertex import robust_calibrated_gp, term_structure

__all__ = ["ENVELOPE_RTOL", "GAP_TARGET", "MAX_ROUNDS", "OBJECTIVES", "TOLERANCE_NAMES", "Envelope", "Proof",
           "RobustGPResult", "RobustResult", "certified_worst_case_of", "check_model", "dual_bound",
           "optimize_robust", "robust_gp", "shifted_problem", "worst_case_of", "worst_case_search"]

#: Share of a mu_upper design's progress that its rounds report; the lower bound over the designs that
#: follows them reports the rest (its boxes' or time's share of their limits). [1]
_PROGRESS_OF_ROUNDS = 0.9


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
    # One BLAS thread: the method's matrices are small (a GP's training rows against a few thousand points
    # or boxes), and threads on them spent ~1.7x the CPU for no gain in wall time (bench/optimize.py
    # --kinds), as in calibrate's GP fits.
    with threadpool_limits(1):
        result = _optimize_robust(problem, envelope, model, objective, starts, max_rounds, progress,
                                  map_calls, time_limit_s)
    if progress is not None:
        progress(1.0)
    return result


def _optimize_robust(problem: DesignProblem, envelope: Envelope, model: Model | None, objective: str,
                     starts: int, max_rounds: int, progress: Callable[[float], None] | None,
                     map_calls: Callable | None, time_limit_s: float) -> RobustResult:
    """:func:`optimize_robust` in the calling thread's BLAS setting."""
    start = time.perf_counter()
    check_model(model, envelope, objective)
    envelope = with_column_defaults(envelope, model)
    if model is not None and model.kind == "physics":
        problem = DesignProblem(problem.bounds, problem.speed_m_s, problem.constraints, problem.fixed,
                                model.convention)
        model = None
    problem = with_model_values(problem, model)
    if model is None:
        return robust_physics(problem, envelope, progress)
    reason = "the objective is mu_upper, whose interval is not log-log convex"
    vertex = None
    if objective == "mu":
        proven = robust_calibrated_gp(problem, envelope, model, progress)
        if isinstance(proven, RobustResult):
            return proven
        reason = proven
    else:
        # Where mu is proven worst (its terms monotone) is where its upper bound is likely worst too: the
        # outer approximation starts from that vertex alone (the search adds any other point that is worse).
        vertex = term_structure(model, envelope)[0]
    # mu_upper's lower bound over the designs follows the rounds: its share of the progress, the last tenth
    rounds_share = 1.0 if objective == "mu" or progress is None else _PROGRESS_OF_ROUNDS
    options = OuterOptions(starts, max_rounds, None if progress is None else (
        lambda fraction: progress(rounds_share * fraction)), map_calls, time_limit_s)
    result = robust_model(problem, envelope, model, objective, options, reason,
                          None if vertex is None else [vertex])
    if objective == "mu":
        return result
    bounded = certificates.with_design_bound(problem, envelope, model, result, start + time_limit_s,
                                             None if progress is None else (
                                                 lambda fraction: progress(rounds_share + (1.0 - rounds_share)
                                                                           * fraction)))
    if isinstance(bounded, RobustResult):
        return bounded
    result = dataclasses.replace(result, proof=result.proof.with_statement(
        f" No lower bound over the designs by branch and bound: {bounded}."))
    noise = getattr(getattr(model, "calibrated", None), "noise_std_log", None)
    proven = robust_calibrated_gp(problem, envelope, model, None, bound_only=True) if vertex else None
    if isinstance(proven, RobustResult) and proven.proof.lower_bound and noise:
        result = certificates.with_interval_bound(result, proven, float(noise),
                                                  certificates.least_widening(problem, model, vertex))
    return result
