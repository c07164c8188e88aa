"""Issue 33, item 7: beyond a physics input's range the interval grows by what the data hint at near its end.

The extrapolation allowance (a documented rule: one interval half-width more per quarter of the data's
span beyond it) holds departures that grow about 0.24 of log μ per span; a departure that the data already
show bending near their end (load 2-10 mN, truth x (1 + 0.5 exp(-load / 1 mN) + 0.3 (load / 30 mN)^2), 6.8 %
at 2 mN, 30 % at 0.5 mN) grew faster, and the interval at 0.5 mN covered 0.745 on one draw. The residuals'
quadratic in log load, read at the end (its level and slope, each less its noise), adds the departure they
trend to; on data the model fits to the edge it adds nothing or little.
"""

from __future__ import annotations

import math
import re
from dataclasses import replace

import numpy as np
import pytest

from microbearing import physics
from microbearing.calibrate import CalibratedModel, calibrate
from microbearing.calibrate.domain import edge_trends, extrapolation_allowance, extrapolation_bound


def draw(rng, n: int, departure: bool, load=None) -> tuple[dict, np.ndarray]:
    """The draw of bench/offdata_inputs.py --input load_edge (a seed gives the bench's rows)."""
    c = {"balls": rng.choice([4, 6, 8], n).astype(float),
         "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
         "speed_m_s": rng.uniform(0.05, 0.3, n)}
    c["load_N"] = np.exp(rng.uniform(np.log(2e-3), np.log(10e-3), n))
    if load is not None:
        c["load_N"] = np.full(n, float(load))
    factor = 1 + 0.5 * np.exp(-c["load_N"] / 1e-3) + 0.3 * (c["load_N"] / 0.03) ** 2 if departure else 1.0
    truth = physics.evaluate(**c, mu_pivot=0.65).mu * factor
    return c, truth * np.exp(rng.normal(0.0, 0.03, n))


def calibrated(seed: int, departure: bool) -> tuple[CalibratedModel, np.random.Generator]:
    rng = np.random.default_rng(seed)
    c, mu = draw(rng, 110, departure)
    rows = [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(mu.size)]
    return calibrate(rows, ["mu_pivot"], make_plots=False).model, rng


def coverage(model: CalibratedModel, points: dict, measured: np.ndarray) -> float:
    p = model.predict(points)
    return float(np.mean((p.mu_lower <= measured) & (measured <= p.mu_upper)))


def test_a_departure_the_data_show_bending_at_their_end_is_covered_beyond_it_and_flagged():
    model, rng = calibrated(1, departure=True)
    draw(rng, 200, True)  # the bench's inside points
    far, measured = draw(rng, 200, True, 0.5e-3)
    answer = model.predict(far)
    assert not answer.in_domain.any()
    # 0.745 by the rule alone (the bench's seed 1); the trend at the low end of load is what widens it
    assert coverage(model, far, measured) >= 0.9
    assert coverage(replace(model, edge_trends={}), far, measured) < 0.8
    assert model.edge_trends["load_N"][1] > 0.05  # log mu per e-fold of load below 2 mN
    (warning,) = [w for w in answer.warnings if "load_N" in w]
    assert "the departure the data's residuals trend to at that end" in warning
    stated = float(re.findall(r"multiplied by up to ([0-9.]+)", warning)[0])
    alone = replace(model, rivals=[])  # the model's own interval (a rival's is not widened by the allowance)
    own, bare = alone.predict(far), replace(alone, cloud=None, domain=None).predict(far)
    applied = np.log(own.mu_upper / own.mu) / np.log(bare.mu_upper / bare.mu)
    assert stated == pytest.approx(float(np.max(applied)), rel=5e-3)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_without_a_departure_the_interval_beyond_the_data_hardly_widens(seed):
    # The physics alone: the residuals' quadratic is noise, and each coefficient less its noise is mostly 0.
    model, rng = calibrated(seed, departure=False)
    far, measured = draw(rng, 200, False, 0.5e-3)
    ratio = (np.log(model.predict(far).mu_upper / model.predict(far).mu)
             / np.log(replace(model, edge_trends={}).predict(far).mu_upper / model.predict(far).mu))
    assert float(np.max(ratio)) <= 1.1
    assert coverage(model, far, measured) >= 0.95


def test_edge_trends_read_a_bend_at_one_end_and_not_flat_noise():
    rng = np.random.default_rng(0)
    x = np.exp(rng.uniform(np.log(2e-3), np.log(10e-3), 200))
    noise = rng.normal(0.0, 0.03, 200)
    bent = 0.5 * np.exp(-x / 1e-3) + noise
    ranges = {"load_N": (float(x.min()), float(x.max()))}
    trends = edge_trends({"load_N": x}, bent, np.ones(200, bool), ranges)
    low_level, low_growth, _, high_growth = trends["load_N"]
    assert low_level > 0.03 and low_growth > 0.05
    assert low_growth > 2.0 * high_growth
    # Flat noise over 40 draws: most coefficients read 0, and the growth stays small on average.
    growth = []
    for seed in range(40):
        flat = np.random.default_rng(seed).normal(0.0, 0.03, 200)
        growth += edge_trends({"load_N": x}, flat, np.ones(200, bool), ranges)["load_N"][1::2]
    assert np.mean(np.asarray(growth) == 0.0) > 0.5
    assert np.mean(growth) < 0.02
    # too few rows or values: no trend
    assert edge_trends({"load_N": x[:7]}, bent[:7], np.ones(7, bool), {"load_N": (2e-3, 10e-3)}) == {}


def test_the_allowance_with_a_trend_grows_with_the_distance_and_its_box_bound_is_exact():
    low, high, rows, trend = 2e-3, 10e-3, 110, [0.3, 1.2, 0.1, 0.5]
    values = np.concatenate([np.geomspace(1e-4, 2e-3, 60), np.geomspace(10e-3, 0.1, 60)])
    plain, side = extrapolation_allowance(values, low, high, rows)
    widened, side_t = extrapolation_allowance(values, low, high, rows, trend)
    assert np.array_equal(side, side_t)
    beyond = plain > 0
    assert np.all(widened[beyond] > plain[beyond]) and np.all(widened[~beyond] == 0.0)
    for part in (side < 0, side > 0):  # away from the range on each side, the allowance never falls
        order = np.argsort(np.abs(np.log(values[part]) - np.log(np.sqrt(low * high))))
        assert np.all(np.diff(widened[part][order]) >= 0.0)
    # the level and the growth per e-fold of load beyond the data's end, on top of the rule
    expected = plain[0] + trend[0] + trend[1] * math.log(low / 1e-4)
    assert widened[0] == pytest.approx(expected)
    # the bound over boxes of load: brute force over each box's points
    rng = np.random.default_rng(1)
    a, b = np.sort(np.exp(rng.uniform(np.log(1e-4), np.log(0.1), (2, 50))), axis=0)
    upper = extrapolation_bound({"load_N": (low, high)}, rows, {"load_N": a}, {"load_N": b}, (50,),
                                trends={"load_N": trend})
    lower = extrapolation_bound({"load_N": (low, high)}, rows, {"load_N": a}, {"load_N": b}, (50,), True,
                                {"load_N": trend})
    for i in range(50):
        inside = extrapolation_allowance(np.geomspace(a[i], b[i], 400), low, high, rows, trend)[0]
        assert upper[i] == pytest.approx(inside.max()) and lower[i] == pytest.approx(inside.min())


def test_the_edge_trends_survive_the_model_s_json():
    model, _ = calibrated(1, departure=True)
    again = CalibratedModel.from_json(model.to_json())
    assert again.edge_trends == model.edge_trends and model.edge_trends["load_N"][1] > 0
    far = {"balls": 6.0, "load_N": 0.5e-3, "speed_m_s": 0.1}
    assert again.predict(far).mu_upper == pytest.approx(model.predict(far).mu_upper, rel=1e-12)
