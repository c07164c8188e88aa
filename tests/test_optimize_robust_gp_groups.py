"""Robust designs on a calibration with a specimen group and a Gaussian-process discrepancy (issue 35): the
discrepancy bounded once per distinct box (:mod:`optimize.gp_boxes`) gives the model's own bounds, and the
robust optimization's proof holds against brute force on a case the speed work was not tuned on."""

import dataclasses
import itertools

import numpy as np
import pytest
from test_optimize_design_bound import brute_worst

from microbearing import physics
from microbearing.calibrate.candidates import EffectTerm
from microbearing.calibrate.groups import GroupEffect
from microbearing.calibrate.model import CalibratedModel, GPCorrection
from microbearing.calibrate.model_view import CalibratedPhysicsModel
from microbearing.optimize import gp_boxes, robust
from microbearing.optimize.over_envelope import with_model_values
from microbearing.optimize.problem import Constraints, DesignBounds, DesignProblem

# Not the bench's envelope: humidity wider, temperature narrower, a larger angle tolerance.
ENVELOPE = robust.Envelope((0.02, 0.08), {"relative_humidity": (0.25, 0.75), "temperature_C": (25.0, 55.0)},
                           {"groove_angle_deg": 0.8})


def _model() -> CalibratedPhysicsModel:
    """Menisci and a thermal term, four specimens (a group on mu), and a GP on humidity and temperature
    trained on 40 rows of a bump neither term has (seed 17, its own length scales)."""
    rng = np.random.default_rng(17)
    x = rng.uniform(-1.8, 1.8, size=(40, 2))
    gp = GPCorrection({"features": ["relative_humidity", "temperature_C"], "centre": [0.5, 40.0],
                       "scale": [0.15, 8.0], "length_scale": [0.5, 0.9], "amplitude": 0.006, "noise": 2e-4,
                       "x": x.tolist(), "y": (0.06 * np.cos(2.0 * x[:, 0]) * np.sin(x[:, 1])).tolist()})
    specimens = GroupEffect("specimen", "mu", 0.06, (0.04, 0.12), 0.025,
                            {f"S{i}": [0.02 * (i - 1.5), 2e-4, 12.0] for i in range(4)})
    calibrated = CalibratedModel(
        fitted={"mu_pivot": 0.55},
        terms=[(EffectTerm("humidity_meniscus", ("relative_humidity",)), [3e-5]),
               (EffectTerm("thermal_shear_strength", ("temperature_C",), {"reference": 35.0}), [0.003])],
        covariance=np.diag([2e-4, 1e-12, 1e-7]), noise_std_log=0.025,
        conditions=["relative_humidity", "temperature_C"])
    return CalibratedPhysicsModel("calibrated:specimens+gp",
                                  dataclasses.replace(calibrated, groups=[specimens], discrepancy=gp))


def test_the_discrepancy_over_many_boxes_is_its_bound_box_by_box_and_holds_inside_each():
    calibrated = _model().calibrated
    rng = np.random.default_rng(4)
    # 60 boxes, only 5 distinct in the GP's features (the load, which it does not read, varies)
    picks = rng.integers(0, 5, 60)
    rh_lo, t_lo = rng.uniform(0.25, 0.6, 5)[picks], rng.uniform(25.0, 45.0, 5)[picks]
    rh_hi, t_hi = rh_lo + rng.uniform(0.01, 0.15, 5)[picks], t_lo + rng.uniform(0.5, 10.0, 5)[picks]
    load = rng.uniform(0.001, 0.05, 60)
    low = {"relative_humidity": rh_lo, "temperature_C": t_lo, "load_N": load}
    high = {"relative_humidity": rh_hi, "temperature_C": t_hi, "load_N": load}
    many = gp_boxes.discrepancy_bound(calibrated, low, high, 60)
    least = gp_boxes.discrepancy_least_variance(calibrated, low, high, 60)
    for box in range(0, 60, 12):
        one = [{k: v[box:box + 1] for k, v in ends.items()} for ends in (low, high)]
        alone = calibrated.discrepancy_bound(one[0], one[1], (1,))
        for got, expected in zip(many, alone, strict=True):
            assert got[box] == pytest.approx(expected[0], rel=1e-12, abs=1e-15)
        assert least[box] == pytest.approx(calibrated.discrepancy_least_variance(one[0], one[1], (1,))[0],
                                           rel=1e-12, abs=1e-18)
        # brute force: 800 points of the box through the GP itself
        samples = {k: rng.uniform(low[k][box], high[k][box], 800)
                   for k in ("relative_humidity", "temperature_C")}
        mean, variance = calibrated.discrepancy(samples, (800,))
        assert many[0][box] <= mean.min() and mean.max() <= many[1][box]
        assert least[box] <= variance.min() and variance.max() <= many[2][box]


def test_robust_mu_upper_with_a_specimen_group_and_a_gp_holds_against_a_dense_grid():
    model = _model()
    problem = DesignProblem(DesignBounds((3, 6), (42, 58), (0.002, 0.03)), 0.05,
                            Constraints(max_contact_pressure_Pa=5.5e8))
    result = robust.optimize_robust(problem, ENVELOPE, model, objective="mu_upper", starts=2)
    proof = result.proof
    held = with_model_values(problem, model)
    design = {k: np.array([float(result.result.design[k])]) for k in ("balls", "groove_angle_deg", "load_N")}
    # The worst case at the design: 9 levels per envelope axis (6,561 points), never above the certified
    # upper bound, and the worst case found within it.
    dense = float(brute_worst(model, held, design, 9, ENVELOPE)[0])
    assert proof["upper_bound"] is not None, proof["statement"]
    assert dense <= proof["upper_bound"]
    assert result.worst_case["mu_upper"] <= proof["upper_bound"]
    assert dense <= result.worst_case["mu_upper"] * (1 + 1e-9)
    # The lower bound: no design of a grid within the pressure limit (angle made high) has a worst case over
    # a 3-level envelope grid below it.
    grid = list(itertools.product(range(3, 7), np.linspace(42, 58, 6), np.geomspace(0.002, 0.03, 8)))
    designs = {"balls": np.array([g[0] for g in grid], dtype=float),
               "groove_angle_deg": np.array([g[1] for g in grid]), "load_N": np.array([g[2] for g in grid])}
    made = held.physics_inputs(designs["balls"], designs["groove_angle_deg"] + 0.8, designs["load_N"])
    pressure = physics.evaluate(convention=held.convention, outputs=["max_contact_pressure_Pa"],
                                **made).max_contact_pressure_Pa
    feasible = pressure <= 5.5e8
    assert feasible.sum() > 10
    worst = brute_worst(model, held, {k: v[feasible] for k, v in designs.items()}, 3, ENVELOPE)
    assert worst.min() >= proof["lower_bound"]
    assert proof["proven"] == (proof["relative_gap"] <= robust.GAP_TARGET), proof["statement"]
