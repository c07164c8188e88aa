"""Bounded least squares on log μ of the declared model, optionally with one added effect.

The residual of a measurement is ``log(mu_model) - log(mu_measured)``, divided
by the standard deviation of ``log(mu_measured)`` (``mu_measured_std /
mu_measured``) when the data give it. :func:`fit` adjusts the declared physics
parameters named in ``fit_parameters`` (bounds from :data:`physics.PARAMETERS`)
jointly with the parameters of an :class:`EffectChoice`, and reports their
standard deviations from the Jacobian: covariance = s² (JᵀJ)⁻¹ with
s² = Σ r² / (n - p).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

import physics
from physics.effects import EFFECTS, Effect

from .data import Dataset

__all__ = ["EffectChoice", "FitResult", "fit", "predict_mu", "kfold_indices", "prediction_errors",
           "check_fit_parameters"]

# A bound that the physics excludes is approached to within this relative margin.
_EXCLUSIVE_MARGIN = 1e-9
# Weighted log residual standing in for a non-finite model output during the fit.
_REJECTED_RESIDUAL = 1e3


@dataclass(frozen=True)
class EffectChoice:
    """An effect of :data:`physics.effects.EFFECTS` bound to its driver columns.

    Attributes
    ----------
    name : str
        Effect name.
    drivers : tuple of str
        Driving columns, main driver first.
    constants : dict
        Constants fixed from the whole data set (centre and scale of a generic term).
    """

    name: str
    drivers: tuple[str, ...]
    constants: dict[str, float] = field(default_factory=dict)

    @property
    def effect(self) -> Effect:
        """The :class:`physics.effects.Effect`."""
        return EFFECTS[self.name]


@dataclass(frozen=True)
class FitResult:
    """Fitted values of the declared parameters and of the effect's.

    Attributes
    ----------
    declared : dict of str to float
        Fitted physics parameters, in their units.
    declared_std : dict of str to float
        Their standard deviations, same units.
    effect : EffectChoice or None
        The effect fitted with them.
    effect_parameters : dict of str to float
        Its fitted parameters, in their units.
    effect_std : dict of str to float
        Their standard deviations.
    rms_residual : float
        Root mean square of the (weighted) log residual at the optimum. [1]
    success : bool
        Whether the optimizer reported convergence.
    """

    declared: dict[str, float]
    declared_std: dict[str, float]
    effect: EffectChoice | None
    effect_parameters: dict[str, float]
    effect_std: dict[str, float]
    rms_residual: float
    success: bool


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


def _rows_of(values, rows):
    arr = np.asarray(values)
    return arr if rows is None or arr.ndim == 0 else arr[rows]


def predict_mu(dataset: Dataset, declared: Mapping[str, float], effect: EffectChoice | None = None,
               effect_parameters: Mapping[str, float] | None = None, rows=None,
               base_mu: np.ndarray | None = None, convention: str = physics.DEFAULT_CONVENTION) -> np.ndarray:
    """μ of the declared model (with ``declared`` values) and the effect at the data's rows.

    Parameters
    ----------
    dataset : Dataset
        Inputs per row.
    declared : mapping of str to float
        Values of fitted physics parameters, in their units.
    effect : EffectChoice, optional
        Effect to add.
    effect_parameters : mapping, optional
        Its parameters.
    rows : array of int, optional
        Row indices (default: all).
    base_mu : numpy.ndarray, optional
        μ of the physics at every row, used instead of evaluating it (``declared`` is then ignored). [1]
    convention : str
        See :data:`physics.CONVENTIONS`.

    Returns
    -------
    numpy.ndarray
        μ per selected row. [1]
    """
    inputs = {k: _rows_of(v, rows) for k, v in dataset.inputs().items()}
    if base_mu is None:
        mu = physics.evaluate(convention=convention, **inputs, **declared).mu
    else:
        mu = _rows_of(base_mu, rows)
    if effect is None:
        return np.asarray(mu, dtype=float)
    columns = {**physics.defaults(), **inputs, **declared,
               **{k: _rows_of(v, rows) for k, v in dataset.conditions.items()}}
    return effect.effect.apply(mu, columns, effect_parameters or {}, effect.drivers, effect.constants)


def _log_weights(dataset: Dataset, rows) -> np.ndarray:
    if dataset.mu_measured_std is None:
        return np.ones_like(_rows_of(dataset.mu_measured, rows))
    return _rows_of(dataset.mu_measured / dataset.mu_measured_std, rows)


def fit(dataset: Dataset, fit_parameters: Sequence[str], effect: EffectChoice | None = None, rows=None,
        start: Mapping[str, float] | None = None, base_mu: np.ndarray | None = None,
        convention: str = physics.DEFAULT_CONVENTION) -> FitResult:
    """Fit the declared parameters and the effect's by bounded least squares on log μ.

    Parameters
    ----------
    dataset : Dataset
        Measurements.
    fit_parameters : sequence of str
        Physics parameters to fit (see :func:`check_fit_parameters`); ignored with ``base_mu``.
    effect : EffectChoice, optional
        Effect fitted jointly.
    rows : array of int, optional
        Training rows (default: all).
    start : mapping, optional
        Initial values of any fitted parameter, declared or effect (default: the physics default and
        the effect's data-based initial guess).
    base_mu : numpy.ndarray, optional
        Frozen μ of the physics at every row: only the effect's parameters are fitted. [1]
    convention : str
        See :data:`physics.CONVENTIONS`.

    Returns
    -------
    FitResult

    Raises
    ------
    ValueError
        For parameters that cannot be fitted or an effect whose driver values are outside its domain.
    """
    declared = [] if base_mu is not None else check_fit_parameters(dataset, fit_parameters)
    start = dict(start or {})
    x0 = [float(start.get(n, physics.PARAMETERS[n].default)) for n in declared]
    bounds = [_bounds(n) for n in declared]
    effect_names: list[str] = []
    if effect is not None:
        spec = effect.effect
        effect_names = spec.parameter_names
        columns = {**physics.defaults(), **dataset.inputs(), **dataset.conditions}
        if not spec.accepts(columns, effect.drivers):
            raise ValueError(f"{effect.drivers[0]} is outside the domain of effect {effect.name}")
        mu0 = predict_mu(dataset, dict(zip(declared, x0, strict=True)), base_mu=base_mu,
                         convention=convention)
        guesses = spec.initial(mu0, columns, effect.drivers, effect.constants)
        x0 += [float(start.get(n, g)) for n, g in zip(effect_names, guesses, strict=True)]
        bounds += [(p.minimum, p.maximum) for p in spec.parameters]
    lo = np.array([b[0] for b in bounds], dtype=float)
    hi = np.array([b[1] for b in bounds], dtype=float)
    x0 = np.clip(np.array(x0, dtype=float), lo, hi)
    log_measured = np.log(_rows_of(dataset.mu_measured, rows))
    weights = _log_weights(dataset, rows)
    n_declared = len(declared)

    def residual(x):
        # A trial step may overflow an exponential term or drive an additive one negative; a large
        # finite residual makes the optimizer reject the step.
        with np.errstate(all="ignore"):
            mu = predict_mu(dataset, dict(zip(declared, x[:n_declared], strict=True)), effect,
                            dict(zip(effect_names, x[n_declared:], strict=True)), rows, base_mu, convention)
            r = weights * (np.log(np.maximum(mu, 1e-300)) - log_measured)
        return np.where(np.isfinite(r), r, _REJECTED_RESIDUAL)

    if x0.size == 0:
        r = residual(x0)
        return FitResult({}, {}, None, {}, {}, float(np.sqrt(np.mean(r * r))), True)
    result = least_squares(residual, x0, bounds=(lo, hi), x_scale="jac", method="trf")
    r, jac = result.fun, result.jac
    dof = max(r.size - x0.size, 1)
    s2 = float(r @ r) / dof
    cov = s2 * np.linalg.pinv(jac.T @ jac)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    names = declared + effect_names
    values = dict(zip(names, result.x.tolist(), strict=True))
    stds = dict(zip(names, std.tolist(), strict=True))
    return FitResult(
        {n: values[n] for n in declared}, {n: stds[n] for n in declared}, effect,
        {n: values[n] for n in effect_names}, {n: stds[n] for n in effect_names},
        float(np.sqrt(np.mean(r * r))), bool(result.success),
    )


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
