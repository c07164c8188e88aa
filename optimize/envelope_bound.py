r"""A certified upper bound of a calibrated model's μ over an envelope at one design, by branch and bound.

At a fixed design (balls z, load G, nominal angle θ) a calibrated model's μ over the envelope is the
physics' μ, with the model's fitted values, followed by its effect terms in order, each either *added*
(μ + a(x)) or *multiplying* (μ m(x), m > 0), each a function of one driver x (the speed or a condition;
the design's balls and load are fixed). Both forms are non-decreasing in μ and in their own piece, so
over a box of the envelope

    μ(x) <= compose(μ_phys^max(box), a^max(box), m^max(box), ...)

with each maximum exact:

* the physics' μ is a posynomial with positive coefficients in tan θ and the speed
  (:mod:`optimize.dgp`), so its maximum over a box is at the box's highest angle made and speed;
* every effect of :data:`_PIECES` is monotone in its driver (its formula in :mod:`physics.effects`)
  except ``generic_quadratic``, exp(c1 z + c2 z²), whose maximum over an interval is at an end or at the
  stationary point z = -c1 / (2 c2); so each piece's maximum over the box's driver interval is the
  largest of its values at the interval's ends (and that point when inside).

The bound is exact where every piece peaks at the same point (a vertex, or the stationary point of a
lone quadratic), and otherwise over-estimates by at most the pieces' variation across the box. Branch
and bound (the box of largest bound split in half along its widest axis, relative to the envelope)
narrows it until the largest bound left is within ``rtol`` of the largest value of the model itself
found (at every box's centre and at the point where its pieces peak): the true maximum lies between
the two, a certificate, not a search. A term drifting a physics parameter, a Gaussian-process
discrepancy or an effect not in :data:`_PIECES` have no such bound here: :func:`term_pieces` says why.
"""

from __future__ import annotations

import heapq
import itertools
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["BOUND_RTOL", "CertifiedMax", "Piece", "certified_max", "term_pieces"]

#: Relative distance between the certified upper bound and the value found at which branching stops. [1]
BOUND_RTOL = 1e-7
#: Relative allowance for rounding added to every box's bound (floating-point composition). [1]
_ROUNDING = 1e-12
#: Most boxes branched before the bound found so far is returned as it stands. [1]
MAX_BOXES = 20000
#: Boxes split per vectorized step. [1]
_BATCH = 64

#: How each effect of physics.effects enters μ ("add": μ + a(x), "mul": μ m(x)), and whether it is monotone
#: in its main driver (True) or log-quadratic (False: an end or the stationary point).
_PIECES: dict[str, tuple[str, bool]] = {
    "humidity_meniscus": ("add", True),     # + p z / (G ln(1/h))
    "viscous_drag": ("add", True),          # + p V / G
    "constant_drag": ("add", True),         # + p / G (driver: the load, fixed at a design)
    "stribeck_breakaway": ("add", True),    # + a exp(-V / V0)
    "viscous_power_law": ("add", True),     # + p (V / V0)^e / G, e >= 0.3
    "thermal_shear_strength": ("mul", True),  # x exp(-p (T - T0))
    "run_in": ("mul", True),                # x (1 + a exp(-n / L)), a > -1
    "generic_linear": ("mul", True),        # x exp(c (x - centre) / scale)
    "generic_power": ("mul", True),         # x (x / reference)^c
    "generic_quadratic": ("mul", False),    # x exp(c1 z + c2 z^2), z = (x - centre) / scale
}


@dataclass(frozen=True)
class Piece:
    """One effect term of a calibrated model as it enters μ at a design.

    Attributes
    ----------
    term : calibrate.candidates.EffectTerm
        The term.
    values : list of float
        Its fitted values.
    kind : {"add", "mul"}
        μ + a(x) or μ m(x).
    monotone : bool
        Whether the piece is monotone in its driver (else log-quadratic).
    """

    term: Any
    values: list[float]
    kind: str
    monotone: bool

    @property
    def driver(self) -> str:
        """The main driver column."""
        return self.term.drivers[0]

    def at(self, x: np.ndarray, columns: Mapping[str, Any]) -> np.ndarray:
        """a(x) or m(x) [1] at driver values ``x``, other columns as given."""
        effect = self.term.effect
        params = dict(zip(effect.parameter_names, self.values, strict=True))
        base = 0.0 if self.kind == "add" else 1.0
        with np.errstate(all="ignore"):
            return np.asarray(effect.apply(np.full(np.shape(x), base), {**columns, self.driver: x}, params,
                                           self.term.drivers, self.term.constants), dtype=float)

    def stationary(self) -> float | None:
        """The driver value where a log-quadratic piece is stationary (None: monotone, or linear)."""
        if self.monotone or self.values[1] == 0:
            return None
        c1, c2 = self.values
        return self.term.constants["centre"] - c1 * self.term.constants["scale"] / (2.0 * c2)


def term_pieces(model: Any) -> tuple[list[Piece] | None, str]:
    """The pieces of a calibrated model's μ, or None and why no bound is known for it.

    Parameters
    ----------
    model : physics.model.Model
        A calibrated model (``model.calibrated``).

    Returns
    -------
    pieces : list of Piece or None
    reason : str
        Empty when pieces are returned.
    """
    calibrated = getattr(model, "calibrated", None)
    if calibrated is None:
        return None, f"{model.reference} is not a calibrated model"
    if getattr(calibrated, "discrepancy", None) is not None:
        return None, "its Gaussian-process discrepancy has no bound over a box here"
    pieces = []
    for term, values in calibrated.terms:
        label = getattr(term, "label", term)
        if getattr(term, "kind", None) != "effect":
            return None, (f"its term {label!r} drifts a physics parameter: the physics' monotonicity is not "
                          "proven")
        if term.name not in _PIECES:
            return None, f"its term {label!r} has no known bound over an interval"
        if term.drivers[0] == "groove_angle_deg":
            return None, f"its term {label!r} is driven by the groove angle"
        kind, monotone = _PIECES[term.name]
        pieces.append(Piece(term, list(map(float, values)), kind, monotone))
    return pieces, ""


@dataclass(frozen=True)
class CertifiedMax:
    """The maximum of μ over an envelope at a design, bracketed.

    Attributes
    ----------
    value : float
        The largest μ found, the model's own value at ``point``: a lower bound of the maximum. [1]
    upper_bound : float
        Certified upper bound of the maximum. [1]
    point : dict
        Where ``value`` occurs (:meth:`optimize.robust.Envelope.point`).
    boxes : int
        Boxes bounded. [1]
    complete : bool
        Whether the bracket closed to ``rtol`` (False: stopped at the box or time limit).
    """

    value: float
    upper_bound: float
    point: dict[str, Any]
    boxes: int
    complete: bool

    @property
    def relative_gap(self) -> float:
        """(upper_bound - value) / upper_bound. [1]"""
        return max(0.0, (self.upper_bound - self.value) / self.upper_bound)


def certified_max(pieces: list[Piece], physics_mu: Callable[[np.ndarray, np.ndarray], np.ndarray],
                  evaluate: Callable[[list[dict[str, Any]]], np.ndarray], envelope: Any,
                  design: Mapping[str, float], rtol: float = BOUND_RTOL, max_boxes: int = MAX_BOXES,
                  time_limit_s: float = math.inf) -> CertifiedMax:
    """Bracket the maximum of a calibrated model's μ over the envelope at one design (module docstring).

    Parameters
    ----------
    pieces : list of Piece
        From :func:`term_pieces`.
    physics_mu : callable
        ``(angle_offset_deg, speed_m_s) -> μ`` [1] of the physics with the model's values at the design.
    evaluate : callable
        The model's μ [1] at a list of envelope points (:meth:`Envelope.point`), at the design.
    envelope : optimize.robust.Envelope
        The envelope.
    design : mapping
        ``balls`` [1] and ``load_N`` [N] (columns of the pieces).
    rtol : float, default :data:`BOUND_RTOL`
        Relative gap at which branching stops. [1]
    max_boxes : int, default :data:`MAX_BOXES`
        Most boxes bounded. [1]
    time_limit_s : float, default inf
        No new batch of boxes after this long. [s]

    Returns
    -------
    CertifiedMax
    """
    start = time.perf_counter()
    axes = envelope.axes()
    names = list(axes)
    k = len(names)
    root_lo = np.array([axes[n][0] for n in names], dtype=float)
    root_hi = np.array([axes[n][1] for n in names], dtype=float)
    span = np.where(root_hi > root_lo, root_hi - root_lo, 1.0)
    fixed_point = envelope.point({})
    speed_index = names.index("speed_m_s") if "speed_m_s" in names else None
    angle_index = names.index("groove_angle_offset_deg") if "groove_angle_offset_deg" in names else None
    balls, load = float(design["balls"]), float(design["load_N"])

    def driver_interval(driver: str, lo: np.ndarray,
                        hi: np.ndarray) -> tuple[np.ndarray, np.ndarray, int | None]:
        axis = "speed_m_s" if driver == "speed_m_s" else f"conditions.{driver}"
        if axis in names:
            j = names.index(axis)
            return lo[:, j], hi[:, j], j
        if driver == "speed_m_s":
            value = fixed_point["speed_m_s"]
        elif driver == "load_N":
            value = load
        elif driver == "balls":
            value = balls
        else:
            value = fixed_point["conditions"][driver]
        return np.full(len(lo), value), np.full(len(lo), value), None

    def bound(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Upper bounds of the boxes [1], and the point of each where its pieces peak (axis values)."""
        n = len(lo)
        peak = hi.copy()
        speed_hi = hi[:, speed_index] if speed_index is not None else np.full(n, fixed_point["speed_m_s"])
        offset_hi = hi[:, angle_index] if angle_index is not None else np.zeros(n)
        upper = np.asarray(physics_mu(offset_hi, speed_hi), dtype=float)
        columns = {"balls": np.full((n, 3), balls), "load_N": np.full((n, 3), load),
                   "speed_m_s": np.broadcast_to(speed_hi[:, None], (n, 3)),
                   **{c: np.full((n, 3), v) for c, v in fixed_point["conditions"].items()}}
        for piece in pieces:
            a, b, j = driver_interval(piece.driver, lo, hi)
            stationary = piece.stationary()
            third = a if stationary is None else np.clip(stationary, a, b)
            x = np.column_stack([a, b, third])
            values = piece.at(x, columns)
            if not np.all(np.isfinite(values)):
                upper = np.full(n, np.inf)
                continue
            best = np.argmax(values, axis=1)
            top = values[np.arange(n), best]
            if j is not None and j not in (speed_index, angle_index):
                peak[:, j] = x[np.arange(n), best]
            if piece.kind == "add":
                upper = upper + top
            else:
                # mu m <= U max(m) for 0 < m and mu <= U with U >= 0 (a negative U gives no bound).
                ok = (np.min(values, axis=1) > 0) & (upper >= 0)
                upper = np.where(ok, upper * top, np.inf)
        if speed_index is not None:  # a term falling with speed may outweigh the physics: both ends tried
            low_speed = peak.copy()
            low_speed[:, speed_index] = lo[:, speed_index]
            peak = np.vstack([peak, low_speed])
        return upper * (1.0 + _ROUNDING), peak

    def points_of(rows: np.ndarray) -> list[dict[str, Any]]:
        return [envelope.point(dict(zip(names, row, strict=True))) for row in rows]

    def evaluated(rows: np.ndarray) -> np.ndarray:
        with np.errstate(all="ignore"):
            values = np.asarray(evaluate(points_of(rows)), dtype=float)
        return np.where(np.isfinite(values), values, -np.inf)

    if k == 0:
        value = float(evaluated(np.zeros((1, 0)))[0])
        upper, _ = bound(np.zeros((1, 0)), np.zeros((1, 0)))
        return CertifiedMax(value, max(value, float(upper[0])), fixed_point, 1, True)
    upper, peak = bound(root_lo[None, :], root_hi[None, :])
    corners = np.array(list(itertools.product(*zip(root_lo, root_hi, strict=True))), dtype=float)
    rows = np.vstack([corners, 0.5 * (root_lo + root_hi)[None, :], peak])
    values = evaluated(rows)
    best_index = int(np.argmax(values))
    best_value, best_row = float(values[best_index]), rows[best_index]
    heap: list[tuple[float, int, np.ndarray, np.ndarray]] = [(-float(upper[0]), 0, root_lo, root_hi)]
    counter, pruned_max, boxes = 1, -math.inf, 1
    complete = True
    while heap:
        if -heap[0][0] <= best_value * (1.0 + rtol) + 0.0:
            break
        if boxes >= max_boxes or time.perf_counter() - start > time_limit_s:
            complete = False
            break
        batch = [heapq.heappop(heap) for _ in range(min(_BATCH, len(heap)))]
        lo = np.array([b[2] for b in batch])
        hi = np.array([b[3] for b in batch])
        axis = np.argmax((hi - lo) / span, axis=1)
        middle = 0.5 * (lo[np.arange(len(lo)), axis] + hi[np.arange(len(lo)), axis])
        left_hi, right_lo = hi.copy(), lo.copy()
        left_hi[np.arange(len(lo)), axis] = middle
        right_lo[np.arange(len(lo)), axis] = middle
        child_lo, child_hi = np.vstack([lo, right_lo]), np.vstack([left_hi, hi])
        upper, peak = bound(child_lo, child_hi)
        boxes += len(child_lo)
        rows = np.vstack([0.5 * (child_lo + child_hi), peak])
        values = evaluated(rows)
        found = int(np.argmax(values))
        if values[found] > best_value:
            best_value, best_row = float(values[found]), rows[found]
        for u, lo_i, hi_i in zip(upper, child_lo, child_hi, strict=True):
            if u > best_value * (1.0 + rtol):
                heapq.heappush(heap, (-float(u), counter, lo_i, hi_i))
                counter += 1
            else:
                pruned_max = max(pruned_max, float(u))
    left = -heap[0][0] if heap else -math.inf
    certified = max(best_value, pruned_max, left)
    return CertifiedMax(best_value, certified, points_of(best_row[None, :])[0], boxes, complete)
