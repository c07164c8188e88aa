"""Tests of optimize.pareto: epsilon-constraint fronts of μ against load and contact pressure."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

from microbearing import physics
from microbearing.optimize import Constraints, DesignBounds, DesignProblem, optimize_design
from microbearing.optimize.pareto import ParetoFront, pareto_front

PROBLEM = DesignProblem(DesignBounds((4, 12), (35, 70), (0.001, 0.05)), speed_m_s=0.05,
                        fixed={"mu_pivot": 1.0}, constraints=Constraints(max_contact_pressure_Pa=1e9))


def test_pressure_front_trades_friction_for_pressure():
    front = pareto_front(PROBLEM, "max_contact_pressure_Pa", points=5)
    values = np.array([p["value"] for p in front.points])
    mus = np.array([p["mu"] for p in front.points])
    assert len(front.points) >= 3
    # along a front, lower pressure costs friction
    assert np.all(np.diff(values) > 0) and np.all(np.diff(mus) < 0)
    best = optimize_design(PROBLEM)
    assert mus.min() == pytest.approx(best.mu, rel=1e-6)
    for p in front.points:
        d = p["design"]
        r = physics.evaluate(**PROBLEM.physics_inputs(d["balls"], d["groove_angle_deg"], d["load_N"]))
        assert float(r.max_contact_pressure_Pa) == pytest.approx(p["value"], rel=1e-12)
        assert float(r.mu) == pytest.approx(p["mu"], rel=1e-12)
        assert p["value"] <= p["level"] * (1 + 1e-12)
        # no design meeting the same pressure level is better: a brute-force scan of the box
        z, th, g = np.arange(4, 13)[:, None, None], np.linspace(35, 70, 60)[None, :, None], \
            np.geomspace(0.001, 0.05, 120)[None, None, :]
        scan = physics.evaluate(**PROBLEM.physics_inputs(z, th, g))
        allowed = scan.max_contact_pressure_Pa <= p["level"]
        assert scan.mu[allowed].min() >= p["mu"] * (1 - 1e-6)


def test_load_front_and_png():
    front = pareto_front(PROBLEM, "load_N", points=4)
    loads = [p["value"] for p in front.points]
    assert loads == sorted(loads) and max(loads) == pytest.approx(0.05)
    png = front.to_png()
    assert png.startswith(b"\x89PNG") and len(png) > 5000
    assert front.to_dict()["unit"] == "N"


@pytest.mark.parametrize("kwargs, match", [({"objective": "speed"}, "objective"), ({"points": 1}, "points")])
def test_arguments_are_checked(kwargs, match):
    with pytest.raises(ValueError, match=match):
        pareto_front(PROBLEM, **kwargs)


def test_wide_pressure_front_is_non_dominated():
    # bench/optimize.py's front: 3..40 balls over a speed range, levels down to infeasible ones
    wide = DesignProblem(DesignBounds((3, 40), (35, 70), (0.001, 0.05)), speed_m_s=(0.0, 0.05),
                         fixed={"mu_pivot": 1.0}, constraints=Constraints(max_contact_pressure_Pa=6e8))
    front = pareto_front(wide, "max_contact_pressure_Pa", points=8)
    values = np.array([p["value"] for p in front.points])
    mus = np.array([p["mu"] for p in front.points])
    assert len(front.points) >= 3
    assert np.all(np.diff(values) > 0) and np.all(np.diff(mus) < 0)
    assert mus.min() == pytest.approx(optimize_design(wide).mu, rel=1e-6)




def test_counts_far_from_feasible_are_infeasible_without_warnings():
    # At the front's tightest pressure levels the smallest counts are infeasible, their phase-I slack
    # so large that its exponential overflows: that is inf (infeasible), not a warning on every request.
    wide = DesignProblem(DesignBounds((3, 40), (35, 70), (0.001, 0.05)), speed_m_s=(0.0, 0.05),
                         fixed={"mu_pivot": 1.0}, constraints=Constraints(max_contact_pressure_Pa=6e8))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        front = pareto_front(wide, "max_contact_pressure_Pa", points=8)
    assert [str(w.message) for w in caught] == []
    tightest = front.points[0]
    tight = Constraints(max_contact_pressure_Pa=tightest["level"])
    result = optimize_design(replace(wide, constraints=tight))
    infeasible = [row.balls for row in result.per_ball_count if row.status == "infeasible"]
    assert infeasible and max(infeasible) < result.design["balls"]
    # brute force: no design with those counts meets the level
    z, th, g = np.array(infeasible)[:, None, None], np.linspace(35, 70, 50)[None, :, None], \
        np.geomspace(0.001, 0.05, 100)[None, None, :]
    scan = physics.evaluate(**wide.physics_inputs(z, th, g))
    assert scan.max_contact_pressure_Pa.min() > tightest["level"]


def test_a_front_with_infeasible_levels_says_so_on_its_plot():
    complete = pareto_front(PROBLEM, "load_N", points=4)
    assert complete.infeasible_levels == 0 and "infeasible" not in complete.figure().axes[0].get_title()
    # the same points, had one more level been asked for and found infeasible (a 5-point request answered
    # with 4): the title says how many of the levels asked for it draws
    short = ParetoFront(complete.objective, complete.points, infeasible_levels=1)
    title = short.figure().axes[0].get_title()
    assert f"{len(complete.points)} of {len(complete.points) + 1} levels: 1 infeasible" in title
