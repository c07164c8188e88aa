"""Step 5 of the pipeline: how sure the calibrated model is, in figures and in words.

* :func:`find_outliers`: rows whose residual lies beyond :func:`outlier_threshold` robust standard
  deviations from the median residual (the rows the Huber loss down-weighted most), each with its row
  number, measured and predicted μ and standardized residual.
* :func:`noise_report`: with ``mu_measured_std``, the chi-square p-value of the final model and the
  unexplained scatter beside the declared noise.
* :func:`parameter_warnings`: declared parameters that moved by more than their 95 % interval when
  the terms were added (they were absorbing what the terms explain), and values on a bound.

The covariance of the fitted values is the sandwich of :func:`calibrate.fit.fit`; the intervals
themselves come from :meth:`calibrate.model.CalibratedModel.predict`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import stats

from .data import Dataset
from .fit import Z95, FitResult

__all__ = ["MAX_LISTED_OUTLIERS", "find_outliers", "noise_report", "outlier_threshold", "parameter_warnings"]

#: Outlier rows listed in a report at most (all are counted). [1]
MAX_LISTED_OUTLIERS = 200
# Efficiency of the median absolute deviation against the standard deviation on Gaussian data. [1]
_MAD_EFFICIENCY = 0.37


def outlier_threshold(n_points: int) -> float:
    """Standardized residual beyond which a row is an outlier: 5 % chance of any false flag on Gaussian data.

    Two-sided Bonferroni over the rows, at least 3.5, on Student's t with the degrees of freedom of the
    robust scale the residuals are standardized by: the median absolute deviation is 37 % efficient on
    Gaussian data, so from n rows it is known as well as a standard deviation from 0.37 (n - 1). On 15
    rows the normal quantile (3.5) flagged two Gaussian rows of 15 in some draws, and the scatter left by
    the others came out 1.2 % for a true 3 %.

    Examples
    --------
    >>> [round(outlier_threshold(n), 2) for n in (15, 200, 10_000)]
    [5.13, 3.85, 4.57]
    """
    n = max(n_points, 1)
    return max(3.5, float(stats.t.isf(0.05 / (2 * n), max(_MAD_EFFICIENCY * (n - 1), 1.0))))


def find_outliers(
    dataset: Dataset, mu_predicted: np.ndarray, residual: np.ndarray, scale: float,
    sent: np.ndarray | None = None,
) -> dict[str, Any]:
    """The rows the robust fit treats as gross outliers.

    Parameters
    ----------
    dataset : Dataset
        Measurements.
    mu_predicted : numpy.ndarray
        μ of the final model at every row. [1]
    residual : numpy.ndarray
        Its weighted log residual at every row. [1]
    scale : float
        Robust standard deviation of that residual. [1]
    sent : numpy.ndarray, optional
        Each row's index among the rows as sent (0-based), when some were left out before the fit (unit
        slips, :func:`calibrate.measurement.unit_slips`): rows are numbered as sent. None: the same rows.

    Returns
    -------
    dict
        ``count`` [1], ``threshold`` [1] (in robust standard deviations), ``rows`` (at most
        :data:`MAX_LISTED_OUTLIERS`, largest first: ``row`` 1-based, ``mu_measured``, ``mu_predicted``
        [1], ``standardized_residual`` [1], measured above the model when positive), ``mask`` (every
        row, not JSON) and ``summary`` in words.
    """
    threshold = outlier_threshold(dataset.n_points)
    # From the median residual: a model held off the data by a parameter on its bound misses every row
    # by about the same amount, which makes none of them an outlier (and at least half are inliers).
    z = -(residual - np.median(residual)) / scale
    mask = np.abs(z) > threshold
    order = np.flatnonzero(mask)[np.argsort(-np.abs(z[mask]))]
    rows = [
        {
            "row": int(i if sent is None else sent[i]) + 1,
            "mu_measured": float(dataset.mu_measured[i]),
            "mu_predicted": float(mu_predicted[i]),
            "standardized_residual": float(z[i]),
        }
        for i in order[:MAX_LISTED_OUTLIERS]
    ]
    count = int(mask.sum())
    if count == 0:
        summary = (
            f"no outliers: every row lies within {threshold:.2f} robust standard deviations of the model"
        )
    else:
        listed = ", ".join(str(r["row"]) for r in rows[:10]) + (", ..." if count > 10 else "")
        summary = (
            f"{count} of {dataset.n_points} rows ({100 * count / dataset.n_points:.1f} %) are outliers "
            f"beyond {threshold:.2f} robust standard deviations (rows {listed}); the robust fit "
            f"down-weighted them"
        )
    return {"count": count, "threshold": threshold, "rows": rows, "mask": mask, "summary": summary}


def noise_report(
    dataset: Dataset, mu_predicted: np.ndarray, n_parameters: int, inliers: np.ndarray
) -> dict[str, Any] | None:
    """Chi-square test of the final model against the declared ``mu_measured_std`` (None without it).

    Parameters
    ----------
    dataset : Dataset
        Measurements with ``mu_measured_std``.
    mu_predicted : numpy.ndarray
        μ of the final model at every row. [1]
    n_parameters : int
        Fitted values in the model. [1]
    inliers : numpy.ndarray
        Rows that are not outliers (the test is on them).

    Returns
    -------
    dict or None
        ``chi2_p_value`` [1], ``declared_noise`` and ``unexplained_scatter`` (median relative
        standard deviations of μ [1]: declared, and the declared scaled by the RMS of the
        standardized residual), ``statement`` in words.
    """
    if dataset.mu_measured_std is None:
        return None
    relative = dataset.mu_measured_std / dataset.mu_measured
    standardized = np.log(mu_predicted / dataset.mu_measured)[inliers] / relative[inliers]
    dof = max(int(inliers.sum()) - n_parameters, 1)
    chi2 = float(np.sum(standardized**2))
    p = float(stats.chi2.sf(chi2, dof))
    declared = float(np.median(relative))
    scatter = declared * float(np.sqrt(chi2 / dof))
    if p < 0.01 and scatter > declared:
        statement = (
            f"unexplained scatter: {100 * scatter:.3g} % vs {100 * declared:.3g} % declared "
            f"(chi-square p = {p:.3g}): the model misses something, or the declared noise is too small"
        )
    elif p > 0.99:
        statement = (
            f"the residual is smaller than the declared noise ({100 * scatter:.3g} % vs "
            f"{100 * declared:.3g} %, chi-square p = {p:.3g}): mu_measured_std looks too large"
        )
    else:
        statement = (
            f"the residual is consistent with the declared noise ({100 * scatter:.3g} % vs "
            f"{100 * declared:.3g} %, chi-square p = {p:.3g})"
        )
    return {
        "chi2_p_value": p,
        "declared_noise": declared,
        "unexplained_scatter": scatter,
        "statement": statement,
    }


def parameter_warnings(before: FitResult, after: FitResult) -> list[str]:
    """Sentences on declared parameters that moved beyond their 95 % interval, and values on a bound.

    Parameters
    ----------
    before : FitResult
        The declared-only fit.
    after : FitResult
        The fit with the chosen terms.

    Returns
    -------
    list of str
    """
    warnings = []
    before_std, after_std = before.declared_std, after.declared_std
    for name, value in after.declared.items():
        old = before.declared[name]
        margin = Z95 * float(np.hypot(before_std[name], after_std[name]))
        if after.terms and abs(value - old) > margin:
            sigmas = abs(value - old) / max(float(np.hypot(before_std[name], after_std[name])), 1e-300)
            warnings.append(
                f"{name} moved from {old:.6g} +/- {before_std[name]:.2g} to {value:.6g} +/- "
                f"{after_std[name]:.2g} ({sigmas:.0f} standard deviations) when "
                f"{', '.join(t.label for t in after.terms)} was added: the declared model alone "
                f"bent it to absorb what the added terms explain"
            )
    for fit, which in ((after, "calibrated model"), (before, "declared-only fit")):
        for name in fit.at_bound:
            warnings.append(
                f"{name} ended on a bound of its range in the {which}: its value is limited by "
                f"the bound, not by the data, and its interval is not meaningful"
            )
        for name in fit.unidentified:
            warnings.append(
                f"{name} is not identified by the data in the {which}: it trades off with another fitted "
                f"value (a near-singular direction of the fit), so its standard deviation is reported at "
                f"least as large as its value, not the pseudo-inverse's"
            )
    return warnings
