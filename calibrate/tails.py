"""The form of a new measurement's interval: a small-sample allowance, and heavy tails where there are some.

A calibrated model's 95 % interval is ``mu exp(+-z s f)``, ``s`` the scatter of log μ of a new
measurement (the held-out RMS of the nested cross-validation, outliers left out) and ``f`` a factor of
two parts, kept with the scatter model (:attr:`calibrate.scatter.ScatterModel.form`):

* **Degrees of freedom.** ``s`` is estimated from ``n`` held-out residuals of a model of ``p`` fitted
  values: on 15 rows it is off by a fifth in either direction about one time in three (the scatter of 3 %
  came out 2.2 %). One spread everywhere takes the allowance of :func:`calibrate.scatter.allowance` at
  ``nu = n - p`` degrees of freedom: Student's t quantile of ``nu`` over the normal's. Negligible on 200
  rows (+0.6 %), +9 % on 15. (A spread that varies takes its local degrees of freedom and the tolerance
  rule too: :meth:`calibrate.scatter.ScatterModel.quantile_factor`.)
* **Heavy tails.** Gaussian scatter is an assumption. :func:`tail_form` fits Student's t (location,
  scale and degrees of freedom, maximum likelihood) to every held-out residual of a measured row,
  outliers included (a clipped reading's residual is its distance to the clip, not scatter), and keeps
  it when the likelihood ratio against the Gaussian rejects the Gaussian (p < :data:`TAIL_ALPHA`)
  with tails of a continuous heavy-tailed law (:data:`MIN_TAIL_DOF` <= nu_t < :data:`MAX_TAIL_DOF`): the
  half-width is then that t's quantile of the level, but never wider than the residuals' own
  (conformal) quantile, the ``ceil((n + 1) level)``-th smallest absolute residual. A few gross outliers
  (a mixture, not a tail) fit nu_t below 2: they stay outliers, excluded from the scatter, as before.
  With Student-t (3 dof) scatter the Gaussian interval of the trimmed RMS covered 0.89-0.93; the t form
  0.94-0.96 (bench/calibration_trust.py, ``--part heavy``).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy import stats

__all__ = ["MAX_TAIL_DOF", "MIN_TAIL_DOF", "TAIL_ALPHA", "IntervalForm", "interval_form", "tail_form"]

#: Likelihood-ratio p-value below which the residuals are not Gaussian (Student's t instead). [1]
TAIL_ALPHA = 0.01
#: Fewest degrees of freedom of a fitted t taken for a tail (below: a mixture with gross outliers). [1]
MIN_TAIL_DOF = 2.0
#: Most degrees of freedom of a fitted t taken for a tail (above: as Gaussian as makes no difference). [1]
MAX_TAIL_DOF = 30.0
# Fewest held-out residuals a t is fitted to.
_MIN_ROWS = 30


@dataclass(frozen=True)
class IntervalForm:
    """How a new measurement's interval is formed around its scatter.

    Attributes
    ----------
    dof : float
        Degrees of freedom of the scatter's estimate: held-out residuals less fitted values. [1]
    tail_factor : float
        Factor on the Gaussian half-width z s for heavy tails (1: Gaussian). [1]
    tail_dof : float or None
        Degrees of freedom of the Student t fitted to the residuals when it was kept, else None. [1]
    """

    dof: float
    tail_factor: float = 1.0
    tail_dof: float | None = None

    def to_json(self) -> dict[str, float]:
        """JSON-ready data."""
        out = {"dof": float(self.dof), "tail_factor": float(self.tail_factor)}
        if self.tail_dof is not None:
            out["tail_dof"] = float(self.tail_dof)
        return out

    @classmethod
    def from_json(cls, data) -> IntervalForm | None:
        """Rebuild from :meth:`to_json` data (None for an empty mapping: a model stored before it).

        Raises
        ------
        ValueError
            For degrees of freedom below 1 or a tail factor below 1.
        """
        if not data:
            return None
        dof, factor = float(data["dof"]), float(data.get("tail_factor", 1.0))
        if not dof >= 1.0 or not factor >= 1.0:
            raise ValueError("scatter form: dof and tail_factor must be >= 1")
        tail = data.get("tail_dof")
        return cls(dof, factor, None if tail is None else float(tail))

    def words(self, varies: bool = False) -> str:
        """The form in words, for the report; ``varies``: of a spread that varies with an input, whose
        interval takes the degrees of freedom that inform it at each point."""
        text = ("the interval allows for the spread being estimated from the degrees of freedom that inform "
                "it at each point (Student's t or the tolerance rule, the wider)" if varies else
                f"the interval allows for the scatter being estimated from {self.dof:.0f} degrees of freedom "
                f"(Student's t)")
        if self.tail_dof is not None:
            text += (f"; the residuals are heavy-tailed (Student's t of {self.tail_dof:.2g} degrees of "
                     f"freedom fits them better than a Gaussian), so the half-width follows that t: "
                     f"x{self.tail_factor:.2f}")
        return text


def tail_form(residual: np.ndarray, scale: float, level: float = 0.95) -> tuple[float, float | None]:
    """The factor on the Gaussian half-width ``z scale`` for the residuals' tails, and the t's dof.

    Parameters
    ----------
    residual : numpy.ndarray
        Held-out log residuals, every row (outliers included). [1]
    scale : float
        The scatter the Gaussian interval uses (std of log μ). [1]
    level : float
        The interval's level. [1]

    Returns
    -------
    tuple
        ``(factor >= 1, nu_t or None)``: 1 and None where the Gaussian stands (see the module's text).

    Examples
    --------
    Gaussian residuals keep the Gaussian form:

    >>> r = np.random.default_rng(0).normal(0.0, 0.03, 400)
    >>> tail_form(r, 0.03)
    (1.0, None)
    """
    r = np.asarray(residual, dtype=float)
    r = r[np.isfinite(r)]
    if r.size < _MIN_ROWS or not scale > 0:
        return 1.0, None
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        nu, loc, t_scale = stats.t.fit(r)
        gauss = float(np.sum(stats.norm.logpdf(r, float(np.mean(r)), float(np.std(r)))))
        heavy = float(np.sum(stats.t.logpdf(r, nu, loc, t_scale)))
    p = float(stats.chi2.sf(2.0 * max(heavy - gauss, 0.0), 1))
    if not (p < TAIL_ALPHA and MIN_TAIL_DOF <= nu < MAX_TAIL_DOF):
        return 1.0, None
    z = float(stats.norm.isf((1.0 - level) / 2.0))
    half_t = float(stats.t.isf((1.0 - level) / 2.0, nu)) * t_scale
    rank = min(int(np.ceil((r.size + 1) * level)), r.size)
    half_data = float(np.sort(np.abs(r - loc))[rank - 1])
    return max(1.0, min(half_t, half_data) / (z * scale)), float(nu)


def interval_form(residual: np.ndarray, inliers: np.ndarray, scale: float, n_fitted: int,
                  level: float = 0.95) -> IntervalForm:
    """The interval's form from the held-out residuals (see the module's text).

    Parameters
    ----------
    residual : numpy.ndarray
        Held-out log residuals of every row. [1]
    inliers : numpy.ndarray of bool
        Rows that are not outliers (their count informs the scatter).
    scale : float
        The scatter of a new measurement (std of log μ). [1]
    n_fitted : int
        Values the model fitted. [1]
    level : float
        The interval's level. [1]

    Returns
    -------
    IntervalForm
    """
    dof = max(float(np.sum(inliers)) - n_fitted, 1.0)
    factor, tail_dof = tail_form(residual, scale, level)
    return IntervalForm(dof, factor, tail_dof)
