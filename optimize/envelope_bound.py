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
* every effect that declares how it enters μ (:attr:`physics.effects.Effect.enters`) is monotone in its
  driver (:attr:`~physics.effects.Effect.monotone`) except a log-quadratic such as ``generic_quadratic``,
  exp(c1 z + c2 z²), whose maximum over an interval is at an end or at the stationary point it declares
  (z = -c1 / (2 c2)); so each piece's maximum over the box's driver interval is the
  largest of its values at the interval's ends (and that point when inside).

The bound is exact where every piece peaks at the same point (a vertex, or the stationary point of a
lone quadratic), and otherwise over-estimates by at most the pieces' variation across the box. Branch
and bound (the box of largest bound split in half along the axis where halving has lowered the bound
most, :class:`AxisCosts`) narrows it until the largest bound left is within ``rtol`` of the largest
value of the model itself found (at the centre and the point where the pieces peak of the boxes of
largest bound): the true maximum lies between the two, a certificate, not a search.

The 95 % upper bound, μ exp(z σ) with σ² = g'Cg + noise² (g the finite-difference gradient of log μ in
the fitted values, C their covariance), is bounded the same way by interval arithmetic on that closed
form (:func:`optimize.interval_bound.mu_upper_box_bound`), for the model and each rival whose envelope it
takes. Every value the model itself gives at a point of a box is checked against the box's bound
(:class:`BoundFailedError`), so a model the premises do not fit is caught where it shows.

The other parts of a calibrated model are bounded over a box too:

* **a drifting physics parameter** (a viscosity falling with temperature by Arrhenius' law, ...): each
  law is monotone in its driver, so the parameter's range over the box is the law at the driver's ends
  (:func:`drift_ranges`), and the physics' μ is monotone in every parameter a drift may move
  (its declared ``direction``, :data:`physics.effects.PARAMETER_SHARES`): its maximum is at the
  parameter's worst end; for ``mu_upper`` the drift's values' gradient of log μ is bounded in closed form
  where the parameter enters the physics as one power (its declared ``output`` and ``exponent``: the
  parameter moves by f(c + h, x) / f(c, x), monotone in x, and its share by that ratio to the power), or
  through the contact load (the adhesion energy, declared ``contact_load``: Q moves by that ratio to a
  power between Q's least and largest elasticity in it over the box, and each share of μ by Q's ratio
  to its declared power);
* **group effects** at a point naming no group: a group on μ (or on a parameter the model does not fit)
  shifts log μ by its offset and adds the new-group variance, constants; one on a fitted parameter p
  shifts it by s b0 with s = p × p's gradient entry, bounded by that entry's interval (``mu_upper``; for
  μ alone it is refused, said);
* **the data cloud's widening of the interval**: the k-th smallest distance from the rows to the box's
  farthest corner bounds the k-th nearest distance of every point of the box
  (:meth:`calibrate.domain.DataCloud.score_bound`), and the widening is non-decreasing in it;
* **a Gaussian-process discrepancy**: its mean between the kernel's ends per training point and a
  second-order Taylor bound at the box's centre, its variance from the tangent plane of the convex
  k'K⁻¹k (:meth:`calibrate.model.GPCorrection.bound`). Each factor is bounded on its own, so where the GP's
  mean and a term slope opposite ways at the worst point the bound closes only linearly with the box, and
  the branch and bound may stop at its box limit with a wider bracket (stated: ``complete`` False).

An effect that declares nothing, a drift of another parameter or a scatter that depends on an input
have no bound here: :func:`term_pieces` says why.
"""

from __future__ import annotations

import dataclasses
import heapq
import itertools
import math
import time
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import optimize, stats

from microbearing import physics
from microbearing.physics.effects import PARAMETER_SHARES

from . import gp_boxes

__all__ = ["BOUND_RTOL", "MAX_BOXES", "AxisCosts", "BoundFailedError", "BranchAndBound", "CertifiedMax",
           "Narrowing", "Piece", "certified_max", "drift_ranges", "group_shift", "interval_floor",
           "mu_box_bound", "term_pieces"]

#: Relative distance between the certified upper bound and the value found at which branching stops. [1]
BOUND_RTOL = 1e-7
#: Relative allowance for rounding added to every box's bound (floating-point composition). [1]
_ROUNDING = 1e-12
#: Most boxes branched before the bound found so far is returned as it stands. [1]
MAX_BOXES = 20000
#: Boxes split per vectorized step. [1]
_BATCH = 256
#: Children per step (those of largest bound) at which the function itself is evaluated. [1]
_EVALUATED = 16
#: Most steps skipped between two evaluations once they have stopped raising the value found (the gap
#: between evaluations doubles from one step at each evaluation that raises nothing, and closes at one that
#: does): the boxes' bounds, not the values, then narrow the bracket. [1]
_MOST_SKIPPED = 8
#: Boxes bounded after which the best point found is polished by a local ascent (and again at the box
#: or time limit). [1]
_POLISH_AT = (1000, 5000)



@dataclass(frozen=True)
class Piece:
    """One effect term of a calibrated model as it enters μ at a design.

    Attributes
    ----------
    term : calibrate.candidates.EffectTerm
        The term.
    values : list of float
        Its fitted values.
    kind : {"add", "mul", "drift"}
        μ + a(x), μ m(x), or a drift of a physics parameter (applied to the physics' inputs first).
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
        """The driver value where a non-monotone piece is stationary, as its effect declares (None:
        monotone, or no stationary point)."""
        declared = self.term.effect.stationary
        if self.monotone or declared is None:
            return None
        return declared(self.values, self.term.constants)

    def value_form(self, i: int) -> str | None:
        """How μ moves with the piece's i-th fitted value (:data:`physics.effects.VALUE_FORMS`; None: no
        closed form), as its effect declares."""
        forms = self.term.effect.value_forms
        return forms[i] if i < len(forms) else None


#: The parts of a calibrated model the bounds here account for (``domain_rows`` only moves the domain
#: flag; ``clock`` and ``headers`` say how a point's keys and times are read, before μ is asked;
#: ``edge_trends`` only widens the interval beyond a range, in ``cloud_ratio_bound``); a model with any
#: other part set (group effects, whose shift follows a parameter's sensitivity) is not bounded: said,
#: not guessed.
_BOUNDED_PARTS = frozenset({"fitted", "fixed", "terms", "convention", "covariance", "noise_std_log", "domain",
                            "conditions", "discrepancy", "rivals", "domain_rows", "cloud", "groups", "clock",
                            "headers", "edge_trends"})


def _unbounded_part(calibrated: Any, interval: bool = False) -> str | None:
    """The first part of a calibrated model that is set and that the bounds do not know, or None.

    A scatter model of one spread everywhere is the ``noise_std_log`` the interval bounds use; one that
    depends on an input is not bounded. The data cloud widens only the interval beyond the data (it
    does not move μ): :func:`mu_upper_box_bound` bounds its widening over a box.
    """
    for part in dataclasses.fields(calibrated) if dataclasses.is_dataclass(calibrated) else ():
        if part.name in _BOUNDED_PARTS:
            continue
        value = getattr(calibrated, part.name)
        if part.name == "scatter" and (value is None or getattr(value, "kind", None) == "constant"):
            continue
        default = (part.default_factory() if part.default_factory is not dataclasses.MISSING
                   else part.default)
        if value is not default and not (isinstance(value, type(default)) and value == default):
            return part.name
    return None


class BoundFailedError(ValueError):
    """A box bound below the model's own value at a point inside the box: the bound's premise fails."""


def term_pieces(model: Any, interval: bool = False) -> tuple[list[Piece] | None, str]:
    """The pieces of a calibrated model's μ, or None and why no bound is known for it.

    Parameters
    ----------
    model : physics.model.Model
        A calibrated model (``model.calibrated``).
    interval : bool
        For bounds of its 95 % interval (``mu_upper``), which its data cloud widens off the data.

    Returns
    -------
    pieces : list of Piece or None
    reason : str
        Empty when pieces are returned.
    """
    calibrated = getattr(model, "calibrated", None)
    if calibrated is None:
        return None, f"{model.reference} is not a calibrated model"
    unknown = _unbounded_part(calibrated, interval)
    if unknown is not None:
        return None, f"its {unknown} has no bound over a box here"
    for group in getattr(calibrated, "groups", None) or []:
        if group.parameter != "mu" and group.parameter in calibrated.fitted and not interval:
            return None, (f"its group effect of {group.factor} on {group.parameter} shifts log mu by a share "
                          "that has no bound over a box here (objective mu)")
    pieces = []
    for term, values in calibrated.terms:
        label = getattr(term, "label", term)
        if getattr(term, "kind", None) == "drift":
            if term.parameter not in PARAMETER_SHARES:
                return None, (f"its term {label!r} drifts a physics parameter in which the physics' "
                              "monotonicity is not proven")
            share = PARAMETER_SHARES[term.parameter]
            if interval and share.output is None and not share.contact_load:
                return None, (f"its term {label!r} drifts a physics parameter: its fitted coefficient's "
                              "share of the interval has no closed form here (it moves the modulus)")
            pieces.append(Piece(term, list(map(float, values)), "drift", True))
            continue
        if getattr(term, "kind", None) != "effect":
            return None, f"its term {label!r} has no known bound over an interval"
        effect = term.effect
        if effect.enters is None:
            return None, f"its term {label!r} has no known bound over an interval"
        if term.drivers[0] == "groove_angle_deg":
            return None, f"its term {label!r} is driven by the groove angle"
        pieces.append(Piece(term, list(map(float, values)), effect.enters, effect.monotone))
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
    narrowing : Narrowing or None
        How the bracket was narrowing when it stopped unclosed (None when complete).
    """

    value: float
    upper_bound: float
    point: dict[str, Any]
    boxes: int
    complete: bool
    narrowing: Narrowing | None = None

    def stopped_words(self) -> str:
        """Why the bracket is open, for a proof's statement: '' when it closed, else which limit stopped it
        and how it was narrowing then (:meth:`Narrowing.words`)."""
        if self.complete:
            return ""
        return ", stopped at the box limit" if self.narrowing is None else f", {self.narrowing.words()}"

    @property
    def relative_gap(self) -> float:
        """(upper_bound - value) / upper_bound. [1]"""
        return max(0.0, (self.upper_bound - self.value) / self.upper_bound)


@dataclass(frozen=True)
class Narrowing:
    """How a bracket stopped before closing was narrowing: its relative gap at about half its boxes and at
    the end, and the order p of gap ∝ boxes^-p between the two.

    A box bound exact only to first order in the box's widths at the worst point (each term bounded at its
    own extreme where the terms peak at different points) narrows the gap as a power of the boxes: the boxes
    left open are those within the bound's excess of the worst value, about w^(-k/2) of width w around a
    peak curved in k axes, so the gap ~ w narrows at order p = 2/k (2 with one such axis). A bound exact to
    second order there keeps a bounded number of boxes open and closes geometrically.
    ``boxes_to_close`` extrapolates at the order measured: a reading of the trend, not a promise.

    Attributes
    ----------
    limit : {"box limit", "time limit"}
        What stopped the branching.
    half_boxes, boxes : int
        Boxes bounded at the earlier reading and at the end. [1]
    half_gap, gap : float
        Relative gap (certified upper bound over the value found at the end, less one) at the two
        readings. [1]
    rtol : float
        The relative gap the bracket was to close to. [1]

    Examples
    --------
    >>> n = Narrowing("box limit", 20000, 4e-4, 40000, 2e-4, 1e-7)
    >>> round(n.order, 6), f"{n.boxes_to_close:.0e}"
    (1.0, '8e+07')
    """

    limit: str
    half_boxes: int
    half_gap: float
    boxes: int
    gap: float
    rtol: float

    @property
    def order(self) -> float:
        """p in gap ∝ boxes^-p between the two readings (0 when the gap did not narrow). [1]"""
        if not (self.gap > 0.0 and self.half_gap > self.gap and self.boxes > self.half_boxes):
            return 0.0
        return math.log(self.half_gap / self.gap) / math.log(self.boxes / self.half_boxes)

    @property
    def boxes_to_close(self) -> float:
        """Boxes at which the gap would reach ``rtol`` at :attr:`order` (inf when it did not narrow). [1]"""
        if self.gap <= self.rtol:
            return float(self.boxes)
        order = self.order
        return math.inf if order <= 0.0 else self.boxes * (self.gap / self.rtol) ** (1.0 / order)

    def words(self) -> str:
        """One clause for a proof's statement: the limit, the readings, the order and what it means."""
        head = (f"stopped at the {self.limit}: the relative gap went from {self.half_gap:.1e} at "
                f"{self.half_boxes:,} boxes to {self.gap:.1e} at {self.boxes:,}")
        order = self.order
        if order <= 0.0:
            return head + " (not narrowing: more boxes would not close it)"
        meaning = (" (a power of the boxes, not geometric, as a box bound exact only to first order at the "
                   "worst point narrows: terms bounded each at its own extreme where they peak at different "
                   "points, such as a rise and a fall balancing inside the envelope)" if order < 3.0 else "")
        return (head + f", order {order:.1f} in the boxes{meaning}; at that order it would close to "
                f"{self.rtol:g} in about {self.boxes_to_close:.0e} boxes")


class _Boxes:
    """The envelope's axes and what every box bound needs from them."""

    def __init__(self, envelope: Any, design: Mapping[str, float]):
        axes = envelope.axes()
        self.envelope = envelope
        self.names = list(axes)
        self.root_lo = np.array([axes[n][0] for n in self.names], dtype=float)
        self.root_hi = np.array([axes[n][1] for n in self.names], dtype=float)
        self.span = np.where(self.root_hi > self.root_lo, self.root_hi - self.root_lo, 1.0)
        self.fixed_point = envelope.point({})
        self.speed = self.names.index("speed_m_s") if "speed_m_s" in self.names else None
        self.angle = (self.names.index("groove_angle_offset_deg") if "groove_angle_offset_deg" in self.names
                      else None)
        self.balls, self.load = float(design["balls"]), float(design["load_N"])

    def physics_corner(self, corner: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(angle offset [deg], speed [m/s]) of each box's corner: the physics' extreme there."""
        n = len(corner)
        speed = corner[:, self.speed] if self.speed is not None else np.full(n, self.fixed_point["speed_m_s"])
        offset = corner[:, self.angle] if self.angle is not None else np.zeros(n)
        return offset, speed

    def driver_interval(self, driver: str, lo: np.ndarray,
                        hi: np.ndarray) -> tuple[np.ndarray, np.ndarray, int | None]:
        """The interval of a piece's driver over each box, and its axis (None: one value)."""
        axis = "speed_m_s" if driver == "speed_m_s" else f"conditions.{driver}"
        if axis in self.names:
            j = self.names.index(axis)
            return lo[:, j], hi[:, j], j
        if driver == "speed_m_s":
            value = self.fixed_point["speed_m_s"]
        elif driver == "load_N":
            value = self.load
        elif driver == "balls":
            value = self.balls
        else:
            value = self.fixed_point["conditions"][driver]
        return np.full(len(lo), value), np.full(len(lo), value), None

    def columns(self, n: int, speed: np.ndarray, width: int) -> dict[str, np.ndarray]:
        """Columns of the pieces at ``width`` driver values per box (the driver's own column replaced)."""
        return {"balls": np.full((n, width), self.balls), "load_N": np.full((n, width), self.load),
                "speed_m_s": np.broadcast_to(speed[:, None], (n, width)),
                **{c: np.full((n, width), v) for c, v in self.fixed_point["conditions"].items()}}


def _candidates(piece: Piece, boxes: _Boxes, lo: np.ndarray, hi: np.ndarray,
                extra: float | None = None) -> tuple[np.ndarray, int | None]:
    """Driver values at which a piece (or a function of its driver of the same shape) takes its extremes
    over each box: the ends, the stationary point of a log-quadratic and ``extra`` when inside."""
    a, b, j = boxes.driver_interval(piece.driver, lo, hi)
    stationary = piece.stationary() if extra is None else extra
    third = a if stationary is None else np.clip(stationary, a, b)
    return np.column_stack([a, b, third]), j


def _pieces_range(pieces: list[Piece], boxes: _Boxes, lo: np.ndarray, hi: np.ndarray,
                  speed: np.ndarray, peak: np.ndarray | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each piece's exact [min, max] over each box (NaN-free or +-inf); the driver value of its maximum is
    written into ``peak`` for condition axes."""
    n = len(lo)
    out = []
    for piece in pieces:
        if piece.kind == "drift":  # moves the physics' inputs, no factor of its own
            out.append((np.ones(n), np.ones(n)))
            continue
        x, j = _candidates(piece, boxes, lo, hi)
        values = piece.at(x, boxes.columns(n, speed, 3))
        if not np.all(np.isfinite(values)):
            out.append((np.full(n, -np.inf), np.full(n, np.inf)))
            continue
        best = np.argmax(values, axis=1)
        if peak is not None and j is not None and j not in (boxes.speed, boxes.angle):
            peak[:, j] = x[np.arange(n), best]
        out.append((np.min(values, axis=1), values[np.arange(n), best]))
    return out


def _compose_upper(physics_upper: np.ndarray, pieces: list[Piece],
                   ranges: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """An upper bound of the composed μ from the physics' and each piece's maximum (module docstring)."""
    upper = physics_upper
    for piece, (low, top) in zip(pieces, ranges, strict=True):
        if piece.kind == "add":
            upper = upper + top
        else:
            # mu m <= U max(m) for 0 < m and mu <= U with U >= 0 (a negative U gives no bound).
            upper = np.where((low > 0) & (upper >= 0), upper * top, np.inf)
    return upper


def _corner_points(boxes: _Boxes, inputs_fn: Callable[[np.ndarray, np.ndarray], Mapping[str, Any]],
                   lo: np.ndarray, hi: np.ndarray) -> tuple[dict[str, Any], dict[str, Any]]:
    """The model's points (physics inputs and conditions) at each box's lowest and highest corner.

    Every column of a point is non-decreasing in every axis (the speed, the angle made = nominal + offset,
    each condition): the two corners give each column's range over the box.
    """
    corners = []
    for corner in (lo, hi):
        offset, speed = boxes.physics_corner(corner)
        points = dict(inputs_fn(offset, speed))
        for name in boxes.envelope.conditions:
            a, b, _ = boxes.driver_interval(name, lo, hi)
            points[name] = a if corner is lo else b
        corners.append(points)
    return corners[0], corners[1]


def drift_ranges(drifts: list[Piece], base: Mapping[str, Any], driver_interval: Callable[[str], tuple],
                 n: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each drifting parameter's exact [min, max] over each of ``n`` boxes [its unit].

    As :func:`calibrate.candidates.drifted_inputs` applies them: p = base × factor(x), in order (a later
    drift of the same parameter multiplies the earlier result, unless it fits its own level), clipped to
    the parameter's range. Every law's factor is monotone in its driver (linear; Arrhenius, exp(c/R (1/T -
    1/T_ref)); Kelvin, linear in 1/ln(1/h), increasing in h), so over a driver interval it lies between its
    values at the ends; the product of two intervals is the least and largest of its corners' products,
    and the clip is non-decreasing.

    Parameters
    ----------
    drifts : list of Piece
        The drift pieces of :func:`term_pieces`, in order.
    base : mapping
        Physics inputs the model holds or is given at the design (its fixed and fitted values, defaults).
    driver_interval : callable
        ``driver -> (low [n], high [n], axis)``.
    n : int
        Boxes. [1]
    """
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for piece in drifts:
        term = piece.term
        spec = physics.PARAMETERS[term.parameter]
        if term.level:
            low = high = np.full(n, piece.values[1])
        elif term.parameter in out:
            low, high = out[term.parameter]
        else:
            low = high = np.full(n, float(base.get(term.parameter, spec.default)))
        a, b, _ = driver_interval(term.driver)
        with np.errstate(all="ignore"):
            ends = [np.asarray(term.factor({term.driver: x}, piece.values[0]), dtype=float) for x in (a, b)]
        corners = np.array([c * f for c in (low, high) for f in ends])
        lo_clip = -np.inf if spec.minimum is None else spec.minimum
        hi_clip = np.inf if spec.maximum is None else (
            np.nextafter(spec.maximum, lo_clip) if spec.exclusive_maximum else spec.maximum)
        out[term.parameter] = (np.clip(np.min(corners, axis=0), lo_clip, hi_clip),
                               np.clip(np.max(corners, axis=0), lo_clip, hi_clip))
    return out


def group_shift(calibrated: Any) -> float:
    """The shift of log μ by the model's groups at a point that names none [1], where it is the same at
    every point (each group's parameter μ itself or one the model does not fit: sensitivity 1)."""
    return float(sum(g.offset_log for g in getattr(calibrated, "groups", None) or []
                     if g.parameter == "mu" or g.parameter not in calibrated.fitted))


def interval_floor(calibrated: Any, z: float, widening: float = 1.0) -> float | None:
    """A factor F [1] with mu_upper >= F μ_terms at every point that names no group, μ_terms the physics with
    the model's terms (no group shift), or None when none is known.

    mu_upper >= μ_terms exp(shift + z σ) with σ² = g'Cg + the groups' variance + (noise W)², W the cloud's
    widening >= 1 (the rivals only raise it): F = exp(sum b0 + z sqrt((noise W)² + sum v)) over the groups of
    sensitivity 1. A group on a fitted parameter has sensitivity s >= 0 (μ never falls with the parameter:
    it enters the physics as a non-negative share and every term is non-decreasing in μ), so its shift
    s b0 >= 0 when b0 >= 0 and it is left out; with b0 < 0 no floor is known. ``widening`` (>= 1): a lower
    bound of the data cloud's widening at the points the floor is for, which multiplies the noise.
    """
    noise = getattr(calibrated, "noise_std_log", None)
    if noise is None:
        return None
    level = 1.0 - 2.0 * float(stats.norm.sf(z))
    shift, variance = 0.0, (float(noise) * max(widening, 1.0)) ** 2
    for group in getattr(calibrated, "groups", None) or []:
        if group.parameter == "mu" or group.parameter not in calibrated.fitted:
            shift += group.offset_log
            variance += group.new_group_variance(level)
        elif group.offset_log < 0:
            return None
    return math.exp(shift + z * math.sqrt(variance))


def mu_box_bound(pieces: list[Piece], physics_mu: Callable[..., np.ndarray],
                 envelope: Any, design: Mapping[str, float], calibrated: Any = None,
                 base: Mapping[str, Any] | None = None,
                 inputs_fn: Callable[[np.ndarray, np.ndarray], Mapping[str, Any]] | None = None) -> Callable:
    """The box bound of a calibrated model's μ at a design, for :func:`certified_max`.

    Drift pieces move the physics' inputs: each drifting parameter's range over the box
    (:func:`drift_ranges`) and the physics' direction in it (declared in
    :data:`physics.effects.PARAMETER_SHARES`) give its worst end, passed to ``physics_mu``. A group
    effect on μ (or on a parameter the model does not fit) moves log μ by its offset at every point that
    names no group: a constant factor.

    Parameters
    ----------
    pieces : list of Piece
        From :func:`term_pieces`.
    physics_mu : callable
        ``(angle_offset_deg, speed_m_s, **parameters) -> μ`` [1] of the physics with the model's values at
        the design, the given physics parameters (arrays, their units) replacing them.
    envelope : optimize.robust.Envelope
        The envelope.
    design : mapping
        ``balls`` [1] and ``load_N`` [N].
    calibrated : calibrate.CalibratedModel, optional
        The model, for its groups and its Gaussian-process discrepancy (whose mean multiplies μ by
        exp(mean), bounded over the box by :meth:`calibrate.CalibratedModel.discrepancy_bound`).
    base : mapping, optional
        Physics inputs at the design as the model reads them (for the drifts' base values).
    inputs_fn : callable, optional
        ``(angle_offset_deg, speed_m_s) -> physics inputs`` the model is given at the design (needed for a
        discrepancy).

    Returns
    -------
    callable
        ``(lo, hi) -> (upper bounds [1], points to evaluate)`` over boxes given by their corners.
    """
    boxes = _Boxes(envelope, design)
    drifts = [p for p in pieces if p.kind == "drift"]
    effects = [p for p in pieces if p.kind != "drift"]
    factor = math.exp(group_shift(calibrated)) if calibrated is not None else 1.0
    gp = calibrated is not None and getattr(calibrated, "discrepancy", None) is not None
    if gp and inputs_fn is None:
        raise ValueError("a model with a discrepancy needs inputs_fn for its bound")

    def bound(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        offset_hi, speed_hi = boxes.physics_corner(hi)
        peak = hi.copy()
        ranges = _pieces_range(effects, boxes, lo, hi, speed_hi, peak)
        drifted = drift_ranges(drifts, base or {}, lambda driver: boxes.driver_interval(driver, lo, hi),
                               len(lo))
        worst = {name: (high if PARAMETER_SHARES[name].direction > 0 else low)
                 for name, (low, high) in drifted.items()}
        for piece in drifts:  # the driver's end where the drifting parameter moves mu up
            a, b, j = boxes.driver_interval(piece.driver, lo, hi)
            if j is not None and j not in (boxes.speed, boxes.angle):
                with np.errstate(all="ignore"):
                    rise = (np.asarray(piece.term.factor({piece.driver: b}, piece.values[0]), dtype=float)
                            >= np.asarray(piece.term.factor({piece.driver: a}, piece.values[0]), dtype=float))
                peak[:, j] = np.where(rise == (PARAMETER_SHARES[piece.term.parameter].direction > 0), b, a)
        phys = np.asarray(physics_mu(offset_hi, speed_hi, **worst), dtype=float)
        upper = _compose_upper(phys, effects, ranges) * factor
        if gp:
            low, high = _corner_points(boxes, inputs_fn, lo, hi)
            mean = gp_boxes.discrepancy_bound(calibrated, low, high, len(lo))[1]
            upper = np.where(upper >= 0, upper * np.exp(mean), np.inf)
        return upper * (1.0 + _ROUNDING), _with_low_speed(boxes, lo, peak)

    return bound


def _with_low_speed(boxes: _Boxes, lo: np.ndarray, peak: np.ndarray) -> np.ndarray:
    if boxes.speed is None:
        return peak
    # A term falling with speed may outweigh the physics: both ends of the speed tried.
    low_speed = peak.copy()
    low_speed[:, boxes.speed] = lo[:, boxes.speed]
    return np.vstack([peak, low_speed])


def certified_max(bound: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
                  evaluate: Callable[[list[dict[str, Any]]], np.ndarray], envelope: Any,
                  rtol: float = BOUND_RTOL, max_boxes: int = MAX_BOXES,
                  time_limit_s: float = math.inf) -> CertifiedMax:
    """Bracket the maximum of a function over the envelope by branch and bound (module docstring).

    Parameters
    ----------
    bound : callable
        ``(lo, hi) -> (upper, rows)``: a valid upper bound of the function over each box (corners ``lo``,
        ``hi`` of shape (n, axes)), and axis values of points worth evaluating (:func:`mu_box_bound`,
        :func:`mu_upper_box_bound`).
    evaluate : callable
        The function itself [1] at a list of envelope points (:meth:`Envelope.point`).
    envelope : optimize.robust.Envelope
        The envelope.
    rtol : float, default :data:`BOUND_RTOL`
        Relative gap at which branching stops. [1]
    max_boxes : int, default :data:`MAX_BOXES`
        Most boxes bounded. [1]
    time_limit_s : float, default inf
        No new batch of boxes after this long. [s]

    Returns
    -------
    CertifiedMax

    Raises
    ------
    BoundFailedError
        When the function exceeds a box's bound at a point of the box (checked at every point evaluated):
        the bound's premise does not hold for this model, and nothing is certified.
    """
    return BranchAndBound(bound, evaluate, envelope, rtol, max_boxes).run(time_limit_s=time_limit_s)


class BranchAndBound:
    """The branch and bound of :func:`certified_max`, run in stages: :meth:`run` continues where the last
    run stopped, so a bracket run first to a few boxes (``final`` false) and then to its box limit is the
    same computation, box for box, as one run to the limit.

    A robust design's rounds bracket every design they visit first to a share of the boxes (enough to find
    its worst point) and only the design they end on to the limit (:mod:`optimize.robust_outer`).

    Parameters
    ----------
    bound, evaluate, envelope, rtol
        As for :func:`certified_max`.
    max_boxes : int, default :data:`MAX_BOXES`
        Most boxes bounded by a final run. [1]

    Raises
    ------
    BoundFailedError
        As :func:`certified_max` (here or in :meth:`run`).
    """

    def __init__(self, bound: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
                 evaluate: Callable[[list[dict[str, Any]]], np.ndarray], envelope: Any,
                 rtol: float = BOUND_RTOL, max_boxes: int = MAX_BOXES) -> None:
        self.max_boxes, self._rtol, self._bound, self._evaluate = max_boxes, rtol, bound, evaluate
        self._envelope = envelope
        boxes = _Boxes(envelope, {"balls": 0.0, "load_N": 0.0})
        self._names, self._span = boxes.names, boxes.span
        self._root_lo, self._root_hi = root_lo, root_hi = boxes.root_lo, boxes.root_hi
        upper, peak = bound(root_lo[None, :], root_hi[None, :])
        corners = np.array(list(itertools.product(*zip(root_lo, root_hi, strict=True))), dtype=float)
        rows = (np.vstack([corners, 0.5 * (root_lo + root_hi)[None, :], peak]) if self._names
                else np.zeros((1, 0)))
        values = self._evaluated(rows)
        if np.any(values > float(upper[0]) * (1.0 + 1e-9)):
            raise BoundFailedError("the model's value above the envelope's bound")
        best_index = int(np.argmax(values))
        self._best_value, self._best_row = float(values[best_index]), rows[best_index]
        self._root_upper = float(upper[0])
        # (-bound, insertion order, lo, hi) of the boxes still open: the largest bound first
        self._heap: list[tuple[float, int, np.ndarray, np.ndarray]] = [(-self._root_upper, 0, root_lo,
                                                                        root_hi)]
        self._counter, self._pruned_max, self.boxes = 1, -math.inf, 1
        self._axes = AxisCosts(len(root_lo))
        self._polish_at = list(_POLISH_AT)
        self._final: CertifiedMax | None = None
        self._skip, self._skip_left = 0, 0
        # (boxes, certified upper bound) after each step: how the bracket narrows (:class:`Narrowing`)
        self._uppers: list[tuple[int, float]] = []

    def _points_of(self, rows: np.ndarray) -> list[dict[str, Any]]:
        return [self._envelope.point(dict(zip(self._names, row, strict=True))) for row in rows]

    def _evaluated(self, rows: np.ndarray) -> np.ndarray:
        with np.errstate(all="ignore"):
            values = np.asarray(self._evaluate(self._points_of(rows)), dtype=float)
        return np.where(np.isfinite(values), values, -np.inf)

    def _polish(self) -> None:
        """A bounded quasi-Newton ascent from the best point found (a better value prunes more boxes)."""
        value, row = _ascent(self._evaluated, self._best_row, self._root_lo, self._root_hi)
        if value > self._best_value:
            self._best_value, self._best_row = value, row

    def _closed(self) -> bool:
        return not self._heap or -self._heap[0][0] <= self._best_value * (1.0 + self._rtol)

    def run(self, max_boxes: int | None = None, time_limit_s: float = math.inf,
            final: bool = True) -> CertifiedMax:
        """Branch until the bracket closes to ``rtol`` or ``max_boxes`` (default :attr:`max_boxes`) are
        bounded or ``time_limit_s`` [s] has passed in this run, and return the bracket as it stands. A
        final run polishes the best point at its limit; a run that is not final leaves that to a later
        run, which continues the same sequence of boxes."""
        if self._final is not None:
            return self._final
        if not self._names:
            self._final = CertifiedMax(self._best_value, max(self._best_value, self._root_upper),
                                       self._points_of(self._best_row[None, :])[0], 1, True)
            return self._final
        start, limit = time.perf_counter(), self.max_boxes if max_boxes is None else max_boxes
        complete, ended, stopped = True, True, ""
        while self._heap:
            if self._polish_at and self.boxes >= self._polish_at[0]:
                self._polish_at.pop(0)
                self._polish()
            if self._closed():
                break
            if self.boxes >= limit or time.perf_counter() - start > time_limit_s:
                if final:
                    self._polish()
                complete, ended = self._closed(), final
                stopped = "box limit" if self.boxes >= limit else "time limit"
                break
            self._branch()
            self._uppers.append((self.boxes, self._upper()))
        upper = self._upper()
        bracket = CertifiedMax(self._best_value, upper, self._points_of(self._best_row[None, :])[0],
                               self.boxes, complete, None if complete else self._narrowing(stopped, upper))
        if ended:
            self._final = bracket
        return bracket

    def _upper(self) -> float:
        """The certified upper bound as it stands: the largest bound of a box open or pruned, or the value."""
        left = -self._heap[0][0] if self._heap else -math.inf
        return max(self._best_value, self._pruned_max, left)

    def _narrowing(self, stopped: str, upper: float) -> Narrowing:
        """The bracket's narrowing from about half its boxes to now, gaps relative to the value found now."""
        half_boxes, half_upper = next(((b, u) for b, u in reversed(self._uppers) if b <= self.boxes // 2),
                                      (1, self._root_upper))
        best = self._best_value
        return Narrowing(stopped, half_boxes, half_upper / best - 1.0, self.boxes,
                         upper / best - 1.0, self._rtol)

    def _branch(self) -> None:
        """Split the batch of boxes of largest bound, bound the halves, evaluate the function in the most
        promising ones (every step while that raises the value found, then at doubling gaps of steps, at
        most :data:`_MOST_SKIPPED`) and keep the halves that may hold a larger value."""
        heap, rtol = self._heap, self._rtol
        batch = [heapq.heappop(heap) for _ in range(min(_BATCH, len(heap)))]
        lo = np.array([b[2] for b in batch])
        hi = np.array([b[3] for b in batch])
        index = np.arange(len(lo))
        widths = (hi - lo) / self._span
        axis = self._axes.choose(widths)
        middle = 0.5 * (lo[index, axis] + hi[index, axis])
        left_hi, right_lo = hi.copy(), lo.copy()
        left_hi[index, axis] = middle
        right_lo[index, axis] = middle
        child_lo, child_hi = np.vstack([lo, right_lo]), np.vstack([left_hi, hi])
        upper, peak = self._bound(child_lo, child_hi)
        self._axes.learn(axis, widths[index, axis], np.array([-b[0] for b in batch]),
                         np.maximum(upper[:len(lo)], upper[len(lo):]))
        self.boxes += len(child_lo)
        if self._skip_left > 0:
            self._skip_left -= 1
        else:
            self._evaluate_top(upper, peak, child_lo, child_hi)
        for u, lo_i, hi_i in zip(upper, child_lo, child_hi, strict=True):
            if u > self._best_value * (1.0 + rtol):
                heapq.heappush(heap, (-float(u), self._counter, lo_i, hi_i))
                self._counter += 1
            else:
                self._pruned_max = max(self._pruned_max, float(u))

    def _evaluate_top(self, upper: np.ndarray, peak: np.ndarray, child_lo: np.ndarray,
                      child_hi: np.ndarray) -> None:
        """Ask the function at the centre and peak points of the children of largest bound, check each value
        against its box's bound, keep the largest and set how many steps pass before the next asking."""
        n = len(child_lo)
        top = np.argsort(-upper)[:_EVALUATED]
        layers = len(peak) // n
        rows = np.vstack([0.5 * (child_lo[top] + child_hi[top]),
                          *(peak[layer * n + top] for layer in range(layers))])
        values = self._evaluated(rows)
        # Every evaluated point lies in its box: a value above the box's bound means the bound is wrong.
        owner = np.tile(upper[top], len(rows) // len(top))
        if np.any(values > owner * (1.0 + 1e-9)):
            excess = float(np.max(values - owner))
            raise BoundFailedError(f"the model's value {excess:.3g} above a box's bound")
        found = int(np.argmax(values))
        raised = values[found] > self._best_value * (1.0 + 0.1 * self._rtol)
        if values[found] > self._best_value:
            self._best_value, self._best_row = float(values[found]), rows[found]
        self._skip = 0 if raised else min(max(1, 2 * self._skip), _MOST_SKIPPED)
        self._skip_left = self._skip


class AxisCosts:
    """Which axis to halve a box along: where halving has lowered the bound most, per width (pseudo-costs).

    A box's bound over-estimates by about the sum over its axes of a rate times the axis's width (the
    pieces' variation, first order in the width, :mod:`optimize.envelope_bound`); the rates differ by axis
    (an axis the bound reads at an exact corner costs nothing, one where two pieces slope opposite ways
    the most). Each halving records its axis's observed rate, the fall of the bound from the box to the
    larger of its halves relative to the box's, per relative width halved; a box is halved along the axis
    of largest mean rate times width. An axis not yet halved counts as the largest (each is tried once,
    widest first), an axis of zero width never. Branch and bound in mixed-integer programming chooses its
    branching variable so (pseudo-costs, Achterberg et al. 2005); here it let bounds that close only
    linearly in one axis (an interior worst point in temperature) close in tens of boxes where halving
    the widest axis took tens of thousands (``bench/optimize.py --kinds``).

    Parameters
    ----------
    axes : int
        The envelope's axes.

    Examples
    --------
    >>> costs = AxisCosts(2)
    >>> costs.choose(np.array([[1.0, 0.5]])).tolist()  # nothing learnt: the widest
    [0]
    >>> costs.learn(np.array([0, 1]), np.array([1.0, 0.5]), np.array([1.0, 1.0]), np.array([0.99, 0.8]))
    >>> costs.choose(np.array([[1.0, 0.5]])).tolist()  # rate 0.01 against 0.4: the second axis
    [1]
    """

    def __init__(self, axes: int) -> None:
        self._sum, self._count = np.zeros(axes), np.zeros(axes)

    def choose(self, widths: np.ndarray) -> np.ndarray:
        """The axis to halve of each box, from the boxes' widths relative to the envelope (n, axes)."""
        learnt = self._count > 0
        rate = self._sum / np.maximum(self._count, 1.0) + 1e-12  # no fall learnt anywhere: the widest
        score = np.where(learnt, rate * widths, np.inf)
        score = np.where(widths > 0, score, -1.0)  # a flat axis never
        untried = np.isinf(score)
        widest_untried = np.argmax(np.where(untried, widths, -1.0), axis=1)
        return np.where(untried.any(axis=1), widest_untried, np.argmax(score, axis=1))

    def learn(self, axis: np.ndarray, width: np.ndarray, bound: np.ndarray, halves: np.ndarray) -> None:
        """Record halvings: each box's axis, its width there, its bound and the larger of its halves'."""
        with np.errstate(divide="ignore", invalid="ignore"):
            rate = np.clip((bound - halves) / np.abs(bound), 0.0, None) / width
        ok = np.isfinite(rate)
        np.add.at(self._sum, axis[ok], rate[ok])
        np.add.at(self._count, axis[ok], 1.0)


def _ascent(evaluated: Callable[[np.ndarray], np.ndarray], row: np.ndarray, lo: np.ndarray,
            hi: np.ndarray) -> tuple[float, np.ndarray]:
    """The best value found by L-BFGS-B from ``row`` within [lo, hi] (forward differences), and where."""
    span = hi - lo
    step = 1e-7

    def negative(u: np.ndarray) -> tuple[float, np.ndarray]:
        sign = np.where(u + step <= 1.0, 1.0, -1.0)
        at = np.vstack([u, u + np.diag(sign * step)])
        f = -evaluated(lo + span * at)
        f = np.where(np.isfinite(f), f, 1e300)
        return float(f[0]), (f[1:] - f[0]) / (sign * step)

    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore")
        found = optimize.minimize(negative, np.clip((row - lo) / span, 0.0, 1.0), jac=True, method="L-BFGS-B",
                                  bounds=[(0.0, 1.0)] * len(row), options={"maxiter": 30})
    at = lo + span * np.clip(found.x, 0.0, 1.0)
    value = float(evaluated(at[None, :])[0])
    return value, at
