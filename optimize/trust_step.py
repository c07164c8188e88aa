r"""The trust-region step of :func:`optimize.optimize_model`: one convex sub-problem per run, solved exactly.

Every run (a ball count and a start) asks, at its iterate (x0, y0) in log coordinates x = log tan θ,
y = log G, with the local monomial model log μ ≈ f + a Δx + b Δy (a, b its slopes), for the step

.. math::

    \min_{Δx, Δy}\; a Δx + b Δy + M \max(0,\; f + a Δx + (b + 1) Δy + y_0 - \log F_{max})

subject to |Δx|, |Δy| <= r (the trust region), the box x_lo <= x0 + Δx <= x_hi, y_lo <= y0 + Δy <= y_hi
(the load cap, the load per ball folded in) and the peak-pressure limit
y0 + Δy + ½ log(1 + e^{2 (x0 + Δx)}) <= P, convex in (x, y). The friction term (an exact penalty of weight
M) and the pressure limit are present when the problem has those limits.

:func:`cvxpy_steps` states it as one stacked, separable cvxpy problem (DCP and DPP): the formulation the
method documents. :func:`exact_steps` solves the same problem for every run at once in numpy, which is
what the iterations use: a cvxpy solve took ~28 ms per iteration of 48 runs, this a few ms, and its exact
steps (Clarabel's are within ~1e-8) let the runs converge in fewer iterations (267 solves -> 29 in the
bench's GP case). The two are compared on random sub-problems, with the pressure and friction limits
active, in ``tests/test_optimize_trust_step.py``.

How :func:`exact_steps` solves it
---------------------------------
For a fixed Δx the objective is convex and piecewise linear in Δy over an interval
[Y_lo, U(Δx)] (U: the box's and the trust region's top, lowered by the pressure limit), so its least value
g(Δx) is at Y_lo, at U(Δx) or where the penalty's argument crosses zero, clipped to the interval. g is
convex in Δx (a partial minimum of a jointly convex function over a convex set), over the interval of Δx
where the set is not empty: golden-section search finds its minimum to 1e-12 of that interval's width,
and the points where g's pieces meet or a curved piece is stationary, known in closed form (the interval's
ends, the penalty's zero line meeting the box's bottom and top, the pressure limit meeting the top, the
points of the pressure limit where a gradient of the objective is normal to it), are tried beside it: the
least of them is the step, exact where the minimum is at one of those points.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

__all__ = ["TrustStep", "exact_steps", "cvxpy_steps", "log_secant"]

#: Golden-section iterations of :func:`exact_steps`: 0.618^58 < 1e-12 of the interval's width.
_GOLDEN_ITERATIONS = 58
_INVERSE_PHI = (np.sqrt(5.0) - 1.0) / 2.0


def log_secant(x: np.ndarray) -> np.ndarray:
    """½ log(1 + e^{2x}) = log sec θ at x = log tan θ: the angle's share of the pressure limit. [1]"""
    return 0.5 * np.log1p(np.exp(2.0 * x))


@dataclass(frozen=True)
class TrustStep:
    """The sub-problems of one iteration, one entry per run (arrays of one length).

    Attributes
    ----------
    x0, y0 : ndarray
        The iterate: log tan θ and log load. [1]
    gx, gy : ndarray
        Slopes of the local model of log μ in x and y. [1]
    f : ndarray
        log μ at the iterate. [1]
    x_lo, x_hi, y_lo, y_hi : ndarray
        The box in x and y (y_hi: the load cap, the load per ball folded in). [1]
    radius : ndarray
        Trust-region radius (0: the run takes no step). [1]
    penalty : float
        Weight M of the exact penalty on the friction-force limit. [1]
    log_friction_max : ndarray or None
        log of the friction-force limit [log N]; None: no such limit.
    log_pressure_cap : ndarray or None
        The cap P on y + log sec θ of the pressure limit [1]; None: no such limit.
    """

    x0: np.ndarray
    y0: np.ndarray
    gx: np.ndarray
    gy: np.ndarray
    f: np.ndarray
    x_lo: np.ndarray
    x_hi: np.ndarray
    y_lo: np.ndarray
    y_hi: np.ndarray
    radius: np.ndarray
    penalty: float
    log_friction_max: np.ndarray | None = None
    log_pressure_cap: np.ndarray | None = None


def _inverse_log_secant(v: np.ndarray) -> np.ndarray:
    """x with log_secant(x) = v (-inf for v <= 0, where no x is low enough). [1]"""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(v > 0, 0.5 * np.log(np.expm1(2.0 * np.maximum(v, 1e-300))), -np.inf)


class _Partial:
    """g(Δx): the objective's least value over Δy at each run's Δx, and the Δy where it is reached."""

    def __init__(self, step: TrustStep):
        r = step.radius
        self.step = step
        self.dy_lo = np.maximum(-r, step.y_lo - step.y0)
        self.dy_hi = np.minimum(r, step.y_hi - step.y0)
        self.penalty = 0.0 if step.log_friction_max is None else step.penalty
        # the penalty's argument: c + a Δx + (b + 1) Δy
        self.c = 0.0 if step.log_friction_max is None else step.f + step.y0 - step.log_friction_max
        self.b1 = step.gy + 1.0
        # The objective is convex and piecewise linear in Δy, its slopes b and b + M (b + 1): with both
        # >= 0 the least Δy is the bottom, with both <= 0 the top, else the penalty's zero, clipped. As
        # one formula, clip(k0 + k1 Δx) with k0 = -inf, +inf or the zero's intercept.
        slopes = (step.gy, step.gy + self.penalty * self.b1)
        low, high = np.minimum(*slopes), np.maximum(*slopes)
        inside = (low < 0) & (high > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            self.k0 = np.where(inside, -self.c / self.b1, np.where(low >= 0, -np.inf, np.inf))
            self.k1 = np.where(inside, -step.gx / self.b1, 0.0)
        self.room = None if step.log_pressure_cap is None else step.log_pressure_cap - step.y0

    def top(self, dx: np.ndarray) -> np.ndarray:
        """U(Δx): the highest Δy (never below the lowest: a pressure limit missed by rounding). [1]"""
        if self.room is None:
            return self.dy_hi
        return np.maximum(self.dy_lo, np.minimum(self.dy_hi, self.room - log_secant(self.step.x0 + dx)))

    def objective(self, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
        """The sub-problem's objective less f (a constant per run) at the steps. [1]"""
        s = self.step
        ax = s.gx * dx
        return ax + s.gy * dy + self.penalty * np.maximum(0.0, self.c + ax + self.b1 * dy)

    def step_y(self, dx: np.ndarray) -> np.ndarray:
        """The Δy where g(Δx) is reached. [1]"""
        return np.minimum(np.maximum(self.k0 + self.k1 * dx, self.dy_lo), self.top(dx))

    def value(self, dx: np.ndarray) -> np.ndarray:
        """g(Δx). [1]"""
        return self.objective(dx, self.step_y(dx))


def _closed_form_points(step: TrustStep, partial: _Partial, lo: np.ndarray, hi: np.ndarray) -> list:
    """Δx where g's pieces meet or a curved piece is stationary, known in closed form, within [lo, hi]."""
    a, b = step.gx, step.gy
    points = [lo, hi]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if partial.penalty:  # the penalty's zero line meets the bottom and the top of the box
            points += [-(partial.c + partial.b1 * dy) / a for dy in (partial.dy_lo, partial.dy_hi)]
        if step.log_pressure_cap is not None:
            # the pressure limit meets the top; on the limit, each linear piece (without and with the
            # penalty) is stationary where the slope of log sec, sigmoid(2x), is the gradient's ratio
            points.append(_inverse_log_secant(step.log_pressure_cap - step.y0 - partial.dy_hi) - step.x0)
            slopes = [(a, b)] + ([(a * (1 + partial.penalty), b + partial.penalty * partial.b1)]
                                 if partial.penalty else [])
            for ga, gb in slopes:
                p = ga / gb  # d/dx of ga x + gb (P - y0 - log sec x) = 0 -> sigmoid(2x) = ga / gb
                p = np.where((p > 0) & (p < 1), p, np.nan)
                points.append(0.5 * np.log(p / (1.0 - p)) - step.x0)
    return [np.clip(np.where(np.isfinite(p), p, lo), lo, hi) for p in points]


def exact_steps(step: TrustStep) -> tuple[np.ndarray, np.ndarray]:
    """The least step of every run's sub-problem (the module docstring): (Δx, Δy) [1].

    The step meets the pressure limit as :func:`log_secant` evaluates it in floating point (a step at the
    limit is lowered by the rounding that would otherwise break it).
    """
    partial = _Partial(step)
    lo = np.maximum(-step.radius, step.x_lo - step.x0)
    hi = np.minimum(step.radius, step.x_hi - step.x0)
    if step.log_pressure_cap is not None:  # the Δx where some Δy meets the pressure limit: x <= that
        hi = np.minimum(hi, _inverse_log_secant(step.log_pressure_cap - step.y0 - partial.dy_lo) - step.x0)
    hi = np.maximum(hi, lo)  # an empty interval (the iterate off the limit by rounding): no move in x
    # golden-section search of the convex g over [lo, hi]
    a, b = lo.copy(), hi.copy()
    c1, c2 = b - _INVERSE_PHI * (b - a), a + _INVERSE_PHI * (b - a)
    g1, g2 = partial.value(c1), partial.value(c2)
    for _ in range(_GOLDEN_ITERATIONS):
        left = g1 <= g2  # the minimum is in [a, c2]
        a, b = np.where(left, a, c1), np.where(left, c2, b)
        new = np.where(left, b - _INVERSE_PHI * (b - a), a + _INVERSE_PHI * (b - a))
        value = partial.value(new)
        c1, c2 = np.where(left, new, c2), np.where(left, c1, new)
        g1, g2 = np.where(left, value, g2), np.where(left, g1, value)
    # the closed-form points first: at a tie, the exact one
    candidates = np.array([*_closed_form_points(step, partial, lo, hi), 0.5 * (a + b)])
    best = np.argmin([partial.value(dx) for dx in candidates], axis=0)
    dx = candidates[best, np.arange(len(lo))]
    dy = partial.step_y(dx)
    if step.log_pressure_cap is not None:
        for _ in range(4):  # lower a step the rounding puts above the limit, by what it misses
            over = step.y0 + dy + log_secant(step.x0 + dx) - step.log_pressure_cap
            if not np.any(over > 0):
                break
            dy = np.where(over > 0, np.nextafter(dy - over, -np.inf), dy)
    return dx, dy


def _cvxpy_problem(size: int, with_friction: bool, with_pressure: bool, penalty: float):
    """The stacked sub-problem in cvxpy, DCP and DPP in its parameters: (problem, Δx, Δy, parameters)."""
    # the step is the variable (not the new point) so that gradients multiply variables only (DPP)
    dx, dy = cp.Variable(size), cp.Variable(size)
    par = {n: cp.Parameter(size) for n in ("x0", "y0", "gx", "gy", "f", "x_lo", "x_hi", "y_lo", "y_hi")}
    par["radius"] = cp.Parameter(size, nonneg=True)
    x, y = par["x0"] + dx, par["y0"] + dy
    model = par["f"] + cp.multiply(par["gx"], dx) + cp.multiply(par["gy"], dy)
    cons = [cp.abs(dx) <= par["radius"], cp.abs(dy) <= par["radius"],
            x >= par["x_lo"], x <= par["x_hi"], y >= par["y_lo"], y <= par["y_hi"]]
    objective = cp.sum(model)
    if with_friction:
        par["log_friction_max"] = cp.Parameter(size)
        slack = cp.Variable(size, nonneg=True)
        cons.append(model + y - par["log_friction_max"] <= slack)
        objective = objective + penalty * cp.sum(slack)
    if with_pressure:
        par["log_pressure_cap"] = cp.Parameter(size)
        cons.append(y + 0.5 * cp.logistic(2 * x) <= par["log_pressure_cap"])
    problem = cp.Problem(cp.Minimize(objective), cons)
    if not problem.is_dcp(dpp=True):  # explicit, not an assert (asserts vanish under python -O)
        raise RuntimeError("the sequential convex sub-problem is not DCP and DPP")
    return problem, dx, dy, par


def cvxpy_steps(step: TrustStep) -> tuple[np.ndarray, np.ndarray]:
    """The same steps as :func:`exact_steps`, from the sub-problem stated in cvxpy and solved by Clarabel
    (to its tolerance, ~1e-8): the reference formulation. [1]

    Raises
    ------
    RuntimeError
        When Clarabel ends without an optimal (or inaccurate optimal) status.
    """
    problem, dx, dy, par = _cvxpy_problem(len(step.x0), step.log_friction_max is not None,
                                          step.log_pressure_cap is not None, step.penalty)
    for name, p in par.items():
        p.value = np.asarray(getattr(step, name), dtype=float)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        problem.solve(solver=cp.CLARABEL)
    if problem.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE):
        raise RuntimeError(f"sequential convex sub-problem ended with status {problem.status!r}")
    return dx.value, dy.value
