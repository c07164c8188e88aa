"""A calibrated model's Gaussian-process discrepancy bounded over many boxes, each distinct box once.

The branch and bounds over an envelope (:mod:`optimize.envelope_bound`, :mod:`optimize.interval_bound`)
and over the designs (:mod:`optimize.design_bound`) bound the discrepancy over hundreds to thousands of
boxes per pass, but the discrepancy reads only its own features (a few conditions, sometimes the ball
count or the load), and most boxes share their features' ranges: every design box at one envelope point,
every envelope box split along the speed or the angle. The bounds of
:meth:`calibrate.CalibratedModel.discrepancy_bound` are computed box by box (the kernel's ends against
every training row, a Cholesky solve per box), so computing them once per distinct row of the features'
ends and spreading them back gives the same numbers at a fraction of the work; the bound stays the
model's own, so whatever it certifies still holds.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["discrepancy_bound", "discrepancy_least_variance"]


def _distinct(calibrated: Any, low: Mapping[str, Any], high: Mapping[str, Any], n: int
              ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], int, np.ndarray]:
    """The discrepancy's features given by the boxes, their distinct (low, high) rows and the map back."""
    features = [f for f in calibrated.discrepancy.features if f in low and f in high]
    if not features:  # every feature from the model's own values: one box stands for all
        return {}, {}, 1, np.zeros(n, dtype=int)
    ends = np.column_stack([np.broadcast_to(np.asarray(points[f], dtype=float), (n,))
                            for points in (low, high) for f in features])
    rows, inverse = np.unique(ends, axis=0, return_inverse=True)
    k = len(features)
    return ({f: rows[:, j] for j, f in enumerate(features)},
            {f: rows[:, k + j] for j, f in enumerate(features)}, len(rows), np.ravel(inverse))


def discrepancy_bound(calibrated: Any, low: Mapping[str, Any], high: Mapping[str, Any], n: int
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:meth:`calibrate.CalibratedModel.discrepancy_bound` over ``n`` boxes (columnar ``low`` and ``high``,
    one box per entry), each distinct box of the discrepancy's features bounded once: the least and largest
    mean of log μ and the largest latent variance, shaped (n,) [1]."""
    if calibrated.discrepancy is None:
        return np.zeros(n), np.zeros(n), np.zeros(n)
    lo, hi, m, inverse = _distinct(calibrated, low, high, n)
    return tuple(np.ravel(part)[inverse] for part in calibrated.discrepancy_bound(lo, hi, (m,)))


def discrepancy_least_variance(calibrated: Any, low: Mapping[str, Any], high: Mapping[str, Any], n: int
                               ) -> np.ndarray:
    """:meth:`calibrate.CalibratedModel.discrepancy_least_variance` over ``n`` boxes, each distinct box of
    the discrepancy's features once, shaped (n,) [1]."""
    if calibrated.discrepancy is None:
        return np.zeros(n)
    lo, hi, m, inverse = _distinct(calibrated, low, high, n)
    return np.ravel(calibrated.discrepancy_least_variance(lo, hi, (m,)))[inverse]
