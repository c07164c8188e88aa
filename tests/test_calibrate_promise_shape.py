"""calibrate.experiments: ``predict`` over an envelope beyond the data in speed hedges the catalogue's speed
laws over their shape (issue 33, item 8; calibrate.shape_hedges).

The pivot friction rises at low speed as 1 + 0.8 exp(-v / 15 mm/s) (written here, not from physics.effects);
the first data cover 50-150 mm/s, where the rise is under the 3 % noise, and the model will be used at
2-20 mm/s. The first calibration takes no speed term; a recalibration on runs in the envelope adds
``stribeck_rise on speed_m_s`` (the truth's form; ``stribeck_breakaway`` before h66), whose decay speed
runs at one speed leave free (the search put all 16 runs at 2 mm/s before, bench/RESULTS.md h60).
"""

from __future__ import annotations

import numpy as np
import pytest

from microbearing import physics
from microbearing.calibrate import calibrate, parse_rows
from microbearing.calibrate.experiments import (
    CalibratedResponse,
    ExperimentRequest,
    next_experiments,
    read_space,
)
from microbearing.calibrate.shape_hedges import off_data_inputs, shape_hedges

NOISE = 0.03
SPACE = {"balls": {"low": 4, "high": 8}, "load_N": {"low": 3e-3, "high": 3e-2, "spacing": "log"},
         "speed_m_s": {"low": 0.002, "high": 0.15}}
ENVELOPE = {"balls": [6], "load_N": {"low": 5e-3, "high": 2e-2}, "speed_m_s": {"low": 0.002, "high": 0.02}}


def truth(c) -> np.ndarray:
    """A boundary film's breakaway on the pivot share, Stribeck-like, in the physics."""
    speed = np.asarray(c["speed_m_s"], dtype=float)
    return physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=speed,
                            mu_pivot=0.7 * (1 + 0.8 * np.exp(-speed / 0.015))).mu


def rows(c, rng) -> list[dict]:
    mu = truth(c) * np.exp(rng.normal(0.0, NOISE, c["balls"].size))
    return [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(mu.size)]


@pytest.fixture(scope="module")
def stribeck():
    rng = np.random.default_rng(211)
    n = 40
    c = {"balls": rng.choice([4, 6, 8], n).astype(float),
         "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
         "speed_m_s": rng.uniform(0.05, 0.15, n)}
    first = rows(c, rng)
    dataset = parse_rows(first)
    return first, dataset, calibrate(dataset, ["mu_pivot"], make_plots=False)


def test_the_runs_spread_over_the_speeds_and_the_promise_holds_relative_to_mu(stribeck):
    first, dataset, report = stribeck
    model = report.model
    assert not model.terms  # the rise is under the noise at 50-150 mm/s
    request = ExperimentRequest(read_space(SPACE), 16, "predict", envelope=read_space(ENVELOPE, "envelope"),
                                seed=211)
    plan = next_experiments(model, request, data=dataset.columns())
    speeds = np.array([r["speed_m_s"] for r in plan.runs])
    # one speed leaves the Stribeck speed free: the runs spread over the envelope's decade (all at 2 mm/s
    # before)
    assert np.unique(np.round(speeds, 4)).size >= 3 and speeds.max() / speeds.min() >= 3.0, speeds
    envelope = plan.expected["envelope"]
    promise = envelope["reported_relative_half_width_after"]["mean"]
    runs = {k: np.array([r[k] for r in plan.runs], dtype=float) for k in ("balls", "load_N", "speed_m_s")}
    again = calibrate(parse_rows(first + rows(runs, np.random.default_rng([30_211, 0]))), ["mu_pivot"],
                      make_plots=False)
    assert any(t.name == "stribeck_rise" for t, _ in again.model.terms), again.decision
    rng = np.random.default_rng(10_211)
    at = {"balls": np.full(200, 6.0), "load_N": rng.uniform(5e-3, 2e-2, 200),
          "speed_m_s": rng.uniform(0.002, 0.02, 200)}
    predicted = again.model.predict(at)
    reported = float(np.mean((predicted.mu_upper - predicted.mu_lower) / 2 / predicted.mu))
    # what the service reports after the runs, as a fraction of mu, is what the plan promised
    assert 0.8 < reported / promise < 1.2, (reported, promise)


def test_no_law_is_hedged_where_the_envelope_stays_within_the_data(stribeck):
    _, dataset, report = stribeck
    response = CalibratedResponse(report.model, report.model.fixed)
    inside = {"balls": np.full(50, 6.0), "load_N": np.full(50, 1e-2),
              "speed_m_s": np.linspace(0.06, 0.14, 50)}
    assert off_data_inputs(report.model, inside) == {}
    assert shape_hedges(response, dataset.columns(), inside) == []
    beyond = dict(inside, speed_m_s=np.linspace(0.002, 0.02, 50))
    low, high = off_data_inputs(report.model, beyond)["speed_m_s"]
    assert low == pytest.approx(0.002) and high == pytest.approx(max(dataset.columns()["speed_m_s"]))
    hedged = shape_hedges(response, dataset.columns(), beyond)
    # each speed law of the catalogue with a shape (Stribeck speed, exponent of speed), at several shapes
    names = {m.terms[-1][0].name for _, m in hedged}
    assert names == {"stribeck_breakaway", "stribeck_rise", "viscous_power_law"}
    decay = sorted(m.terms[-1][1][1] for _, m in hedged if m.terms[-1][0].name == "stribeck_breakaway")
    assert decay[0] == pytest.approx(0.002) and decay[-1] == pytest.approx(high) and len(decay) >= 3
