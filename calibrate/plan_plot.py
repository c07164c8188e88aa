"""The plot of a proposal of runs (:class:`calibrate.experiments.ExperimentPlan`), drawn from its document:
the proposed runs over the data taken and the envelope, and for ``discriminate`` the rivals' predictions."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from microbearing import physics

__all__ = ["plan_png"]


def _axis_label(name: str) -> str:
    spec = physics.PARAMETERS.get(name)
    return f"{name} [{spec.unit}]" if spec is not None else f"{name} [as in the data]"


def plan_png(document: Mapping[str, Any]) -> bytes:
    """The plot of a proposal (:meth:`ExperimentPlan.to_dict`) as PNG bytes.

    Left: the proposed runs (red, the area grows with the replicates) over the data taken (grey) on
    the two columns of the space that vary most in the runs. Right, for ``discriminate``: μ of the
    calibrated model and of each rival along the first column, the others at the runs' medians, with
    the runs' values of that column marked.
    """
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    plot = document["plot"]
    axes_names = list(plot["axes"])
    curves = plot.get("curves") or []
    figure, panels = plt.subplots(1, 2 if curves else 1, figsize=(11 if curves else 6, 4.5), squeeze=False)
    ax = panels[0][0]
    x_name = axes_names[0] if axes_names else None
    y_name = axes_names[1] if len(axes_names) > 1 else None
    runs = plot["runs"]
    data = plot.get("data") or {}
    if x_name is not None:
        xs = np.asarray(runs[x_name], dtype=float)
        ys = np.asarray(runs[y_name], dtype=float) if y_name else np.zeros_like(xs)
        if x_name in data and (y_name is None or y_name in data):
            dx = np.asarray(data[x_name], dtype=float)
            dy = np.asarray(data[y_name], dtype=float) if y_name else np.zeros_like(dx)
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
        if x_name in box:
            (x0, x1) = box[x_name]
            (y0, y1) = box[y_name] if y_name in box else ax.get_ylim()
            # A single value is drawn as a thin band, 2 % of the axis.
            (xa, xb), (ya, yb) = ax.get_xlim(), ax.get_ylim()
            if x1 - x0 < 0.02 * (xb - xa):
                x0, x1 = (x0 + x1) / 2 - 0.01 * (xb - xa), (x0 + x1) / 2 + 0.01 * (xb - xa)
            if y1 - y0 < 0.02 * (yb - ya):
                y0, y1 = (y0 + y1) / 2 - 0.01 * (yb - ya), (y0 + y1) / 2 + 0.01 * (yb - ya)
            ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, facecolor=(0.12, 0.47, 0.71, 0.2),
                                   edgecolor="tab:blue", linewidth=1.5,
                                   label="envelope (where the model is used)"))
        ax.set_xlabel(_axis_label(x_name))
        ax.set_ylabel(_axis_label(y_name) if y_name else "")
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, fontsize=8)
    ax.set_title(f"goal {document['goal']}: efficiency >= {document['efficiency_lower_bound']:.3f}")
    if curves:
        right = panels[0][1]
        for k, curve in enumerate(curves):
            right.plot(curve["x"], curve["mu"], lw=2.5 if k == 0 else 1.5, ls="-" if k == 0 else "--",
                       label=curve["label"][:60])
        for value in np.unique(np.asarray(runs[x_name], dtype=float)):
            right.axvline(value, color="red", alpha=0.3, lw=1)
        right.set_xlabel(_axis_label(x_name))
        right.set_ylabel("mu [1]")
        others = ", ".join(f"{k} = {v:.3g}" for k, v in (plot.get("others") or {}).items())
        right.set_title(f"rivals' predictions ({others})", fontsize=8)
        right.legend(loc="best", fontsize=7)
    figure.tight_layout()
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=90, bbox_inches="tight", pad_inches=0.1)
    plt.close(figure)
    return buffer.getvalue()
