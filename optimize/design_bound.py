r"""A certified lower bound on the best achievable worst ``mu_upper`` over the designs, by branch and bound.

A calibrated model's 95 % upper bound U(d, e) = μ exp(z σ), σ² = g'Cg + noise² (g the finite-difference
gradient of log μ in the fitted values, C their covariance; :mod:`calibrate.model`), at design
d = (z balls, nominal angle θ, load G) and envelope point e (speed, conditions, angle offset). For any
envelope points e_1 .. e_m,

    min over d of max over e of U(d, e)  >=  min over d of max_j U(d, e_j),

and the right side is bounded below by branch and bound over the designs: per ball count the box of
(θ, G), split in halves, each box given a certified lower bound of U at every point e_j:

* the physics' friction force F = μ G is z times the moments and forces of :mod:`optimize.dgp`, each a
  positive monomial of the contact load Q, which grows with G sec θ, or of tan θ, sec θ: F never falls as
  θ or G grows, so over a box F lies between its values at the lowest and the highest corner, and
  μ = F / G in [F(lo) / G_hi, F(hi) / G_lo]; the pivoting share (the output the fitted ``mu_pivot``
  scales) likewise, and its ratio to the physics' μ in [F_P(lo) / F(hi), F_P(hi) / F(lo)];
* at a fixed point every effect term's driver is fixed or is the load, and the term is a positive
  monomial in balls and load there (read at three designs and checked at a fourth by the caller): its
  range over [G_lo, G_hi] is at the ends, and so is the range of each fitted value's effect on it (a
  basis linear in the value, or a factor exp(h φ) with φ of the driver); or it is a term of the load
  alone that declares where its extremes lie (:class:`physics.effects.Effect`: monotone, or at its
  ``stationary`` point, as a ``generic_quadratic`` on the load): its range is at the ends and that point
  where inside, and each value's φ at the ends (``log``) and its data's centre (``log_square``,
  :data:`physics.effects.VALUE_FORMS`);
* the composed μ and each fitted value's gradient of log μ by interval arithmetic in closed form, term by
  term as :func:`optimize.envelope_bound.mu_upper_box_bound` does over the envelope at one design;
* the least g'Cg over the box of gradients, a convex quadratic program: a few sweeps of coordinate
  descent give a point ĝ of the box, and convexity gives, for every g of the box,
  g'Cg >= ĝ'Cĝ + 2 (Cĝ)'(g - ĝ) >= ĝ'Cĝ + Σ_i min over g_i's ends of 2 (Cĝ)_i (g_i - ĝ_i), a bound
  whatever ĝ is (the Frank-Wolfe gap; interval arithmetic on the quadratic form when C is not positive
  semi-definite);
* a drifting physics parameter (a drift term) is, at a fixed point, the law at the point's driver value (a
  condition): a constant over the design box, given to the physics as its input
  (:func:`optimize.envelope_bound.drift_ranges`); its coefficient's (or level's) finite-difference step
  moves the parameter by a known ratio, and the parameter's share of the physics
  (declared in :data:`physics.effects.PARAMETER_SHARES`: an output whose friction force grows like F) by that
  ratio to its power (the adhesion energy: the contact load Q by that ratio to a power between Q's least
  and largest elasticity in it, and each share of μ by Q's ratio to its declared power,
  :data:`physics.effects.CONTACT_LOAD_EXPONENTS`), so its gradient entry by interval arithmetic as the
  envelope's bound does; a fitted value a drift with its own level replaces has gradient entry 0;
* group effects at a point naming no group (:meth:`_Bounds._groups`): one on μ (or on a parameter the
  model does not fit) shifts log μ by its offset b0 and adds its new-group variance v, constants; one on a
  fitted parameter p by s b0 and s² v, s = p g_p its sensitivity, g_p in the gradient's box: the least
  of s b0 at the box's ends and s² v at its least (0 where the box holds s = 0);
* a Gaussian-process discrepancy adds its least mean over the box to the shift and its least latent variance
  to σ² (:meth:`calibrate.model.GPCorrection.bound`, :meth:`~calibrate.model.GPCorrection.least_variance`),
  every column of the model's points at the box's two corners (monotone in θ and G);
* so U >= μ_lo exp(shift + z sqrt(least g'Cg + groups' variance + noise²) w), for the model and for each
  rival whose interval enters U (U is the largest of their bounds), less 1e-9 relative for rounding; w >= 1
  is a lower bound of the factor a data cloud widens σ by off the data (the caller's,
  :func:`kth_distance_to_boxes`: the distance to the k-th nearest row is at least the k-th smallest distance
  from the box to the rows), or 1.

A box is dropped where a limit is certainly broken there (the peak pressure at its lowest load and the
angle made high; the load per ball; the minimum load; the friction force U G at its lowest), and where its
bound is within ``rtol`` of the incumbent, the least max_j U found at a design that meets the limits (the
design given first, then the centres of the boxes of lowest bound, whose values also check every box's
bound: a value below it raises :class:`~optimize.envelope_bound.BoundFailedError`). The certified lower
bound is the least bound of the boxes left or dropped by the incumbent, capped by the incumbent; where the
box or time limit stops the search, the bound found so far, said so (``complete`` False).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from microbearing import physics
from microbearing.physics.effects import PARAMETER_SHARES

from . import gp_boxes
from .envelope_bound import (
    BoundFailedError,
    drift_ranges,
)
from .interval_bound import (
    INTERVAL_OUTPUTS,
    IntervalStructure,
    _composed,
    _drift_share_change,
    _log_gradient,
    _physics_change,
    _product,
    _times_positive,
)
from .problem import DesignProblem

__all__ = ["DESIGN_RTOL", "MAX_DESIGN_BOXES", "DesignLowerBound", "DesignPoints", "design_lower_bound",
           "kth_distance_to_boxes"]

#: Relative distance below the incumbent at which a box is dropped (with the bracket at the design, within
#: the gap target of a proof). [1]
DESIGN_RTOL = 1e-7
#: Most design boxes bounded before the bound found so far is returned as it stands. [1]
MAX_DESIGN_BOXES = 400_000
#: Relative allowance for rounding taken off every box's bound (the finite-difference gradient's rounding,
#: about 1e-16 / 1e-6 in g, and the composition's). [1]
_ROUNDING = 1e-9
#: Boxes split per vectorized step. [1]
_BATCH = 2048
#: Children per step at whose centres the model itself is evaluated. [1]
_EVALUATED = 16
#: Most sweeps of coordinate descent towards the least g'Cg over a box (any number gives a valid bound; they
#: stop where every box's Frank-Wolfe gap is below 1e-10 relative). [1]
_SWEEPS = 200
#: A box narrower than this, relative to the design box in every variable, is not split further. [1]
_NARROWEST = 1e-12


@dataclass(frozen=True)
class DesignLowerBound:
    """The certified lower bound of min over designs of max_j U(d, e_j), with what it rests on.

    Attributes
    ----------
    lower_bound : float
        Certified lower bound over every design meeting the limits (relaxed to the points). [1]
    incumbent : float
        The least max_j U(d, e_j) found at a design meeting the limits there. [1]
    incumbent_design : dict
        That design: ``balls`` [1], ``groove_angle_deg`` (nominal) [deg], ``load_N`` [N].
    improved : bool
        Whether a design other than the one given has a lower value at the points (then the points do
        not yet hold the given design's worst case for it: more are needed).
    boxes : int
        Design boxes bounded. [1]
    complete : bool
        Whether every box was settled (False: stopped at the box or time limit).
    design_meets_limits : bool
        Whether the design given meets every limit at the points (else it was no incumbent).
    """

    lower_bound: float
    incumbent: float
    incumbent_design: dict[str, float]
    improved: bool
    boxes: int
    complete: bool
    design_meets_limits: bool


def _least_quadratic(covariance: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """A certified lower bound of min g'Cg over each box [lo, hi] of gradients (rows) (module docstring)."""
    n, k = lo.shape
    if k == 0:
        return np.zeros(n)
    eigen = np.linalg.eigvalsh(0.5 * (covariance + covariance.T))
    if eigen.min() < -1e-12 * max(abs(eigen.max()), 1e-300):
        # Not positive semi-definite: interval arithmetic on each product g_i g_j.
        total = np.zeros(n)
        for i in range(k):
            for j in range(k):
                if i == j:
                    low = np.where((lo[:, i] <= 0) & (hi[:, i] >= 0), 0.0,
                                   np.minimum(lo[:, i] ** 2, hi[:, i] ** 2))
                    high = np.maximum(lo[:, i] ** 2, hi[:, i] ** 2)
                else:
                    products = np.stack([lo[:, i] * lo[:, j], lo[:, i] * hi[:, j], hi[:, i] * lo[:, j],
                                         hi[:, i] * hi[:, j]])
                    low, high = products.min(axis=0), products.max(axis=0)
                c = covariance[i, j]
                total += c * (low if c >= 0 else high)
        return total
    g = np.clip(0.0, lo, hi)
    diagonal = np.diag(covariance)
    for sweep in range(_SWEEPS):
        for i in range(k):
            if diagonal[i] <= 0:
                continue
            g[:, i] = np.clip(g[:, i] - (g @ covariance[i]) / diagonal[i], lo[:, i], hi[:, i])
        slope = 2.0 * g @ covariance
        value = np.einsum("ni,ij,nj->n", g, covariance, g)
        gap = np.minimum(slope * (lo - g), slope * (hi - g)).sum(axis=1)
        if sweep % 8 == 7 and np.all(-gap <= 1e-10 * value + 1e-300):
            break
    return value + gap


def _range_of(at: Callable, piece: Any, n: int) -> tuple[np.ndarray, np.ndarray]:
    """A piece's range over each of n boxes from its values at the load's two ends and, for a term of the load
    that is not monotone, at its stationary point where inside (``at(piece, extra=...)``); a drift moves the
    physics' inputs and has no factor of its own."""
    if piece.kind == "drift":
        return np.ones(n), np.ones(n)
    v = at(piece, extra=piece.stationary())
    return ((v.min(axis=1), v.max(axis=1)) if np.all(np.isfinite(v))
            else (np.full(n, -np.inf), np.full(n, np.inf)))


def _gradient_box(covariance: np.ndarray, g_lo: list, g_hi: list,
                  n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The box of gradients over each of n design boxes (zero where an end is not finite), whether it is
    finite, and the least g'Cg over it [1]."""
    if not g_lo:
        return np.zeros((n, 0)), np.zeros((n, 0)), np.ones(n, dtype=bool), np.zeros(n)
    low, high = np.column_stack(g_lo), np.column_stack(g_hi)
    finite = np.all(np.isfinite(low) & np.isfinite(high), axis=1)
    low, high = np.where(finite[:, None], low, 0.0), np.where(finite[:, None], high, 0.0)
    return low, high, finite, np.where(finite, _least_quadratic(covariance, low, high), 0.0)


class _Bounds:
    """The box bound of U at fixed envelope points, and the limits' certain violations."""

    def __init__(self, problem: DesignProblem, structures: Sequence[IntervalStructure],
                 calibrated_fixed: Mapping[str, float], points: Sequence[Mapping[str, Any]],
                 angle_tolerance_deg: float, z_quantile: float,
                 widening: Sequence[Callable | None] | None = None):
        self.problem, self.structures, self.points = problem, list(structures), list(points)
        self.calibrated_fixed = dict(calibrated_fixed)
        self.delta, self.z_quantile = angle_tolerance_deg, z_quantile
        self.widening = list(widening) if widening is not None else [None] * len(self.points)
        #: The interval's level, for the groups' new-group variance. [1]
        self.level = 1.0 - 2.0 * float(stats.norm.sf(z_quantile))

    def _physics(self, fitted: Mapping[str, Any], balls: np.ndarray, theta: np.ndarray, load: np.ndarray,
                 speed: float) -> dict[str, np.ndarray]:
        linear = [share.output for share in PARAMETER_SHARES.values() if share.linear]
        outputs = list(dict.fromkeys(["mu", *linear, *INTERVAL_OUTPUTS]))
        columns = self.problem.physics_inputs(balls, theta, load, speed_m_s=speed)
        inputs = {k: v for k, v in columns.items() if k not in fitted}
        with np.errstate(all="ignore"):
            result = physics.evaluate(convention=self.problem.convention, outputs=outputs,
                                      **{**inputs, **self.calibrated_fixed, **fitted})
        return {name: np.asarray(getattr(result, name), dtype=float) for name in outputs}

    def _one(self, s: IntervalStructure, point: Mapping[str, Any], z: np.ndarray, tl: np.ndarray,
             th: np.ndarray, gl: np.ndarray, gh: np.ndarray, widened: np.ndarray) -> np.ndarray:
        n = len(z)
        offset, speed = float(point["groove_angle_offset_deg"]), float(point["speed_m_s"])

        def driver_interval(driver: str) -> tuple[np.ndarray, np.ndarray, None]:
            """A drift's driver (a condition, or the speed) over the boxes: fixed at the point."""
            value = speed if driver == "speed_m_s" else float(point["conditions"][driver])
            return np.full(n, value), np.full(n, value), None

        # A drifting parameter at the point: the law at the driver's value, a constant over the box (at its
        # end where mu is least for the lowest corner and largest for the highest, were it an interval).
        drifts = [piece for piece in s.pieces if piece.kind == "drift"]
        drifted = drift_ranges(drifts, {**physics.defaults(), **self.problem.fixed, **self.calibrated_fixed,
                                        **s.fitted}, driver_interval, n)
        moved = {name: np.r_[(low, high) if PARAMETER_SHARES[name].direction > 0 else (high, low)]
                 for name, (low, high) in drifted.items()}
        phys = self._physics({**s.fitted, **moved}, np.r_[z, z], np.r_[tl, th] + offset, np.r_[gl, gh], speed)
        load = np.r_[gl, gh]
        force = phys["mu"] * load
        f_lo, f_hi = force[:n], force[n:]
        # Each term at the two ends of the load (its driver fixed at the point, or the load itself) and, for a
        # term of the load, at a third load in the box where it declares an extreme (else the low end again).
        columns = {"balls": np.column_stack([z, z, z]), "load_N": np.column_stack([gl, gh, gl]),
                   "speed_m_s": np.full((n, 3), speed),
                   **{c: np.full((n, 3), v) for c, v in point["conditions"].items()}}

        def at(piece, values=None, extra=None) -> np.ndarray:
            return _at_loads(columns, piece, values, extra)

        ranges = [_range_of(at, piece, n) for piece in s.pieces]
        levels_lo, levels_hi, after, adds_after = _composed(s.pieces, ranges, f_lo / gh, f_hi / gl)
        mu_lo, mu_hi = levels_lo[-1], levels_hi[-1]
        usable = (mu_lo > 0) & np.isfinite(mu_hi)
        safe_lo = np.where(usable, mu_lo, 1.0)

        g_lo, g_hi = [], []

        def gradient(ratio_lo: np.ndarray, ratio_hi: np.ndarray, h: float) -> None:
            _log_gradient(g_lo, g_hi, ratio_lo, ratio_hi, h)

        def drift_ratio(piece: Any, i: int, h: float) -> tuple[np.ndarray, np.ndarray, float]:
            """D / mu for a step h in a drift's coefficient (i = 0) or level (i = 1), as
            :func:`optimize.envelope_bound.mu_upper_box_bound` takes it: its share of the physics changes
            by :func:`optimize.envelope_bound._drift_share_change` (x the driver's value at the point),
            and mu by that change times the factors after the physics."""
            changes = _drift_share_change(piece, i, h, driver_interval, drifted, n, phys)
            # each share's friction force grows like F: over G (its ends crossed), or not, where G cancels
            change = _physics_change(changes, phys, n, *((gl / gh, gh / gl) if adds_after(-1) else (gl, gh)))
            if adds_after(-1):
                p_lo, p_hi = after(-1)
                r_lo, r_hi = _product(*change, p_lo / mu_hi, p_hi / safe_lo)
            else:  # mu = physics x the factors: D / mu = D_phys / physics, and G cancels
                good = f_lo > 0
                r_lo, r_hi = _product(*change, 1.0 / f_hi, 1.0 / np.where(good, f_lo, np.nan))
                r_lo, r_hi = np.where(good, r_lo, -np.inf), np.where(good, r_hi, np.inf)
            return np.nan_to_num(r_lo, nan=-np.inf), np.nan_to_num(r_hi, nan=np.inf), h

        # A fitted value a drift with its own level replaces has no effect on mu: its gradient entry is 0.
        replaced = {piece.term.parameter for piece in drifts if piece.term.level}
        for name, value in s.fitted.items():
            h = s.step * (abs(value) if value != 0 else 1.0)
            share = phys[PARAMETER_SHARES[name].output] * load  # the share's friction force, growing like F
            s_lo, s_hi = share[:n], share[n:]
            if name in replaced:
                g_lo.append(np.zeros(n))
                g_hi.append(np.zeros(n))
            elif value <= 0:
                gradient(np.full(n, -np.inf), np.full(n, np.inf), h)
            elif adds_after(-1):
                p_lo, p_hi = after(-1)
                r_lo, r_hi = _times_positive(h * s_lo / (value * gh), h * s_hi / (value * gl),
                                             p_lo / mu_hi, p_hi / safe_lo)
                gradient(r_lo, r_hi, h)
            else:  # D / mu = h x share / (p x physics): the factors after cancel, and so does G
                ok = f_lo > 0
                gradient(np.where(ok, h * s_lo / (value * f_hi), -np.inf),
                         np.where(ok, h * s_hi / (value * np.where(ok, f_lo, 1.0)), np.inf), h)
        for k, piece in enumerate(s.pieces):
            p_lo, p_hi = after(k)
            if piece.kind == "drift":
                for i, value in enumerate(piece.values):
                    gradient(*drift_ratio(piece, i, s.step * (abs(value) if value != 0 else 1.0)))
                continue
            for i, value in enumerate(piece.values):
                h = s.step * (abs(value) if value != 0 else 1.0)
                form = piece.value_form(i)
                moved = list(piece.values)
                if form == "scale":
                    moved[i] = 1.0
                    basis = at(piece, moved)
                    r_lo, r_hi = _times_positive(h * basis.min(axis=1), h * basis.max(axis=1),
                                                 p_lo / mu_hi, p_hi / safe_lo)
                else:
                    moved[i] = value + 1.0
                    # phi of a log_square value is least at its data's centre (physics.effects.VALUE_FORMS)
                    centre = piece.term.constants.get("centre") if form == "log_square" else None
                    with np.errstate(all="ignore"):
                        phi = np.log(at(piece, moved, centre) / at(piece, None, centre))
                    f_low, f_high = np.expm1(h * phi.min(axis=1)), np.expm1(h * phi.max(axis=1))
                    if adds_after(k):
                        q_lo, q_hi = levels_lo[k + 1] * p_lo / mu_hi, levels_hi[k + 1] * p_hi / safe_lo
                    else:
                        q_lo = q_hi = np.ones(n)
                    positive = (q_lo > 0) & np.isfinite(q_hi)
                    r_lo, r_hi = _times_positive(f_low, f_high, np.where(positive, q_lo, 1.0),
                                                 np.where(positive, q_hi, 1.0))
                    r_lo, r_hi = np.where(positive, r_lo, -np.inf), np.where(positive, r_hi, np.inf)
                gradient(r_lo, r_hi, h)
        low, high, finite, quadratic = _gradient_box(s.covariance, g_lo, g_hi, n)
        shift, group_variance = self._groups(s, low, high, finite)
        if getattr(s.model, "discrepancy", None) is not None:
            gp_mean, gp_variance = self._discrepancy(s, point, z, (tl, th), (gl, gh))
            # the discrepancy's variance widened as the scatter's (CalibratedModel.predict)
            shift, group_variance = shift + gp_mean, group_variance + gp_variance * widened**2
        sigma = np.sqrt(np.clip(quadratic, 0.0, None) + group_variance + (s.noise_std_log * widened)**2)
        with np.errstate(all="ignore"):
            return np.where(usable, mu_lo * np.exp(shift + self.z_quantile * sigma), 0.0) * (1.0 - _ROUNDING)

    def _discrepancy(self, s: IntervalStructure, point: Mapping[str, Any], z: np.ndarray,
                     angles: tuple[np.ndarray, np.ndarray],
                     loads: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """The Gaussian-process discrepancy over the design boxes at the point: its least mean and least
        latent variance [1], every column of the model's points monotone in the angle and the load."""
        n = len(z)
        offset, speed = float(point["groove_angle_offset_deg"]), float(point["speed_m_s"])
        corners = []
        for theta, load_end in zip(angles, loads, strict=True):
            columns = self.problem.physics_inputs(z, theta + offset, load_end, speed_m_s=np.full(n, speed))
            corners.append({**{k: v for k, v in columns.items()
                               if k not in self.calibrated_fixed and k not in s.fitted},
                            **{c: np.full(n, v) for c, v in point["conditions"].items()}})
        return (gp_boxes.discrepancy_bound(s.model, corners[0], corners[1], n)[0],
                gp_boxes.discrepancy_least_variance(s.model, corners[0], corners[1], n))

    def _groups(self, s: IntervalStructure, low: np.ndarray, high: np.ndarray,
                finite: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The least shift of log μ [1] and the least variance [1] the groups add over each box, at points
        naming no group: a group on μ (or on a parameter the model does not fit) shifts by b0 and adds the
        new-group variance v, constants; one on a fitted parameter p by s b0 and s² v, s = p g_p (the
        sensitivity, g_p its gradient entry, in [p g_lo, p g_hi]): the least of s b0 at the interval's ends,
        and s² v at its least (0 where the interval holds 0). Unknown gradients: shift -inf (no bound)."""
        n = len(finite)
        shift, variance = np.zeros(n), np.zeros(n)
        names = list(s.fitted)
        for group in s.groups:
            v = group.new_group_variance(self.level)
            if group.parameter != "mu" and group.parameter in s.fitted:
                i, p = names.index(group.parameter), s.fitted[group.parameter]
                a, b = low[:, i] * p, high[:, i] * p
                s_lo, s_hi = np.minimum(a, b), np.maximum(a, b)
                b0 = group.offset_log
                shift += np.where(finite, np.minimum(s_lo * b0, s_hi * b0), -np.inf)
                least = np.where((s_lo <= 0) & (s_hi >= 0), 0.0, np.minimum(s_lo**2, s_hi**2))
                variance += np.where(finite, least, 0.0) * v
            else:
                shift += group.offset_log
                variance += v
        return shift, variance

    def lower(self, z: np.ndarray, tl: np.ndarray, th: np.ndarray, gl: np.ndarray,
              gh: np.ndarray) -> np.ndarray:
        """A certified lower bound of max_j U over each box [1] (0 where nothing is known)."""
        bounds = []
        for point, widening in zip(self.points, self.widening, strict=True):
            widened = np.ones(len(z)) if widening is None else np.maximum(widening(z, tl, th, gl, gh), 1.0)
            bounds += [self._one(s, point, z, tl, th, gl, gh, widened) for s in self.structures]
        return np.nan_to_num(np.max(bounds, axis=0), nan=0.0, posinf=0.0)

    def broken(self, z: np.ndarray, tl: np.ndarray, gl: np.ndarray, gh: np.ndarray,
               lower: np.ndarray) -> np.ndarray:
        """Whether a limit is broken everywhere in each box (the limits exact, at their least there)."""
        c = self.problem.constraints
        out = np.zeros(len(z), dtype=bool)
        allowance = 1.0 + 1e-9
        if c.max_contact_pressure_Pa is not None:
            with np.errstate(all="ignore"):
                pressure = physics.evaluate(convention=self.problem.convention,
                                            outputs=["max_contact_pressure_Pa"],
                                            **self.problem.physics_inputs(z, tl + self.delta, gl))
            peak = np.asarray(pressure.max_contact_pressure_Pa, dtype=float)
            out |= peak > c.max_contact_pressure_Pa * allowance
        if c.max_load_per_ball_N is not None:
            out |= gl / z > c.max_load_per_ball_N * allowance
        if c.min_load_capacity_N is not None:
            out |= gh * allowance < c.min_load_capacity_N
        if c.max_friction_force_N is not None:
            out |= lower * gl > c.max_friction_force_N * allowance
        return out

    def meets(self, design: Mapping[str, np.ndarray], values: np.ndarray) -> np.ndarray:
        """Whether designs meet every limit at the points (values: max_j U there) [bool]."""
        c = self.problem.constraints
        z, theta, load = design["balls"], design["groove_angle_deg"], design["load_N"]
        ok = np.isfinite(values)
        if c.max_contact_pressure_Pa is not None:
            with np.errstate(all="ignore"):
                pressure = physics.evaluate(convention=self.problem.convention,
                                            outputs=["max_contact_pressure_Pa"],
                                            **self.problem.physics_inputs(z, theta + self.delta, load))
            ok &= np.asarray(pressure.max_contact_pressure_Pa, dtype=float) <= c.max_contact_pressure_Pa
        if c.max_load_per_ball_N is not None:
            ok &= load / z <= c.max_load_per_ball_N
        if c.min_load_capacity_N is not None:
            ok &= load >= c.min_load_capacity_N
        if c.max_friction_force_N is not None:
            ok &= values * load <= c.max_friction_force_N
        return ok


def kth_distance_to_boxes(rows: np.ndarray, lo: np.ndarray, hi: np.ndarray, k: int) -> np.ndarray:
    """The k-th smallest distance from each box [lo, hi] (rows of corners) to the given rows: a lower bound
    of the distance from any point of the box to its k-th nearest row. [units of the rows]"""
    out = np.empty(len(lo))
    for start in range(0, len(lo), 256):
        a, b = lo[start:start + 256, None, :], hi[start:start + 256, None, :]
        gap = np.maximum(np.maximum(a - rows[None, :, :], rows[None, :, :] - b), 0.0)
        squared = np.einsum("nmd,nmd->nm", gap, gap)
        out[start:start + 256] = np.sqrt(np.partition(squared, k - 1, axis=1)[:, k - 1])
    return out


def _with_values(piece: Any, values: Sequence[float]) -> Any:
    return dataclasses.replace(piece, values=list(values))


def _at_loads(columns: Mapping[str, np.ndarray], piece: Any, values: Sequence[float] | None = None,
              extra: float | None = None) -> np.ndarray:
    """A piece (its values replaced by ``values``) at each box's columns, three per box: the load's two ends
    and, for a term of the load, ``extra`` clipped into the box (where it declares an extreme), else the low
    end again."""
    each = piece if values is None else _with_values(piece, values)
    if extra is not None and piece.driver == "load_N":
        low, high = columns["load_N"][:, 0], columns["load_N"][:, 1]
        columns = {**columns, "load_N": np.column_stack([low, high, np.clip(extra, low, high)])}
    return each.at(columns[piece.driver], columns)


@dataclass(frozen=True)
class DesignPoints:
    """What a lower bound over the designs is taken of: the model's intervals at fixed envelope points.

    Attributes
    ----------
    problem : DesignProblem
        Bounds (nominal angle), limits, the model's held values and convention.
    structures : sequence of IntervalStructure
        The model and each rival whose interval enters U
        (:func:`optimize.interval_bound.interval_structures`), each effect term a positive monomial in
        balls and load at every point or a term of the load declaring its extremes (the caller checks it).
    calibrated_fixed : mapping
        The calibrated model's fixed physics values. [SI units]
    points : sequence of dict
        Envelope points e_j (:meth:`optimize.robust.Envelope.point`).
    angle_tolerance_deg : float
        δ: the limits are judged at the angle made high, θ + δ. [deg]
    z_quantile : float
        The normal quantile of the interval (1.96 for 95 %). [1]
    widening : sequence of callable or None, optional
        Per point, ``(balls, angle_lo, angle_hi, load_lo, load_hi) -> r`` [1]: a lower bound over each box
        of the factor the interval's σ is widened by off the data (σ times max(r, 1)); None: left out
        (it only widens, so the bound stays valid).
    """

    problem: DesignProblem
    structures: Sequence[IntervalStructure]
    calibrated_fixed: Mapping[str, float]
    points: Sequence[Mapping[str, Any]]
    angle_tolerance_deg: float
    z_quantile: float
    widening: Sequence[Callable | None] | None = None

    def bounds(self) -> _Bounds:
        """The box bound of U at the points."""
        return _Bounds(self.problem, self.structures, self.calibrated_fixed, self.points,
                       self.angle_tolerance_deg, self.z_quantile, self.widening)


class _Incumbent:
    """The best design found so far that meets the limits at the points, and how the model is asked."""

    def __init__(self, bounds: _Bounds, evaluate: Callable, points: int, rtol: float):
        self.bounds, self.evaluate, self.points, self.rtol = bounds, evaluate, points, rtol
        self.value, self.given_value, self.design, self.improved = math.inf, math.inf, {}, False

    def values_at(self, z: np.ndarray, theta: np.ndarray, load: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """max_j U at each design and whether it meets the limits there."""
        designs = {"balls": z, "groove_angle_deg": theta, "load_N": load}
        with np.errstate(all="ignore"):
            values = np.asarray(self.evaluate(designs), dtype=float).reshape(self.points, len(z))
        values = np.max(values, axis=0)
        return values, self.bounds.meets(designs, values)

    def probe(self, cz: np.ndarray, ct: np.ndarray, cg: np.ndarray, clow: np.ndarray) -> None:
        """The model itself at box centres: a check of every bound, and designs that may improve the best."""
        values, meets = self.values_at(cz, ct, cg)
        if np.any(values < clow * (1.0 - 1e-9)):
            worst = int(np.argmin(values / clow))
            raise BoundFailedError(f"the model's mu_upper {values[worst]:.6g} below a design box's bound "
                                   f"{clow[worst]:.6g}")
        better = np.where(meets, values, math.inf)
        best = int(np.argmin(better))
        if better[best] < self.value:
            self.improved = self.improved or better[best] < self.given_value * (1.0 - self.rtol)
            self.value = float(better[best])
            self.design = {"balls": float(cz[best]), "groove_angle_deg": float(ct[best]),
                           "load_N": float(cg[best])}


def _split(boxes: tuple[np.ndarray, ...], take: np.ndarray, span_t: float,
           span_g: float) -> tuple[np.ndarray, ...]:
    """The children of the boxes ``take`` (each halved along its wider side, relative to the design box)."""
    z, tl, th, gl, gh = (a[take] for a in boxes)
    on_angle = (th - tl) / span_t >= (gh - gl) / span_g
    mid_t, mid_g = 0.5 * (tl + th), 0.5 * (gl + gh)
    return (np.r_[z, z], np.r_[tl, np.where(on_angle, mid_t, tl)], np.r_[np.where(on_angle, mid_t, th), th],
            np.r_[gl, np.where(on_angle, gl, mid_g)], np.r_[np.where(on_angle, gh, mid_g), gh])


def design_lower_bound(at: DesignPoints, design: Mapping[str, float],
                       evaluate: Callable[[Mapping[str, np.ndarray]], np.ndarray],
                       rtol: float = DESIGN_RTOL, max_boxes: int = MAX_DESIGN_BOXES,
                       time_limit_s: float = math.inf,
                       progress: Callable[[float], None] | None = None) -> DesignLowerBound:
    """Bracket min over the designs of max_j U(d, e_j) by branch and bound (module docstring).

    Parameters
    ----------
    at : DesignPoints
        The model's interval structures at the envelope points, the problem and the tolerance.
    design : mapping
        The design to start from (the incumbent): ``balls`` [1], ``groove_angle_deg`` (nominal) [deg],
        ``load_N`` [N].
    evaluate : callable
        ``designs -> values`` of shape (len(points), n): U [1] of the model itself at each point and design.
    rtol : float, default :data:`DESIGN_RTOL`
        A box whose bound is within this of the incumbent (relative) is settled. [1]
    max_boxes : int, default :data:`MAX_DESIGN_BOXES`
        Most boxes bounded. [1]
    time_limit_s : float, default inf
        No new batch of boxes after this long. [s]
    progress : callable, optional
        Called after each batch with the larger of the boxes' and the time's share of their limits [1]
        (a job's progress; it may raise to stop the search, e.g. a cancellation).

    Returns
    -------
    DesignLowerBound

    Raises
    ------
    BoundFailedError
        When the model's own value at a box's centre is below the box's bound (the premises fail).
    """
    start = time.perf_counter()
    problem, bounds = at.problem, at.bounds()
    (t0, t1), (g0, g1) = problem.bounds.groove_angle_deg, problem.bounds.load_N
    span_t, span_g = max(t1 - t0, 1e-300), max(g1 - g0, 1e-300)
    best = _Incumbent(bounds, evaluate, len(at.points), rtol)
    given = {k: np.array([float(design[k])]) for k in ("balls", "groove_angle_deg", "load_N")}
    value, meets_given = best.values_at(given["balls"], given["groove_angle_deg"], given["load_N"])
    best.value = best.given_value = float(value[0]) if meets_given[0] else math.inf
    best.design = {k: float(v[0]) for k, v in given.items()}

    counts = np.array(problem.ball_counts(), dtype=float)
    z, tl, th = counts, np.full(len(counts), float(t0)), np.full(len(counts), float(t1))
    gl, gh = np.full(len(counts), float(g0)), np.full(len(counts), float(g1))
    # A box around the given design, a billionth wide: its bound is the design's value to 1e-8 or so, so a
    # bound that does not hold the model shows here first.
    theta, load = float(given["groove_angle_deg"][0]), float(given["load_N"][0])
    tight = float(bounds.lower(given["balls"], np.array([theta]), np.array([theta + 1e-9 * span_t]),
                               np.array([load]), np.array([load * (1 + 1e-9)]))[0])
    if float(value[0]) < tight * (1.0 - 1e-9):
        raise BoundFailedError(f"the model's mu_upper {float(value[0]):.6g} at the design below the bound "
                               f"{tight:.6g} of a box around it")
    low = bounds.lower(z, tl, th, gl, gh)
    keep = ~bounds.broken(z, tl, gl, gh, low)
    z, tl, th, gl, gh, low = z[keep], tl[keep], th[keep], gl[keep], gh[keep], low[keep]
    count, settled, complete = len(counts), math.inf, True
    while True:
        threshold = best.value * (1.0 - rtol)
        done = low >= threshold
        if np.any(done):
            settled = min(settled, float(low[done].min()))
        z, tl, th, gl, gh, low = z[~done], tl[~done], th[~done], gl[~done], gh[~done], low[~done]
        narrow = np.maximum((th - tl) / span_t, (gh - gl) / span_g) < _NARROWEST
        if np.any(narrow):  # a point: its bound is its value, to rounding
            settled = min(settled, float(low[narrow].min()))
            z, tl, th, gl, gh, low = (a[~narrow] for a in (z, tl, th, gl, gh, low))
        if not len(z):
            break
        elapsed = time.perf_counter() - start
        if count >= max_boxes or elapsed > time_limit_s:
            complete = False
            break
        if progress is not None:
            progress(min(1.0, max(count / max_boxes, elapsed / time_limit_s if time_limit_s > 0 else 1.0)))
        take = np.argsort(low)[:_BATCH]
        rest = np.ones(len(z), dtype=bool)
        rest[take] = False
        cz, ctl, cth, cgl, cgh = _split((z, tl, th, gl, gh), take, span_t, span_g)
        clow = bounds.lower(cz, ctl, cth, cgl, cgh)
        count += len(cz)
        fine = ~bounds.broken(cz, ctl, cgl, cgh, clow)
        cz, ctl, cth, cgl, cgh, clow = (a[fine] for a in (cz, ctl, cth, cgl, cgh, clow))
        # The model itself at the centres of the boxes of lowest bound: a check of every bound, and designs
        # that may improve the incumbent.
        probe = np.argsort(clow)[:_EVALUATED]
        if len(probe):
            best.probe(cz[probe], 0.5 * (ctl[probe] + cth[probe]), 0.5 * (cgl[probe] + cgh[probe]),
                       clow[probe])
        z, tl, th, gl, gh, low = (np.r_[a[rest], b] for a, b in ((z, cz), (tl, ctl), (th, cth), (gl, cgl),
                                                                  (gh, cgh), (low, clow)))
    lower = min(best.value, settled, float(low.min()) if len(low) else math.inf)
    return DesignLowerBound(lower, best.value, best.design, best.improved, count, complete,
                            bool(meets_given[0]))
