"""Accuracy of a surrogate on held-out physics evaluations (never its training points)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from .model import GaussianProcessSurrogate
from .sampling import TAIL_FACTOR, design

__all__ = ["MIN_COVERAGE", "accuracy", "holdout_metrics", "quality_warnings"]

#: Least held-out coverage of the 95 % interval that a surrogate keeps without a warning. [1]
MIN_COVERAGE = 0.90


def accuracy(mu_true: Any, mu_pred: Any, mu_lower: Any, mu_upper: Any) -> dict[str, float]:
    """Error figures of predictions against true μ.

    Parameters
    ----------
    mu_true : array_like of shape (n,)
        μ from the physics. [1]
    mu_pred : array_like of shape (n,)
        Predicted μ. [1]
    mu_lower, mu_upper : array_like of shape (n,)
        The predicted 95 % interval. [1]

    Returns
    -------
    dict of str to float
        ``median_relative_error`` and ``p95_relative_error`` of |pred/true - 1|,
        ``nrmse`` (root-mean-square error over the standard deviation of the
        true μ), ``coverage_95`` (fraction of true values inside the interval)
        [1], and ``n_test``.

    Raises
    ------
    ValueError
        For arrays of different shapes, fewer than 2 points, or true μ <= 0.

    Examples
    --------
    >>> m = accuracy([1.0, 2.0], [1.1, 2.0], [0.9, 2.1], [1.2, 2.2])
    >>> round(m["median_relative_error"], 3), m["coverage_95"]
    (0.05, 0.5)
    """
    arrays = [np.asarray(a, dtype=float).reshape(-1) for a in (mu_true, mu_pred, mu_lower, mu_upper)]
    if len({a.shape for a in arrays}) != 1:
        raise ValueError("mu_true, mu_pred, mu_lower and mu_upper must have the same length")
    true, pred, lower, upper = arrays
    if true.size < 2:
        raise ValueError(f"metrics need at least 2 held-out points; got {true.size}")
    if np.any(true <= 0):
        raise ValueError("mu_true must be > 0 (relative errors of mu)")
    relative = np.abs(pred / true - 1.0)
    spread = float(np.std(true))
    rmse = float(np.sqrt(np.mean((pred - true) ** 2)))
    return {
        "median_relative_error": float(np.median(relative)),
        "p95_relative_error": float(np.percentile(relative, 95)),
        "nrmse": rmse / spread if spread > 0 else float("inf"),
        "coverage_95": float(np.mean((true >= lower) & (true <= upper))),
        "n_test": int(true.size),
    }


def holdout_metrics(model: GaussianProcessSurrogate, n_test: int = 1024, seed: int = 9_999,
                    mu_model: Callable[[Mapping[str, Any]], Any] | None = None) -> dict[str, Any]:
    """Accuracy of a fitted surrogate on fresh evaluations over its space.

    The test points are a scrambled Sobol' design of the model's space drawn
    with ``seed``; any that coincide with a training point are dropped, so the
    figures are never computed on training data. A finite space (integer and
    boolean dimensions only) with at most ``n_test`` points is tested on every
    one of its points that is not a training point, each once. When fewer than
    2 such points are left (the surrogate was trained on the whole space), the
    figures are None, ``n_test`` is the number left and ``note`` says so, with
    the largest relative error at the training points (the surrogate there
    reproduces its noise-free data up to its fitted noise).

    Parameters
    ----------
    model : GaussianProcessSurrogate
        A fitted surrogate.
    n_test : int, default 1024
        Number of held-out points before dropping training duplicates. [1]
    seed : int, default 9999
        Seed of the test design; use one not used for training.
    mu_model : callable, optional
        The model the surrogate learned (see :meth:`Space.evaluate`); default the physics.

    Returns
    -------
    dict
        As :func:`accuracy`, plus ``note`` (None unless the figures could not be measured).

    Examples
    --------
    >>> from .space import Space
    >>> s = Space({"balls": (3, 4)}, fixed={"load_N": 0.01, "speed_m_s": 0.01})
    >>> X = np.array([[3.0], [4.0]])
    >>> m = holdout_metrics(GaussianProcessSurrogate(s, random_state=0).fit(X, s.evaluate(X)))
    >>> m["n_test"], m["coverage_95"], m["note"][:69]
    (0, None, '2 of the 2 points of the space are training points: no held-out point')
    """
    everything = model.space.all_points(n_test)
    X = design(model.space, n_test, "sobol", seed) if everything is None else everything
    train = {tuple(row) for row in model.X_train_}
    X = X[[tuple(row) not in train for row in X]]
    if len(X) >= 2:
        prediction = model.predict_interval(X, 0.95)
        return {**accuracy(model.space.evaluate(X, mu_model), prediction.mu, prediction.mu_lower,
                           prediction.mu_upper), "note": None}
    if everything is None:
        raise ValueError(f"fewer than 2 of the {n_test} test points differ from the training points; "
                         f"raise n_test")
    at_training = float(np.max(np.abs(model.predict(model.X_train_) / model.y_train_ - 1.0)))
    left = "no held-out point is left" if len(X) == 0 else f"only {len(X)} held-out point is left"
    return {"median_relative_error": None, "p95_relative_error": None, "nrmse": None, "coverage_95": None,
            "n_test": len(X),
            "note": f"{len(everything) - len(X)} of the {len(everything)} points of the space are training "
                    f"points: {left}, too few to measure; at the training points the surrogate "
                    f"reproduces the model within a relative error of {at_training:.2g}"}


def quality_warnings(result: Mapping[str, Any]) -> list[str]:
    """Where a surrogate's own held-out figures fall short of what it promises.

    Parameters
    ----------
    result : mapping
        A stored surrogate's public result: ``metrics`` (held-out), ``stop_reason`` and, when
        stored, ``target_relative_error``.

    Returns
    -------
    list of str
        One sentence per shortfall: a held-out coverage of the 95 % interval below
        :data:`MIN_COVERAGE`, or a held-out median (95th-percentile) relative error above the
        target (:data:`TAIL_FACTOR` times it); empty when none.

    Examples
    --------
    >>> quality_warnings({"metrics": {"coverage_95": 0.85, "median_relative_error": 1e-4,
    ...                               "p95_relative_error": 1e-3, "n_test": 1000},
    ...                   "target_relative_error": 1e-3, "stop_reason": "budget_exhausted"})[0][:57]
    'the 95 % intervals covered 85.0 % of 1000 held-out points'
    """
    metrics, warnings = result["metrics"], []
    coverage = metrics.get("coverage_95")
    if coverage is not None and coverage < MIN_COVERAGE:
        warnings.append(f"the 95 % intervals covered {100 * coverage:.1f} % of {metrics['n_test']} held-out "
                        f"points (below {100 * MIN_COVERAGE:.0f} %): they are too narrow here; widen them "
                        f"or retrain with a larger budget")
    target = result.get("target_relative_error")
    median, tail = metrics.get("median_relative_error"), metrics.get("p95_relative_error")
    if target is not None and median is not None and (
            median > target or tail > TAIL_FACTOR * target):
        why = ("although the stop rule judged it reached" if result.get("stop_reason") == "target_reached"
               else "the budget ran out first")
        warnings.append(f"held-out relative error of mu: median {median:.3g}, 95th percentile {tail:.3g}, "
                        f"short of the target {target:g} (median) and {TAIL_FACTOR:g} x "
                        f"it (95th percentile): {why}")
    return warnings
