"""The plot of a proposal of runs (:class:`calibrate.experiments.ExperimentPlan`), drawn from its document:
the proposed runs over the data taken and the envelope, and for ``discriminate`` the rivals' predictions.

Each column is drawn in the unit and under the key the request sent it in (``load [mN]``, ``RH [%]``:
the document's ``plot["sent_as"]``, read back through the column registry :mod:`physics.columns`), else
in its own unit; ball counts get whole ticks.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from .plots import DrawnColumn
from .prose import with_headers

__all__ = ["plan_figure", "plan_png"]


def _columns(plot: Mapping[str, Any]) -> dict[str, DrawnColumn]:
    """The plot's axes as drawn: each in the unit of the key it was sent under (``plot["sent_as"]``, which
    the service adds: ``{"relative_humidity": "RH [%]"}``), else in its own unit."""
    sent_as = plot.get("sent_as") or {}
    return {name: DrawnColumn.sent_as(name, sent_as.get(name)) for name in plot["axes"]}


def plan_png(document: Mapping[str, Any]) -> bytes:
    """The plot of a proposal (:func:`plan_figure`) as PNG bytes."""
    import io

    import matplotlib.pyplot as plt

    figure = plan_figure(document)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=90, bbox_inches="tight", pad_inches=0.1)
    plt.close(figure)
    return buffer.getvalue()


def plan_figure(document: Mapping[str, Any]):
    """The plot of a proposal (:meth:`ExperimentPlan.to_dict`) as a matplotlib figure.

    Left: the proposed runs (red, the area grows with the replicates) over the data taken (grey) on
    the two columns of the space that vary most in the runs. Right, for ``discriminate``: μ of the
    calibrated model and of each rival along the first column, the others at the runs' medians, with
    the runs' values of that column marked.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plot = document["plot"]
    columns = _columns(plot)
    curves = plot.get("curves") or []
    figure, panels = plt.subplots(1, 2 if curves else 1, figsize=(11 if curves else 6, 4.5), squeeze=False)
    ax = panels[0][0]
    drawn = list(columns.values())
    if drawn:
        _runs_panel(ax, plot, drawn[0], drawn[1] if len(drawn) > 1 else None)
    ax.set_title(f"goal {document['goal']}: efficiency >= {document['efficiency_lower_bound']:.3f}")
    if curves and drawn:
        _rivals_panel(panels[0][1], plot, drawn[0])
    figure.tight_layout()
    return figure


def _runs_panel(ax, plot: Mapping[str, Any], x: DrawnColumn, y: DrawnColumn | None) -> None:
    """The proposed runs over the data taken and the envelope, on the columns ``x`` and ``y``."""
    from matplotlib.patches import Rectangle

    runs, data = plot["runs"], plot.get("data") or {}
    xs = x.shown(runs[x.name])
    ys = y.shown(runs[y.name]) if y else np.zeros_like(xs)
    if x.name in data and (y is None or y.name in data):
        dx = x.shown(data[x.name])
        dy = y.shown(data[y.name]) if y else np.zeros_like(dx)
        ax.scatter(dx, dy, s=10, c="0.6", label=f"data taken ({dx.size})")
    pairs, counts = np.unique(np.column_stack([xs, ys]), axis=0, return_counts=True)
    ax.scatter(pairs[:, 0], pairs[:, 1], s=30 + 25 * counts, facecolors="none", edgecolors="red",
               linewidths=2, label=f"proposed runs ({xs.size}, {pairs.shape[0]} settings)")
    ax.margins(x=0.08, y=0.12)  # room for a replicate count at a corner of the space
    (xa, xb), (ya, yb) = ax.get_xlim(), ax.get_ylim()
    for (px, py), count in zip(pairs, counts, strict=True):
        if count > 1:
            # the count is written towards the middle of the panel, so a run at an edge keeps it inside
            right, up = px <= (xa + xb) / 2, py <= (ya + yb) / 2
            ax.annotate(f"x{count}", (px, py), textcoords="offset points",
                        xytext=(6 if right else -6, 6 if up else -6), fontsize=8, color="red",
                        ha="left" if right else "right", va="bottom" if up else "top")
    box = plot.get("envelope") or {}
    if x.name in box:
        x0, x1 = sorted(x.shown(box[x.name]))  # an affine unit (degF) keeps the order; sorted all the same
        y0, y1 = sorted(y.shown(box[y.name])) if y and y.name in box else ax.get_ylim()
        # A single value is drawn as a thin band, 2 % of the axis.
        (xa, xb), (ya, yb) = ax.get_xlim(), ax.get_ylim()
        if x1 - x0 < 0.02 * (xb - xa):
            x0, x1 = (x0 + x1) / 2 - 0.01 * (xb - xa), (x0 + x1) / 2 + 0.01 * (xb - xa)
        if y1 - y0 < 0.02 * (yb - ya):
            y0, y1 = (y0 + y1) / 2 - 0.01 * (yb - ya), (y0 + y1) / 2 + 0.01 * (yb - ya)
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, facecolor=(0.12, 0.47, 0.71, 0.2),
                               edgecolor="tab:blue", linewidth=1.5,
                               label="envelope (where the model is used)"))
    ax.set_xlabel(x.label)
    ax.set_ylabel(y.label if y else "")
    x.tick(ax.xaxis)
    if y is not None:
        y.tick(ax.yaxis)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, fontsize=8)


def _rivals_panel(ax, plot: Mapping[str, Any], x: DrawnColumn) -> None:
    """μ of the calibrated model and of each rival along the column ``x``, the runs' values marked."""
    sent_as = plot.get("sent_as") or {}
    for k, curve in enumerate(plot["curves"]):
        ax.plot(x.shown(curve["x"]), curve["mu"], lw=2.5 if k == 0 else 1.5, ls="-" if k == 0 else "--",
                label=with_headers(curve["label"], sent_as)[:60])
    for value in np.unique(x.shown(plot["runs"][x.name])):
        ax.axvline(value, color="red", alpha=0.3, lw=1)
    ax.set_xlabel(x.label)
    x.tick(ax.xaxis)
    ax.set_ylabel("mu [1]")
    others = ", ".join(_other_words(name, value, sent_as.get(name))
                       for name, value in (plot.get("others") or {}).items())
    ax.set_title(f"rivals' predictions ({others})", fontsize=8)
    ax.legend(loc="best", fontsize=7)


def _other_words(name: str, value: float, header: str | None) -> str:
    """A column held fixed along the rivals' curves, in the unit it was sent in (``load [mN] = 3``)."""
    column = DrawnColumn.sent_as(name, header)
    if column.reading is None:
        return f"{name} = {value:.3g}"
    return f"{column.label} = {float(column.shown(value)):.3g}"
