"""Readings at a sensor's clip: censored rows and their likelihood (Tobit).

A tribometer whose force channel saturates writes the same value for every measurement beyond its
range: a pile of identical μ at the top (or the bottom) of the data. Such a reading says only that the
true μ is at least (at most) the clip, not what it is. Fitted as a value it bends the model toward a
plateau that is the sensor's, not the bearing's (a Stribeck law with a breakaway speed far beyond the
data, a pivoting coefficient half its value).

So a clipped row enters the fit through the probability of its side of the clip rather than through
the density of its value (a Tobit-type likelihood; J. Tobin, Econometrica 26, 24-36 (1958)): with
``r = log(mu_model) - log(clip)`` and ``s`` the standard deviation of log μ, a row at an upper clip
has the likelihood ``P(log mu* >= log clip) = Phi(r / s)`` (the survival function of the reading at
the clip), a row at a lower clip ``Phi(-r / s)``. :func:`censored_residual` writes that as a residual
whose square is twice its negative log-likelihood, ``sqrt(-2 log Phi(.)) s``, so the least squares of
:func:`calibrate.fit.fit` maximize the censored likelihood (at ``s``) like they maximize the Gaussian
one on the measured rows: a model far on the right side of the clip leaves the row a residual near
zero, one on the wrong side a residual like an ordinary row's.
"""

from __future__ import annotations

import numpy as np
from scipy.special import log_ndtr

__all__ = ["censored_residual", "measured_rows"]


def censored_residual(residual: np.ndarray, censored: np.ndarray, scale: float) -> np.ndarray:
    """Log residuals with each clipped row's replaced by its censored-likelihood residual. [1]

    Parameters
    ----------
    residual : numpy.ndarray
        ``log(mu_model) - log(mu_measured)`` of each row. [1]
    censored : numpy.ndarray
        Per row +1 (upper clip: the true μ is at least the reading), -1 (lower clip), 0 (measured).
    scale : float
        Standard deviation of log μ of the reading [1]; 0 or less leaves the residuals as they are.

    Returns
    -------
    numpy.ndarray
        ``residual`` on measured rows; on a clipped row ``-sign * sqrt(-2 log Phi(sign * r / s)) * s``,
        whose square is twice the row's negative log-likelihood (sign +1 at an upper clip). [1]

    Examples
    --------
    >>> r = censored_residual(np.array([0.5, 0.5, -0.5]), np.array([0, 1, 1]), 0.1)
    >>> r.round(4).tolist()  # measured; model far above the upper clip; far below it
    [0.5, -0.0001, -0.5489]
    """
    clipped = censored != 0
    if scale <= 0 or not np.any(clipped):
        return residual
    side = np.where(clipped, np.sign(censored), 1.0)
    log_p = log_ndtr(side * residual / scale)
    pseudo = -side * np.sqrt(np.maximum(-2.0 * log_p, 0.0)) * scale
    return np.where(clipped, pseudo, residual)


def measured_rows(censored: np.ndarray | None, n_points: int) -> np.ndarray:
    """Rows whose reading is a value, not a clip (all rows when nothing is censored)."""
    return np.ones(n_points, dtype=bool) if censored is None else censored == 0
