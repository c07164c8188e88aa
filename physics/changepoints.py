"""Where a step in an ordered column may sit: the places a change-point law is searched over.

A step of the reading at ``x_step`` (:data:`physics.effects.EFFECTS` ``measurement_step``) changes μ for
every row with ``x >= x_step``. Between two consecutive distinct values of the column every place is the
same step on the data, so the places worth trying are the midpoints of those gaps; a place with fewer
than :func:`min_side_rows` rows on either side is no step but a few rows set apart (an outlier's
excuse), and is not tried.

>>> [p["step"] for p in step_places(np.arange(12.0))]
[4.5, 5.5, 6.5]
>>> step_places(np.arange(12.0))[0]["before"], step_places(np.arange(12.0))[0]["after"]
(4.0, 5.0)
"""

from __future__ import annotations

import numpy as np

__all__ = ["MAX_STEP_PLACES", "MIN_SIDE_ROWS", "min_side_rows", "step_places"]

#: Fewest rows on each side of a step's place. [1]
MIN_SIDE_ROWS = 5
#: Places searched at most: beyond, every so many gaps in order of the column (evenly by rows). [1]
MAX_STEP_PLACES = 120


def min_side_rows(n_rows: int) -> int:
    """Fewest rows on each side of a step's place: :data:`MIN_SIDE_ROWS`, or 5 % of the rows when more.

    >>> min_side_rows(40), min_side_rows(120), min_side_rows(1000)
    (5, 6, 50)
    """
    return max(MIN_SIDE_ROWS, int(np.ceil(0.05 * n_rows)))


def step_places(x) -> list[dict[str, float]]:
    """Places of a step in the column ``x``: one dict per gap between consecutive distinct values.

    Parameters
    ----------
    x : array_like
        The ordered column's values (a run index, hours). [its unit]

    Returns
    -------
    list of dict
        ``step`` (the gap's midpoint), ``before`` (the last value below it) and ``after`` (the first
        value at or above it), in increasing order; only gaps with :func:`min_side_rows` rows on each
        side, at most :data:`MAX_STEP_PLACES` of them (evenly spread by rows beyond).
    """
    x = np.asarray(x, dtype=float).ravel()
    values, counts = np.unique(x[np.isfinite(x)], return_counts=True)
    below = np.cumsum(counts)[:-1]  # rows below the gap after each value but the last
    need = min_side_rows(int(counts.sum()))
    ok = np.flatnonzero((below >= need) & (counts.sum() - below >= need))
    if ok.size > MAX_STEP_PLACES:
        ok = ok[np.unique(np.round(np.linspace(0, ok.size - 1, MAX_STEP_PLACES)).astype(int))]
    return [{"step": float(0.5 * (values[i] + values[i + 1])), "before": float(values[i]),
             "after": float(values[i + 1])} for i in ok]
