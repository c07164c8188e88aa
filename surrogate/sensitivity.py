"""Variance-based (Sobol') sensitivity indices of μ over a space, computed on a surrogate.

Inputs are independent and uniform in the space's unit cube (log-uniform on
log-scaled dimensions, the distribution of the designs); the indices come from
:func:`scipy.stats.sobol_indices` (Saltelli et al. 2010 estimator for
first-order indices, Jansen 1999 for total ones), costing ``n (d + 2)``
evaluations of the model, cheap on a surrogate. Their 95 % confidence intervals come from
scipy's bootstrap of those evaluations (``sobol_indices(...).bootstrap()``: bias-corrected and
accelerated (BCa) intervals over resampled rows; no new evaluations).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import stats

from .space import Space

__all__ = ["BOOTSTRAP_RESAMPLES", "SobolIndices", "sobol_indices"]

#: Bootstrap resamples of the evaluations behind each confidence interval. [1]
BOOTSTRAP_RESAMPLES = 999


@dataclass(frozen=True)
class SobolIndices:
    """First-order and total Sobol' indices per dimension.

    Attributes
    ----------
    names : tuple of str
        Dimensions, in the space's order.
    first_order : numpy.ndarray
        Share of the output variance explained by each input alone. [1]
    total_order : numpy.ndarray
        Share involving each input, interactions included. [1]
    n : int
        Base sample size (a power of 2). [1]
    first_order_interval, total_order_interval : numpy.ndarray of shape (d, 2)
        95 % bootstrap confidence interval (low, high) of each index. [1]
    """

    names: tuple[str, ...]
    first_order: np.ndarray
    total_order: np.ndarray
    n: int
    first_order_interval: np.ndarray
    total_order_interval: np.ndarray

    def to_dict(self) -> dict[str, object]:
        """The indices and their intervals as JSON-ready data keyed by dimension name."""
        def by_name(values: np.ndarray) -> dict[str, object]:
            return {name: np.asarray(value, dtype=float).tolist()
                    for name, value in zip(self.names, values, strict=True)}

        return {"names": list(self.names), "n": self.n, "first_order": by_name(self.first_order),
                "total_order": by_name(self.total_order),
                "first_order_interval": by_name(self.first_order_interval),
                "total_order_interval": by_name(self.total_order_interval)}


def sobol_indices(func: Callable[[np.ndarray], np.ndarray], space: Space, n: int = 4096,
                  seed: int | None = 0) -> SobolIndices:
    """Sobol' indices of a function of the space's physical points.

    Parameters
    ----------
    func : callable
        ``func(X[m, d]) -> values[m]`` on physical points in ``space.names``
        order, e.g. ``model.predict`` of a fitted surrogate (its ``log`` for
        indices of log μ).
    space : Space
        The input space and its distribution (uniform in the unit cube).
    n : int, default 4096
        Base sample size, a power of 2 >= 16. [1]
    seed : int or None, default 0
        Seed of the scrambled Sobol' samples.

    Returns
    -------
    SobolIndices
        First-order and total indices per dimension, with 95 % bootstrap intervals
        (:data:`BOOTSTRAP_RESAMPLES` resamples).

    Raises
    ------
    ValueError
        If ``n`` is not a power of 2 of at least 16.
    """
    if not isinstance(n, (int, np.integer)) or n < 16 or n & (n - 1):
        raise ValueError(f"n must be a power of 2 >= 16 (Sobol' balance); got {n!r}")

    d = space.dimension
    # scipy's estimator fails for a single input (it indexes a scalar): one input is then studied
    # beside an inert one that the function ignores, whose indices are dropped.
    sampled = max(d, 2)

    def on_unit_cube(U: np.ndarray) -> np.ndarray:
        # scipy passes samples as (sampled, m); the space maps them to valid physical points.
        return np.asarray(func(space.from_unit(np.clip(U[:d].T, 0.0, 1.0))), dtype=float)

    result = stats.sobol_indices(func=on_unit_cube, n=int(n), dists=[stats.uniform()] * sampled, rng=seed)
    # An index that no resample changes (the inert input, an input the function ignores) has no BCa
    # interval: its jackknife divides 0 by 0, scipy warns and answers NaN, replaced below by the index
    # itself. numpy's error state is per thread (a context variable), so the division is silenced here
    # whatever another thread does; the warnings filter is process-wide, and a thread leaving its own
    # catch_warnings restores the filters it saw, so it only backs up scipy's DegenerateDataWarning.
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", stats.DegenerateDataWarning)
        boot = result.bootstrap(confidence_level=0.95, n_resamples=BOOTSTRAP_RESAMPLES)

    def kept(values) -> np.ndarray:
        return np.asarray(values, dtype=float).reshape(-1)[:d]

    def interval(estimate, value) -> np.ndarray:
        ci = estimate.confidence_interval
        bounds = np.column_stack([kept(ci.low), kept(ci.high)])
        return np.where(np.isfinite(bounds), bounds, kept(value)[:, None])

    return SobolIndices(space.names, kept(result.first_order), kept(result.total_order), int(n),
                        interval(boot.first_order, result.first_order),
                        interval(boot.total_order, result.total_order))
