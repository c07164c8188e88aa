"""Tests of calibrate.gp_correction: the discrepancy's predictions against scikit-learn's own, and a
prediction without the domain check against one with it."""

from __future__ import annotations

import numpy as np

from microbearing.calibrate.candidates import EffectTerm
from microbearing.calibrate.model import CalibratedModel, GPCorrection


def _gp() -> GPCorrection:
    x = np.random.default_rng(5).normal(size=(30, 2))
    return GPCorrection({"features": ["temperature_C", "relative_humidity"], "centre": [40.0, 0.5],
                         "scale": [10.0, 0.1], "length_scale": [0.7, 0.7], "amplitude": 0.004, "noise": 1e-4,
                         "x": x.tolist(), "y": (0.05 * np.sin(1.5 * x[:, 0]) + 0.02 * x[:, 1]).tolist()})


def test_the_discrepancy_predicts_what_scikit_learn_predicts_at_every_point():
    gp = _gp()
    rng = np.random.default_rng(0)
    # repeated points (designs sharing conditions) and distinct ones, in no order
    temperature = np.concatenate([np.repeat(rng.uniform(20, 60, 12), 25), rng.uniform(0, 80, 50)])
    humidity = np.concatenate([np.repeat(rng.uniform(0.3, 0.7, 12), 25), rng.uniform(0.0, 1.0, 50)])
    order = rng.permutation(temperature.size)
    columns = {"temperature_C": temperature[order], "relative_humidity": humidity[order]}
    mean, variance = gp(columns, (temperature.size,))
    rows = np.column_stack([(columns["temperature_C"] - 40.0) / 10.0,
                            (columns["relative_humidity"] - 0.5) / 0.1])
    expected_mean, expected_std = gp.gp.predict(rows, return_std=True)
    # the same numbers as the regressor's predict, point by point (each distinct row predicted once)
    np.testing.assert_allclose(mean, expected_mean, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(variance, expected_std**2, rtol=1e-10, atol=1e-18)
    assert np.all(variance >= 0)


def test_a_prediction_without_the_domain_check_has_the_same_mu_and_interval():
    model = CalibratedModel(
        fitted={"mu_pivot": 0.6},
        terms=[(EffectTerm("humidity_meniscus", ("relative_humidity",)), [2e-5])],
        covariance=np.diag([1e-4, 1e-12]), noise_std_log=0.02,
        domain={"load_N": [0.001, 0.05], "relative_humidity": [0.2, 0.8], "temperature_C": [15, 65]},
        conditions=["relative_humidity", "temperature_C"], discrepancy=_gp())
    # half the points outside the data's load range: the check warns there
    points = {"balls": 4.0, "groove_angle_deg": 45.0, "load_N": np.geomspace(1e-4, 0.05, 20),
              "speed_m_s": 0.05, "relative_humidity": np.linspace(0.3, 0.7, 20), "temperature_C": 30.0}
    checked = model.predict(points)
    unchecked = model.predict(points, domain=False)
    assert not checked.in_domain.all() and checked.warnings
    assert unchecked.in_domain is None and unchecked.warnings == []
    for name in ("mu", "mu_lower", "mu_upper"):
        np.testing.assert_array_equal(getattr(unchecked, name), getattr(checked, name))
