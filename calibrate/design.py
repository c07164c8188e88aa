"""Optimal experimental design with a proof of how good it is: D, I and T criteria over a candidate set.

A model enters through :class:`DesignModel`, a small interface that a textbook regression and the
calibrated friction model (:mod:`calibrate.experiments`) both implement: the response at points (log μ
for friction), its sensitivities to the parameters (one row per point), the standard deviation of one
measurement of the response at each point (``scatter_sd``) and the information of the data already
taken (``prior_information``, the inverse of the fitted parameters' covariance). Rivals are
:class:`DesignModel` too.

:func:`plan` solves the continuous (approximate) design over the candidate points as one convex
problem in cvxpy, rounds it to whole runs by Pukelsheim and Rieder's efficient rounding, polishes the
runs by exchanges, and bounds how far the runs can be from the best design on the candidate set:

* ``parameters`` (D-optimal): maximize log det M(w), M(w) = A/N + Σ w_i b_i b_iᵀ, b_i = g_i / σ_i, A
  the prior information and N the runs. Bound (Kiefer-Wolfowitz, in Atwood's form; with a prior it
  follows from the concavity of log det): efficiency (det M / det M*)^(1/p) ≥ p / (tr(M⁻¹A/N) + max_x
  b_xᵀ M⁻¹ b_x).
* ``predict`` (I-optimal): minimize tr(L M(w)⁻¹), L the mean of c cᵀ over the envelope's sensitivities
  c (cvxpy's ``matrix_frac``). Bound: efficiency Φ*/Φ ≥ Φ / (tr(M⁻¹LM⁻¹A/N) + max_x b_xᵀ M⁻¹LM⁻¹ b_x).
  With rivals, Φ sums the same over the model and each rival (model-robust), and so do the bound's
  terms.
* ``discriminate`` (T-optimal, Atkinson and Fedorov 1975): maximize min_k Δ_k(w), Δ_k(w) = min_δ Σ w_i
  (d_ki − J_ki δ)² / σ_i² + (prior of rival k), d_k the reference's response less rival k's and J_k
  rival k's sensitivities (linearized rivals). Each Δ_k is the Schur complement of a matrix linear in
  w, so Δ_k ≥ t is one linear matrix inequality. Bound: with ψ_k(x) the squared standardized
  residual of rival k at its best δ, Δ_min(w*) ≤ min over λ in the simplex of Σ λ_k c_k + max_x Σ λ_k
  ψ_k(x) (one linear programme), c_k the prior's part of Δ_k.

The bound of the whole-run design is computed at the runs themselves (weights n_i / N), so it
contains the efficiency lost by rounding; the continuous design's bound times the rounding
efficiency is a second valid bound, and the larger is reported. Both are relative to the best
design over the candidate set (a fine grid or a space-filling set of the space).

References
----------
Atkinson, A. C. and Fedorov, V. V. (1975). The design of experiments for discriminating between two
rival models. Biometrika 62(1), 57-70.
Pukelsheim, F. and Rieder, S. (1992). Efficient rounding of approximate designs. Biometrika 79(4),
763-770.
Atwood, C. L. (1969). Optimal and efficient designs of experiments. Ann. Math. Statist. 40, 1570-1602.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import cvxpy as cp
import numpy as np
from scipy.optimize import linprog

__all__ = [
    "GOALS",
    "Design",
    "DesignError",
    "DesignModel",
    "FunctionModel",
    "check_identifiable",
    "efficient_rounding",
    "plan",
]

#: The criteria :func:`plan` optimizes.
GOALS = ("parameters", "predict", "discriminate")
# Continuous weights below this share of the largest are not support points (solver round-off). [1]
_SUPPORT = 1e-4
# Exchange passes of the polish at most (each moves one run). [1]
_POLISH_MOVES = 200
# Candidates tried as the destination of a run in each exchange, best by the sensitivity function. [1]
_POLISH_TARGETS = 24
# An information matrix whose smallest eigenvalue is below this share of its largest is singular. [1]
_SINGULAR = 1e-10
#: A rival parameter whose sensitivity over the candidates is below this share of its largest one moves
#: none of them (left out of the T-criterion) [1].
_NEGLIGIBLE_SENSITIVITY = 1e-9
#: Time the fallback solver (SCS) may take on one design problem before it is said unsolved. [s]
_SCS_SECONDS = 60.0


class DesignError(ValueError):
    """A design that cannot be made: parameters the candidates cannot identify, no rival, ..."""


class DesignModel(Protocol):
    """What a design needs of a model at columnar points (``points``: mapping of column to array).

    ``parameter_names``: the fitted parameters. ``response(points)``: the response, one value per point
    (log μ [1] for friction). ``sensitivities(points)``: d response / d parameter, shape (points,
    parameters). ``scatter_sd(points)``: standard deviation of one measurement of the response at each
    point (in the response's unit). ``prior_information()``: information of the data already taken
    on the parameters (the inverse of their covariance), or None.
    """

    parameter_names: Sequence[str]

    def response(self, points: Mapping[str, np.ndarray]) -> np.ndarray: ...

    def sensitivities(self, points: Mapping[str, np.ndarray]) -> np.ndarray: ...

    def scatter_sd(self, points: Mapping[str, np.ndarray]) -> np.ndarray: ...

    def prior_information(self) -> np.ndarray | None: ...


@dataclass(frozen=True)
class FunctionModel:
    """A :class:`DesignModel` from plain functions: a regression ``features(points) @ coefficients``, or
    any response with its sensitivities.

    Attributes
    ----------
    parameter_names : sequence of str
        Names of the parameters (the columns of the sensitivities).
    sensitivity_function : callable
        ``points -> array (points, parameters)``.
    response_function : callable, optional
        ``points -> array (points,)``; default ``sensitivities @ coefficients`` (a linear model).
    coefficients : sequence of float, optional
        The linear model's coefficients (default zeros).
    sd : float
        Standard deviation of one measurement of the response, the same everywhere.
    prior : numpy.ndarray, optional
        Information of data already taken.
    """

    parameter_names: Sequence[str]
    sensitivity_function: Callable[[Mapping[str, np.ndarray]], np.ndarray]
    response_function: Callable[[Mapping[str, np.ndarray]], np.ndarray] | None = None
    coefficients: Sequence[float] | None = None
    sd: float = 1.0
    prior: np.ndarray | None = field(default=None, repr=False)

    def sensitivities(self, points):
        columns = np.asarray(self.sensitivity_function(points), dtype=float)
        return columns.reshape(columns.shape[0], len(self.parameter_names))

    def response(self, points):
        if self.response_function is not None:
            return np.asarray(self.response_function(points), dtype=float)
        coefficients = np.zeros(len(self.parameter_names)) if self.coefficients is None else self.coefficients
        return self.sensitivities(points) @ np.asarray(coefficients, dtype=float)

    def scatter_sd(self, points):
        return np.full(_count(points), float(self.sd))

    def prior_information(self):
        return self.prior


@dataclass(frozen=True)
class Design:
    """A proposed set of runs and what can be proven about it.

    Attributes
    ----------
    goal : str
        One of :data:`GOALS`.
    counts : numpy.ndarray
        Runs at each candidate point (integers summing to ``runs``; replicates allowed).
    weights : numpy.ndarray
        The continuous optimal design's weight of each candidate point (summing to 1). [1]
    criterion : float
        The criterion of the runs (with the data already taken): ``parameters``: log det of the
        information [log of the parameters' units⁻²]; ``predict``: mean variance of the response over
        the envelope [response unit²]; ``discriminate``: min over rivals of the expected increase of a
        rival's chi-square (Δ_k with the runs' counts) [1].
    efficiency_lower_bound : float
        The runs' efficiency against the best continuous design over the candidates is at least this,
        in [0, 1] (rounding included).
    continuous_efficiency_lower_bound : float
        The equivalence-theorem bound of the solver's continuous design. [1]
    rounding_efficiency : float
        The runs' criterion relative to the continuous design's (in the efficiency's scale). [1]
    rival_separation : numpy.ndarray or None
        ``discriminate``: Δ_k of each rival with the runs (expected chi-square increase of its fit). [1]
    information_after : numpy.ndarray
        Information on the parameters after the runs (prior included); its inverse is the covariance.
    solver : str
        The cvxpy solver used and its status.
    """

    goal: str
    counts: np.ndarray
    weights: np.ndarray
    criterion: float
    efficiency_lower_bound: float
    continuous_efficiency_lower_bound: float
    rounding_efficiency: float
    rival_separation: np.ndarray | None
    information_after: np.ndarray = field(repr=False)
    solver: str = ""

    @property
    def runs(self) -> np.ndarray:
        """Index of the candidate point of every run, replicates repeated, in candidate order."""
        return np.repeat(np.arange(self.counts.size), self.counts)


def _count(points: Mapping[str, Any]) -> int:
    sizes = {np.size(v) for v in points.values()}
    return max(sizes) if sizes else 0


def _take(points: Mapping[str, np.ndarray], rows: np.ndarray) -> dict[str, np.ndarray]:
    n = _count(points)
    return {k: np.broadcast_to(np.asarray(v), (n,))[rows] for k, v in points.items()}


# --------------------------------------------------------------------------------------------- criteria
@dataclass
class _Problem:
    """The design problem in per-run units, parameters rescaled for the solver's conditioning."""

    goal: str
    runs: int
    b: np.ndarray  # (n, p) sensitivities / sigma, rescaled
    fixed: np.ndarray  # (p, p) prior + planned information / runs, rescaled
    envelope: np.ndarray | None = None  # (p, p) L, rescaled
    # predict with rivals: each rival's (b, fixed, L), rescaled; the criterion sums tr(L M⁻¹) over all.
    hedges: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=list)
    rival_rows: list[np.ndarray] = field(default_factory=list)  # each (n, q_k + 1): [J / sigma, d / sigma]
    rival_fixed: list[np.ndarray] = field(default_factory=list)  # each (q_k + 1, q_k + 1), per run
    scale: np.ndarray | None = None  # parameter scaling: b = (g / sigma) * scale

    def information(self, w: np.ndarray) -> np.ndarray:
        return self.fixed + (self.b * w[:, None]).T @ self.b

    def predict_terms(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """(b, fixed, L) of every model whose envelope variance the predict criterion sums."""
        return [(self.b, self.fixed, self.envelope), *self.hedges]

    def rival_matrix(self, k: int, w: np.ndarray) -> np.ndarray:
        a = self.rival_rows[k]
        return self.rival_fixed[k] + (a * w[:, None]).T @ a


def _schur_last(m: np.ndarray) -> tuple[float, np.ndarray]:
    """The Schur complement of the top-left block in the last diagonal entry, and the minimizing δ."""
    q = m.shape[0] - 1
    if q == 0:
        return float(m[0, 0]), np.zeros(0)
    delta = np.linalg.lstsq(m[:q, :q], m[:q, q], rcond=None)[0]
    return float(m[q, q] - m[q, :q] @ delta), delta


def _value(problem: _Problem, w: np.ndarray) -> float:
    """The criterion at weights w (per run), larger is better: log det, −tr(L M⁻¹), or min Δ_k."""
    if problem.goal == "discriminate":
        return min(_schur_last(problem.rival_matrix(k, w))[0] for k in range(len(problem.rival_rows)))
    if problem.goal == "predict":
        total = 0.0
        for b, fixed, envelope in problem.predict_terms():
            m = fixed + (b * w[:, None]).T @ b
            if np.linalg.slogdet(m)[0] <= 0:
                return -np.inf
            total += float(np.trace(np.linalg.solve(m, envelope)))
        return -total
    sign, logdet = np.linalg.slogdet(problem.information(w))
    return float(logdet) if sign > 0 else -np.inf


def _efficiency(problem: _Problem, better: float, worse: float) -> float:
    """The efficiency of a design of criterion ``worse`` against one of ``better`` (:func:`_value`)."""
    if problem.goal == "parameters":
        return float(np.exp((worse - better) / problem.b.shape[1]))
    if problem.goal == "predict":
        return float(better / worse) if worse < 0 else 0.0  # both are −Φ: Φ_better / Φ_worse
    return float(worse / better) if better > 0 else 0.0


def _sensitivity_and_bound(problem: _Problem, w: np.ndarray) -> tuple[np.ndarray, float]:
    """The sensitivity function at every candidate (where a run adds most) and the equivalence
    bound on the efficiency of w against the best continuous design on the candidates."""
    if problem.goal == "discriminate":
        psi, offset, values = [], [], []
        for k in range(len(problem.rival_rows)):
            m = problem.rival_matrix(k, w)
            value, delta = _schur_last(m)
            vector = np.append(-delta, 1.0)
            psi.append(np.square(problem.rival_rows[k] @ vector))
            offset.append(float(vector @ problem.rival_fixed[k] @ vector))
            values.append(value)
        psi_matrix = np.array(psi)  # (K, n)
        worst = min(values)
        if worst <= 0:
            return psi_matrix.min(axis=0), 0.0
        k_count, n = psi_matrix.shape
        # min over λ in the simplex and s: Σ λ_k c_k + s, s ≥ Σ λ_k ψ_k(x) at every candidate x.
        cost = np.append(offset, 1.0)
        upper = np.hstack([psi_matrix.T, -np.ones((n, 1))])
        result = linprog(cost, A_ub=upper, b_ub=np.zeros(n), A_eq=np.append(np.ones(k_count), 0.0)[None, :],
                         b_eq=[1.0], bounds=[(0, None)] * k_count + [(None, None)], method="highs")
        solved = result.status == 0
        bound = float(result.fun) if solved else float(np.max(np.array(offset)[:, None] + psi_matrix))
        lam = result.x[:k_count] if solved else np.full(k_count, 1.0 / k_count)
        return lam @ psi_matrix, float(np.clip(worst / bound, 0.0, 1.0))
    if problem.goal == "parameters":
        inverse = np.linalg.inv(problem.information(w))
        d = np.einsum("ij,jk,ik->i", problem.b, inverse, problem.b)
        upper = float(np.trace(inverse @ problem.fixed) + d.max())
        return d, float(np.clip(problem.b.shape[1] / upper, 0.0, 1.0))
    # predict: Φ = Σ_m tr(L_m M_m⁻¹) is convex and each term homogeneous of degree −1 in M_m, so
    # Φ(w*) ≥ Φ(w)² / (Σ_m tr(M_m⁻¹ L_m M_m⁻¹ A_m) + max_x Σ_m φ_m(x)) (see the module).
    phi, value, offset = 0.0, 0.0, 0.0
    for b, fixed, envelope in problem.predict_terms():
        inverse = np.linalg.inv(fixed + (b * w[:, None]).T @ b)
        weighted = inverse @ envelope @ inverse
        phi = phi + np.einsum("ij,jk,ik->i", b, weighted, b)
        value += float(np.trace(envelope @ inverse))
        offset += float(np.trace(weighted @ fixed))
    return phi, float(np.clip(value / (offset + phi.max()), 0.0, 1.0))


# ---------------------------------------------------------------------------------------------- solving
def _solve(problem: _Problem) -> tuple[np.ndarray, str]:
    """The continuous optimal design's weights by cvxpy."""
    n = problem.b.shape[0]
    w = cp.Variable(n, nonneg=True)
    constraints = [cp.sum(w) == 1]

    def affine(fixed: np.ndarray, rows: np.ndarray):
        q = rows.shape[1]
        outer = np.einsum("ij,ik->ijk", rows, rows).reshape(n, q * q)
        flat = cp.reshape(outer.T @ w, (q, q), order="C") + fixed
        return (flat + flat.T) / 2

    if problem.goal == "parameters":
        objective = cp.Maximize(cp.log_det(affine(problem.fixed, problem.b)))
    elif problem.goal == "predict":
        terms = []
        for b, fixed, envelope in problem.predict_terms():
            eigen, vectors = np.linalg.eigh(envelope)
            root = vectors * np.sqrt(np.clip(eigen, 0.0, None))
            terms.append(cp.matrix_frac(root, affine(fixed, b)))
        objective = cp.Minimize(cp.sum(terms))
    else:
        t = cp.Variable()
        for rows, fixed in zip(problem.rival_rows, problem.rival_fixed, strict=True):
            q = rows.shape[1]
            corner = np.zeros((q, q))
            corner[-1, -1] = 1.0
            constraints.append(affine(fixed, rows) - t * corner >> 0)
        objective = cp.Maximize(t)
    program = cp.Problem(objective, constraints)
    status = "not solved"
    if not all(np.all(np.isfinite(a)) for a in (problem.b, problem.fixed, *problem.rival_rows,
                                                 *problem.rival_fixed)):
        raise DesignError("the design problem's numbers are not finite (a sensitivity overflows over the "
                          "space): narrow the space or fix the column that drives it")
    for solver in ("CLARABEL", "SCS"):
        try:
            # An inaccurate solution is said in the status (and the efficiency bound is computed from
            # the rounded design itself), not warned about on stderr.
            with warnings.catch_warnings():
                warnings.filterwarnings("ignore", message="Solution may be inaccurate")
                # SCS, the fallback, stops after a time limit rather than iterate on a hopeless problem
                program.solve(solver=solver, **({"time_limit_secs": _SCS_SECONDS} if solver == "SCS" else {}))
        except cp.error.SolverError:
            continue
        status = f"{solver}: {program.status}"
        if program.status in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) and w.value is not None:
            weights = np.clip(np.asarray(w.value, dtype=float), 0.0, None)
            return weights / weights.sum(), status
    raise DesignError(f"the design problem could not be solved ({status})")


def efficient_rounding(weights: np.ndarray, runs: int) -> np.ndarray:
    """Whole runs from a continuous design by Pukelsheim and Rieder's (1992) efficient rounding.

    Parameters
    ----------
    weights : numpy.ndarray
        Weights of the support points (positive, any sum). [1]
    runs : int
        Runs wanted. [1]

    Returns
    -------
    numpy.ndarray
        Counts summing to ``runs``: n_i = ⌈(runs − l/2) w_i⌉ (l support points), then a run added
        where n_j / w_j is least, or removed where (n_k − 1) / w_k is largest, until they sum to
        ``runs``.

    Examples
    --------
    >>> efficient_rounding(np.array([0.5, 0.3, 0.2]), 10).tolist()
    [5, 3, 2]
    """
    w = np.asarray(weights, dtype=float)
    w = w / w.sum()
    counts = np.ceil(np.clip(runs - w.size / 2.0, 0.0, None) * w).astype(int)
    while counts.sum() < runs:
        counts[np.argmin(counts / w)] += 1
    while counts.sum() > runs:
        ratio = np.where(counts > 0, (counts - 1) / w, -np.inf)
        counts[np.argmax(ratio)] -= 1
    return counts


def _polish(problem: _Problem, counts: np.ndarray) -> np.ndarray:
    """Move single runs between candidates while that improves the whole-run criterion."""
    counts = counts.copy()
    runs = problem.runs
    current = _value(problem, counts / runs)
    for _ in range(_POLISH_MOVES):
        scores, _bound = _sensitivity_and_bound(problem, counts / runs)
        targets = np.argsort(scores)[::-1][:_POLISH_TARGETS]
        best, move = current, None
        for source in np.flatnonzero(counts):
            for target in targets:
                if target == source:
                    continue
                trial = counts.copy()
                trial[source] -= 1
                trial[target] += 1
                value = _value(problem, trial / runs)
                if value > best + 1e-12 * max(abs(best), 1.0):
                    best, move = value, (source, target)
        if move is None:
            break
        counts[move[0]] -= 1
        counts[move[1]] += 1
        current = best
    return counts


# ------------------------------------------------------------------------------------------------- plan
def _rival_arrays(reference: DesignModel, rival: DesignModel, points, sigma: np.ndarray) -> np.ndarray:
    difference = np.asarray(reference.response(points), dtype=float) - np.asarray(
        rival.response(points), dtype=float)
    jacobian = np.asarray(rival.sensitivities(points), dtype=float).reshape(difference.size, -1)
    return np.column_stack([jacobian, difference]) / sigma[:, None]


def _rival_prior(rival: DesignModel, q: int) -> np.ndarray:
    prior = rival.prior_information()
    out = np.zeros((q + 1, q + 1))
    if prior is not None:
        out[:q, :q] = np.asarray(prior, dtype=float)
    return out


def plan(
    model: DesignModel,
    candidates: Mapping[str, np.ndarray],
    runs: int,
    goal: str = "parameters",
    envelope: Mapping[str, np.ndarray] | None = None,
    rivals: Sequence[DesignModel] = (),
    planned: Mapping[str, np.ndarray] | None = None,
    polish: bool = True,
    exchange: Callable[[np.ndarray], np.ndarray] | None = None,
) -> Design:
    """The best ``runs`` runs over candidate points for a goal, with an optimality bound.

    Parameters
    ----------
    model : DesignModel
        The model whose parameters (``parameters``), predictions (``predict``) or rivals
        (``discriminate``, the reference the rivals are told apart from) the runs serve.
    candidates : mapping of str to numpy.ndarray
        The candidate points as columns (any columns ``model`` reads), one value per point.
    runs : int
        Runs to propose, ≥ 1. [1]
    goal : str
        One of :data:`GOALS`.
    envelope : mapping of str to numpy.ndarray, optional
        ``predict``: the points where the model will be used (their mean prediction variance is
        minimized).
    rivals : sequence of DesignModel
        ``discriminate``: the rival models; each is linearized at its parameters. ``predict``: optional;
        the criterion then sums the envelope variance of the model and of every rival (model-robust
        I-optimality, after Läuter 1974), so that the runs also serve the rivals' predictions.
    planned : mapping of str to numpy.ndarray, optional
        Runs already planned (columns like ``candidates``): their information counts as taken.
    polish : bool
        Whether to improve the rounded runs by single-run exchanges.
    exchange : callable, optional
        Counts per candidate -> counts, a last move of the runs by what the information does not hold
        (:class:`calibrate.reported.ReportedWidth`); the bounds are those of the runs it returns.

    Returns
    -------
    Design

    Raises
    ------
    DesignError
        For an unknown goal, a missing envelope or rival, or parameters that the candidates, the data
        taken and the planned runs together cannot identify.
    """
    if goal not in GOALS:
        raise DesignError(f"goal must be one of {', '.join(GOALS)}; got {goal!r}")
    if runs < 1:
        raise DesignError(f"runs must be at least 1; got {runs}")
    sigma, b, fixed, planned_b = _information(model, candidates, planned)
    n, p = b.shape
    if goal != "discriminate":
        _check_identifiable(model, fixed + b.T @ b)
    scale = _parameter_scale(b, fixed, runs)
    problem = _Problem(goal, runs, b * scale, fixed * np.outer(scale, scale) / runs, scale=scale)
    taken = planned if planned_b.shape[0] else None
    if goal == "predict":
        if envelope is None or not _count(envelope):
            raise DesignError("goal predict needs an envelope: the points where the model will be used")
        c = np.asarray(model.sensitivities(envelope), dtype=float).reshape(-1, p) * scale
        problem.envelope = c.T @ c / c.shape[0]
        for rival in rivals:  # model-robust: the rivals' envelope variances count too
            hedge = _hedge(model, rival, candidates, envelope, taken, sigma, runs)
            if hedge is not None:
                problem.hedges.append(hedge)
    if goal == "discriminate":
        if not rivals:
            raise DesignError("goal discriminate needs at least one rival model")
        size = _add_rivals(problem, model, rivals, candidates, taken, sigma)
    weights, solver = _solve(problem)
    _scores, continuous_bound = _sensitivity_and_bound(problem, weights)
    support = np.flatnonzero(weights >= _SUPPORT * weights.max())
    counts = np.zeros(n, dtype=int)
    counts[support] = efficient_rounding(weights[support], runs)
    if polish:
        counts = _polish(problem, counts)
    counts = counts if exchange is None else _exchanged(exchange, counts)
    exact = counts / runs
    rounding = min(_efficiency(problem, _value(problem, weights), _value(problem, exact)), 1.0)
    _scores, exact_bound = _sensitivity_and_bound(problem, exact)
    bound = float(np.clip(max(exact_bound, continuous_bound * rounding), 0.0, 1.0))
    information = (fixed + (b * counts[:, None]).T @ b) if p else np.zeros((0, 0))
    if goal == "parameters":
        criterion = float(np.linalg.slogdet(information)[1])
    elif goal == "predict":
        c = np.asarray(model.sensitivities(envelope), dtype=float).reshape(-1, p)
        criterion = float(np.mean(np.einsum("ij,jk,ik->i", c, np.linalg.inv(information), c)))
    else:
        criterion = 0.0
    separation = None
    if goal == "discriminate":
        size_back = runs * size
        separation = np.array([_schur_last(problem.rival_matrix(k, exact))[0] * size_back
                               for k in range(len(problem.rival_rows))])
        criterion = float(separation.min())
    return Design(goal, counts, weights, criterion, bound, continuous_bound, rounding, separation,
                  information, solver)


def _parameter_scale(b: np.ndarray, fixed: np.ndarray, runs: int) -> np.ndarray:
    """Each parameter's scale for the solver: 1 / the root mean square of its column of ``b`` (every
    column then near 1: the solver's conditioning; D efficiencies, I and T criteria do not depend on it).

    A parameter no candidate moves (a run-in's scale with its cycles held at 0) is scaled by what the data
    taken (``fixed``, the information) hold of it per run instead: 1 / its tiny spread would overflow the
    prior information to inf.
    """
    if not b.shape[1]:
        return np.ones(0)
    spread = np.sqrt(np.mean(np.square(b), axis=0))
    held = np.sqrt(np.clip(np.diag(fixed), 0.0, None) / runs)
    reference = np.where(spread > _NEGLIGIBLE_SENSITIVITY * held, spread, held)
    return 1.0 / np.maximum(reference, 1e-300)


def _exchanged(exchange: Callable[[np.ndarray], np.ndarray], counts: np.ndarray) -> np.ndarray:
    """The runs a caller's exchange returns (:func:`plan`), checked: as many, per candidate."""
    moved = np.asarray(exchange(counts), dtype=int)
    if moved.shape != counts.shape or int(moved.sum()) != int(counts.sum()) or np.any(moved < 0):
        raise ValueError("exchange must return non-negative counts per candidate summing to the runs")
    return moved


def _information(model: DesignModel, candidates: Mapping[str, np.ndarray],
                 planned: Mapping[str, np.ndarray] | None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A measurement's scatter at the candidates, their sensitivities in its units (rows), the information
    held before any run (the prior's and the planned runs') and the planned runs' scaled sensitivities."""
    n = _count(candidates)
    if n < 1:
        raise DesignError("there are no candidate points")
    sigma = np.broadcast_to(np.asarray(model.scatter_sd(candidates), dtype=float), (n,))
    if not np.all(np.isfinite(sigma) & (sigma > 0)):
        raise DesignError("the scatter's standard deviation must be positive and finite at every candidate")
    g = np.asarray(model.sensitivities(candidates), dtype=float).reshape(n, -1)
    p = g.shape[1]
    prior = model.prior_information()
    fixed = np.zeros((p, p)) if prior is None else np.asarray(prior, dtype=float).copy()
    planned_b = np.zeros((0, p))
    if planned is not None and _count(planned):
        planned_sigma = np.asarray(model.scatter_sd(planned), dtype=float)
        planned_g = np.asarray(model.sensitivities(planned), dtype=float).reshape(-1, p)
        planned_b = planned_g / planned_sigma[:, None]
        fixed = fixed + planned_b.T @ planned_b
    return sigma, g / sigma[:, None], fixed, planned_b


def check_identifiable(model: DesignModel, candidates: Mapping[str, np.ndarray],
                       planned: Mapping[str, np.ndarray] | None = None) -> None:
    """Refuse, before any design work, parameters that every candidate measured once, the data taken (the
    model's prior information) and the planned runs together cannot identify: :func:`plan`'s refusal for
    the goals ``parameters`` and ``predict``, for a request's submit.

    Raises
    ------
    DesignError
        Naming the combination of parameters no run moves.
    """
    _, b, fixed, _ = _information(model, candidates, planned)
    total = fixed + b.T @ b
    if np.all(np.isfinite(total)):  # else the design says where the model has no finite mu
        _check_identifiable(model, total)


def _check_identifiable(model: DesignModel, total: np.ndarray) -> None:
    """Raise :class:`DesignError` when the information ``total`` (data taken, planned runs and every
    candidate once) cannot identify the model's parameters."""
    if total.shape[0] == 0:
        raise DesignError("the model has no parameters to design for")
    # Judged on the correlation form of the information: parameters in units of very different
    # size (a drift's coefficient beside a friction coefficient) must not look singular.
    diagonal = np.sqrt(np.clip(np.diag(total), 1e-300, None))
    eigen, vectors = np.linalg.eigh((total + total.T) / 2 / np.outer(diagonal, diagonal))
    if eigen[0] <= _SINGULAR * max(eigen[-1], 1e-300):
        worst = vectors[:, 0]
        names = [f"{c:+.2f} {name}" for c, name in zip(worst, model.parameter_names, strict=True)
                 if abs(c) > 0.1]
        raise DesignError(
            "the candidate points cannot identify the parameters: no run over the space moves "
            f"the combination {' '.join(names)}; widen the space or fix one of them"
        )


def _hedge(model: DesignModel, rival: DesignModel, candidates, envelope, planned, sigma: np.ndarray,
           runs: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """A rival's scaled sensitivities, prior information and envelope moment for the model-robust
    ``predict`` criterion, or None for a rival the space cannot identify (``planned``: runs already
    planned, or None)."""
    n = sigma.size
    g_r = np.asarray(rival.sensitivities(candidates), dtype=float).reshape(n, -1) / sigma[:, None]
    prior_r = rival.prior_information()
    q = g_r.shape[1]
    fixed_r = np.zeros((q, q)) if prior_r is None else np.asarray(prior_r, dtype=float).copy()
    if planned is not None:
        planned_sigma = np.asarray(model.scatter_sd(planned), dtype=float)
        planned_r = np.asarray(rival.sensitivities(planned), dtype=float).reshape(-1, q)
        planned_r = planned_r / planned_sigma[:, None]
        fixed_r = fixed_r + planned_r.T @ planned_r
    c_r = np.asarray(rival.sensitivities(envelope), dtype=float).reshape(-1, q)
    # The criterion is invariant to a rescaling of the parameters; each is scaled by what it moves
    # (the candidates, the envelope, or its prior information) so that the solver sees numbers
    # near 1, and one that moves nothing and has no information is left out (it cannot matter).
    reference = np.maximum.reduce([np.sqrt(np.mean(np.square(g_r), axis=0)),
                                   np.sqrt(np.mean(np.square(c_r), axis=0)),
                                   np.sqrt(np.clip(np.diag(fixed_r), 0.0, None) / runs)])
    used = reference > 0
    g_r, c_r, fixed_r = g_r[:, used], c_r[:, used], fixed_r[np.ix_(used, used)]
    q = int(used.sum())
    scale_r = 1.0 / reference[used]
    total = fixed_r + g_r.T @ g_r
    diagonal = np.sqrt(np.clip(np.diag(total), 1e-300, None))
    if q == 0 or np.linalg.eigvalsh(total / np.outer(diagonal, diagonal))[0] <= _SINGULAR:
        return None  # a rival the space cannot identify has no finite envelope variance to hedge
    c_r = c_r * scale_r
    return (g_r * scale_r, fixed_r * np.outer(scale_r, scale_r) / runs, c_r.T @ c_r / c_r.shape[0])


def _add_rivals(problem: _Problem, model: DesignModel, rivals: Sequence[DesignModel], candidates, planned,
                sigma: np.ndarray) -> float:
    """Add every rival's scaled rows and prior information to a ``discriminate`` problem; the common
    scale of the differences (their largest mean square) the rows were divided by."""
    runs = problem.runs
    for rival in rivals:
        rows = _rival_arrays(model, rival, candidates, sigma)
        q = rows.shape[1] - 1
        spread = np.sqrt(np.mean(np.square(rows[:, :q]), axis=0))
        fixed_k = _rival_prior(rival, q)
        if planned is not None:
            planned_sigma = np.asarray(model.scatter_sd(planned), dtype=float)
            planned_rows = _rival_arrays(model, rival, planned, planned_sigma)
            fixed_k = fixed_k + planned_rows.T @ planned_rows
        # A rival parameter no candidate point moves cannot bring the rival closer to the model
        # anywhere the lab can measure: its column is left out (its scale would be unbounded).
        largest = max(float(np.max(spread, initial=0.0)), 1e-300)
        keep = np.append(spread > _NEGLIGIBLE_SENSITIVITY * largest, True)
        rows, fixed_k, spread = rows[:, keep], fixed_k[np.ix_(keep, keep)], spread[keep[:-1]]
        rival_scale = np.append(1.0 / spread, 1.0)
        problem.rival_rows.append(rows * rival_scale)
        problem.rival_fixed.append(fixed_k * np.outer(rival_scale, rival_scale) / runs)
    # One common scale of the differences keeps t near 1 for the solver.
    size = max(float(np.mean(np.square(r[:, -1]))) for r in problem.rival_rows)
    if size <= 0:
        raise DesignError("the rivals predict the same response as the model at every candidate point")
    for k in range(len(problem.rival_rows)):
        problem.rival_rows[k][:, -1] /= np.sqrt(size)
        problem.rival_fixed[k][:, -1] /= np.sqrt(size)
        problem.rival_fixed[k][-1, :] /= np.sqrt(size)
    return size
