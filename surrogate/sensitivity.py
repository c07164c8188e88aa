"""Variance-based (Sobol') sensitivity indices of μ over a space, computed on a surrogate.

Inputs are independent and uniform in the space's unit cube (log-uniform on
log-scaled dimensions, the distribution of the designs); the indices come from
:func:`scipy.stats.sobol_indices` (Saltelli et al. 2010 estimator for
first-order indices, Jansen 1999 for total ones), costing ``n (d + 2)``
evaluations of the model, cheap on a surrogate.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import stats

from .space import Space

__all__ = ["SobolIndices", "sobol_indices"]


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
    """

    names: tuple[str, ...]
    first_order: np.ndarray
    total_order: np.ndarray
    n: int

    def to_dict(self) -> dict[str, object]:
        """The indices as JSON-ready data keyed by dimension name."""
        return {"names": list(self.names), "n": self.n,
                "first_order": dict(zip(self.names, map(float, self.first_order), strict=True)),
                "total_order": dict(zip(self.names, map(float, self.total_order), strict=True))}


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
        First-order and total indices per dimension.

    Raises
    ------
    ValueError
        If ``n`` is not a power of 2 of at least 16.
    """
    if not isinstance(n, (int, np.integer)) or n < 16 or n & (n - 1):
        raise ValueError(f"n must be a power of 2 >= 16 (Sobol' balance); got {n!r}")

    def on_unit_cube(U: np.ndarray) -> np.ndarray:
        # scipy passes samples as (d, m); the space maps them to valid physical points.
        return np.asarray(func(space.from_unit(np.clip(U.T, 0.0, 1.0))), dtype=float)

    result = stats.sobol_indices(func=on_unit_cube, n=int(n), dists=[stats.uniform()] * space.dimension,
                                 rng=seed)
    return SobolIndices(space.names, np.asarray(result.first_order, dtype=float).reshape(-1),
                        np.asarray(result.total_order, dtype=float).reshape(-1), int(n))
