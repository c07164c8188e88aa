"""calibrate.experiments: the promise of ``predict`` holds a generic rival the recalibration keeps (issue 33,
item 8, on a lab the bench was not tuned on).

The pivot friction ploughs with load as 0.7 (W / 5 mN)^0.2 (written here, not from physics.effects); the
first data cover 3-8 mN and the model will be used at 20-30 mN. The calibration names no mechanism but a
generic law in load, and keeps another generic form of it as its rival; the service reports the envelope of
both. The promise (``reported_half_width_after``) and the search hedged named rivals only: the plan left the
rival form open and the recalibration on its runs reported 1.58x the promise (this seed).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from microbearing import physics
from microbearing.calibrate import calibrate, parse_rows
from microbearing.calibrate.experiments import (
    ExperimentRequest,
    held_out_scale,
    next_experiments,
    read_space,
    rival_models,
)

NOISE = 0.03
SPACE = {"balls": {"low": 4, "high": 8}, "load_N": {"low": 3e-3, "high": 3e-2, "spacing": "log"},
         "speed_m_s": {"low": 0.0, "high": 0.15}}
ENVELOPE = {"balls": [6], "load_N": {"low": 2e-2, "high": 3e-2}, "speed_m_s": [0.05]}


def truth(c) -> np.ndarray:
    """The pivot friction ploughing deeper with load, (W / 5 mN)^0.2 from 0.7, in the physics."""
    return physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"],
                            mu_pivot=0.7 * (np.asarray(c["load_N"]) / 5e-3) ** 0.2).mu


def rows(c, rng) -> list[dict]:
    mu = truth(c) * np.exp(rng.normal(0.0, NOISE, c["balls"].size))
    return [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(mu.size)]


@pytest.fixture(scope="module")
def ploughing():
    rng = np.random.default_rng(103)  # a data set whose generic law in load keeps a generic rival
    n = 40
    c = {"balls": rng.choice([4, 6, 8], n).astype(float),
         "load_N": np.exp(rng.uniform(math.log(3e-3), math.log(8e-3), n)),
         "speed_m_s": rng.uniform(0.0, 0.15, n)}
    first = rows(c, rng)
    dataset = parse_rows(first)
    return first, dataset, calibrate(dataset, ["mu_pivot"], make_plots=False)


def test_the_promise_holds_the_generic_rival_a_recalibration_keeps(ploughing):
    first, dataset, report = ploughing
    model = report.model
    assert all(t.generic for t, _ in model.terms) and model.terms  # no mechanism named: a generic law
    rivals = rival_models(report.to_dict(), dataset, model, near=True)
    request = ExperimentRequest(read_space(SPACE), 16, "predict", envelope=read_space(ENVELOPE, "envelope"),
                                seed=103)
    plan = next_experiments(model, request, rivals=rivals, data=dataset.columns(),
                            held_out_scale=held_out_scale(report.to_dict(), dataset, model))
    promise = plan.expected["envelope"]["reported_half_width_after"]["mean"]
    runs = {k: np.array([r[k] for r in plan.runs], dtype=float) for k in ("balls", "load_N", "speed_m_s")}
    again = calibrate(parse_rows(first + rows(runs, np.random.default_rng([30_103, 0]))), ["mu_pivot"],
                      make_plots=False)
    rng = np.random.default_rng(10_103)
    at = {"balls": np.full(200, 6.0), "load_N": rng.uniform(2e-2, 3e-2, 200), "speed_m_s": np.full(200, 0.05)}
    predicted = again.model.predict(at)
    reported = float(np.mean((predicted.mu_upper - predicted.mu_lower) / 2))
    # what the service reports after the runs is what the plan promised, within 20 % (1.58x before)
    assert 0.8 < reported / promise < 1.2, (reported, promise)  # 0.83 on this seed
    assert any(all(t.generic for t, _ in r.terms) for _, r in rivals)  # its other generic form, hedged
