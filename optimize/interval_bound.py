"""A certified upper bound of a calibrated model's 95 % upper bound ``mu_upper`` over boxes of an envelope.

mu_upper = μ exp(z σ) with σ² = g'Cg + noise² (g the finite-difference gradient of log μ in the fitted
values, C their covariance) is bounded over a box by interval arithmetic on that closed form, for the model
and each rival whose envelope it takes (:func:`mu_upper_box_bound`, for
:func:`optimize.envelope_bound.certified_max`); :mod:`optimize.envelope_bound` says why each piece's range
over a box is exact, and :mod:`optimize.design_bound` takes the same intervals over boxes of designs.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from microbearing import physics
from microbearing.physics.contact import jkr_load_elasticity
from microbearing.physics.effects import CONTACT_LOAD_EXPONENTS, PARAMETER_SHARES

from . import gp_boxes
from .envelope_bound import (
    Piece,
    _Boxes,
    _candidates,
    _corner_points,
    _pieces_range,
    _with_low_speed,
    drift_ranges,
    term_pieces,
)

__all__ = ["INTERVAL_OUTPUTS", "INTERVAL_RTOL", "MAX_VALUES", "IntervalStructure", "interval_structures",
           "mu_upper_box_bound"]

#: The physics' outputs the interval's bound reads (``physics_fn`` of :func:`mu_upper_box_bound`).
INTERVAL_OUTPUTS = ("mu", "mu_pivoting", "mu_rolling", "mu_ball_ball", "mu_hysteresis", "contact_load_N",
                    "adhesion_force_N")
#: Relative allowance for rounding in the interval's bound: the finite-difference gradient's rounding,
#: about 1e-16 / 1e-6 in g, is far below it. [1]
_INTERVAL_ROUNDING = 1e-9


#: Relative gap at which branching stops for mu_upper: its bound over a box tightens only linearly with the
#: box, and its certified lower bound over designs is far looser (the parameters' share). [1]
INTERVAL_RTOL = 1e-5
#: Most fitted values per model (the box of gradients has 2^n vertices). [1]
MAX_VALUES = 10


@dataclass(frozen=True)
class IntervalStructure:
    """One model whose interval enters ``mu_upper``: the calibrated model itself or a rival.

    Attributes
    ----------
    fitted : dict of str to float
        Its fitted physics parameters (each declared ``linear`` in :data:`physics.effects.PARAMETER_SHARES`).
    pieces : list of Piece
        Its effect terms.
    covariance : numpy.ndarray
        Covariance of its fitted values (declared, then each term's).
    noise_std_log : float
        Scatter of log μ of a new measurement. [1]
    step : float
        Relative finite-difference step of its gradient. [1]
    model : calibrate.CalibratedModel
        The model itself (for its Gaussian-process discrepancy's bounds).
    groups : list of calibrate.groups.GroupEffect
        Its group effects (a point of the envelope names no group: each shifts log μ by s b0 and adds
        s² times the new-group variance, s the sensitivity to the group's parameter, 1 for μ itself).
    """

    fitted: dict[str, float]
    pieces: list[Piece]
    covariance: np.ndarray
    noise_std_log: float
    step: float
    groups: list = dataclasses.field(default_factory=list)
    model: Any = None


def interval_structures(model: Any) -> tuple[list[IntervalStructure] | None, str]:
    """The structures of a calibrated model's ``mu_upper`` (itself and each rival), or None and why not."""
    pieces, reason = term_pieces(model, interval=True)
    if pieces is None:
        return None, reason
    calibrated = model.calibrated
    if calibrated.covariance is None or calibrated.noise_std_log is None:
        return None, "it has no interval"
    step = float(getattr(calibrated, "gradient_step", math.nan))
    models = [calibrated, *calibrated.rival_models()]
    out = []
    for index, each in enumerate(models):
        label = "its rival" if index else "it"
        pieces_of, reason = term_pieces(_Holder(model.reference, each), interval=True)
        if pieces_of is None:
            return None, f"{label}: {reason}"
        unknown = [n for n in each.fitted if n not in PARAMETER_SHARES or not PARAMETER_SHARES[n].linear]
        if unknown:
            return None, f"{label} fits {unknown[0]}, whose effect on mu has no bound over a box here"
        for piece in pieces_of:
            for i, name in enumerate(piece.term.parameter_names):
                if piece.kind != "drift" and piece.value_form(i) is None:
                    return None, (f"{label}: the fitted {name} of {piece.term.label} changes mu in a way "
                                  "with no bound over a box here")
        size = len(each.fitted) + sum(len(p.values) for p in pieces_of)
        if size > MAX_VALUES:
            return None, f"{label} has {size} fitted values (at most {MAX_VALUES} are bounded)"
        groups = list(getattr(each, "groups", None) or [])
        out.append(IntervalStructure(dict(each.fitted), pieces_of, np.asarray(each.covariance, dtype=float),
                                     _noise_std_log(each), step, groups, each))
    return out, ""


def _noise_std_log(model: Any) -> float:
    """The noise of log μ the model's interval applies (its small-sample and tail factor included)."""
    declared = getattr(model, "interval_noise_std_log", None)
    return float(declared()) if callable(declared) else float(model.noise_std_log)


@dataclass(frozen=True)
class _Holder:
    reference: str
    calibrated: Any


def _composed(pieces: list[Piece], ranges: list[tuple[np.ndarray, np.ndarray]], start_lo: np.ndarray,
              start_hi: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray], Callable, Callable]:
    """μ composed over boxes by interval arithmetic: the physics' range, then each piece's added or
    multiplying range (a drift moves the physics' inputs and passes the level on); the levels after each
    step (the first the physics'), ``after(k)``, the product of the factors after piece k (k = -1: after
    the physics), and ``adds_after(k)``, whether an addition follows piece k."""
    levels_lo, levels_hi = [start_lo], [start_hi]
    for piece, (low, top) in zip(pieces, ranges, strict=True):
        if piece.kind == "drift":
            levels_lo.append(levels_lo[-1])
            levels_hi.append(levels_hi[-1])
        elif piece.kind == "add":
            levels_lo.append(levels_lo[-1] + low)
            levels_hi.append(levels_hi[-1] + top)
        else:
            ok = (low > 0) & (levels_lo[-1] >= 0)
            levels_lo.append(np.where(ok, levels_lo[-1] * low, -np.inf))
            levels_hi.append(np.where(ok, levels_hi[-1] * top, np.inf))
    n = len(start_lo)

    def after(k: int) -> tuple[np.ndarray, np.ndarray]:
        p_lo, p_hi = np.ones(n), np.ones(n)
        for piece, (low, top) in list(zip(pieces, ranges, strict=True))[k + 1:]:
            if piece.kind == "mul":
                p_lo, p_hi = p_lo * low, p_hi * top
        return p_lo, p_hi

    def adds_after(k: int) -> bool:
        return any(piece.kind == "add" for piece in pieces[k + 1:])

    return levels_lo, levels_hi, after, adds_after


def _drift_share_change(piece: Piece, i: int, h: float, driver_interval: Callable[[str], tuple],
                        drifted: Mapping[str, tuple[np.ndarray, np.ndarray]], n: int,
                        phys: Mapping[str, np.ndarray]) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """How a step h in a drift's coefficient (i = 0) or level (i = 1) changes the shares of the physics its
    parameter drives, over n boxes: per share, the output it is and [d_lo, d_hi], the interval of its
    relative change [1] (the physics changes by the sum of share x change).

    The parameter moves by the ratio r = f(c + h, x) / f(c, x), monotone in x so taken at the ends of the
    driver's interval (``driver_interval(driver) -> (low, high, ...)``), or by (level + h) / level; where
    the box may clip the parameter at a bound (``drifted``: its range per box), one is inside the ratio's
    interval. A share that is a power a of the parameter (:data:`physics.effects.PARAMETER_SHARES`) changes
    by r^a - 1; a parameter that moves the contact load Q (``contact_load``, the adhesion energy) moves ln Q
    by ln r times Q's elasticity in it (:func:`physics.contact.jkr_load_elasticity`, non-decreasing in it
    over the load Q0: between its values at the box's least parameter over its largest Q0 and the largest
    over the least, both stepped), and each share of :data:`physics.effects.CONTACT_LOAD_EXPONENTS` by
    Q's ratio to its power. ``phys``: the physics' outputs at the boxes' lowest corners, then the highest
    (the parameter at its low, then high end, as it moves μ). A ratio that is not positive gives an
    unbounded change.
    """
    term = piece.term
    share = PARAMETER_SHARES[term.parameter]
    if i == 0:
        a, b = driver_interval(term.driver)[:2]
        c = piece.values[0]
        with np.errstate(all="ignore"):
            ratios = [np.asarray(term.factor({term.driver: x}, c + h), dtype=float)
                      / np.asarray(term.factor({term.driver: x}, c), dtype=float) for x in (a, b)]
        ratio_lo, ratio_hi = np.minimum(*ratios), np.maximum(*ratios)
    else:
        ratio_lo = ratio_hi = np.full(n, (piece.values[1] + h) / piece.values[1])
    spec = physics.PARAMETERS[term.parameter]
    low, high = drifted[term.parameter]
    clipped = ((spec.minimum is not None) & (low <= spec.minimum)) | (
        (spec.maximum is not None) & (high >= np.nextafter(spec.maximum, -np.inf)))
    ratio_lo = np.where(clipped, np.minimum(ratio_lo, 1.0), ratio_lo)
    ratio_hi = np.where(clipped, np.maximum(ratio_hi, 1.0), ratio_hi)
    ok = ratio_lo > 0
    with np.errstate(all="ignore"):
        log_lo, log_hi = np.log(np.where(ok, ratio_lo, 1.0)), np.log(np.where(ok, ratio_hi, 1.0))
        if share.contact_load:
            load, force = phys["contact_load_N"], phys["adhesion_force_N"]
            e_lo = jkr_load_elasticity(load[n:], force[:n] * np.minimum(ratio_lo, 1.0))
            e_hi = jkr_load_elasticity(load[:n], force[n:] * np.maximum(ratio_hi, 1.0))
            log_lo, log_hi = _product(log_lo, log_hi, e_lo, e_hi)
            powers = CONTACT_LOAD_EXPONENTS.items()
        else:
            powers = [(share.output, share.exponent)]
        return [(output, np.where(ok, np.expm1(exponent * log_lo), -np.inf),
                 np.where(ok, np.expm1(exponent * log_hi), np.inf)) for output, exponent in powers]


def _physics_change(changes: list[tuple[str, np.ndarray, np.ndarray]], phys: Mapping[str, np.ndarray], n: int,
                    low: Any = 1.0, high: Any = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The interval of the physics' change over n boxes, the sum over :func:`_drift_share_change`'s shares of
    each share (its output at the lowest corners times ``low``, at the highest times ``high``) times its
    relative change (interval arithmetic)."""
    parts = [_product(d_lo, d_hi, phys[output][:n] * low, phys[output][n:] * high)
             for output, d_lo, d_hi in changes]
    return sum(p[0] for p in parts), sum(p[1] for p in parts)


def _log_gradient(g_lo: list, g_hi: list, ratio_lo: np.ndarray, ratio_hi: np.ndarray, h: float) -> None:
    """Append to ``g_lo``/``g_hi`` the interval of the finite-difference gradient of log mu,
    log1p(D / mu) / h, from the interval [ratio_lo, ratio_hi] of D / mu (unbounded where D / mu may reach
    -1)."""
    ok = ratio_lo > -1
    g_lo.append(np.where(ok, np.log1p(np.where(ok, ratio_lo, 0.0)) / h, -np.inf))
    g_hi.append(np.where(ok, np.log1p(np.where(ok, ratio_hi, 0.0)) / h, np.inf))


def _times_positive(low: np.ndarray, high: np.ndarray, pos_low: np.ndarray,
                    pos_high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[low, high] × [pos_low, pos_high] with 0 < pos_low <= pos_high (interval arithmetic)."""
    return (np.where(low >= 0, low * pos_low, low * pos_high),
            np.where(high >= 0, high * pos_high, high * pos_low))


def _product(a_lo: Any, a_hi: Any, b_lo: Any, b_hi: Any) -> tuple[np.ndarray, np.ndarray]:
    """[a_lo, a_hi] × [b_lo, b_hi] (interval arithmetic, any signs; NaN where an end is not finite)."""
    with np.errstate(all="ignore"):
        corners = np.array(np.broadcast_arrays(a_lo * b_lo, a_lo * b_hi, a_hi * b_lo, a_hi * b_hi),
                           dtype=float)
    return np.min(corners, axis=0), np.max(corners, axis=0)


def mu_upper_box_bound(structures: list[IntervalStructure],
                       physics_fn: Callable[[np.ndarray, np.ndarray, Mapping[str, float]],
                                            dict[str, np.ndarray]],
                       envelope: Any, design: Mapping[str, float], z: float, calibrated: Any = None,
                       inputs_fn: Callable[[np.ndarray, np.ndarray], Mapping[str, Any]] | None = None,
                       base: Mapping[str, Any] | None = None) -> Callable:
    """The box bound of a calibrated model's ``mu_upper`` at a design, for :func:`certified_max`.

    Over a box every quantity of each structure gets an interval: the physics' μ and each linear output
    between the box's lowest and highest corner (posynomials), each piece's exact range, the composed μ
    by interval arithmetic (add and multiply of positive intervals); each fitted value's finite-difference
    gradient of log μ, log1p(D / μ) / h, with D = μ(p + h) - μ(p) in closed form (``h`` × the physics
    output / p, ``h`` × the piece's basis, or the composed μ up to that factor × expm1(h φ)) times the
    product of the factors after it; the largest g'Cg over the box of gradients (a convex function: at one
    of its vertices); so mu_upper <= max over the structures of max(μ) exp(z sqrt(max g'Cg + (noise W)²)),
    (the discrepancy's variance, where there is one, widened as the noise's),
    W the widening beyond the data cloud and the data's ranges at an upper bound of the distance
    ratio over the box (:meth:`calibrate.CalibratedModel.cloud_ratio_bound`; the widening,
    :meth:`calibrate.domain.DataCloud.widening`, is non-decreasing in the ratio, and one cloud serves the
    model and its rivals).

    Parameters
    ----------
    structures : list of IntervalStructure
        From :func:`interval_structures`.
    physics_fn : callable
        ``(angle_offset_deg, speed_m_s, fitted) -> {"mu": ..., <output>: ...}`` [1] of the physics at the
        design with those fitted values (and drifted parameters, arrays), for :data:`INTERVAL_OUTPUTS`.
    envelope : optimize.robust.Envelope
        The envelope.
    design : mapping
        ``balls`` [1] and ``load_N`` [N].
    z : float
        The normal quantile of the interval (1.96 for 95 %). [1]
    calibrated : calibrate.CalibratedModel, optional
        The model, for its data cloud (needed when it has one).
    inputs_fn : callable, optional
        ``(angle_offset_deg, speed_m_s) -> physics inputs`` [their units] the model is given at the design
        (as its evaluation at envelope points is), for the cloud's columns.
    base : mapping, optional
        Physics inputs at the design as the model reads them, for the drifts' base values (each structure's
        fitted values take precedence).

    Returns
    -------
    callable
        ``(lo, hi) -> (upper bounds [1], points to evaluate)``.

    Raises
    ------
    ValueError
        For a model with a data cloud and no ``inputs_fn``.
    """
    boxes = _Boxes(envelope, design)
    level = 1.0 - 2.0 * float(stats.norm.sf(z))
    cloud = None if calibrated is None else getattr(calibrated, "cloud", None)
    gp = any(getattr(s.model, "discrepancy", None) is not None for s in structures)
    if (cloud is not None or gp) and inputs_fn is None:
        raise ValueError("a model with a data cloud or a discrepancy needs inputs_fn for their bounds")
    context = _IntervalContext(boxes, physics_fn, dict(base or {}), inputs_fn, z, level)

    def widening(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """An upper bound of the widening off the data over each box: the cloud's and the extrapolation
        allowance beyond the data's ranges (ones without a calibrated model or its inputs). [1]"""
        n = len(lo)
        if calibrated is None or inputs_fn is None:
            return np.ones(n)
        low, high = _corner_points(boxes, inputs_fn, lo, hi)
        return np.asarray(calibrated.widening(calibrated.cloud_ratio_bound(low, high, (n,))), dtype=float)

    def bound(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        peak = hi.copy()
        with np.errstate(all="ignore"):
            wide = widening(lo, hi)
            shared: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # a discrepancy's bound, once per batch
            upper = np.max([_structure_bound(context, s, lo, hi, peak, wide, shared) for s in structures],
                           axis=0)
        return upper * (1.0 + _INTERVAL_ROUNDING), _with_low_speed(boxes, lo, peak)

    return bound


@dataclass(frozen=True)
class _IntervalContext:
    """What every structure's bound over a batch of boxes reads (the arguments of
    :func:`mu_upper_box_bound`)."""

    boxes: _Boxes
    physics_fn: Callable
    base: Mapping[str, Any]
    inputs_fn: Callable | None
    z: float
    level: float


@dataclass(frozen=True)
class _Composed:
    """One structure's physics and composed μ over a batch of n boxes, by interval arithmetic."""

    lo: np.ndarray
    hi: np.ndarray
    phys: dict[str, np.ndarray]
    drifted: dict[str, tuple[np.ndarray, np.ndarray]]
    levels_lo: list[np.ndarray]
    levels_hi: list[np.ndarray]
    after: Callable
    adds_after: Callable
    usable: np.ndarray
    safe_lo: np.ndarray

    @property
    def n(self) -> int:
        """Boxes. [1]"""
        return len(self.lo)

    @property
    def mu_hi(self) -> np.ndarray:
        """The composed μ's upper end over each box. [1]"""
        return self.levels_hi[-1]


def _compose_structure(context: _IntervalContext, s: IntervalStructure, lo: np.ndarray, hi: np.ndarray,
                       peak: np.ndarray) -> _Composed:
    """The physics at each box's lowest and highest corner (drifted parameters at their ends where μ is least
    and largest) and the composed μ."""
    boxes, n = context.boxes, len(lo)
    offset_lo, speed_lo = boxes.physics_corner(lo)
    offset_hi, speed_hi = boxes.physics_corner(hi)
    # Drifted parameters at the ends where mu is least (the lowest corner) and largest (the highest);
    # every output read moves with each of them as mu does (PARAMETER_SHARES).
    drifts = [p for p in s.pieces if p.kind == "drift"]
    drifted = drift_ranges(drifts, {**physics.defaults(), **context.base, **s.fitted},
                           lambda driver: boxes.driver_interval(driver, lo, hi), n)
    moved = {name: np.r_[(low, high) if PARAMETER_SHARES[name].direction > 0 else (high, low)]
             for name, (low, high) in drifted.items()}
    phys = context.physics_fn(np.r_[offset_lo, offset_hi], np.r_[speed_lo, speed_hi], {**s.fitted, **moved})
    ranges = _pieces_range(s.pieces, boxes, lo, hi, speed_hi, peak)
    levels_lo, levels_hi, after, adds_after = _composed(s.pieces, ranges, phys["mu"][:n], phys["mu"][n:])
    mu_lo, mu_hi = levels_lo[-1], levels_hi[-1]
    usable = (mu_lo > 0) & np.isfinite(mu_hi)
    return _Composed(lo, hi, phys, drifted, levels_lo, levels_hi, after, adds_after, usable,
                     np.where(usable, mu_lo, 1.0))


def _drift_ratio(context: _IntervalContext, c: _Composed, piece: Piece, i: int,
                 h: float) -> tuple[np.ndarray, np.ndarray, float]:
    """D / mu for a step h in a drift's coefficient (i = 0) or level (i = 1): its share of the physics
    changes by :func:`_drift_share_change`, and mu by that change times the factors after the physics."""
    n, phys = c.n, c.phys
    changes = _drift_share_change(piece, i, h,
                                  lambda driver: context.boxes.driver_interval(driver, c.lo, c.hi),
                                  c.drifted, n, phys)
    change = _physics_change(changes, phys, n)  # D of the physics
    if c.adds_after(-1):
        q_lo, q_hi = c.after(-1)
        r_lo, r_hi = _product(*change, q_lo / c.mu_hi, q_hi / c.safe_lo)
    else:  # mu = physics x the factors: D / mu = D_phys / physics
        phys_lo = phys["mu"][:n]
        good = phys_lo > 0
        r_lo, r_hi = _product(*change, 1.0 / phys["mu"][n:], 1.0 / np.where(good, phys_lo, np.nan))
        r_lo, r_hi = np.where(good, r_lo, -np.inf), np.where(good, r_hi, np.inf)
    return r_lo, r_hi, h


def _fitted_ratios(s: IntervalStructure, c: _Composed, g_lo: list, g_hi: list) -> None:
    """Append the gradient intervals of the fitted physics values: each one's share is linear in it."""
    n, phys = c.n, c.phys
    for name, value in s.fitted.items():
        h = s.step * (abs(value) if value != 0 else 1.0)
        output = PARAMETER_SHARES[name].output
        basis_lo, basis_hi = phys[output][:n] / value, phys[output][n:] / value
        if c.adds_after(-1):
            p_lo, p_hi = c.after(-1)
            r_lo, r_hi = _times_positive(h * basis_lo, h * basis_hi, p_lo / c.mu_hi, p_hi / c.safe_lo)
        else:  # mu = physics x the factors: D / mu = h x output / (p physics), the factors cancel
            phys_lo = phys["mu"][:n]
            ok = phys_lo > 0
            r_lo = np.where(ok, h * basis_lo / phys["mu"][n:], -np.inf)
            r_hi = np.where(ok, h * basis_hi / np.where(ok, phys_lo, 1.0), np.inf)
        _log_gradient(g_lo, g_hi, r_lo, r_hi, h)


def _piece_ratio(context: _IntervalContext, c: _Composed, k: int, piece: Piece, i: int,
                 h: float) -> tuple[np.ndarray, np.ndarray]:
    """D / mu for a step h in an effect piece's i-th value, by its declared value form."""
    boxes, n, lo, hi = context.boxes, c.n, c.lo, c.hi
    speed_hi = boxes.physics_corner(hi)[1]
    p_lo, p_hi = c.after(k)
    value = piece.values[i]
    form = piece.value_form(i)
    unit = list(piece.values)
    if form == "scale":
        unit[i] = 1.0
        x, _ = _candidates(piece, boxes, lo, hi)
        basis = dataclasses.replace(piece, values=unit).at(x[:, :2], boxes.columns(n, speed_hi, 2))
        b_lo, b_hi = np.min(basis, axis=1), np.max(basis, axis=1)
        return _times_positive(h * b_lo, h * b_hi, p_lo / c.mu_hi, p_hi / c.safe_lo)
    unit[i] = value + 1.0
    centre = piece.term.constants.get("centre") if form == "log_square" else None
    x, _ = _candidates(piece, boxes, lo, hi, extra=centre if centre is not None else None)
    if form == "log":
        x = x[:, :2]
    columns = boxes.columns(n, speed_hi, x.shape[1])
    with np.errstate(all="ignore"):
        stepped = dataclasses.replace(piece, values=unit).at(x, columns)
        phi = np.log(stepped / piece.at(x, columns))
    f_lo, f_hi = np.expm1(h * np.min(phi, axis=1)), np.expm1(h * np.max(phi, axis=1))
    if c.adds_after(k):
        q_lo = c.levels_lo[k + 1] * p_lo / c.mu_hi
        q_hi = c.levels_hi[k + 1] * p_hi / c.safe_lo
    else:  # mu = (mu after this piece) x the factors after it: Q = 1 exactly
        q_lo = q_hi = np.ones(n)
    positive = (q_lo > 0) & np.isfinite(q_hi)
    r_lo, r_hi = _times_positive(f_lo, f_hi, np.where(positive, q_lo, 1.0), np.where(positive, q_hi, 1.0))
    return np.where(positive, r_lo, -np.inf), np.where(positive, r_hi, np.inf)


def _groups_shift(context: _IntervalContext, s: IntervalStructure, g_low: np.ndarray,
                  g_high: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The groups' largest shift of log μ and variance over each box [1]: the sensitivity s to a fitted
    parameter p is p times its gradient entry (the same finite difference), so it lies in p [g_lo, g_hi]; the
    shift s b0 and the variance s² v at their largest."""
    shift, group_variance = np.zeros(n), np.zeros(n)
    names = list(s.fitted)
    for group in s.groups:
        if group.parameter != "mu" and group.parameter in s.fitted:
            i, p = names.index(group.parameter), s.fitted[group.parameter]
            ends = (g_low[:, i] * p, g_high[:, i] * p)
            shift += np.maximum(ends[0] * group.offset_log, ends[1] * group.offset_log)
            group_variance += np.maximum(ends[0] ** 2, ends[1] ** 2) * group.new_group_variance(context.level)
        else:
            shift += group.offset_log
            group_variance += group.new_group_variance(context.level)
    return shift, group_variance


def _structure_bound(context: _IntervalContext, s: IntervalStructure, lo: np.ndarray, hi: np.ndarray,
                     peak: np.ndarray, wide: np.ndarray,
                     shared: dict[int, tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """One structure's upper bound of mu_upper over each box [1] (:func:`mu_upper_box_bound`); ``shared``:
    the discrepancies' bounds over these boxes by discrepancy, which the model and its rivals share
    (computed by the first structure that reads one, unless its features read a fitted value)."""
    c = _compose_structure(context, s, lo, hi, peak)
    n = c.n
    g_lo, g_hi = [], []
    _fitted_ratios(s, c, g_lo, g_hi)
    for k, piece in enumerate(s.pieces):
        for i, value in enumerate(piece.values):
            h = s.step * (abs(value) if value != 0 else 1.0)
            if piece.kind == "drift":
                _log_gradient(g_lo, g_hi, *_drift_ratio(context, c, piece, i, h))
            else:
                _log_gradient(g_lo, g_hi, *_piece_ratio(context, c, k, piece, i, h), h)
    g_low, g_high = np.column_stack(g_lo), np.column_stack(g_hi)
    finite = np.all(np.isfinite(g_low) & np.isfinite(g_high), axis=1) & c.usable
    g_low, g_high = np.where(finite[:, None], g_low, 0.0), np.where(finite[:, None], g_high, 0.0)
    corners = np.array(list(itertools.product((0, 1), repeat=g_low.shape[1])), dtype=bool)
    vertices = np.where(corners[None, :, :], g_high[:, None, :], g_low[:, None, :])
    quadratic = np.einsum("nvi,ij,nvj->nv", vertices, s.covariance, vertices).max(axis=1)
    shift, group_variance = _groups_shift(context, s, g_low, g_high, n)
    discrepancy = getattr(s.model, "discrepancy", None)
    if discrepancy is not None:
        key = id(discrepancy) if set(discrepancy.features).isdisjoint(s.fitted) else None
        if key is None or key not in shared:
            low, high = _corner_points(context.boxes, context.inputs_fn, lo, hi)
            _, gp_mean, gp_variance = gp_boxes.discrepancy_bound(s.model, low, high, n)
            if key is not None:
                shared[key] = gp_mean, gp_variance
        else:
            gp_mean, gp_variance = shared[key]
        # the discrepancy's variance widened as the scatter's (CalibratedModel.predict)
        shift, group_variance = shift + gp_mean, group_variance + gp_variance * wide**2
    sigma = np.sqrt(np.clip(quadratic, 0.0, None) + group_variance + (s.noise_std_log * wide)**2)
    return np.where(finite, c.mu_hi * np.exp(shift + context.z * sigma), np.inf)
