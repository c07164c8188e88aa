"""Trade-offs: the Pareto front of μ against load capacity or contact pressure.

By the epsilon-constraint method: the certified optimizer
:func:`optimize.solve.optimize_design` is run with the second objective turned
into a limit at each of several levels ε,

* ``"load_N"`` (more is better): ``min_load_capacity_N = ε`` for ε from the load
  of the minimum-μ design up to the upper load bound,
* ``"max_contact_pressure_Pa"`` (less is better): ``max_contact_pressure_Pa = ε``
  for ε from the lowest pressure in the box down from the pressure of the
  minimum-μ design,

levels spaced geometrically. Each point is a global optimum for its level, so
the points are Pareto optimal (weakly; dominated ones are dropped). Levels
that no design can meet are left out and counted.
"""

from __future__ import annotations

import io
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter, ScalarFormatter

from microbearing import physics

from .problem import DesignProblem
from .solve import TIE_TOLERANCE, InfeasibleDesignError, optimize_design

__all__ = ["PARETO_OBJECTIVES", "ParetoFront", "pareto_front"]

#: Second objectives: name -> (unit, True when larger is better).
PARETO_OBJECTIVES = {"load_N": ("N", True), "max_contact_pressure_Pa": ("Pa", False)}
#: How the plot shows each objective: axis name, the unit a designer reads, factor from SI.
_PLOT_UNITS = {"load_N": ("load capacity G", "mN", 1e3),
               "max_contact_pressure_Pa": ("peak contact pressure", "MPa", 1e-6)}


@dataclass(frozen=True)
class ParetoFront:
    """Pareto-optimal designs of μ against a second objective.

    Attributes
    ----------
    objective : str
        A key of :data:`PARETO_OBJECTIVES`.
    points : list of dict
        Ordered by the second objective: ``level`` (ε) [unit of the objective],
        ``mu`` [1], ``value`` (the objective at the design) [unit], ``design``
        (``balls`` [1], ``groove_angle_deg`` [deg], ``load_N`` [N]).
    infeasible_levels : int
        Levels ε that no design could meet. [1]
    """

    objective: str
    points: list[dict[str, Any]]
    infeasible_levels: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields."""
        return {"objective": self.objective, "unit": PARETO_OBJECTIVES[self.objective][0],
                "points": [dict(p) for p in self.points], "infeasible_levels": self.infeasible_levels}

    def to_png(self) -> bytes:
        """The front as a PNG image drawn for a bearing designer (:meth:`figure`), saved with a tight
        bounding box, so no label is cut at the edges."""
        buffer = io.BytesIO()
        self.figure().savefig(buffer, format="png", bbox_inches="tight", pad_inches=0.15)
        return buffer.getvalue()

    def figure(self) -> Figure:
        """The front drawn for a bearing designer, as a matplotlib figure.

        The upper panel shows μ against the second objective in the units a designer reads
        (contact pressure in MPa, load in mN), one marker and colour per ball count z with a
        key; the panels below show the design along the front, each quantity in a panel of its
        own so that none hides another (a constant one is a flat, labelled line): the load
        carried [mN] (for the pressure front) and the groove angle [deg]. A second objective
        spanning more than 20x is on a log axis ticked at 1-2-5 steps (at least three labels).
        """
        if not self.points:
            raise ValueError("the front has no points to plot")
        name, unit, scale = _PLOT_UNITS[self.objective]
        larger_better = PARETO_OBJECTIVES[self.objective][1]
        x = np.array([p["value"] for p in self.points]) * scale
        mu = np.array([p["mu"] for p in self.points])
        balls = np.array([p["design"]["balls"] for p in self.points])
        load_mN = np.array([p["design"]["load_N"] for p in self.points]) * 1e3
        angle = np.array([p["design"]["groove_angle_deg"] for p in self.points])

        pressure = self.objective != "load_N"
        fig = Figure(figsize=(7.0, 7.4 if pressure else 6.2), dpi=100, layout="constrained")
        FigureCanvasAgg(fig)
        panels = fig.subplots(3 if pressure else 2, 1, sharex=True,
                              height_ratios=(3, 1.5, 1.5) if pressure else (3, 2))
        top, bottom = panels[0], panels[-1]
        top.plot(x, mu, "-", color="0.6", zorder=1)
        markers = "osD^vP*Xhp<>"
        colours = matplotlib.colormaps["tab10"]
        for k, z in enumerate(np.unique(balls)):
            at = balls == z
            top.scatter(x[at], mu[at], marker=markers[k % len(markers)], color=colours(k % 10), s=45,
                        zorder=2, label=f"z = {z} balls")
        top.legend(title="ball count z (both grooves)", fontsize=8, title_fontsize=8, loc="best")
        top.set_ylabel("friction coefficient μ [-]")
        better = "higher" if larger_better else "lower"
        title = f"Pareto front: least friction against {name} ({better} is better)"
        if self.infeasible_levels:
            # asked for more points than were found: say so where the designer looks
            title += (f"\n{len(self.points)} of {len(self.points) + self.infeasible_levels} levels: "
                      f"{self.infeasible_levels} infeasible under the limits")
        top.set_title(title, fontsize=10)
        top.grid(True, alpha=0.3)

        if pressure:
            panels[1].plot(x, load_mN, "o-", color="tab:purple")
            panels[1].set_ylabel("load carried\nG [mN]", color="tab:purple")
        bottom.plot(x, angle, "s-", color="tab:green")
        bottom.set_ylabel("groove angle\nθ [deg]", color="tab:green")
        for panel in panels:
            panel.grid(True, alpha=0.3)
            # plain numbers, no offset: a narrow range reads "0.0112", not "0.0002 + 1.1e-2"
            panel.yaxis.set_major_formatter(ScalarFormatter(useOffset=False))
        bottom.set_xlabel(f"{name} [{unit}]")
        if x.max() > 20 * x.min():
            top.set_xscale("log")
            bottom.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
            bottom.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:.3g}"))
            bottom.xaxis.set_minor_formatter(NullFormatter())
        else:
            bottom.xaxis.set_major_formatter(ScalarFormatter(useOffset=False))
        return fig


def _value(problem: DesignProblem, objective: str, design: dict[str, Any]) -> float:
    if objective == "load_N":
        return float(design["load_N"])
    r = physics.evaluate(convention=problem.convention, **problem.physics_inputs(
        design["balls"], design["groove_angle_deg"], design["load_N"]))
    return float(r.max_contact_pressure_Pa)


def pareto_front(problem: DesignProblem, objective: str = "load_N", points: int = 10,
                 progress: Callable[[float], None] | None = None) -> ParetoFront:
    """Pareto front of μ against load capacity or contact pressure by epsilon-constraint solves.

    Parameters
    ----------
    problem : DesignProblem
        The design problem; its own limits stay in force.
    objective : {"load_N", "max_contact_pressure_Pa"}
        The second objective. [-]
    points : int, default 10
        Number of levels ε, 2 to 50. [1]
    progress : callable, optional
        Called with the fraction of levels done, 0..1. [1]

    Returns
    -------
    ParetoFront
        The non-dominated designs found.

    Raises
    ------
    ValueError
        For an unknown objective or ``points`` outside [2, 50].
    InfeasibleDesignError
        When the problem itself is infeasible.
    """
    if objective not in PARETO_OBJECTIVES:
        raise ValueError(f"objective must be one of {', '.join(PARETO_OBJECTIVES)}; got {objective!r}")
    if isinstance(points, bool) or not isinstance(points, int) or not 2 <= points <= 50:
        raise ValueError(f"points must be a whole number in [2, 50]; got {points!r}")
    best = optimize_design(problem)
    start = _value(problem, objective, best.design)
    limits = problem.constraints
    if objective == "load_N":
        end = problem.bounds.load_N[1]
        field = "min_load_capacity_N"
    else:
        floor = max(problem.bounds.load_N[0], limits.min_load_capacity_N or 0.0)
        # the pressure grows with G and theta and falls with z: its least value in the box is at this corner
        corner = {"balls": max(problem.ball_counts()), "load_N": floor,
                  "groove_angle_deg": problem.bounds.groove_angle_deg[0]}
        end = _value(problem, objective, corner)
        field = "max_contact_pressure_Pa"
        if limits.max_contact_pressure_Pa is not None:
            start = min(start, limits.max_contact_pressure_Pa)
    levels = np.geomspace(start, end, points) if end != start else np.array([start])
    found, infeasible = [], 0
    for i, level in enumerate(levels):
        if i == 0:
            result = best
        else:
            try:
                limited = replace(problem, constraints=replace(limits, **{field: float(level)}))
                result = optimize_design(limited)
            except InfeasibleDesignError:
                infeasible += 1
                result = None
        if result is not None:
            found.append({"level": float(level), "mu": result.mu, "value": _value(problem, objective,
                                                                                  result.design),
                          "design": dict(result.design)})
        if progress is not None:
            progress((i + 1) / len(levels))
    larger_better = PARETO_OBJECTIVES[objective][1]
    sign = -1.0 if larger_better else 1.0  # both objectives as "smaller is better"

    def dominates(q, p):
        # μ within the tie tolerance counts as equal: solver rounding must not decide dominance
        no_worse = q["mu"] <= p["mu"] * (1 + TIE_TOLERANCE) and sign * q["value"] <= sign * p["value"]
        better = q["mu"] < p["mu"] * (1 - TIE_TOLERANCE) or sign * q["value"] < sign * p["value"]
        return no_worse and better

    front = [p for p in found if not any(dominates(q, p) for q in found)]
    front.sort(key=lambda p: p["value"])
    return ParetoFront(objective, front, infeasible)
