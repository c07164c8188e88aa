"""The statistician's baseline: a Gaussian-process discrepancy on the log residual (Kennedy-O'Hagan).

log μ_measured = log μ_declared(θ) + δ(x) + ε, with δ a Gaussian process over
every varying data column (standardized) with an anisotropic RBF kernel and a
white-noise term, θ the declared parameters fitted first (a modular, not fully
Bayesian, Kennedy-O'Hagan calibration). Its held-out error, on the same folds
as the named effects, shows what the named effect is worth: a named effect
close to the GP explains the discrepancy with a formula and a few parameters
instead of a black box.

References
----------
.. [1] M.C. Kennedy, A. O'Hagan, "Bayesian calibration of computer models",
   J. R. Statist. Soc. B 63(3), 425-464 (2001).
.. [2] C.E. Rasmussen, C.K.I. Williams, Gaussian Processes for Machine
   Learning, MIT Press, 2006, ch. 5 (automatic relevance determination).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import numpy as np

from .data import Dataset
from .fit import prediction_errors
from .select import ModelCV

__all__ = ["gp_discrepancy"]


def _features(dataset: Dataset) -> tuple[list[str], np.ndarray]:
    names, columns = [], []
    for name, values in dataset.columns().items():
        x = np.asarray(values, dtype=float)
        if np.unique(x).size > 1:
            names.append(name)
            columns.append((x - x.mean()) / x.std())
    return names, (np.column_stack(columns) if columns else np.zeros((dataset.n_points, 0)))


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
    # scikit-learn is imported here, not at module level: it takes seconds to import.
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel
    from threadpoolctl import threadpool_limits

    report = progress or (lambda fraction: None)
    names, x = _features(dataset)
    log_measured = np.log(dataset.mu_measured)
    oof = baseline.oof_mu.copy()
    if not names:
        return {"errors": prediction_errors(oof, dataset.mu_measured), "features": [],
                "length_scales": {}, "noise_std_log": None, "max_train_rows": max_train}
    rng = np.random.default_rng(seed)
    everything = np.arange(dataset.n_points)
    scales, noise = np.zeros(len(names)), []
    kernel = (ConstantKernel(1.0, (1e-4, 1e2)) * RBF(np.ones(len(names)), (1e-2, 1e3))
              + WhiteKernel(0.1, (1e-8, 1e1)))
    for k, (test, fold_mu) in enumerate(zip(baseline.folds, baseline.fold_mu, strict=True)):
        train = np.setdiff1d(everything, test)
        if train.size > max_train:
            train = np.sort(rng.choice(train, max_train, replace=False))
        target = log_measured[train] - np.log(fold_mu[train])
        gp = GaussianProcessRegressor(kernel, normalize_y=True, random_state=seed)
        # One BLAS thread: the small GP matrices gain nothing from threads, and on a shared machine
        # oversubscribed threads made the fit several times slower.
        with warnings.catch_warnings(), threadpool_limits(1):
            # A length scale at its bound is an answer (the column is irrelevant), not a failure.
            warnings.simplefilter("ignore", ConvergenceWarning)
            gp.fit(x[train], target)
        oof[test] = fold_mu[test] * np.exp(gp.predict(x[test]))
        fitted = gp.kernel_
        # Each fold refits the hyperparameters on its own training rows, starting from the last fold's.
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
