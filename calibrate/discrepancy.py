"""Gaussian-process discrepancies on the log residual (Kennedy-O'Hagan).

log μ_measured = log μ_model(θ) + δ(x) + ε, with δ a Gaussian process over
every varying data column (standardized) with an anisotropic RBF kernel and a
white-noise term, θ fitted first (a modular, not fully Bayesian, Kennedy-O'Hagan
calibration). Two uses:

* :func:`gp_discrepancy`, the statistician's baseline: a GP on what the
  *declared* model leaves, held out on the same folds as the named effects. A
  named effect close to it explains the discrepancy with a formula and a few
  parameters instead of a black box.
* :func:`residual_gp`, a GP on what the *calibrated* model (declared + chosen
  terms) still leaves. Nested cross-validation decides whether it helps: each
  outer fold's GP is trained on the residual of the model that fold's own
  selection built, and predicts the held-out rows. Only when it beats the terms
  alone by more than noise does it become part of the calibrated model
  (:class:`calibrate.model.CalibratedModel`), whose mean it corrects and whose
  intervals its predictive standard deviation widens.

References
----------
.. [1] M.C. Kennedy, A. O'Hagan, "Bayesian calibration of computer models",
   J. R. Statist. Soc. B 63(3), 425-464 (2001).
.. [2] C.E. Rasmussen, C.K.I. Williams, Gaussian Processes for Machine
   Learning, MIT Press, 2006, ch. 2 (prediction) and ch. 5 (automatic relevance determination).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from scipy import stats

from .data import Dataset
from .fit import prediction_errors
from .select import ModelCV

__all__ = ["GP_HELPS_ALPHA", "gp_discrepancy", "residual_gp", "residual_gp_words"]

#: One-sided level of the paired test by which a GP on the calibrated model's residual must beat the
#: terms alone, held out, to become part of the model. [1]
GP_HELPS_ALPHA = 0.01
# A column across whose data range the fitted GP correlates above exp(-0.5 * 0.1**2) = 0.995 is
# irrelevant to it: the stored GP drops it, so that a prediction need not give it. [1]
_IRRELEVANT_RANGE = 0.1


def _features(dataset: Dataset) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """Varying columns, standardized: names, values, centres and scales."""
    names, columns, centres, scales = [], [], [], []
    for name, values in dataset.columns().items():
        x = np.asarray(values, dtype=float)
        if np.unique(x).size > 1:
            names.append(name)
            centres.append(x.mean())
            scales.append(x.std())
            columns.append((x - x.mean()) / x.std())
    x = np.column_stack(columns) if columns else np.zeros((dataset.n_points, 0))
    return names, x, np.array(centres), np.array(scales)


def _kernel(n_features: int):
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

    return (ConstantKernel(1.0, (1e-4, 1e2)) * RBF(np.ones(n_features), (1e-2, 1e3))
            + WhiteKernel(0.1, (1e-8, 1e1)))


def _fit_gp(x: np.ndarray, target: np.ndarray, kernel, seed: int, optimize: bool = True):
    """A scikit-learn GP regressor fitted to ``target``: hyperparameters by marginal likelihood from
    ``kernel``'s, or ``kernel``'s own when ``optimize`` is false (the GP then only conditions on the rows)."""
    # scikit-learn is imported here, not at module level: it takes seconds to import.
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.gaussian_process import GaussianProcessRegressor
    from threadpoolctl import threadpool_limits

    gp = GaussianProcessRegressor(kernel, normalize_y=True, random_state=seed,
                                  **({} if optimize else {"optimizer": None}))
    # One BLAS thread: the small GP matrices gain nothing from threads, and on a shared machine
    # oversubscribed threads made the fit several times slower.
    with warnings.catch_warnings(), threadpool_limits(1):
        # A length scale at its bound is an answer (the column is irrelevant), not a failure.
        warnings.simplefilter("ignore", ConvergenceWarning)
        gp.fit(x, target)
    return gp


def _optimize_fold(k: int, subset: bool) -> bool:
    """Whether fold ``k``'s GP fits its hyperparameters. Folds whose training rows exceed the subset size
    (large data: every fold trains on its own random subset of the same size) share the first fold's:
    hyperparameters fitted on one such subset describe the others as well (their sampling spread is
    the same), while each fit costs seconds. The shared values were fitted on rows that include later
    folds' test rows; what reaches a held-out row through a dozen hyperparameters, fitted on a few
    hundred of thousands of rows, is negligible beside the GP's mean, which never sees them. Smaller
    data refit every fold (starting from the previous fold's values). [2]"""
    return k == 0 or not subset


def gp_discrepancy(dataset: Dataset, baseline: ModelCV, max_train: int = 300, seed: int = 0,
                   progress: Callable[[float], None] | None = None) -> dict:
    """Cross-validated error of the declared model plus a GP discrepancy on log μ.

    Parameters
    ----------
    dataset : Dataset
        Measurements.
    baseline : ModelCV
        Declared model fitted per fold (its folds are reused).
    max_train : int
        At most this many training rows per fold (a random subset), to bound the GP's cubic cost. [1]
    seed : int
        Seed of the subset and of the optimizer.
    progress : callable, optional
        Called with the fraction done, 0..1.

    Returns
    -------
    dict
        ``errors``: held-out ``rmse``, ``relative_rmse``, ``max_abs_error`` [1] (see
        :func:`calibrate.fit.prediction_errors`); ``features``: the columns used; ``length_scales``:
        fitted RBF length scale per column, in standard deviations of the column (short = relevant);
        ``noise_std_log``: fitted white-noise standard deviation of log μ [1]; ``max_train_rows``.
    """
    report = progress or (lambda fraction: None)
    names, x, _, _ = _features(dataset)
    log_measured = np.log(dataset.mu_measured)
    oof = baseline.oof_mu.copy()
    if not names:
        return {"errors": prediction_errors(oof, dataset.mu_measured), "features": [],
                "length_scales": {}, "noise_std_log": None, "max_train_rows": max_train}
    rng = np.random.default_rng(seed)
    everything = np.arange(dataset.n_points)
    scales, noise = np.zeros(len(names)), []
    kernel = _kernel(len(names))
    for k, (test, fold_mu) in enumerate(zip(baseline.folds, baseline.fold_mu, strict=True)):
        train = np.setdiff1d(everything, test)
        subset = train.size > max_train
        if subset:
            train = np.sort(rng.choice(train, max_train, replace=False))
        target = log_measured[train] - np.log(fold_mu[train])
        gp = _fit_gp(x[train], target, kernel, seed, optimize=_optimize_fold(k, subset))
        oof[test] = fold_mu[test] * np.exp(gp.predict(x[test]))
        fitted = gp.kernel_
        # Each fold refits the hyperparameters on its own training rows, starting from the last fold's
        # (or shares the first fold's: see _optimize_fold).
        kernel = fitted
        scales += np.log(np.atleast_1d(fitted.k1.k2.length_scale))
        noise.append(np.sqrt(fitted.k2.noise_level) * np.std(target))
        report((k + 1) / len(baseline.folds))
    folds = len(baseline.folds)
    return {
        "errors": prediction_errors(oof, dataset.mu_measured),
        "features": names,
        "length_scales": dict(zip(names, np.exp(scales / folds).tolist(), strict=True)),
        "noise_std_log": float(np.mean(noise)),
        "max_train_rows": max_train,
    }


def residual_gp(dataset: Dataset, folds: list[np.ndarray], fold_mu: list[np.ndarray], mu: np.ndarray,
                inliers: np.ndarray, max_train: int = 300, seed: int = 0,
                progress: Callable[[float], None] | None = None) -> dict:
    """A GP on what the calibrated model leaves, judged by nested cross-validation.

    Parameters
    ----------
    dataset : Dataset
        Measurements.
    folds : list of numpy.ndarray
        Test rows of each outer fold.
    fold_mu : list of numpy.ndarray
        μ at every row of the model each outer fold's own selection built on its training rows
        (:attr:`calibrate.select.NestedValidation.fold_mu`). [1]
    mu : numpy.ndarray
        μ of the calibrated model (fitted on all rows) at every row. [1]
    inliers : numpy.ndarray
        Rows that are not outliers: the GPs are trained and judged on them only.
    max_train : int
        Training rows of a GP at most (a random subset). [1]
    seed : int
        Seed of the subsets and of the optimizer.
    progress : callable, optional
        Called with the fraction done, 0..1.

    Returns
    -------
    dict
        ``errors``: held-out errors (inliers) of each outer fold's model corrected by its GP;
        ``errors_without``: the same without the GP; ``z``: paired z of the decrease of the squared
        held-out log error [1]; ``helps``: whether ``z`` exceeds the one-sided
        :data:`GP_HELPS_ALPHA` point; ``gp``: when it helps, the GP fitted on all inlier rows'
        residual of the calibrated model (JSON-ready, see :func:`gp_state`), else None; ``features``:
        the columns it reads.
    """
    report = progress or (lambda fraction: None)
    names, x, centres, scales = _features(dataset)
    log_measured = np.log(dataset.mu_measured)
    oof = np.empty(dataset.n_points)
    for test, model_mu in zip(folds, fold_mu, strict=True):
        oof[test] = model_mu[test]
    without = oof.copy()
    rng = np.random.default_rng(seed)
    everything = np.arange(dataset.n_points)
    kernel = _kernel(len(names)) if names else None
    for k, (test, model_mu) in enumerate(zip(folds, fold_mu, strict=True)):
        if kernel is None:
            break
        train = np.setdiff1d(everything, test)
        train = train[inliers[train]]
        subset = train.size > max_train
        if subset:
            train = np.sort(rng.choice(train, max_train, replace=False))
        target = log_measured[train] - np.log(model_mu[train])
        gp = _fit_gp(x[train], target, kernel, seed, optimize=_optimize_fold(k, subset))
        kernel = gp.kernel_
        oof[test] = model_mu[test] * np.exp(gp.predict(x[test]))
        report((k + 1) / (len(folds) + 1))
    held = inliers
    error_without = np.square(np.log(without / dataset.mu_measured))[held]
    error_with = np.square(np.log(oof / dataset.mu_measured))[held]
    diff = error_without - error_with
    spread = float(np.std(diff, ddof=1)) if diff.size > 1 else 0.0
    z = float(np.mean(diff) / (spread / np.sqrt(diff.size))) if spread > 0 else 0.0
    helps = bool(names) and z > float(stats.norm.isf(GP_HELPS_ALPHA))
    state = None
    if helps:
        train = np.flatnonzero(inliers)
        if train.size > max_train:
            train = np.sort(rng.choice(train, max_train, replace=False))
        target = log_measured[train] - np.log(mu[train])
        gp = _fit_gp(x[train], target, kernel, seed)
        state = gp_state(gp.kernel_, names, centres, scales, x[train], target, x)
    report(1.0)
    return {
        "errors": prediction_errors(oof[held], dataset.mu_measured[held]),
        "errors_without": prediction_errors(without[held], dataset.mu_measured[held]),
        "z": z,
        "helps": helps,
        "gp": state,
        "features": names,
    }


def residual_gp_words(leftover: Mapping[str, Any], n_points: int) -> list[str]:
    """What the report says of a GP on what the terms leave (:func:`residual_gp`, after the calibration's
    checks: ``helps``, and ``clipped_rows`` or ``rows_for_gp`` when it was held back), in words: none
    when its held-out test did not pass."""
    z = leftover.get("z")
    if leftover["helps"]:
        return [f"a Gaussian-process discrepancy on what the terms leave predicts held-out rows better "
                f"(nested CV, outliers left out: relative rmse {leftover['errors']['relative_rmse']:.3g} vs "
                f"{leftover['errors_without']['relative_rmse']:.3g}, z = {z:.1f}): it is part of the "
                f"calibrated model, whose mean it corrects and whose intervals it widens where it is unsure"]
    passed = (f"a Gaussian-process discrepancy on what the terms leave predicted held-out rows better "
              f"(z = {z:.1f})")
    if leftover.get("clipped_rows"):
        return [f"{passed}, but {leftover['clipped_rows']} rows are clipped at the sensor's limit: beside a "
                f"clip the measured rows are a truncated sample, which a GP would learn as an effect, so it "
                f"is not part of the model, whose intervals keep the censored scatter"]
    if leftover.get("rows_for_gp"):
        return [f"{passed}, but {n_points} rows cannot weigh its {len(leftover['features']) + 2} "
                f"hyperparameters (about {leftover['rows_for_gp']} rows would): it is not part of the model, "
                f"whose intervals keep the held-out scatter"]
    return []


def gp_state(kernel, names: list[str], centres: np.ndarray, scales: np.ndarray, x_train: np.ndarray,
             y_train: np.ndarray, x_data: np.ndarray) -> dict:
    """A fitted GP as JSON-ready data for :class:`calibrate.model.CalibratedModel`.

    Columns across whose data range the GP varies by less than :data:`_IRRELEVANT_RANGE` length
    scales are left out (a prediction need not give them).

    Parameters
    ----------
    kernel : sklearn kernel
        The fitted kernel, ConstantKernel * RBF + WhiteKernel on the normalized target.
    names : list of str
        Feature columns.
    centres, scales : numpy.ndarray
        Their standardization, in each column's unit.
    x_train : numpy.ndarray
        Standardized training inputs.
    y_train : numpy.ndarray
        Training log residual. [1]
    x_data : numpy.ndarray
        Standardized inputs of every row (their ranges decide relevance).

    Returns
    -------
    dict
        ``features``, ``centre``, ``scale`` (of the columns kept), ``length_scale`` (in scales of
        the column), ``amplitude`` and ``noise`` (signal and white-noise variances of the target
        normalized to zero mean and unit variance) [1], ``x`` (standardized training inputs) and
        ``y`` (training log residual) [1].
    """
    length = np.atleast_1d(kernel.k1.k2.length_scale).astype(float)
    if length.size == 1:
        length = np.full(len(names), float(length[0]))
    keep = np.ptp(x_data, axis=0) / length >= _IRRELEVANT_RANGE
    return {
        "features": [n for n, k in zip(names, keep, strict=True) if k],
        "centre": centres[keep].tolist(),
        "scale": scales[keep].tolist(),
        "length_scale": length[keep].tolist(),
        "amplitude": float(kernel.k1.k1.constant_value),
        "noise": float(kernel.k2.noise_level),
        "x": x_train[:, keep].tolist(),
        "y": np.asarray(y_train, dtype=float).tolist(),
    }
