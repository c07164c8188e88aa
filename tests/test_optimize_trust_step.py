"""Tests of optimize.trust_step: the exact trust-region step against cvxpy's and against brute force."""

from __future__ import annotations

import numpy as np
import pytest

from microbearing.optimize.general import PENALTY
from microbearing.optimize.trust_step import TrustStep, cvxpy_steps, exact_steps, log_secant

RUNS = 40


def _random_steps(seed: int, friction: bool, pressure: bool) -> TrustStep:
    """Random sub-problems like the method's: the iterate inside the box and under the pressure cap (often
    on it), the friction limit's zero line within reach, radii from 0 (a finished run) to 1."""
    rng = np.random.default_rng(seed)
    x_lo = np.full(RUNS, np.log(np.tan(np.radians(40.0))))
    x_hi = np.full(RUNS, np.log(np.tan(np.radians(60.0))))
    y_lo, y_hi = np.full(RUNS, np.log(1e-3)), np.full(RUNS, np.log(0.05))
    x0 = rng.uniform(x_lo, x_hi)
    cap = rng.uniform(-5.0, -1.0, RUNS)
    y0 = rng.uniform(y_lo, np.maximum(y_lo, np.minimum(y_hi, cap - log_secant(x0))))
    on_cap = rng.random(RUNS) < 0.3  # a third of the iterates on the pressure limit
    cap = np.where(on_cap, y0 + log_secant(x0), np.maximum(cap, y0 + log_secant(x0)))
    f = rng.uniform(-4.0, -2.0, RUNS)
    radius = rng.choice([0.0, 1e-6, 1e-2, 0.5, 1.0], RUNS)
    # the friction limit's zero line passes within about the trust region of the iterate, or (a third of
    # the runs) out of reach
    friction_cap = f + y0 + np.where(rng.random(RUNS) < 0.3, 5.0, rng.normal(0.2, 0.5, RUNS) * radius)
    slopes = rng.normal(0.0, 1.0, RUNS), rng.normal(-0.3, 0.6, RUNS)
    return TrustStep(x0, y0, *slopes, f, x_lo, x_hi, y_lo, y_hi, radius, PENALTY,
                     friction_cap if friction else None, cap if pressure else None)


def _objective(step: TrustStep, dx, dy):
    friction = 0.0 if step.log_friction_max is None else PENALTY * np.maximum(
        0.0, step.f + step.gx * dx + step.gy * dy + step.y0 + dy - step.log_friction_max)
    return step.gx * dx + step.gy * dy + friction


def _violation(step: TrustStep, dx, dy):
    """The largest amount by which a step breaks a constraint (0 if none). [1]"""
    parts = [np.abs(dx) - step.radius, np.abs(dy) - step.radius, step.x_lo - step.x0 - dx,
             step.x0 + dx - step.x_hi, step.y_lo - step.y0 - dy, step.y0 + dy - step.y_hi]
    if step.log_pressure_cap is not None:
        parts.append(step.y0 + dy + log_secant(step.x0 + dx) - step.log_pressure_cap)
    return np.maximum(0.0, np.maximum.reduce(parts))


@pytest.mark.parametrize("friction, pressure", [(True, True), (True, False), (False, True), (False, False)])
def test_exact_step_is_feasible_and_no_worse_than_cvxpy(friction, pressure):
    active_pressure = active_friction = active_both = 0
    for seed in range(3):
        step = _random_steps(seed, friction, pressure)
        dx, dy = exact_steps(step)
        # feasible as evaluated in floating point: the pressure check of the iterations accepts it
        assert np.all(np.abs(dx) <= step.radius) and np.all(np.abs(dy) <= step.radius)
        assert np.all(step.x0 + dx >= step.x_lo) and np.all(step.x0 + dx <= step.x_hi)
        assert np.all(step.y0 + dy >= step.y_lo) and np.all(step.y0 + dy <= step.y_hi)
        on_pressure = on_friction = np.zeros(RUNS, dtype=bool)
        if pressure:
            assert np.all(step.y0 + dy + log_secant(step.x0 + dx) <= step.log_pressure_cap)
            on_pressure = step.y0 + dy + log_secant(step.x0 + dx) > step.log_pressure_cap - 1e-12
        if friction:
            hinge = step.f + step.gx * dx + (step.gy + 1) * dy + step.y0 - step.log_friction_max
            on_friction = np.abs(hinge) < 1e-12
        active_pressure += np.count_nonzero(on_pressure)
        active_friction += np.count_nonzero(on_friction)
        active_both += np.count_nonzero(on_pressure & on_friction)
        cx, cy = cvxpy_steps(step)
        # Clarabel's step may break a constraint by its tolerance and gain by it: at most the objective's
        # largest slope times that; beyond it, the exact step is never worse
        slope = (1 + PENALTY) * (np.abs(step.gx) + np.abs(step.gy) + 1)
        allowance = slope * _violation(step, cx, cy) + 1e-9
        assert np.all(_objective(step, dx, dy) <= _objective(step, cx, cy) + allowance)
        # and cvxpy's never better by more than its tolerance: the two agree
        assert np.all(_objective(step, cx, cy) <= _objective(step, dx, dy) + allowance + 1e-6)
    # the limits are active at the optimum in a good share of the runs, and both at once (where the
    # pressure limit meets the penalty's zero line) in some: the test exercises them
    if pressure:
        assert active_pressure >= 0.15 * 3 * RUNS
    if friction:
        assert active_friction >= 0.15 * 3 * RUNS
    if pressure and friction:
        assert active_both >= 2


def test_exact_step_matches_brute_force_over_a_grid():
    step = _random_steps(7, friction=True, pressure=True)
    dx, dy = exact_steps(step)
    best = _objective(step, dx, dy)
    grid = np.linspace(-1.0, 1.0, 601)
    for k in np.flatnonzero(step.radius > 0)[:12]:
        r = step.radius[k]
        gx, gy = np.meshgrid(r * grid, r * grid, indexing="ij")
        one = TrustStep(*(np.full(gx.shape, np.asarray(v)[k]) if isinstance(v, np.ndarray) else v
                          for v in (getattr(step, name) for name in TrustStep.__dataclass_fields__)))
        values = np.where(_violation(one, gx, gy) == 0, _objective(one, gx, gy), np.inf)
        # every feasible grid point is at least the exact step's value; the grid's best is within its
        # resolution (the objective's slope times the cell's diagonal) of it
        assert best[k] <= values.min() + 1e-12
        slope = (1 + PENALTY) * (abs(one.gx.flat[0]) + abs(one.gy.flat[0]) + 1)
        assert values.min() <= best[k] + slope * 2 * r * 2 / 600 * np.sqrt(2)


def test_a_finished_run_takes_no_step():
    step = _random_steps(3, friction=True, pressure=True)
    dx, dy = exact_steps(step)
    still = step.radius == 0
    assert still.any() and np.all(dx[still] == 0) and np.all(dy[still] == 0)
