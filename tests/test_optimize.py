"""Tests of optimize.problem, optimize.dgp and optimize.solve against the exact physics and brute force."""

from __future__ import annotations

import functools
import itertools
from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import minimize

from microbearing import physics
from microbearing.optimize import (
    Constraints,
    DesignBounds,
    DesignProblem,
    InfeasibleDesignError,
    OptimizationResult,
    optimize_design,
)
from microbearing.optimize.dgp import LIMIT_NAMES, BallCountResolver, build_design_gp, design_gp

GRID = 200


def _feasible(problem: DesignProblem, z, theta, load, r) -> np.ndarray:
    c = problem.constraints
    ok = np.ones(np.broadcast_shapes(np.shape(z), np.shape(theta), np.shape(load)), dtype=bool)
    if c.max_contact_pressure_Pa is not None:
        ok &= r.max_contact_pressure_Pa <= c.max_contact_pressure_Pa
    if c.max_friction_force_N is not None:
        ok &= r.friction_force_N <= c.max_friction_force_N
    if c.min_load_capacity_N is not None:
        ok &= load >= c.min_load_capacity_N
    if c.max_load_per_ball_N is not None:
        ok &= load / z <= c.max_load_per_ball_N
    return ok


def brute_force(problem: DesignProblem) -> tuple[float, tuple[int, float, float]]:
    """Best feasible μ of a 200 x 200 (θ, log G) grid per ball count, refined locally by Nelder-Mead."""
    counts = np.array(problem.ball_counts())
    (t_lo, t_hi), (g_lo, g_hi) = problem.bounds.groove_angle_deg, problem.bounds.load_N
    theta = np.linspace(t_lo, t_hi, GRID)
    load = np.geomspace(g_lo, g_hi, GRID)
    z3, t3, g3 = counts[:, None, None], theta[None, :, None], load[None, None, :]
    r = physics.evaluate(convention=problem.convention, **problem.physics_inputs(z3, t3, g3))
    mu = np.where(_feasible(problem, z3, t3, g3, r), r.mu, np.inf)
    best = (np.inf, None)
    per_count = mu.reshape(len(counts), -1).min(axis=1)
    for k in np.argsort(per_count)[:3]:
        if not np.isfinite(per_count[k]):
            continue
        i, j = np.unravel_index(np.argmin(mu[k]), mu[k].shape)
        z = int(counts[k])

        def objective(x, z=z):
            th, g = float(x[0]), float(np.exp(x[1]))
            rr = physics.evaluate(convention=problem.convention, **problem.physics_inputs(z, th, g))
            return float(rr.mu) if _feasible(problem, z, th, g, rr) else 1e9

        box = [(theta[max(i - 1, 0)], theta[min(i + 1, GRID - 1)]),
               (np.log(load[max(j - 1, 0)]), np.log(load[min(j + 1, GRID - 1)]))]
        res = minimize(objective, [theta[i], np.log(load[j])], method="Nelder-Mead", bounds=box,
                       options={"xatol": 1e-10, "fatol": 1e-14, "maxiter": 400})
        candidates = [(mu[k, i, j], (z, theta[i], load[j])), (res.fun, (z, res.x[0], np.exp(res.x[1])))]
        best = min([best, *candidates], key=lambda c: c[0])
    return best


def random_problem(seed: int) -> DesignProblem:
    """Random bounds, fixed parameters and limits of one of four kinds (``seed % 4``).

    mu of the physics depends on G and z only through G/z and falls with it, and it grows with θ; so
    without limits the optimum has the fewest balls and the smallest angle. The kinds make limits bind:

    0. limits drawn around a random design inside the box (each switched on with probability 0.6);
    1. a minimum load G_min with a peak-pressure limit 1 % above that of G_min on z* balls at the
       smallest angle: z* - 1 balls exceed it (their load per ball is larger), so the optimum has
       z* > z_lo balls with the pressure limit active;
    2. the same with a load-per-ball limit G_min / z* (1 + 1e-3) instead of the pressure limit;
    3. infeasible: the pressure limit 5 % below that of G_min on all z_hi balls at the smallest angle.
    """
    rng = np.random.default_rng(seed)
    kind = seed % 4
    z_lo = int(rng.integers(1, 8))
    z_hi = z_lo + int(rng.integers(0 if kind == 0 else 3, 14))
    a_lo = float(rng.uniform(20, 60))
    a_hi = min(a_lo + float(rng.uniform(2, 25)), 89.0)
    g_lo = float(10 ** rng.uniform(-4, -2.5))
    g_hi = g_lo * float(10 ** rng.uniform(0.5, 2.5))
    fixed = {"mu_pivot": float(rng.uniform(0.1, 1.0)), "balls_touching": bool(rng.integers(0, 2)),
             "adhesion_energy_J_m2": float(rng.choice([0.0, 0.05, 0.18])),
             "ball_diameter_m": float(rng.uniform(150e-6, 500e-6))}
    speed = float(rng.uniform(0, 0.2)) if seed % 2 else (0.01, float(rng.uniform(0.02, 0.3)))
    bounds = DesignBounds((z_lo, z_hi), (a_lo, a_hi), (g_lo, g_hi))
    probe = DesignProblem(bounds, speed_m_s=speed, fixed=fixed)
    if kind == 0:
        z = int(rng.integers(z_lo, z_hi + 1))
        r = physics.evaluate(**probe.physics_inputs(z, rng.uniform(a_lo, a_hi), g_lo * (g_hi / g_lo) ** 0.7))
        limits = {
            "max_contact_pressure_Pa": float(r.max_contact_pressure_Pa) * rng.uniform(0.9, 1.1),
            "max_friction_force_N": float(r.friction_force_N) * rng.uniform(0.9, 1.5),
            "min_load_capacity_N": g_lo * (g_hi / g_lo) ** rng.uniform(0.0, 0.5),
            "max_load_per_ball_N": float(g_hi / z) * rng.uniform(0.5, 1.5),
            "groove_length_m": fixed["ball_diameter_m"] * (z_lo + z_hi) / 4 * rng.uniform(1.0, 1.3),
        }
        chosen = {k: v for k, v in limits.items() if rng.random() < 0.6}
        return DesignProblem(bounds, speed_m_s=speed, fixed=fixed, constraints=Constraints(**chosen))
    g_min = g_lo * (g_hi / g_lo) ** float(rng.uniform(0.3, 0.9))
    z_star = z_hi if kind == 3 else int(rng.integers(z_lo + 1, z_hi + 1))
    pressure = float(physics.evaluate(**probe.physics_inputs(z_star, a_lo, g_min)).max_contact_pressure_Pa)
    limits = {"min_load_capacity_N": g_min}
    if kind == 1:
        limits["max_contact_pressure_Pa"] = pressure * 1.01
    elif kind == 2:
        limits["max_load_per_ball_N"] = g_min / z_star * (1 + 1e-3)
    else:
        limits["max_contact_pressure_Pa"] = pressure * 0.95
    if rng.random() < 0.5:  # a slack friction limit on top
        limits["max_friction_force_N"] = float(physics.evaluate(
            **probe.physics_inputs(z_hi, a_hi, g_hi)).friction_force_N) * 10
    return DesignProblem(bounds, speed_m_s=speed, fixed=fixed, constraints=Constraints(**limits))


SEEDS = range(12)


@functools.cache
def _solved(seed: int) -> OptimizationResult | InfeasibleDesignError:
    try:
        return optimize_design(random_problem(seed))
    except InfeasibleDesignError as err:
        return err


@pytest.mark.parametrize("seed", SEEDS)
def test_no_feasible_grid_design_beats_the_optimizer(seed):
    problem = random_problem(seed)
    result = _solved(seed)
    if isinstance(result, InfeasibleDesignError):
        brute_mu, _ = brute_force(problem)
        assert not np.isfinite(brute_mu), f"optimizer: infeasible ({result}); brute force: mu={brute_mu}"
        return
    brute_mu, brute_design = brute_force(problem)
    assert brute_mu >= result.mu * (1 - 1e-4), (brute_design, result.design)
    # the grid must come close too, or it did not search the right region
    assert brute_mu <= result.mu * 1.05
    assert all(c.satisfied for c in result.constraints), [c for c in result.constraints if not c.satisfied]
    assert abs(result.relative_gap) < 1e-4  # solver value vs exact physics at the (polished) design
    balls = result.design["balls"]
    assert isinstance(balls, int) and problem.bounds.balls[0] <= balls <= problem.bounds.balls[1]
    assert balls in problem.ball_counts()


def test_random_instances_cover_binding_limits_and_infeasibility():
    results = {seed: _solved(seed) for seed in SEEDS}
    solved = [(seed, r) for seed, r in results.items() if isinstance(r, OptimizationResult)]
    infeasible = [seed for seed, r in results.items() if isinstance(r, InfeasibleDesignError)]
    above_lowest_count = [seed for seed, r in solved
                          if r.design["balls"] > random_problem(seed).bounds.balls[0]]
    limits = set(LIMIT_NAMES) | {"groove_length_m"}
    active_limit = [seed for seed, r in solved if any(c.active and c.name in limits for c in r.constraints)]
    assert len(above_lowest_count) >= 2, above_lowest_count
    assert len(active_limit) >= 2, active_limit
    assert len(infeasible) >= 2, infeasible


def test_worked_example_with_every_limit():
    bounds = DesignBounds((4, 24), (35, 70), (0.001, 0.05))
    problem = DesignProblem(bounds, speed_m_s=0.05, fixed={"mu_pivot": 1.0},
                            constraints=Constraints(max_contact_pressure_Pa=6e8, max_friction_force_N=2e-4,
                                                    min_load_capacity_N=0.004, max_load_per_ball_N=4e-3,
                                                    groove_length_m=2.5e-3, min_ball_gap_m=20e-6))
    result = optimize_design(problem)
    brute_mu, _ = brute_force(problem)
    assert result.mu <= brute_mu * (1 + 1e-4)
    assert all(c.satisfied for c in result.constraints)
    # 8 balls per groove need 8*285 um + 7*20 um = 2.42 mm <= 2.5 mm; 9 need 2.705 mm
    assert max(problem.ball_counts()) == 16
    assert [r.status for r in result.per_ball_count if r.balls > 16] == ["does not fit the groove"] * 8
    assert result.design["groove_angle_deg"] == pytest.approx(35.0)  # every term of mu grows with theta
    assert "global" in result.certificate.lower()


def test_speed_range_is_designed_for_its_upper_end():
    rng = np.random.default_rng(7)
    z, theta, load = rng.integers(1, 30, 500), rng.uniform(10, 80, 500), 10 ** rng.uniform(-4, -1, 500)
    speeds = np.sort(rng.uniform(0, 1, (500, 2)), axis=1)
    low = physics.evaluate(balls=z, groove_angle_deg=theta, load_N=load, speed_m_s=speeds[:, 0])
    high = physics.evaluate(balls=z, groove_angle_deg=theta, load_N=load, speed_m_s=speeds[:, 1])
    assert np.all(high.mu >= low.mu) and np.all(high.friction_force_N >= low.friction_force_N)
    bounds = DesignBounds((3, 12), (40, 60), (0.002, 0.02))
    limits = Constraints(max_friction_force_N=1.2e-4)
    ranged = optimize_design(DesignProblem(bounds, speed_m_s=(0.01, 0.1), constraints=limits))
    top = optimize_design(DesignProblem(bounds, speed_m_s=0.1, constraints=limits))
    assert ranged.speed_m_s == 0.1
    assert ranged.mu == pytest.approx(top.mu, rel=1e-8)
    assert "worst case" in ranged.certificate


@pytest.mark.parametrize("convention", sorted(physics.CONVENTIONS))
@pytest.mark.parametrize("touching, adhesion, speed",
                         [(False, 0.18, 0.05), (True, 0.0, 0.0), (True, 0.3, 1.0)])
def test_dgp_expressions_equal_the_physics(convention, touching, adhesion, speed):
    problem = DesignProblem(DesignBounds((1, 50), (5, 85), (1e-5, 1.0)), speed_m_s=speed,
                            fixed={"balls_touching": touching, "adhesion_energy_J_m2": adhesion},
                            constraints=Constraints(max_contact_pressure_Pa=1e9, max_friction_force_N=1.0),
                            convention=convention)
    rng = np.random.default_rng(3)
    counts = [1, *rng.integers(1, 50, 19)]  # a single ball (no neighbour, no ball-ball term) included
    for z, theta, load in zip(counts, rng.uniform(5, 85, 20), 10 ** rng.uniform(-5, 0, 20), strict=True):
        gp, values = design_gp(problem, balls=int(z))
        with gp.lock:
            gp.assign(values, int(z))
            gp.tan_theta.value, gp.load_N.value = np.tan(np.deg2rad(theta)), load
            r = physics.evaluate(convention=convention, **problem.physics_inputs(int(z), theta, load))
            for name in ("mu", "friction_force_N", "max_contact_pressure_Pa", "contact_load_adhesive_N",
                         "contact_load_N", "contact_radius_m", "hysteresis_moment_Nm", "ball_race_force_N"):
                assert gp.expressions[name].value == pytest.approx(float(getattr(r, name)), rel=1e-10), name


@pytest.mark.parametrize("limits", [{}, {"min_load_capacity_N": 1e-2, "max_load_per_ball_N": 4e-3}])
def test_a_single_ball_is_optimized_without_a_ball_ball_moment(limits):
    # One ball has no neighbour, so touching balls add nothing at balls=1 and the least friction per
    # unit load is there, unless a per-ball limit forbids it. The DGP of each count must equal the
    # physics at its optimum (the proof's premise) and no grid design may beat the optimizer.
    problem = DesignProblem(DesignBounds((1, 5), (40, 70), (1e-3, 2e-2)), speed_m_s=0.05,
                            fixed={"balls_touching": True, "mu_ball": 1.0}, constraints=Constraints(**limits))
    result = optimize_design(problem)
    assert all(abs(row.relative_gap) < 1e-6 for row in result.per_ball_count if row.mu is not None)
    brute_mu, brute_design = brute_force(problem)
    assert result.mu * (1 - 1e-4) <= brute_mu <= result.mu * 1.05, (brute_design, result.design)
    assert (result.design["balls"] == 1) == (not limits)
    assert all(c.satisfied for c in result.constraints)


def test_every_structure_is_dgp_and_dpp():
    terms = ("adhesion_load_N", "pivoting_coefficient", "rolling_coefficient", "ball_ball_moment_Nm")
    for k in range(len(terms) + 1):
        for chosen in itertools.combinations(terms, k):
            for phase_one in (False, True):
                gp = build_design_gp(frozenset(chosen), frozenset(LIMIT_NAMES), phase_one)
                assert gp.problem.is_dgp(dpp=True) and gp.problem.is_dpp("dgp")
                assert gp.balls.is_dgp() and not gp.problem.is_mixed_integer()


def test_ties_have_equal_load_per_ball():
    # mu depends on load and balls only through G/z: with the load bounds slack, counts tie
    problem = DesignProblem(DesignBounds((4, 8), (50, 60), (1e-4, 1.0)), speed_m_s=0.01)
    result = optimize_design(problem)
    assert len(result.ties) == 5 and result.design["balls"] == 4
    per_ball = np.array([t["load_per_ball_N"] for t in result.ties])
    assert np.allclose(per_ball, per_ball[0], rtol=1e-3)
    assert np.ptp([t["mu"] for t in result.ties]) <= 1e-6 * result.mu


def test_conflicting_limits_are_named():
    bounds = DesignBounds((4, 10), (40, 60), (0.001, 0.05))
    base = DesignProblem(bounds, speed_m_s=0.05)
    # pressure at G = 0.01 N on 10 balls at 40 deg: a limit just below it allows only G < 0.01 N
    p_limit = float(physics.evaluate(**base.physics_inputs(10, 40.0, 0.01)).max_contact_pressure_Pa) * 0.999
    each_alone = [Constraints(max_contact_pressure_Pa=p_limit), Constraints(min_load_capacity_N=0.01)]
    for limits in each_alone:
        optimize_design(DesignProblem(bounds, speed_m_s=0.05, constraints=limits))
    both = Constraints(max_contact_pressure_Pa=p_limit, min_load_capacity_N=0.01, max_friction_force_N=1.0)
    with pytest.raises(InfeasibleDesignError) as info:
        optimize_design(DesignProblem(bounds, speed_m_s=0.05, constraints=both))
    assert sorted(info.value.conflicts) == ["max_contact_pressure_Pa", "min_load_capacity_N"]
    assert "balls_max" in info.value.binding_bounds and "groove_angle_deg_min" in info.value.binding_bounds
    assert "max_contact_pressure_Pa" in str(info.value)

    with pytest.raises(InfeasibleDesignError) as info:
        optimize_design(replace(base, constraints=Constraints(min_load_capacity_N=1.0)))
    assert info.value.conflicts == ["min_load_capacity_N"] and info.value.binding_bounds == ["load_N_max"]

    # 285 um balls, apart: 3 per groove need 855 um < 860 um; 4 need 1140 um
    groove = 860e-6
    short = Constraints(groove_length_m=groove)  # 4 balls need 2 per groove: fits; 7 need 4: does not
    assert DesignProblem(bounds, speed_m_s=0.05, constraints=short).ball_counts() == [4, 5, 6]
    with pytest.raises(InfeasibleDesignError) as info:
        optimize_design(replace(base, constraints=Constraints(groove_length_m=400e-6)))
    assert info.value.conflicts == ["balls", "groove_length_m"]

    # max load per ball needs z >= 0.01 / 0.0015 = 6.7, the groove holds 6 at most: both are named
    per_ball = Constraints(min_load_capacity_N=0.01, max_load_per_ball_N=0.0015, groove_length_m=groove)
    with pytest.raises(InfeasibleDesignError) as info:
        optimize_design(DesignProblem(bounds, speed_m_s=0.05, constraints=per_ball))
    assert sorted(info.value.conflicts) == ["groove_length_m", "max_load_per_ball_N", "min_load_capacity_N"]


def test_progress_reaches_one():
    seen = []
    optimize_design(DesignProblem(DesignBounds((3, 9), (40, 60), (0.001, 0.05)), speed_m_s=0.05),
                    progress=seen.append)
    assert len(seen) == 7 and seen == sorted(seen) and seen[-1] == 1.0


@pytest.mark.parametrize("kwargs, field", [
    ({"bounds": DesignBounds((4, 8), (30, 60), (0.001, 0.01)), "speed_m_s": -1.0}, "speed_m_s"),
    ({"bounds": DesignBounds((4, 8), (30, 60), (0.001, 0.01)), "speed_m_s": 0.1,
      "fixed": {"load_N": 1.0}}, "fixed.load_N"),
    ({"bounds": DesignBounds((4, 8), (30, 60), (0.001, 0.01)), "speed_m_s": 0.1,
      "fixed": {"mu_pivot": -1.0}}, "fixed.mu_pivot"),
    ({"bounds": DesignBounds((4, 8), (30, 60), (0.001, 0.01)), "speed_m_s": 0.1,
      "fixed": {"colour": 1.0}}, "fixed.colour"),
    ({"bounds": DesignBounds((4, 8), (30, 60), (0.001, 0.01)), "speed_m_s": (0.2, 0.1)}, "speed_m_s"),
])
def test_problem_validation_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match="^" + field.replace(".", r"\.")):  # the message starts with it
        DesignProblem(**kwargs)


@pytest.mark.parametrize("args, field", [
    (((0, 8), (30, 60), (0.001, 0.01)), "bounds.balls"),
    (((4, 8.5), (30, 60), (0.001, 0.01)), "bounds.balls"),
    (((9, 8), (30, 60), (0.001, 0.01)), "bounds.balls"),
    (((4, 8), (30, 90), (0.001, 0.01)), "bounds.groove_angle_deg"),
    (((4, 8), (30, 60), (0.0, 0.01)), "bounds.load_N"),
    (((4, 8), (30, 60), 0.01), "bounds.load_N"),
])
def test_bounds_validation_names_the_field(args, field):
    with pytest.raises(ValueError, match=field.replace(".", r"\.")):
        DesignBounds(*args)


@pytest.mark.parametrize("kwargs, field", [
    ({"max_contact_pressure_Pa": 0.0}, "max_contact_pressure_Pa"),
    ({"groove_length_m": float("nan")}, "groove_length_m"),
    ({"min_ball_gap_m": -1e-6}, "min_ball_gap_m"),
    ({"max_friction_force_N": True}, "max_friction_force_N"),
])
def test_constraints_validation_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=f"constraints.{field}"):
        Constraints(**kwargs)


def test_fast_resolver_agrees_with_cvxpy_solve():
    problem = DesignProblem(DesignBounds((3, 30), (35, 70), (0.001, 0.05)), speed_m_s=0.05,
                            fixed={"balls_touching": True},
                            constraints=Constraints(max_contact_pressure_Pa=6e8, max_friction_force_N=3e-4))
    gp, values = design_gp(problem)
    with gp.lock:
        gp.assign(values, 3)
        fast = BallCountResolver(gp)
        statuses = set()
        for z in (3, 7, 12, 30):
            status, value, tan_theta, load = fast.solve(z)
            gp.balls.value = z
            gp.problem.solve(gp=True, solver="CLARABEL")
            assert status == gp.problem.status
            statuses.add(status)
            if status == "optimal":
                assert value == pytest.approx(gp.problem.value, rel=1e-7)
                assert tan_theta == pytest.approx(gp.tan_theta.value, rel=1e-6)
                assert load == pytest.approx(gp.load_N.value, rel=1e-5)
    assert statuses == {"optimal", "infeasible"}  # both kinds of answer are covered


def test_conflicts_at_the_edges_of_the_physics_range_are_named_not_crashed():
    # bounds on the physics' own limits: the conflict analysis may not widen them past it
    lowest = DesignBounds((1, 1), (0.01, 0.01), (1e-9, 1e-9))
    with pytest.raises(InfeasibleDesignError) as info:
        limits = Constraints(max_contact_pressure_Pa=1.0)
        optimize_design(DesignProblem(lowest, speed_m_s=0.0, constraints=limits))
    assert info.value.conflicts == ["max_contact_pressure_Pa"]
    assert "groove_angle_deg_min" not in info.value.binding_bounds


def test_balls_declared_apart_must_not_just_touch_in_the_groove():
    # d = 250 um, groove 2 mm: 8 balls per groove fill 8 x 0.25 = 2.0 mm exactly (touching), 7 fill 1.75 mm
    bounds = DesignBounds((10, 20), (40, 60), (0.001, 0.05))
    groove = Constraints(groove_length_m=2e-3)
    common = {"ball_diameter_m": 250e-6}
    apart = DesignProblem(bounds, 0.05, groove, fixed={**common, "balls_touching": False})
    touching = DesignProblem(bounds, 0.05, groove, fixed={**common, "balls_touching": True})
    assert max(apart.ball_counts()) == 14  # ceil(14/2) = 7 balls, 0.25 mm to spare
    assert max(touching.ball_counts()) == 16  # ceil(16/2) = 8 balls may just touch
    # a 10 um gap: 7 balls need 7 x 250 + 6 x 10 = 1810 um <= 2000; 8 need 2070 um
    gapped = replace(apart, constraints=Constraints(groove_length_m=2e-3, min_ball_gap_m=10e-6))
    assert max(gapped.ball_counts()) == 14
    with pytest.raises(InfeasibleDesignError, match="positive clearance"):
        optimize_design(replace(apart, bounds=DesignBounds((15, 20), (40, 60), (0.001, 0.05))))
    design = optimize_design(replace(apart, bounds=DesignBounds((14, 20), (40, 60), (0.001, 0.05))))
    fit = next(c for c in design.constraints if c.name == "groove_length_m")
    assert design.design["balls"] == 14 and fit.satisfied and fit.active
    assert fit.value == pytest.approx(1.75e-3)


def test_a_problem_that_is_not_dgp_raises_even_under_python_O(monkeypatch):
    # the check is explicit, not an assert, so that python -O keeps it: patch cvxpy to say "not DGP"
    import cvxpy as cp

    build = getattr(build_design_gp, "__wrapped__", build_design_gp)  # past any cache
    monkeypatch.setattr(cp.Problem, "is_dgp", lambda self, dpp=False: False)
    with pytest.raises(RuntimeError, match="not DGP and DPP"):
        build(frozenset(), frozenset(LIMIT_NAMES), False)


def test_clearing_the_dgp_cache_makes_the_next_problem_compile_anew():
    from microbearing.optimize import dgp

    problem = DesignProblem(DesignBounds((4, 6), (40, 60), (0.001, 0.05)), speed_m_s=0.05)
    before, _ = design_gp(problem)
    assert design_gp(problem)[0] is before and dgp.cached_structures() >= 1
    dgp.clear_cache()
    assert dgp.cached_structures() == 0
    assert design_gp(problem)[0] is not before and dgp.cached_structures() == 1


def test_a_solver_design_breaking_a_limit_is_resolved_by_scs_not_returned(monkeypatch):
    # A pressure level equal to the least pressure in the box leaves one feasible design, the corner
    # (most balls, smallest angle, least load). Clarabel has called that degenerate program optimal at a
    # design 7.5 % over the limit; here the count solver is made to do so for every count, and the result
    # must still meet the limit, through SCS, and say so.
    import microbearing.optimize.solve as solve_module

    box = DesignProblem(DesignBounds((4, 12), (35, 70), (0.001, 0.05)), speed_m_s=0.05,
                        fixed={"mu_pivot": 1.0})
    corner = physics.evaluate(**box.physics_inputs(12, 35.0, 0.001))
    level = float(corner.max_contact_pressure_Pa)
    problem = replace(box, constraints=Constraints(max_contact_pressure_Pa=level))
    original = solve_module._CountSolver.solve

    def wrong_but_optimal(self, balls):
        status, solver, value, tan_theta, load = original(self, balls)
        return ("optimal", solver, 0.05, np.tan(np.radians(53.35)), 0.0027677) if balls == 12 else (
            status, solver, value, tan_theta, load)

    monkeypatch.setattr(solve_module._CountSolver, "solve", wrong_but_optimal)
    result = optimize_design(problem)
    assert all(c.satisfied or c.value <= c.limit * (1 + 1e-9) for c in result.constraints)
    assert result.design["balls"] == 12 and result.design["groove_angle_deg"] == pytest.approx(35.0)
    assert result.design["load_N"] == pytest.approx(0.001, rel=1e-6)
    assert result.mu == pytest.approx(float(corner.mu), rel=1e-6)
    assert "solved by SCS" in result.certificate and "[12]" in result.certificate
