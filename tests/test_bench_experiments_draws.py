"""``bench/experiments.py --draws K``: the same proposed runs measured under K noise draws (issue 32's last
bench figure is one draw, and a data set's truth error moves up to 7x between draws).

The calibration and the plans are replaced by light stand-ins (the bench's plumbing is what is tested: which
noise each strategy's runs get), the truths, the measurement and the judging are the bench's own. Before
``--draws`` the bench had no ``measure_rng`` and ``run_case`` took no draws (these tests fail there)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from bench import experiments as bench

NAME = "adhesion, Kelvin law in humidity"


class _Plan:
    def __init__(self, runs: int, seed: int):
        rng = np.random.default_rng(seed)
        self.runs = [{"balls": 6.0, "load_N": float(rng.uniform(3e-3, 3e-2)), "speed_m_s": 0.05,
                      "conditions": {"relative_humidity": float(rng.uniform(0.2, 0.9))}} for _ in range(runs)]

    def to_dict(self):
        return {"runs": self.runs}


def _calibrate(dataset, fit_parameters, make_plots, seed):
    """A model that predicts the geometric mean of the measured mu everywhere (so the noise moves it)."""
    level = float(np.exp(np.mean(np.log(dataset.mu_measured))))

    def predict(points):
        mu = np.full(np.shape(points["load_N"]), level)
        return SimpleNamespace(mu=mu, mu_lower=0.9 * mu, mu_upper=1.1 * mu)

    return SimpleNamespace(model=SimpleNamespace(predict=predict), effects=[], to_dict=dict)


@pytest.fixture
def light(monkeypatch):
    monkeypatch.setattr(bench, "calibrate", _calibrate)
    monkeypatch.setattr(bench, "rival_models", lambda report, dataset, model: [])
    monkeypatch.setattr(bench, "next_experiments",
                        lambda model, request, rivals=(): _Plan(request.runs, len(request.goal)))


def _case(draws=1, recalibrated=None):
    return bench.run_case(NAME, 3, 5, draws, recalibrated)


def test_draw_zero_is_the_single_draw_and_the_others_are_fresh_and_repeatable(light):
    single, three, again = _case(), _case(3), _case(3)
    for s in bench.STRATEGIES:
        assert single[s]["error"] == three["draws"][0][s]["error"] == three[s]["error"]
        errors = [d[s]["error"] for d in three["draws"]]
        assert len(set(errors)) == 3  # fresh noise each draw
        assert errors == [d[s]["error"] for d in again["draws"]]
    # draw 0's generator is the bench's of before (30 000 + seed); the others are not
    assert bench.measure_rng(3, 0).random() == np.random.default_rng(30_003).random()
    assert bench.measure_rng(3, 1).random() != bench.measure_rng(3, 0).random()


def test_a_strategy_left_out_keeps_the_others_noise(light):
    full, only = _case(2), _case(2, {"predict+rivals"})
    for d in range(2):
        assert set(only["draws"][d]) == {"predict+rivals"}
        assert only["draws"][d]["predict+rivals"]["error"] == full["draws"][d]["predict+rivals"]["error"]


def test_the_spread_is_each_draws_geometric_mean_and_the_relative_standard_error_of_their_mean():
    per_draw = [[0.01, 0.04], [0.02, 0.02], [0.005, 0.02]]  # geometric means 0.02, 0.02, 0.01
    figures = np.array([0.02, 0.02, 0.01])
    se = np.std(np.log(figures), ddof=1) / np.sqrt(3)  # by hand: ln 2 / 3 = 0.231
    assert se == pytest.approx(np.log(2) / 3)
    assert bench._spread(per_draw, 3) == f"0.0200 0.0200 0.0100, {np.expm1(se):>4.0%}"
    pairs = bench._ratio([[{"error": 0.01}], [{"error": 0.04}]], [[{"error": 0.02}], [{"error": 0.02}]],
                         "error")
    assert pairs == pytest.approx(1.0)  # 0.5 and 2, paired by draw
