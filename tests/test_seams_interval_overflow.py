"""An interval that overflows far outside the data is refused, never answered as mu 0 with no interval.

A generic power term on temperature (mu ~ T^-2) asked at 1e308 K: mu underflows to 0 and its upper bound is
0 x inf = NaN, which the service read as "a model stored before intervals" and answered 200 with mu 0 and
null bounds, while at 1e6 K the same model answered 422 "mu_upper is not finite" (issue 32's seams: every
HTTP error a problem naming why, never a silent answer)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from microbearing import physics
from microbearing.calibrate import CalibratedModel
from microbearing.calibrate.candidates import EffectTerm
from microbearing.calibrate.domain import DataCloud
from microbearing.calibrate.model_view import CalibratedPhysicsModel
from microbearing.physics.effects import EFFECTS

N_ROWS = 60
POINT = {"balls": 8, "load_N": 0.01, "speed_m_s": 0.05}


def temperature_model(covariance: bool = True) -> CalibratedPhysicsModel:
    rng = np.random.default_rng(0)
    columns = {"balls": rng.integers(3, 13, N_ROWS).astype(float),
               "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), N_ROWS)),
               "speed_m_s": rng.uniform(0.01, 0.15, N_ROWS), "temp_K": rng.uniform(290.0, 320.0, N_ROWS)}
    term = EffectTerm("generic_power", ("temp_K",), EFFECTS["generic_power"].constants(columns, ("temp_K",)))
    model = CalibratedModel(fitted={"mu_pivot": 0.7}, terms=[(term, [-2.0])],
                            convention=physics.DEFAULT_CONVENTION,
                            covariance=np.eye(2) * 1e-4 if covariance else None,
                            noise_std_log=0.02 if covariance else None,
                            domain={k: [float(v.min()), float(v.max())] for k, v in columns.items()},
                            conditions=["temp_K"], cloud=DataCloud.from_columns(columns), domain_rows=N_ROWS)
    return CalibratedPhysicsModel("calibrated:overflow", model)


@pytest.mark.parametrize("kelvin", [1e6, 1e30, 1e308])
def test_an_interval_overflowing_far_outside_the_data_is_not_finite(kelvin):
    model = temperature_model()
    inside = model.evaluate({**POINT, "temp_K": 300.0}, ["mu", "mu_lower", "mu_upper"]).values
    assert 0 < inside["mu_lower"] < inside["mu"] < inside["mu_upper"] < 1.2 * inside["mu"]
    far = model.evaluate({**POINT, "temp_K": kelvin}, ["mu", "mu_lower", "mu_upper"]).values
    # (T / T_ref)^-2 at 1e308 K underflows mu to 0: its interval is unbounded above, never "no interval"
    assert float(far["mu_upper"]) == math.inf
    points = {**{k: np.full(2, v) for k, v in POINT.items()}, "temp_K": np.array([300.0, kelvin])}
    batch = model.evaluate(points, ["mu", "mu_upper"]).values
    assert np.isfinite(batch["mu_upper"][0]) and batch["mu_upper"][1] == math.inf


def test_a_model_stored_without_an_interval_still_answers_nan_bounds():
    far = temperature_model(covariance=False).evaluate({**POINT, "temp_K": 1e308}, ["mu", "mu_upper"]).values
    assert math.isnan(float(far["mu_upper"]))


def test_the_api_refuses_an_overflowing_interval_naming_the_column_outside_the_data(tmp_path):
    from fastapi.testclient import TestClient

    from microbearing.service.app import create_app
    from microbearing.service.settings import Settings
    from microbearing.service.store import Store

    store = Store(tmp_path)
    stored = {"report": {}, "model": temperature_model().calibrated.to_json()}
    model_id = store.save_model("calibration", stored, {}, name="overflow")
    store.close()
    model = f"calibrated:{model_id}"
    with TestClient(create_app(Settings(data_dir=tmp_path))) as client:
        inside = client.post("/v1/friction", json={**POINT, "model": model, "conditions": {"temp_K": 300.0}})
        assert inside.status_code == 200, inside.text
        for key, value in (("temp_K", 1e308), ("temp_K", 1e6), ("temperature [K]", 1e6)):
            far = client.post("/v1/friction", json={**POINT, "model": model, "conditions": {key: value}})
            # 422, never 200 with mu 0 and null bounds; at the condition as sent, not at "/"
            assert far.status_code == 422 and far.headers["content-type"] == "application/problem+json"
            assert [e["pointer"] for e in far.json()["errors"]] == [f"/conditions/{key}"], far.text
            assert "mu_upper is not finite" in far.text
        batch = client.post("/v1/friction/batch", json={
            "points": {k: [v, v] for k, v in POINT.items()}, "model": model,
            "conditions": {"temp_K": [300.0, 1e308]}})
        assert batch.status_code == 422, batch.text
        assert [e["pointer"] for e in batch.json()["errors"]] == ["/conditions/temp_K"], batch.text
        assert "at point 1" in batch.text
