"""Step 6 of the pipeline: the figures of a calibration report, as PNG bytes.

* ``effect_<k>``: for the k-th term added, its share of log μ against its
  driver (with units), the other columns at their medians, with the 95 %
  prediction band of a new measurement around it, over the data as component
  plus residual (the curve at each row's driver value plus the row's residual).
* ``residuals``: the calibrated model's residual against every varying input,
  the declared model's (before) in grey behind it.
* ``measured_vs_predicted``: measured against predicted μ on log axes, before
  and after, with the 1:1 line; its ticks are chosen for the data's range
  (:func:`log_ticks`: decades over a wide range, 1-2-5 or every digit over a
  narrow one, plain numbers below that), so both axes are labelled at any range.

Every plot writes the held-out errors before and after on itself and marks the
outliers (red crosses). Columns are drawn in the units the upload used (``speed [mm/s]``,
``relative humidity [%]``: :attr:`calibrate.Dataset.headers`, read back through the column registry
:mod:`physics.columns`); the model is evaluated in SI. Whole-number columns (ball counts, cycles) get
whole-number grids and ticks.
"""

from __future__ import annotations

import io
import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from microbearing.physics.columns import ColumnError, Reading, match_column, unit_of, whole_number

from .data import Dataset
from .model import CalibratedModel
from .prose import in_sent_words

__all__ = ["DrawnColumn", "calibration_figures", "calibration_plots", "log_ticks", "tick_texts"]

_GRID = 120


@dataclass(frozen=True)
class DrawnColumn:
    """A data column as the plots draw it: in the unit it was sent in (``reading`` None: its own).

    Attributes
    ----------
    name : str
        The column's name (its values in SI, as the model reads them).
    reading : physics.columns.Reading or None
        How its header as sent was read, to draw its values back in that unit.
    """

    name: str
    reading: Reading | None = None

    @classmethod
    def of(cls, dataset: Dataset, name: str) -> DrawnColumn:
        """The column ``name`` of the dataset, in the unit its header was sent in."""
        return cls(name, dataset.sent_reading(name))

    @classmethod
    def sent_as(cls, name: str, header: str | None) -> DrawnColumn:
        """The column ``name`` drawn in the unit of the key a request sent it under (``RH [%]``, read as
        the service read it: :func:`physics.columns.match_column`), in its own unit when ``header`` is None,
        names it so or no longer reads as it."""
        try:
            reading = None if header is None else match_column(header, [name])
        except ColumnError:
            return cls(name)
        return cls(name, reading if reading is not None and reading.reading else None)

    def shown(self, values: Any) -> np.ndarray:
        """Values (SI) in the unit drawn."""
        values = np.asarray(values, dtype=float)
        return values if self.reading is None else np.asarray(self.reading.sent_value(values), dtype=float)

    @property
    def label(self) -> str:
        """The axis label: the header as sent with its unit, or the name with its own unit."""
        if self.reading is not None:
            return self.reading.label
        unit = unit_of(self.name)
        unit = {"percent": "%", None: "1, as in the data"}.get(unit, unit)
        return f"{self.name} [{unit}]"

    @property
    def whole(self) -> bool:
        """Whether its values are whole numbers (:func:`physics.columns.whole_number`) as drawn."""
        return self.reading is None and whole_number(self.name)

    def tick(self, axis) -> None:
        """Whole-number ticks on a matplotlib axis (``ax.xaxis``) drawing this column, if it is whole."""
        from matplotlib.ticker import MaxNLocator

        if self.whole:
            axis.set_major_locator(MaxNLocator(integer=True))


def _grid(column: DrawnColumn, x: np.ndarray) -> np.ndarray:
    """Values of a column (SI) to draw a curve at over its data's range: whole numbers for a whole-number
    column (the physics refuses 4.067 balls), :data:`_GRID` even steps otherwise."""
    if not whole_number(column.name):
        return np.linspace(x.min(), x.max(), _GRID)
    return np.unique(np.round(np.linspace(np.ceil(x.min()), np.floor(x.max()), _GRID)))


def log_ticks(low: float, high: float, least: int = 3) -> list[float]:
    """Tick positions for a log axis over [low, high] with at least ``least`` ticks inside.

    Decades when the range holds ``least`` of them, else 1-2-5 steps, else every digit
    (1, 2, ..., 9 x 10^k), else evenly spaced round numbers: a log axis over less than a
    decade keeps numbered ticks.

    Examples
    --------
    >>> log_ticks(1e-4, 1.0)
    [0.0001, 0.001, 0.01, 0.1, 1.0]
    >>> log_ticks(0.004, 0.03)
    [0.005, 0.01, 0.02]
    >>> log_ticks(0.0112, 0.0125)
    [0.0112, 0.0116, 0.012, 0.0124]
    """
    if not (0 < low < high):
        raise ValueError(f"log_ticks needs 0 < low < high; got {low!r}, {high!r}")
    for subs in ((1,), (1, 2, 5), tuple(range(1, 10))):
        decades = range(int(np.floor(np.log10(low))), int(np.ceil(np.log10(high))) + 1)
        ticks = [float(f"{m}e{e}") for e in decades for m in subs]
        inside = [t for t in ticks if low <= t <= high]
        if len(inside) >= least:
            return inside
    from matplotlib.ticker import MaxNLocator

    for bins in range(least + 1, 4 * least + 1):
        values = MaxNLocator(nbins=bins, steps=[1, 2, 2.5, 4, 5, 10]).tick_values(low, high)
        inside = [float(f"{v:.6g}") for v in values if low <= v <= high]
        if len(inside) >= least:
            break
    return inside


def tick_texts(ticks: Sequence[float]) -> list[str]:
    """Labels of ticks: the fewest significant digits (3 or more) that write every tick exactly.

    >>> tick_texts([19.025, 19.05, 19.075, 19.1]), tick_texts([0.001, 0.01])
    (['19.025', '19.05', '19.075', '19.1'], ['0.001', '0.01'])
    """
    for digits in range(3, 16):
        texts = [f"{t:.{digits}g}" for t in ticks]
        if all(abs(float(text) - t) <= 1e-9 * abs(t) for text, t in zip(texts, ticks, strict=True)):
            return texts
    return [repr(float(t)) for t in ticks]


def _label_log_axes(ax, low: float, high: float) -> None:
    """Log x and y axes over [low, high] (padded 5 %), ticked by :func:`log_ticks`, every tick numbered."""
    from matplotlib.ticker import FixedFormatter, FixedLocator, NullFormatter, NullLocator

    pad = (high / low) ** 0.05 if high > low else 1.1
    low, high = low / pad, high * pad
    ticks = log_ticks(low, high)
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_locator(FixedLocator(ticks))
        axis.set_major_formatter(FixedFormatter(tick_texts(ticks)))
        axis.set_minor_locator(NullLocator())
        axis.set_minor_formatter(NullFormatter())
    ax.set_xlim(low, high)
    ax.set_ylim(low, high)


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


def _effect_figure(dataset: Dataset, model: CalibratedModel, k: int, outliers: np.ndarray, errors):
    plt = _pyplot()
    term, _ = model.terms[k]
    driver = term.drivers[0]
    drawn = DrawnColumn.of(dataset, driver)
    columns = dataset.columns()
    without = CalibratedModel(
        model.fitted, model.fixed, model.terms[:k] + model.terms[k + 1 :], model.convention
    )
    x = np.asarray(columns[driver], dtype=float)
    grid = _grid(drawn, x)
    # The other columns at a median row value (a whole ball count stays whole).
    typical = {
        n: np.full(grid.size, np.quantile(v, 0.5, method="nearest"))
        for n, v in columns.items() if n != driver
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
    x, grid = drawn.shown(x), drawn.shown(grid)  # in the upload's unit from here on
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
    ax.set_xlabel(drawn.label)
    ax.set_ylabel("log(mu / mu without the term) [-]")
    low, high = float(np.min(grid)), float(np.max(grid))
    ax.set_xlim(low - 0.02 * (high - low), high + 0.02 * (high - low))
    drawn.tick(ax.xaxis)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    # the term named by the column's header as sent, as its axis is
    wrapped = "\n".join(textwrap.wrap(_errors_text(errors), 80))
    ax.set_title(f"Term {k + 1}: {in_sent_words(dataset, term.label)}\n{wrapped}", fontsize=9)
    return fig


def _residuals_figure(
    dataset: Dataset, before: np.ndarray, after: np.ndarray, outliers: np.ndarray, errors, title: str
):
    plt = _pyplot()
    varying = [
        (DrawnColumn.of(dataset, n), np.asarray(v, dtype=float))
        for n, v in dataset.columns().items() if np.unique(v).size > 1
    ][:9]
    varying = [(column, column.shown(x)) for column, x in varying]
    if not varying:
        varying = [(DrawnColumn("row"), np.arange(1, dataset.n_points + 1, dtype=float))]
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
    for ax, (column, x) in zip(axes.flat, varying, strict=False):
        ax.scatter(x, before, s=6, color="0.7", label="before: fitted declared model")
        ax.scatter(x[~outliers], after[~outliers], s=8, alpha=0.6, label="after: calibrated model")
        if outliers.any():
            ax.scatter(x[outliers], after[outliers], marker="x", color="red", s=30, label="outliers")
        ax.axhline(0.0, color="0.3", lw=0.8)
        ax.set_xlabel(column.label if column.name != "row" else "row (data row)")
        ax.grid(alpha=0.3)
    for axis, (column, _) in zip(axes.flat, varying, strict=False):  # ball counts: whole ticks
        column.tick(axis.xaxis)
    for ax in axes.flat[len(varying) :]:
        ax.set_visible(False)
    for ax in axes[:, 0]:
        ax.set_ylabel("log(mu_measured / mu_model) [-]")
    axes[0][0].legend(fontsize=7)
    fig.suptitle(f"{title}\n{_errors_text(errors)}", fontsize=10)
    return fig


def _measured_figure(
    dataset: Dataset, mu_before: np.ndarray, mu_after: np.ndarray, outliers: np.ndarray, errors
):
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
    _label_log_axes(ax, lo, hi)
    ax.set_xlabel("predicted mu [-]")
    ax.set_ylabel("measured mu [-]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    ax.set_title("Measured against predicted\n" + "\n".join(textwrap.wrap(_errors_text(errors), 66)),
                 fontsize=9)
    return fig


def calibration_plots(*args, **kwargs) -> dict[str, bytes]:
    """Every figure of the report as PNG bytes by name (arguments of :func:`calibration_figures`)."""
    return {name: _png(fig) for name, fig in calibration_figures(*args, **kwargs).items()}


def calibration_figures(
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
    dict of str to matplotlib.figure.Figure
        The figures by name (the caller closes them; :func:`calibration_plots` saves them as PNG).
    """
    plots = {
        f"effect_{k + 1}": _effect_figure(dataset, model, k, outliers, errors)
        for k in range(len(model.terms))
    }
    # as the effects' titles name them
    named = {term.label: in_sent_words(dataset, term.label) for term, _ in model.terms}
    title = (
        ("Residuals after " + " + ".join(named.get(label, label) for label in labels))
        if labels
        else "Residuals: nothing added to the declared model"
    )
    plots["residuals"] = _residuals_figure(
        dataset,
        np.log(dataset.mu_measured / mu_before),
        np.log(dataset.mu_measured / mu_after),
        outliers,
        errors,
        title,
    )
    plots["measured_vs_predicted"] = _measured_figure(dataset, mu_before, mu_after, outliers, errors)
    from matplotlib.ticker import ScalarFormatter

    for fig in plots.values():
        for ax in fig.axes:
            for axis in (ax.xaxis, ax.yaxis):
                if axis.get_scale() == "linear":  # plain numbers, no offset over a narrow range
                    axis.set_major_formatter(ScalarFormatter(useOffset=False))
    return plots
