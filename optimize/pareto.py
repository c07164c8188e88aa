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

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

import physics

from .problem import DesignProblem
from .solve import TIE_TOLERANCE, InfeasibleDesignError, optimize_design

__all__ = ["PARETO_OBJECTIVES", "ParetoFront", "pareto_front"]

#: Second objectives: name -> (unit, True when larger is better).
PARETO_OBJECTIVES = {"load_N": ("N", True), "max_contact_pressure_Pa": ("Pa", False)}


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
        """The front as a PNG image (μ against the second objective, ball counts annotated)."""
        fig = Figure(figsize=(6.0, 4.2), dpi=100)
        FigureCanvasAgg(fig)
        ax = fig.add_subplot()
        x = [p["value"] for p in self.points]
        y = [p["mu"] for p in self.points]
        ax.plot(x, y, "o-", color="tab:blue")
        for p in self.points:
            ax.annotate(f"z={p['design']['balls']}", (p["value"], p["mu"]), textcoords="offset points",
                        xytext=(4, 4), fontsize=7)
        unit, larger_better = PARETO_OBJECTIVES[self.objective]
        ax.set_xscale("log")
        ax.set_xlabel(f"{self.objective} [{unit}] ({'larger' if larger_better else 'smaller'} is better)")
        ax.set_ylabel("mu [1]")
        ax.set_title(f"Pareto front: mu against {self.objective}", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        fig.tight_layout()
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png")
        return buffer.getvalue()


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
