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
from scipy.optimize import minimize_scalar
from scipy.special import log_ndtr
from scipy.stats import norm

__all__ = ["beyond_clip", "censored_residual", "measured_rows", "residual_variance"]


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


def residual_variance(residual: np.ndarray, censored: np.ndarray | None, rows: np.ndarray) -> float:
    """Variance of log μ about the model from residuals ``log(mu_measured / mu_model)``, clips counted. [1]

    Without clipped rows, the mean square. With them, the maximum-likelihood variance of a zero-mean
    Gaussian whose clipped rows say only on which side of their residual the true one lies (Tobit): the
    measured rows alone are a truncated sample, narrower than the scatter, and an interval from them
    would cover less than it says near the clip.

    Parameters
    ----------
    residual : numpy.ndarray
        ``log(mu_measured / mu_model)`` of every row. [1]
    censored : numpy.ndarray or None
        +1 / -1 / 0 per row (:attr:`calibrate.data.Dataset.censored`).
    rows : numpy.ndarray
        Rows to count (bool mask), e.g. the ones that are not outliers.

    Examples
    --------
    >>> r = np.random.default_rng(0).normal(0.0, 0.03, 4000)
    >>> clip = np.where(r > 0.01, 1, 0)  # readings above +0.01 clipped there
    >>> cut = np.where(clip == 1, 0.01, r)
    >>> round(float(np.sqrt(residual_variance(cut, clip, np.ones(4000, bool)))), 3)
    0.03
    """
    r = np.asarray(residual, dtype=float)[rows]
    if censored is None or not np.any(censored[rows] != 0):
        return float(np.mean(np.square(r)))
    side = np.asarray(censored)[rows]
    value = side == 0

    def negative_log_likelihood(log_s: float) -> float:
        s = np.exp(log_s)
        return float(np.sum(0.5 * np.square(r[value] / s) + log_s)
                     - np.sum(log_ndtr(-side[~value] * r[~value] / s)))

    start = np.log(max(float(np.sqrt(np.mean(np.square(r)))), 1e-6))
    best = minimize_scalar(negative_log_likelihood, bounds=(start - 5.0, start + 5.0), method="bounded")
    return float(np.exp(2.0 * best.x))


def beyond_clip(mu_model: np.ndarray, mu_measured: np.ndarray, censored: np.ndarray | None,
                scale: float) -> np.ndarray:
    """The readings with each clipped row's replaced by the mean true reading beyond its clip. [1]

    A clipped row says only on which side of the clip the true reading lies; a method that reads values
    (a GP on the residual) cannot take it as it is, and without it the measured rows near the clip are a
    truncated sample (those whose scatter fell on the near side), which bends any smooth fit toward the
    clip just where the rows end. Given the model's μ and the reading's scatter ``scale`` (standard
    deviation of log μ), log μ* ~ N(log mu_model, scale²) truncated to the clip's side has the mean
    ``log mu_model + scale * phi(a) / (1 - Phi(a))`` beyond an upper clip (``a`` the clip's standard
    score) and ``log mu_model - scale * phi(a) / Phi(a)`` below a lower one (one E-step of the censored
    likelihood's EM).

    Parameters
    ----------
    mu_model : numpy.ndarray
        The model's μ at every row. [1]
    mu_measured : numpy.ndarray
        The readings, clipped rows at their clip. [1]
    censored : numpy.ndarray or None
        +1 / -1 / 0 per row (:attr:`calibrate.data.Dataset.censored`); None: nothing clipped.
    scale : float
        Standard deviation of log μ of the reading [1]; 0 or less leaves the readings as they are.

    Examples
    --------
    >>> beyond_clip(np.array([1.0, 1.0]), np.array([1.0, 1.0]), np.array([0, 1]), 0.1).round(4).tolist()
    [1.0, 1.0831]
    """
    mu_measured = np.asarray(mu_measured, dtype=float)
    if censored is None or scale <= 0 or not np.any(censored != 0):
        return mu_measured
    side = np.sign(censored).astype(float)
    a = np.log(mu_measured / mu_model) / scale  # the clip's standard score under the model
    # phi(a) / P(beyond the clip), in logs for clips far in a tail
    ratio = np.exp(norm.logpdf(a) - log_ndtr(np.where(side > 0, -a, a)))
    imputed = mu_model * np.exp(side * scale * ratio)
    return np.where(side != 0, imputed, mu_measured)
