"""Issue 33 item 8: a low-speed rise of the pivot friction itself is named as the multiplicative Stribeck law.

The truth raises mu_pivot as 0.7 (1 + 0.8 exp(-v / 15 mm/s)) (bench/plans_promise.py's speed lab): the rise
is a fraction of the friction it raises, so over loads 3-30 mN and 4-8 balls the additive law
(``stribeck_breakaway``, a fixed excess) fits it with an average excess, too small where μ is large and too
large where it is small (on the speed lab's runs its μ sat 1-3 % below the truth at 6 balls; bench/RESULTS.md,
h66). On data spread over 2-150 mm/s the calibration names ``stribeck_rise`` with about the true values
(before the law existed no named law fitted: generic_power then generic_quadratic on speed), and fresh
measurements at 2-20 mm/s fall in its 95 % interval.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from microbearing import physics
from microbearing.calibrate import calibrate
from microbearing.physics.effects import apply_effect

NOISE = 0.03


def truth(c: dict) -> np.ndarray:
    pivot = 0.7 * (1 + 0.8 * np.exp(-c["speed_m_s"] / 0.015))
    return physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"], mu_pivot=pivot).mu


def draw(rng, n: int, speed: tuple[float, float], balls=(4, 6, 8)) -> dict:
    return {"balls": rng.choice(balls, n).astype(float),
            "load_N": np.exp(rng.uniform(math.log(3e-3), math.log(3e-2), n)),
            "speed_m_s": np.exp(rng.uniform(math.log(speed[0]), math.log(speed[1]), n))}


def test_stribeck_rise_multiplies_mu_by_a_factor_decaying_with_speed():
    columns = {"speed_m_s": np.array([0.0, 0.01, 1.0])}
    out = apply_effect(np.array([0.01, 0.02, 0.02]), "stribeck_rise", columns,
                       {"rise_ratio": 0.5, "rise_speed_m_s": 0.01})
    by_hand = [0.01 * 1.5, 0.02 * (1 + 0.5 / math.e), 0.02 * (1 + 0.5 * math.exp(-100))]
    assert out.tolist() == pytest.approx(by_hand)


def test_a_rise_of_the_pivot_friction_is_named_multiplicative_and_covered():
    rng = np.random.default_rng(66)
    c = draw(rng, 120, (0.002, 0.15))
    measured = truth(c) * np.exp(rng.normal(0.0, NOISE, 120))
    rows = [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(measured[i])} for i in range(120)]
    report = calibrate(rows, ["mu_pivot"], make_plots=False)
    assert [t.name for t, _ in report.model.terms] == ["stribeck_rise"], report.decision
    (rise, speed), = [v for _, v in report.model.terms]
    assert rise == pytest.approx(0.8, rel=0.25) and speed == pytest.approx(0.015, rel=0.3)
    fresh = draw(np.random.default_rng(67), 400, (0.002, 0.02), balls=(6,))
    answer = report.model.predict(fresh)
    true = truth(fresh)
    bias = np.log(answer.mu / true)
    assert abs(float(np.mean(bias))) < 0.01  # the additive law: -1 to -3 % here
    seen = true * np.exp(np.random.default_rng(68).normal(0.0, NOISE, 400))
    assert 0.92 <= np.mean((answer.mu_lower <= seen) & (seen <= answer.mu_upper))
