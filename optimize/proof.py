"""What a robust design proves and returns: its :class:`Proof` and the :class:`RobustResult`."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from .over_envelope import (
    Envelope,
)
from .solve import (
    OptimizationResult,
)

#: Relative gap between the certified lower bound and the worst case that counts as closed. [1]
GAP_TARGET = 1e-6


#: Proof fields present only for some methods (left out of :meth:`Proof.to_dict` when not set).
_OPTIONAL = ("rounds", "worst_case_boxes", "worst_case_relative_gap", "lower_bound_boxes",
             "upper_bound_certified")


@dataclass(frozen=True)
class Proof(Mapping):
    """What is proven about a robust design: the bracket of the best achievable worst case, and how.

    Read by attribute, or as the mapping of its JSON form (:meth:`to_dict`: ``proof["proven"]``), which the
    REST service returns.

    Attributes
    ----------
    proven : bool
        Whether the relative gap is within ``gap_target`` with both ends certified.
    method : str
        ``robust-gp-vertex``, ``outer-approximation-certified`` or ``outer-approximation-local``.
    lower_bound : float or None
        Certified lower bound on the best achievable worst case. [1]
    upper_bound : float
        The worst case at the design: exact, certified by branch and bound, or as searched when the method
        says no bound. [1]
    relative_gap : float or None
        (upper - lower) / upper. [1]
    statement : str
        The argument in words, written from the figures above by the method's formatter.
    gap_target : float
        The gap that counts as closed. [1]
    rounds : list of dict or None
        The outer approximation's rounds (``round``, ``points``, ``on_set``, ``searched``).
    worst_case_boxes : int or None
        Boxes of the branch and bound over the envelope at the design. [1]
    worst_case_relative_gap : float or None
        Its bracket. [1]
    lower_bound_boxes : int or None
        Boxes of the branch and bound over the designs (``mu_upper``). [1]
    upper_bound_certified : bool or None
        Whether the upper end is certified (``mu_upper`` with a lower bound over the designs).
    """

    proven: bool
    method: str
    lower_bound: float | None
    upper_bound: float
    relative_gap: float | None
    statement: str
    gap_target: float = GAP_TARGET
    rounds: list[dict[str, Any]] | None = None
    worst_case_boxes: int | None = None
    worst_case_relative_gap: float | None = None
    lower_bound_boxes: int | None = None
    upper_bound_certified: bool | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields (those of one method only)."""
        out = {"proven": self.proven, "method": self.method, "lower_bound": self.lower_bound,
               "upper_bound": self.upper_bound, "relative_gap": self.relative_gap,
               "gap_target": self.gap_target, "statement": self.statement}
        out.update({name: getattr(self, name) for name in _OPTIONAL if getattr(self, name) is not None})
        return out

    def __getitem__(self, key: str) -> Any:
        return self.to_dict()[key]

    def __iter__(self):
        return iter(self.to_dict())

    def __len__(self) -> int:
        return len(self.to_dict())

    def with_statement(self, more: str) -> Proof:
        """The proof with ``more`` appended to its statement."""
        return dataclasses.replace(self, statement=self.statement + more)


@dataclass(frozen=True)
class RobustResult:
    """The robust design, its worst case, what is proven and the price of robustness.

    Attributes
    ----------
    result : OptimizationResult
        The design (nominal groove angle), with ``mu`` the worst case of the objective over the
        envelope, its constraint report (the limits at their worst over the envelope) and per-count table.
    objective : str
        ``"mu"`` or ``"mu_upper"``.
    envelope : Envelope
        The envelope designed for.
    worst_case : dict
        ``{objective: value [1], "speed_m_s" [m/s], "groove_angle_deg" [deg] (the angle made),
        "conditions": {...}}``: where the worst case occurs at the returned design.
    proof : Proof
        What is proven, and how.
    price_of_robustness : dict
        ``nominal`` and ``robust``: each a design with its objective at the envelope's centre and its
        worst case over the envelope; ``ratio`` [1], the nominal design's worst case over the robust one's.
    """

    result: OptimizationResult
    objective: str
    envelope: Envelope
    worst_case: dict[str, Any]
    proof: Proof
    price_of_robustness: dict[str, Any]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready nested dict: the fields of :meth:`OptimizationResult.to_dict` and the robust ones."""
        return {**self.result.to_dict(), "objective": self.objective, "envelope": self.envelope.to_dict(),
                "worst_case": dict(self.worst_case), "proof": self.proof.to_dict(),
                "price_of_robustness": dict(self.price_of_robustness)}


def unshift(result: OptimizationResult, delta: float,
            extra: dict[str, Any] | None = None) -> OptimizationResult:
    """The result with every angle moved back from θ' to the nominal θ = θ' - δ."""
    if delta == 0 and not extra:
        return result
    design = {**result.design, "groove_angle_deg": result.design["groove_angle_deg"] - delta}
    rows = [dataclasses.replace(r, groove_angle_deg=None if r.groove_angle_deg is None
                                else r.groove_angle_deg - delta) for r in result.per_ball_count]
    ties = [{**t, "groove_angle_deg": t["groove_angle_deg"] - delta} for t in result.ties]
    constraints = [dataclasses.replace(c, value=c.value - delta, limit=c.limit - delta)
                   if c.name.startswith("groove_angle_deg") else c for c in result.constraints]
    return dataclasses.replace(result, design=design, per_ball_count=rows, ties=ties, constraints=constraints,
                               extra={**result.extra, **(extra or {})})


def worst_case_dict(objective: str, value: float, point: Mapping[str, Any],
                    nominal_deg: float) -> dict[str, Any]:
    """The worst case as a result states it: its value [1], speed [m/s], angle made [deg], conditions."""
    return {objective: float(value), "speed_m_s": float(point["speed_m_s"]),
            "groove_angle_deg": float(nominal_deg + point["groove_angle_offset_deg"]),
            "conditions": {n: float(v) for n, v in point["conditions"].items()}}


def design_of(result: OptimizationResult) -> dict[str, Any]:
    """The design variables of a result: ``balls`` [1], ``groove_angle_deg`` [deg], ``load_N`` [N]."""
    return {k: result.design[k] for k in ("balls", "groove_angle_deg", "load_N")}


def price_of(nominal_design: dict[str, Any], nominal_centre: float, nominal_worst: float, nominal_holds: bool,
             robust_design: dict[str, Any], robust_centre: float, robust_worst: float,
             nominal_upper: float | None = None, robust_upper: float | None = None) -> dict[str, Any]:
    """Both designs; ``*_upper``: a certified upper bound of each worst case [1] (None: searched only)."""
    def certified(upper: float | None) -> dict[str, Any]:
        return {"worst_case_certified": upper is not None,
                "worst_case_upper_bound": None if upper is None else float(upper)}

    return {
        "nominal": {"design": dict(nominal_design), "at_centre": float(nominal_centre),
                    "worst_case": float(nominal_worst), "limits_hold_over_envelope": bool(nominal_holds),
                    **certified(nominal_upper)},
        "robust": {"design": dict(robust_design), "at_centre": float(robust_centre),
                   "worst_case": float(robust_worst), "limits_hold_over_envelope": True,
                   **certified(robust_upper)},
        "ratio": float(nominal_worst / robust_worst),
    }
