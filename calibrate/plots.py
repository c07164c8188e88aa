"""Step 6 of the pipeline: the figures of a calibration report, as PNG bytes.

* ``effect_<k>``: for the k-th term added, its share of log μ against its
  driver (with units), the other columns at their medians, with the 95 %
  prediction band of a new measurement around it, over the data as component
  plus residual (the curve at each row's driver value plus the row's residual).
* ``residuals``: the calibrated model's residual against every varying input,
  the declared model's (before) in grey behind it.
* ``measured_vs_predicted``: measured against predicted μ on log axes, before
  and after, with the 1:1 line.

Every plot writes the held-out errors before and after on itself and marks the
outliers (red crosses).
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from microbearing import physics

from .data import Dataset
from .model import CalibratedModel

__all__ = ["calibration_plots"]

_GRID = 120


def _unit(name: str) -> str:
    spec = physics.PARAMETERS.get(name)
    if spec is not None:
        return f" [{spec.unit}]"
    words = name.lower().split("_")
    for suffix, unit in (
        ("c", "degC"),
        ("k", "K"),
        ("pct", "%"),
        ("percent", "%"),
        ("um", "um"),
        ("s", "s"),
        ("m", "m"),
    ):
        if len(words) > 1 and words[-1] == suffix:
            return f" [{unit}]"
    return " [1, as in the data]"


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _png(fig) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=90)
    _pyplot().close(fig)
    return buffer.getvalue()


def _errors_text(errors: Mapping[str, Any]) -> str:
    text = (
        f"held-out relative RMSE of mu: before {errors['before']['relative_rmse']:.3g}, "
        f"after {errors['after']['relative_rmse']:.3g} (nested CV)"
    )
    robust = errors.get("robust")
    if robust and robust["excluded_rows"]:
        text += (f"; without the {robust['excluded_rows']} outliers: {robust['before']['relative_rmse']:.3g}"
                 f" -> {robust['after']['relative_rmse']:.3g}")
    return text


def _effect_png(dataset: Dataset, model: CalibratedModel, k: int, outliers: np.ndarray, errors) -> bytes:
    plt = _pyplot()
    term, _ = model.terms[k]
    driver = term.drivers[0]
    columns = dataset.columns()
    without = CalibratedModel(
        model.fitted, model.fixed, model.terms[:k] + model.terms[k + 1 :], model.convention
    )
    x = np.asarray(columns[driver], dtype=float)
    grid = np.linspace(x.min(), x.max(), _GRID)
    # The other columns at a median row value (a whole ball count stays whole).
    typical = {
        n: np.full(_GRID, np.quantile(v, 0.5, method="nearest")) for n, v in columns.items() if n != driver
    }
    typical[driver] = grid
    prediction = model.predict(typical)
    base = without(typical)
    curve = np.log(prediction.mu / base)
    # Component plus residual: the term's share at a row's driver value (others at their medians) plus
    # the row's residual, so that the points scatter about the curve as the data do about the model.
    with np.errstate(all="ignore"):
        partial = np.interp(x, grid, curve) + np.log(dataset.mu_measured / model(columns))
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    ax.scatter(x[~outliers], partial[~outliers], s=8, alpha=0.5, label="data: term + residual")
    if outliers.any():
        ax.scatter(x[outliers], partial[outliers], marker="x", color="red", s=30, label="outliers")
    ax.plot(grid, curve, color="black", lw=1.2, label="fitted term (others at their medians)")
    if prediction.mu_lower is not None:
        # Edges drawn over the points: with thousands of rows the shaded band alone is hidden.
        lower, upper = np.log(prediction.mu_lower / base), np.log(prediction.mu_upper / base)
        ax.fill_between(grid, lower, upper, color="0.5", alpha=0.25, label="95 % band of a new measurement")
        for edge in (lower, upper):
            ax.plot(grid, edge, color="black", lw=0.8, ls="--", zorder=3)
    ax.set_xlabel(f"{driver}{_unit(driver)}")
    ax.set_ylabel("log(mu / mu without the term) [-]")
    ax.set_xlim(grid[0] - 0.02 * (grid[-1] - grid[0]), grid[-1] + 0.02 * (grid[-1] - grid[0]))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title(f"Term {k + 1}: {term.label}\n{_errors_text(errors)}", fontsize=9)
    return _png(fig)


def _residuals_png(
    dataset: Dataset, before: np.ndarray, after: np.ndarray, outliers: np.ndarray, errors, title: str
) -> bytes:
    plt = _pyplot()
    varying = [
        (n, np.asarray(v, dtype=float)) for n, v in dataset.columns().items() if np.unique(v).size > 1
    ][:9]
    if not varying:
        varying = [("row", np.arange(1, dataset.n_points + 1, dtype=float))]
    columns = min(3, len(varying))
    rows = -(-len(varying) // columns)
    fig, axes = plt.subplots(
        rows,
        columns,
        figsize=(4.2 * columns, 3.3 * rows + 0.6),
        squeeze=False,
        sharey=True,
        constrained_layout=True,
    )
    for ax, (name, x) in zip(axes.flat, varying, strict=False):
        ax.scatter(x, before, s=6, color="0.7", label="before: fitted declared model")
        ax.scatter(x[~outliers], after[~outliers], s=8, alpha=0.6, label="after: calibrated model")
        if outliers.any():
            ax.scatter(x[outliers], after[outliers], marker="x", color="red", s=30, label="outliers")
        ax.axhline(0.0, color="0.3", lw=0.8)
        ax.set_xlabel(f"{name}{_unit(name) if name != 'row' else ' (data row)'}")
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(varying) :]:
        ax.set_visible(False)
    for ax in axes[:, 0]:
        ax.set_ylabel("log(mu_measured / mu_model) [-]")
    axes[0][0].legend(fontsize=7)
    fig.suptitle(f"{title}\n{_errors_text(errors)}", fontsize=10)
    return _png(fig)


def _measured_png(
    dataset: Dataset, mu_before: np.ndarray, mu_after: np.ndarray, outliers: np.ndarray, errors
) -> bytes:
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.2, 5.0), constrained_layout=True)
    measured = dataset.mu_measured
    ax.scatter(mu_before, measured, s=6, color="0.7", label="before: fitted declared model")
    ax.scatter(mu_after[~outliers], measured[~outliers], s=8, alpha=0.6, label="after: calibrated model")
    if outliers.any():
        ax.scatter(mu_after[outliers], measured[outliers], marker="x", color="red", s=30, label="outliers")
    lo = float(min(measured.min(), mu_before.min(), mu_after.min()))
    hi = float(max(measured.max(), mu_before.max(), mu_after.max()))
    ax.plot([lo, hi], [lo, hi], color="black", lw=0.8, label="measured = predicted")
    ax.set_xscale("log")
    ax.set_yscale("log")
    from matplotlib.ticker import NullFormatter

    for axis in (ax.xaxis, ax.yaxis):
        axis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("predicted mu [-]")
    ax.set_ylabel("measured mu [-]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    ax.set_title(f"Measured against predicted\n{_errors_text(errors)}", fontsize=9)
    return _png(fig)


def calibration_plots(
    dataset: Dataset,
    model: CalibratedModel,
    mu_before: np.ndarray,
    mu_after: np.ndarray,
    outliers: np.ndarray,
    errors: Mapping[str, Mapping[str, float]],
    labels: Sequence[str],
) -> dict[str, bytes]:
    """Every figure of the report.

    Parameters
    ----------
    dataset : Dataset
        Measurements.
    model : CalibratedModel
        The calibrated model.
    mu_before : numpy.ndarray
        μ of the fitted declared model at every row. [1]
    mu_after : numpy.ndarray
        μ of the calibrated model at every row. [1]
    outliers : numpy.ndarray
        Boolean mask of the outlier rows.
    errors : mapping
        ``{"before": ..., "after": ...}`` held-out errors (:func:`calibrate.fit.prediction_errors`) and
        optionally ``"robust"``, the report's ``robust_errors``.
    labels : sequence of str
        The terms added, in order (for the titles).

    Returns
    -------
    dict of str to bytes
        PNG images by name.
    """
    plots = {
        f"effect_{k + 1}": _effect_png(dataset, model, k, outliers, errors) for k in range(len(model.terms))
    }
    title = (
        ("Residuals after " + " + ".join(labels))
        if labels
        else "Residuals: nothing added to the declared model"
    )
    plots["residuals"] = _residuals_png(
        dataset,
        np.log(dataset.mu_measured / mu_before),
        np.log(dataset.mu_measured / mu_after),
        outliers,
        errors,
        title,
    )
    plots["measured_vs_predicted"] = _measured_png(dataset, mu_before, mu_after, outliers, errors)
    return plots
