"""Step 3 of the pipeline: robust bounded least squares on log μ of the declared model plus terms.

The residual of a measurement is ``log(mu_model) - log(mu_measured)``, divided
by the standard deviation of ``log(mu_measured)`` (``mu_measured_std /
mu_measured``) when the data give it. :func:`fit` adjusts the declared physics
parameters named in ``fit_parameters`` (bounds from :data:`physics.PARAMETERS`)
jointly with the parameters of the terms (:mod:`calibrate.candidates`).

The loss is Huber's with the threshold 1.345 ``scale`` (95 % efficient on
Gaussian noise), ``scale`` a robust standard deviation of the residual
(:func:`robust_scale`): a gross outlier pulls with a bounded force instead of
its square, so a few percent of them neither bias the parameters nor hide an
effect. The covariance of the estimates is the sandwich of the M-estimator,
A⁻¹ B A⁻¹ · n / (n - p), with A = Σ ψ'(r) JᵀJ and B = Σ ψ(r)² JᵀJ: it stays
consistent when the residual's spread varies from row to row, where the
classical s² (JᵀJ)⁻¹ does not.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from microbearing import physics

from .candidates import FrozenBase, Term, mu_of
from .censored import censored_residual, measured_rows
from .data import Dataset

__all__ = [
    "FitResult",
    "HUBER_K",
    "Z95",
    "UNIDENTIFIED_RCOND",
    "check_fit_parameters",
    "fit",
    "huber_loss",
    "kfold_indices",
    "level_factor",
    "predict_mu",
    "prediction_errors",
    "robust_scale",
    "weighted_log_residual",
]

#: Huber threshold in robust standard deviations: 95 % efficiency on Gaussian residuals. [1]
HUBER_K = 1.345
#: The standard normal quantile of a two-sided 95 % interval (scipy.stats.norm.ppf(0.975)), declared once in
#: the package: the unit of an edge trend in the allowance, the plans' fast half-width
#: (calibrate.experiments), a parameter's interval in the words (calibrate.prose), the measurement system's
#: steps and drifts, the groups' and the parameter-shift margins read it here. [1]
Z95 = 1.959963984540054
# A bound that the physics excludes is approached to within this relative margin.
_EXCLUSIVE_MARGIN = 1e-9
# Weighted log residual standing in for a non-finite model output during the fit.
_REJECTED_RESIDUAL = 1e3
# Relative step of the finite-difference Jacobian used by the sandwich covariance.
_JACOBIAN_STEP = 1e-6
#: A direction of the relative Jacobian (each column times its value) whose singular value is below this
#: share of the largest is not identified by the data. [1]
UNIDENTIFIED_RCOND = 1e-4
# A value loads on an unidentified direction when its share of that singular vector exceeds this. [1]
_LOADING = 0.1
# Largest relative shift (log scale) of a declared parameter in a first-order screening fit.
_MAX_SHIFT = 2.0
# Tolerances of a fit: tight for the reported ones, loose for ranking candidates. Not looser than 1e-5:
# at 1e-4 a fold's refit could stop short (adhesion 0.083 for 0.115 in one fold of a 200-row set weighted
# by a scatter of 1-12 %), and its rows' held-out loss then ranked a correct term below a wrong one.
_TOLERANCE = {True: 1e-8, False: 1e-5}


@dataclass(frozen=True)
class FitResult:
    """Fitted declared parameters and term parameters, with their sandwich covariance.

    Attributes
    ----------
    declared : dict of str to float
        Fitted physics parameters, in their units.
    terms : tuple of Term
        The terms fitted with them, in order.
    term_values : list of list of float
        Each term's fitted parameters, in the order of its ``parameter_names``.
    names : list of str
        Labels of every fitted value in covariance order: declared names, then ``"<term label>:
        <parameter>"``.
    values : numpy.ndarray
        Every fitted value in that order.
    covariance : numpy.ndarray
        Sandwich covariance of ``values``.
    scale : float
        Robust standard deviation of the (weighted) log residual the Huber loss used. [1]
    residual : numpy.ndarray
        Weighted log residual ``log(mu_model / mu_measured)`` of the fitted rows. [1]
    at_bound : list of str
        Names (as in ``names``) of the values that ended on a bound.
    success : bool
        Whether the optimizer reported convergence.
    unidentified : list of str
        Names of the values the data do not identify: they load on a direction of the relative Jacobian
        whose singular value is below :data:`UNIDENTIFIED_RCOND` of the largest (a modulus that trades
        off exactly against another parameter). The pseudo-inverse gives them a tiny variance along that
        direction; :attr:`std` reports at least their own magnitude instead.
    group_levels : numpy.ndarray or None
        With :attr:`Dataset.search_groups`: each group code's level of log μ the fit profiled out [1]
        (0 for a code without fitted rows), the row-weighted levels summing to zero
        (:func:`level_factor`); None without.
    """

    declared: dict[str, float]
    terms: tuple[Term, ...]
    term_values: list[list[float]]
    names: list[str]
    values: np.ndarray = field(repr=False)
    covariance: np.ndarray = field(repr=False)
    scale: float
    residual: np.ndarray = field(repr=False)
    at_bound: list[str]
    success: bool
    unidentified: list[str] = field(default_factory=list)
    group_levels: np.ndarray | None = field(default=None, repr=False)

    @property
    def std(self) -> np.ndarray:
        """Standard deviation of every value, in ``names`` order: the sandwich's, and at least the value's
        own magnitude for an :attr:`unidentified` one (the data do not bound it)."""
        std = np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))
        wide = np.array([n in self.unidentified for n in self.names], dtype=bool)
        return np.where(wide, np.maximum(std, np.abs(self.values)), std)

    @property
    def declared_std(self) -> dict[str, float]:
        """Standard deviation of each declared parameter, in its unit."""
        return dict(zip(self.declared, self.std[: len(self.declared)].tolist(), strict=False))

    def term_std(self) -> list[list[float]]:
        """Standard deviations of each term's parameters, like :attr:`term_values`."""
        out, i = [], len(self.declared)
        for values in self.term_values:
            out.append(self.std[i : i + len(values)].tolist())
            i += len(values)
        return out


def check_fit_parameters(dataset: Dataset, fit_parameters: Sequence[str]) -> list[str]:
    """Validate the names of the parameters to fit.

    Parameters
    ----------
    dataset : Dataset
        The data (its columns and fixed values cannot be fitted).
    fit_parameters : sequence of str
        Names of :data:`physics.PARAMETERS` of kind float.

    Returns
    -------
    list of str
        The names, in order, without repeats.

    Raises
    ------
    ValueError
        Naming the offending parameter.
    """
    names = list(dict.fromkeys(fit_parameters))
    for name in names:
        spec = physics.PARAMETERS.get(name)
        if spec is None or spec.kind != "float" or spec.required:
            fittable = [n for n, p in physics.PARAMETERS.items() if p.kind == "float" and not p.required]
            raise ValueError(f"fit_parameters: {name!r} cannot be fitted; allowed: {', '.join(fittable)}")
        if name in dataset.physics_columns or name in dataset.fixed:
            raise ValueError(f"fit_parameters: {name!r} is given by the data or fixed; it cannot be fitted")
    return names


def _bounds(name: str) -> tuple[float, float]:
    spec = physics.PARAMETERS[name]
    lo = -np.inf if spec.minimum is None else float(spec.minimum)
    hi = np.inf if spec.maximum is None else float(spec.maximum)
    if spec.exclusive_minimum:
        lo += _EXCLUSIVE_MARGIN * max(abs(lo), abs(float(spec.default)))
    if spec.exclusive_maximum:
        hi -= _EXCLUSIVE_MARGIN * max(abs(hi), 1.0)
    return lo, hi


def predict_mu(
    dataset: Dataset,
    declared: Mapping[str, float],
    terms: Sequence[Term] = (),
    term_values: Sequence[Sequence[float]] = (),
    rows=None,
    base: FrozenBase | None = None,
    convention: str = physics.DEFAULT_CONVENTION,
) -> np.ndarray:
    """μ of the declared model (with ``declared`` values) and terms at the data's rows.

    Parameters
    ----------
    dataset : Dataset
        Inputs per row.
    declared : mapping of str to float
        Values of fitted physics parameters, in their units.
    terms : sequence of Term
        Terms to add, in order.
    term_values : sequence of sequence of float
        Their parameters.
    rows : array of int, optional
        Row indices (default: all).
    base : FrozenBase, optional
        The frozen current model at every row, used instead of the physics (``declared`` is then
        ignored).
    convention : str
        See :data:`physics.CONVENTIONS`.

    Returns
    -------
    numpy.ndarray
        μ per selected row. [1]
    """
    return mu_of(
        {**dataset.inputs(), **declared}, dataset.conditions, terms, term_values, base, rows, convention
    )


def weighted_log_residual(dataset: Dataset, mu: np.ndarray, rows=None) -> np.ndarray:
    """``log(mu / mu_measured)``, over the log noise ``mu_measured_std / mu_measured`` when given; a row at
    a sensor's clip (``dataset.censored``) takes its censored-likelihood residual
    (:func:`calibrate.censored.censored_residual`). [1]"""
    measured = dataset.mu_measured if rows is None else dataset.mu_measured[rows]
    r = np.log(np.maximum(mu, 1e-300)) - np.log(measured)
    if dataset.censored is not None:
        r = censored_residual(r, dataset.censored if rows is None else dataset.censored[rows],
                              dataset.censor_scale)
    if dataset.mu_measured_std is None:
        return r
    std = dataset.mu_measured_std if rows is None else dataset.mu_measured_std[rows]
    return r * measured / std


def robust_scale(residual) -> float:
    """Robust standard deviation: 1.4826 × the median absolute deviation from the median.

    Examples
    --------
    >>> round(robust_scale([-1.0, 0.0, 1.0, 100.0]), 4)
    1.4826
    """
    r = np.asarray(residual, dtype=float)
    return float(1.4826 * np.median(np.abs(r - np.median(r)))) if r.size else 0.0


def huber_loss(residual, scale: float) -> np.ndarray:
    """Huber's loss of each residual, threshold :data:`HUBER_K` ``scale``: r² inside, 2k|r| - k² outside.

    Examples
    --------
    >>> huber_loss([0.5, 3.0], 1.0).round(4).tolist()
    [0.25, 6.261]
    """
    r = np.abs(np.asarray(residual, dtype=float))
    k = HUBER_K * scale
    return np.where(r <= k, r * r, 2.0 * k * r - k * k)


def fit(
    dataset: Dataset,
    fit_parameters: Sequence[str],
    terms: Sequence[Term] = (),
    rows=None,
    start: Mapping[str, float] | None = None,
    start_terms: Sequence[Sequence[float]] | None = None,
    base: FrozenBase | None = None,
    scale: float | None = None,
    precise: bool = True,
    convention: str = physics.DEFAULT_CONVENTION,
) -> FitResult:
    """Fit the declared parameters and the terms' by robust bounded least squares on log μ.

    Parameters
    ----------
    dataset : Dataset
        Measurements.
    fit_parameters : sequence of str
        Physics parameters to fit (see :func:`check_fit_parameters`); ignored with ``base``, whose
        ``declared`` parameters are shifted to first order instead (``declared`` of the result then
        holds their relative shifts, log scale).
    terms : sequence of Term
        Terms fitted jointly (with ``base``: only the new terms, the base holds the others).
    rows : array of int, optional
        Training rows (default: all).
    start : mapping, optional
        Initial declared values (default: the physics defaults).
    start_terms : sequence of sequence of float, optional
        Initial values of the first terms (e.g. the previous step's fit); the others start from
        their data-based guess.
    base : FrozenBase, optional
        Frozen current model at every row: only the terms' parameters are fitted.
    scale : float, optional
        Robust standard deviation of the weighted log residual for the Huber loss; by default it is
        estimated from the residual at the start, the fit run, re-estimated and the fit refined.
    precise : bool
        Whether to fit to tight tolerances and compute the sandwich covariance (False: a looser fit
        without covariance, enough to rank candidates; ``covariance`` is then all NaN).
    convention : str
        See :data:`physics.CONVENTIONS`.

    Returns
    -------
    FitResult

    Raises
    ------
    ValueError
        For parameters that cannot be fitted.
    """
    unknowns = _unknowns(dataset, fit_parameters, terms, start, start_terms, base, convention)
    x0, lo, hi = unknowns.x0, unknowns.lo, unknowns.hi

    def residual(x, profiled=True):
        # A trial step may overflow an exponential term or drive an additive one negative; a large
        # finite residual makes the optimizer reject the step.
        with np.errstate(all="ignore"):
            values, term_values = unknowns.split(x)
            try:
                if base is None:
                    mu = predict_mu(dataset, values, terms, term_values, rows, convention=convention)
                else:
                    mu = predict_mu(
                        dataset, {}, terms, term_values, rows, base.shifted(list(values.values())), convention
                    )
            except ValueError:  # a trial drift outside a physics input's range
                return np.full(np.size(dataset.mu_measured if rows is None else rows), _REJECTED_RESIDUAL)
            r = weighted_log_residual(dataset, mu, rows)
        if profiled and groups is not None and np.all(np.isfinite(r)):
            return r + weights * groups.levels(r, weights)[groups.codes]
        return np.where(np.isfinite(r), r, _REJECTED_RESIDUAL)

    groups, weights = _Groups.of(dataset, rows), _weights(dataset, rows)  # levels profiled out with groups
    r = residual(x0)
    # The scale is the measured rows' (a clipped row's residual is not a value's).
    measured = measured_rows(dataset.censored, dataset.n_points)
    measured = measured if rows is None else measured[rows]
    if x0.size == 0:
        s = scale if scale is not None else max(robust_scale(r[measured]), 1e-12)
        return FitResult({}, (), [], [], x0, np.zeros((0, 0)), s, r, [], True,
                         group_levels=_levels_at(groups, residual, x0, weights))
    passes = [scale] if scale is not None else [None, None]
    x = x0
    for given in passes:
        s = given if given is not None else max(robust_scale(r[measured]), 1e-12)
        tol = _TOLERANCE[precise]
        result = least_squares(
            residual,
            x,
            bounds=(lo, hi),
            x_scale="jac",
            method="trf",
            loss="huber",
            f_scale=HUBER_K * s,
            ftol=tol,
            xtol=tol,
        )
        x, r = result.x, result.fun
    cov, weak = (_sandwich(residual, x, r, lo, hi, HUBER_K * s) if precise
                 else (np.full((x.size, x.size), np.nan), np.zeros(x.size, dtype=bool)))
    values, term_values = unknowns.split(x)
    # On a bound within a millionth of the value's own scale (its start when it ends near zero).
    scale_of = 1e-6 * np.maximum(np.abs(x), np.abs(x0))
    on_bound = (np.abs(x - lo) <= scale_of) | (np.abs(hi - x) <= scale_of)
    names = unknowns.names
    return FitResult(
        values,
        tuple(terms),
        term_values,
        names,
        x,
        cov,
        s,
        r,
        [n for n, b in zip(names, on_bound, strict=True) if b],
        bool(result.success),
        [n for n, w in zip(names, weak, strict=True) if w],
        _levels_at(groups, residual, x, weights),
    )


@dataclass(frozen=True)
class _Groups:
    """The group codes of a fit's rows, for the levels the fit profiles out (see :func:`level_factor`)."""

    codes: np.ndarray
    n_codes: int

    @staticmethod
    def of(dataset: Dataset, rows) -> _Groups | None:
        if dataset.search_groups is None:
            return None
        codes = np.asarray(dataset.search_groups if rows is None else dataset.search_groups[rows], dtype=int)
        return _Groups(codes, int(np.max(dataset.search_groups, initial=-1)) + 1)

    def levels(self, r: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """Each code's level of log μ on the weighted residual ``r = w log(mu / mu_measured)``: the weighted
        least-squares level of its rows, less the rows' overall one (so the declared parameters keep the
        population's level); 0 for a code without rows. [1]"""
        num = np.bincount(self.codes, weights * r, self.n_codes)
        den = np.bincount(self.codes, weights * weights, self.n_codes)
        total = float(den.sum())
        overall = float(num.sum()) / total if total > 0 else 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(den > 0, overall - num / den, 0.0)


def _weights(dataset: Dataset, rows) -> np.ndarray:
    """Each row's weight ``mu_measured / mu_measured_std`` in the weighted log residual (1 without). [1]"""
    measured = dataset.mu_measured if rows is None else dataset.mu_measured[rows]
    if dataset.mu_measured_std is None:
        return np.ones_like(measured, dtype=float)
    return measured / (dataset.mu_measured_std if rows is None else dataset.mu_measured_std[rows])


def _levels_at(groups: _Groups | None, residual, x, weights) -> np.ndarray | None:
    """The group levels the fit's residual profiled out at ``x``, or None without groups."""
    if groups is None:
        return None
    r = residual(x, False)
    return groups.levels(r, weights) if np.all(np.isfinite(r)) else np.zeros(groups.n_codes)


def level_factor(dataset: Dataset, result: FitResult, rows=None) -> np.ndarray | float:
    """The factor ``exp(level)`` of each row's group on μ (:attr:`FitResult.group_levels`), 1 without groups:
    a fit on :attr:`Dataset.search_groups` predicts ``mu * level_factor``. A held-out row takes the level
    of its group estimated on the training rows (1 for a group that has none there). [1]"""
    if dataset.search_groups is None or result.group_levels is None:
        return 1.0
    codes = dataset.search_groups if rows is None else dataset.search_groups[rows]
    return np.exp(result.group_levels[np.asarray(codes, dtype=int)])


@dataclass(frozen=True)
class _Unknowns:
    """The values one fit adjusts: the declared parameters' names, then every term's parameters.

    Attributes
    ----------
    declared : list of str
        Declared parameters (with a frozen base: their relative shifts, log scale).
    x0, lo, hi : numpy.ndarray
        Start (inside the bounds) and bounds of every value, declared first.
    names : list of str
        Label of every value (``"<term label>: <parameter>"`` for a term's).
    sizes : list of int
        Parameters of each term. [1]
    """

    declared: list[str]
    x0: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    names: list[str]
    sizes: list[int]

    def split(self, x) -> tuple[dict[str, float], list[list[float]]]:
        """The declared values by name and each term's values, from one vector of values."""
        values, i = [], len(self.declared)
        for size in self.sizes:
            values.append(list(x[i : i + size]))
            i += size
        return dict(zip(self.declared, x[: len(self.declared)], strict=True)), values


def _unknowns(dataset, fit_parameters, terms, start, start_terms, base, convention) -> _Unknowns:
    """The values :func:`fit` adjusts, with their start and bounds (its parameters of the same names)."""
    if base is None:
        declared = check_fit_parameters(dataset, fit_parameters)
        start = dict(start or {})
        x0 = [float(start.get(n, dataset.fixed.get(n, physics.PARAMETERS[n].default))) for n in declared]
        bounds = [_bounds(n) for n in declared]
    else:
        declared = list(base.declared)
        x0, bounds = [0.0] * len(declared), [(-_MAX_SHIFT, _MAX_SHIFT)] * len(declared)
    names = list(declared)
    sizes = []
    start_terms = list(start_terms or [])
    if terms:
        mu0 = (
            base.mu
            if base is not None
            else predict_mu(
                dataset,
                dict(zip(declared, x0, strict=True)),
                terms[: len(start_terms)],
                start_terms,
                convention=convention,
            )
        )
        columns = {**physics.defaults(), **dataset.inputs(), **dataset.conditions}
        for i, term in enumerate(terms):
            guess = start_terms[i] if i < len(start_terms) else term.initial(mu0, columns)
            x0 += [float(g) for g in guess]
            bounds += term.bounds()
            names += [f"{term.label}: {n}" for n in term.parameter_names]
            sizes.append(len(term.parameter_names))
    lo = np.array([b[0] for b in bounds], dtype=float)
    hi = np.array([b[1] for b in bounds], dtype=float)
    return _Unknowns(declared, np.clip(np.array(x0, dtype=float), lo, hi), lo, hi, names, sizes)


def _sandwich(residual, x, r, lo, hi, k) -> tuple[np.ndarray, np.ndarray]:
    """Sandwich covariance of the Huber M-estimator from a finite-difference Jacobian at ``x``, and which
    values the data do not identify (see :attr:`FitResult.unidentified`)."""
    jac = np.empty((r.size, x.size))
    for j in range(x.size):
        step = _JACOBIAN_STEP * max(abs(x[j]), 1e-300) if x[j] != 0 else _JACOBIAN_STEP
        if x[j] + step > hi[j]:
            step = -step
        shifted = x.copy()
        shifted[j] = np.clip(x[j] + step, lo[j], hi[j])
        jac[:, j] = (residual(shifted) - r) / (shifted[j] - x[j])
    inside = np.abs(r) <= k
    psi = np.clip(r, -k, k)
    # In relative units (each column times its value): the same covariance in exact arithmetic, but values
    # tens of orders of magnitude apart (an activation energy of 4e4 J/mol beside a meniscus force of 2e-5 N)
    # make J^T J singular to the pseudo-inverse's precision (condition ~1e21), which then gives the large
    # value a variance of ~0 (an activation energy of 44 kJ/mol +/- 6e-9 J/mol); relative, ~1e3.
    unit = np.where(x != 0, np.abs(x), 1.0)
    relative = jac * unit
    bread = np.linalg.pinv(relative[inside].T @ relative[inside])
    meat = (relative * psi[:, None]).T @ (relative * psi[:, None])
    dof = max(r.size - x.size, 1)
    return bread @ meat @ bread * np.outer(unit, unit) * (r.size / dof), _unidentified(relative[inside])


def _unidentified(relative: np.ndarray) -> np.ndarray:
    """Which columns of a relative Jacobian load on a direction it hardly sees (bool per column)."""
    if relative.size == 0 or not np.all(np.isfinite(relative)):
        return np.zeros(relative.shape[1], dtype=bool)
    _, singular, vt = np.linalg.svd(relative, full_matrices=False)
    weak = singular < UNIDENTIFIED_RCOND * max(float(singular[0]), 1e-300)
    return np.any(np.abs(vt[weak]) > _LOADING, axis=0)


def kfold_indices(n_points: int, folds: int, seed: int = 0) -> list[np.ndarray]:
    """Shuffled test-row indices of each fold of a k-fold cross-validation.

    Parameters
    ----------
    n_points : int
        Number of rows. [1]
    folds : int
        Number of folds, 2 <= folds <= n_points. [1]
    seed : int
        Seed of the shuffle.

    Returns
    -------
    list of numpy.ndarray
        ``folds`` disjoint arrays covering ``range(n_points)``.

    Raises
    ------
    ValueError
        For a number of folds outside [2, n_points].

    Examples
    --------
    >>> sorted(np.concatenate(kfold_indices(5, 2)).tolist())
    [0, 1, 2, 3, 4]
    """
    if not 2 <= folds <= n_points:
        raise ValueError(f"folds must be in [2, {n_points}] (the number of rows); got {folds}")
    order = np.random.default_rng(seed).permutation(n_points)
    return [np.sort(part) for part in np.array_split(order, folds)]


def prediction_errors(mu_predicted, mu_measured) -> dict[str, float]:
    """Errors of predicted against measured μ.

    Parameters
    ----------
    mu_predicted, mu_measured : array_like
        μ per measurement. [1]

    Returns
    -------
    dict
        ``rmse`` [1] of μ, ``relative_rmse`` [1] (RMS of log(predicted / measured)),
        ``max_abs_error`` [1] of μ.

    Examples
    --------
    >>> e = prediction_errors([1.0, 2.0], [1.0, 1.0])
    >>> round(e["rmse"], 4), round(e["relative_rmse"], 4), e["max_abs_error"]
    (0.7071, 0.4901, 1.0)
    """
    p = np.asarray(mu_predicted, dtype=float)
    m = np.asarray(mu_measured, dtype=float)
    return {
        "rmse": float(np.sqrt(np.mean(np.square(p - m)))),
        "relative_rmse": float(np.sqrt(np.mean(np.square(np.log(p / m))))),
        "max_abs_error": float(np.max(np.abs(p - m))),
    }
