"""Tests of optimize.general: sequential convex approximation on black-box μ models."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from microbearing import physics
from microbearing.optimize import (
    Constraints,
    DesignBounds,
    DesignProblem,
    InfeasibleDesignError,
    optimize_design,
)
from microbearing.optimize.general import SPEED_GRID_POINTS, optimize_model, physics_model, speed_grid_m_s


def _problems():
    bounds = DesignBounds((3, 12), (35, 70), (0.0005, 0.05))
    yield DesignProblem(bounds, speed_m_s=0.05, fixed={"mu_pivot": 1.0})
    yield DesignProblem(bounds, speed_m_s=(0.0, 0.1), fixed={"balls_touching": True},
                        constraints=Constraints(max_contact_pressure_Pa=5e8, max_load_per_ball_N=1e-3))
    yield DesignProblem(bounds, speed_m_s=0.2, fixed={"adhesion_energy_J_m2": 0.0},
                        constraints=Constraints(max_friction_force_N=1e-4, min_load_capacity_N=0.002))
    yield DesignProblem(DesignBounds((4, 9), (40, 60), (0.01, 0.05)), speed_m_s=0.1,
                        constraints=Constraints(groove_length_m=1.2e-3))


@pytest.mark.parametrize("problem", list(_problems()))
def test_physics_as_a_black_box_lands_on_the_dgp_optimum(problem):
    certified = optimize_design(problem)
    local = optimize_model(problem, physics_model(), model_name="physics")
    # a local method cannot beat the global optimum (beyond rounding) and must land next to it
    assert local.mu >= certified.mu * (1 - 1e-7)
    assert local.mu <= certified.mu * (1 + 1e-4)
    assert local.mu == pytest.approx(local.extra["mu_physics"], rel=1e-12)
    assert all(c.satisfied for c in local.constraints), [c for c in local.constraints if not c.satisfied]
    assert local.method == "sequential-convex-approximation"
    assert "not a global proof" in local.certificate


def test_a_non_convex_model_is_improved_from_every_start_and_verified():
    # a ripple in log G makes several local minima per ball count
    def rippled(points):
        return physics.evaluate(**points).mu * (1.0 + 0.2 * np.sin(4.0 * np.log(points["load_N"])) ** 2)

    problem = DesignProblem(DesignBounds((4, 6), (40, 60), (0.001, 0.05)), speed_m_s=0.05)
    result = optimize_model(problem, rippled, starts=5, model_name="rippled")
    design = result.design
    check = rippled(problem.physics_inputs(design["balls"], design["groove_angle_deg"], design["load_N"]))
    assert result.mu == pytest.approx(float(check), rel=1e-12)
    # no worse than the best of a 40-point load scan at the design's angle, to the local tolerance of a grid
    scan = np.geomspace(0.001, 0.05, 40)
    values = rippled(problem.physics_inputs(np.arange(4, 7)[:, None], design["groove_angle_deg"], scan))
    assert result.mu <= values.min() * (1 + 1e-9)
    assert all(c.satisfied for c in result.constraints)


def test_exact_limits_out_of_reach_name_the_same_conflict_as_the_dgp():
    # 1e7 Pa is below the pressure of the adhesive JKR load alone (Q >= 2 c at Q0 = 0)
    problem = DesignProblem(DesignBounds((4, 6), (40, 60), (0.001, 0.05)), speed_m_s=0.05,
                            constraints=Constraints(max_contact_pressure_Pa=1e7))
    with pytest.raises(InfeasibleDesignError) as local:
        optimize_model(problem, physics_model())
    with pytest.raises(InfeasibleDesignError) as certified:
        optimize_design(problem)
    assert local.value.conflicts == certified.value.conflicts == ["max_contact_pressure_Pa"]


def test_unreachable_friction_limit_is_infeasible():
    problem = DesignProblem(DesignBounds((4, 6), (40, 60), (0.001, 0.05)), speed_m_s=0.05,
                            constraints=Constraints(max_friction_force_N=1e-9))
    with pytest.raises(InfeasibleDesignError) as info:
        optimize_model(problem, physics_model())
    assert "max_friction_force_N" in info.value.conflicts


@pytest.mark.parametrize("kwargs, match",
                         [({"starts": 0}, "starts"), ({"max_iterations": 0}, "max_iterations")])
def test_arguments_are_checked(kwargs, match):
    problem = DesignProblem(DesignBounds((4, 6), (40, 60), (0.001, 0.05)), speed_m_s=0.05)
    with pytest.raises(ValueError, match=match):
        optimize_model(problem, physics_model(), **kwargs)


def test_model_returning_nonsense_is_rejected():
    problem = DesignProblem(DesignBounds((4, 6), (40, 60), (0.001, 0.05)), speed_m_s=0.05)
    with pytest.raises(ValueError, match="non-finite or non-positive"):
        optimize_model(problem, lambda points: -np.ones(np.shape(points["load_N"])))


def test_speed_range_worst_case_of_a_model_falling_with_speed_is_its_low_end():
    # mu of this model falls with speed for every design: the worst case over [0.01, 0.2] is 0.01 m/s
    def slower_is_worse(points):
        return physics.evaluate(**points).mu * (1.0 + 50.0 * (0.2 - np.asarray(points["speed_m_s"])))

    bounds = DesignBounds((4, 8), (40, 60), (0.001, 0.05))
    ranged = DesignProblem(bounds, speed_m_s=(0.01, 0.2), constraints=Constraints(max_friction_force_N=2e-3))
    result = optimize_model(ranged, slower_is_worse, model_name="falling")
    assert result.speed_m_s == pytest.approx(0.01, abs=1e-15)
    d = result.design
    at = {v: float(slower_is_worse(ranged.physics_inputs(d["balls"], d["groove_angle_deg"], d["load_N"],
                                                         speed_m_s=v))) for v in (0.01, 0.1, 0.2)}
    assert result.mu == pytest.approx(at[0.01], rel=1e-12)
    assert at[0.01] > 5 * at[0.2]  # the top speed alone would understate the worst case
    # the worst case everywhere is the low end: the same optimum as designing for 0.01 m/s alone
    low = optimize_model(replace(ranged, speed_m_s=0.01), slower_is_worse, model_name="falling")
    assert result.mu == pytest.approx(low.mu, rel=1e-6)
    assert all(c.satisfied for c in result.constraints)
    friction = next(c for c in result.constraints if c.name == "max_friction_force_N")
    assert friction.value == pytest.approx(at[0.01] * d["load_N"], rel=1e-12)
    assert "grid of 9 equally spaced speeds" in result.certificate and "0.01 m/s" in result.certificate


def test_speed_grid_spans_the_range_for_models_and_is_the_top_for_the_physics():
    problem = DesignProblem(DesignBounds((4, 6), (40, 60), (0.001, 0.05)), speed_m_s=(0.02, 0.1))
    grid = speed_grid_m_s(problem, lambda points: points["load_N"])
    assert len(grid) == SPEED_GRID_POINTS == 9 and grid[0] == 0.02 and grid[-1] == 0.1
    assert np.allclose(np.diff(grid), 0.01)
    assert speed_grid_m_s(problem, physics_model()).tolist() == [0.1]
    assert speed_grid_m_s(replace(problem, speed_m_s=0.05), lambda p: p["load_N"]).tolist() == [0.05]


def test_rows_say_whether_their_run_converged_and_claim_no_gap():
    problem = DesignProblem(DesignBounds((4, 6), (40, 60), (0.001, 0.05)), speed_m_s=0.05,
                            constraints=Constraints(max_friction_force_N=1e-3))
    capped = optimize_model(problem, physics_model(), max_iterations=1)
    converged = optimize_model(problem, physics_model())
    # one trust-region step from the middle of the box cannot converge; 100 do
    assert {r.status for r in capped.per_ball_count} == {"iteration cap reached"}
    assert "NOT a converged local optimum" in capped.certificate
    assert {r.status for r in converged.per_ball_count} == {"local optimum"}
    assert converged.certificate.startswith("Local optimum")
    for result in (capped, converged):
        assert all(r.relative_gap is None and r.mu_solver is None for r in result.per_ball_count)
        # the returned design: the batch value against a fresh one-point evaluation, measured
        assert result.mu_solver is not None and abs(result.relative_gap) < 1e-8
        assert result.relative_gap == pytest.approx(result.mu_solver / result.mu - 1.0, abs=1e-15)


def _under_predicting(factor):
    """A stand-in surrogate: the physics scaled by ``factor`` (< 1 under-predicts friction)."""
    return lambda points: factor * physics.evaluate(**points).mu


def _physics_mu(problem, design):
    inputs = problem.physics_inputs(design["balls"], design["groove_angle_deg"], design["load_N"])
    return float(physics.evaluate(**inputs).mu)


def test_a_surrogate_design_breaking_a_limit_under_its_source_is_re_solved_with_a_margin():
    problem = DesignProblem(DesignBounds((4, 8), (40, 60), (0.002, 0.05)), speed_m_s=0.05,
                            constraints=Constraints(max_friction_force_N=1e-4))
    trusting = optimize_model(problem, _under_predicting(0.97), model_name="low")
    # on its own the low model puts the force on the limit, where the physics (3 % more) breaks it
    first = next(c for c in trusting.constraints if c.name == "max_friction_force_N")
    d = trusting.design
    exact = _physics_mu(problem, d)
    assert first.value == pytest.approx(1e-4, rel=1e-3) and exact * d["load_N"] > 1e-4
    verified = optimize_model(problem, _under_predicting(0.97), model_name="low",
                              source_model=physics_model())
    d = verified.design
    exact = _physics_mu(problem, d)
    report = verified.extra["verification"]
    assert report["satisfied"] and report["resolves"] >= 1 and report["violated"] == []
    assert verified.extra["mu_source"] == pytest.approx(exact, rel=1e-12) == verified.extra["mu_physics"]
    assert verified.mu == pytest.approx(0.97 * exact, rel=1e-9)
    friction = next(c for c in verified.constraints if c.name == "max_friction_force_N")
    # both values: the physics decides (and meets the limit), the surrogate's beside it
    assert friction.decided_by == "physics" and friction.satisfied
    assert friction.value == pytest.approx(exact * d["load_N"], rel=1e-12) and friction.value <= 1e-4
    assert friction.value_model == pytest.approx(0.97 * exact * d["load_N"], rel=1e-9)
    assert "re-solved" in verified.certificate and "VIOLATING" not in verified.certificate


def test_a_surrogate_design_no_re_solve_can_fix_is_reported_violating():
    problem = DesignProblem(DesignBounds((4, 8), (40, 60), (0.002, 0.05)), speed_m_s=0.05)
    # the least physics friction force in the box, at the smallest load, by brute force over counts and angles
    grid = problem.physics_inputs(np.arange(4, 9)[:, None, None], np.linspace(40, 60, 21)[None, :, None],
                                  np.full((1, 1, 1), 0.002))
    least = float(np.min(physics.evaluate(**grid).mu * 0.002))
    # a model at half the physics meets a limit of 0.7 times that force; the physics cannot
    tight = replace(problem, constraints=Constraints(max_friction_force_N=0.7 * least))
    result = optimize_model(tight, _under_predicting(0.5), model_name="half", source_model=physics_model())
    report = result.extra["verification"]
    assert not report["satisfied"] and report["violated"] == ["max_friction_force_N"]
    friction = next(c for c in result.constraints if c.name == "max_friction_force_N")
    assert not friction.satisfied and friction.value > 0.7 * least >= friction.value_model
    assert "VIOLATING" in result.certificate
