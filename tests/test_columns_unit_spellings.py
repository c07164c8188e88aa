"""A unit spelled as labs write it in brackets (``temperature [℃]``) is read in that unit at every door: the
upload, /v1/friction, UM-Bridge and the CLI answer as they do for its usual spelling (``[degC]``)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from jobs_helper import finished_job

from microbearing import physics
from microbearing.service.cli import main


@pytest.fixture(scope="module")
def model(client) -> str:
    """A model calibrated on a CSV whose temperature header is 'temperature [℃]' (U+2103), friction
    falling 3 % per kelvin, so that a temperature read in another unit would change mu."""
    rng = np.random.default_rng(11)
    n = 60
    balls, load, speed = rng.choice([4, 8], n), rng.uniform(0.005, 0.03, n), rng.uniform(0.01, 0.15, n)
    celsius = rng.uniform(20.0, 40.0, n)
    mu = physics.evaluate(balls=balls.astype(float), load_N=load, speed_m_s=speed, mu_pivot=0.7).mu
    mu = mu * np.exp(-0.03 * (celsius - 30.0)) * np.exp(rng.normal(0.0, 0.01, n))
    text = "balls,load_N,speed_m_s,temperature [\u2103],mu_measured\n" + "".join(
        f"{b},{w:.17g},{v:.17g},{t:.17g},{m:.17g}\n"
        for b, w, v, t, m in zip(balls, load, speed, celsius, mu, strict=True))
    response = client.post("/v1/calibrations/csv", params=[("fit_parameters", "mu_pivot"), ("folds", "3")],
                           content=text.encode("utf-8"), headers={"content-type": "text/csv; charset=utf-8"})
    assert response.status_code == 202, response.text
    job = finished_job(client, response.headers["location"], timeout_s=300, interval_s=0.2)
    result = client.get(job["result_url"]).json()
    assert "temperature_K" in result["model"]["conditions"], result["model"]
    return result["model_id"]


def _mu(client, model: str, conditions: dict) -> float:
    point = {"balls": 4, "load_N": 0.01, "speed_m_s": 0.05, "model": model, "conditions": conditions}
    response = client.post("/v1/friction", json=point)
    assert response.status_code == 200, response.text
    return response.json()["mu"]


def test_a_model_uploaded_in_celsius_sign_answers_in_degf_as_by_hand(client, model, data_dir, tmp_path):
    # hand: 35 degC = 95 degF = 308.15 K
    kelvin = _mu(client, model, {"temperature_K": 308.15})
    assert kelvin != pytest.approx(_mu(client, model, {"temperature_K": 298.15}), rel=1e-3)  # it reads T
    for conditions in ({"temperature [degF]": 95.0}, {"temperature [\u2103]": 35.0},
                       {"temperature [\u2109]": 95.0}, {"temperature [deg F]": 95.0}):
        assert _mu(client, model, conditions) == pytest.approx(kelvin, rel=1e-9), conditions
    batch = client.post("/v1/friction/batch", json={
        "points": {"balls": [4, 4], "load_N": 0.01, "speed_m_s": 0.05}, "model": model,
        "conditions": {"temperature [\u00baF]": [95.0, 95.0]}})
    assert batch.status_code == 200, batch.text
    assert batch.json()["mu"] == pytest.approx([kelvin, kelvin], rel=1e-9)
    bridged = client.post("/umbridge/Evaluate", json={"name": model, "input": [[4, 0.01, 0.05]], "config": {
        "inputs": ["balls", "load_N", "speed_m_s"], "fixed": {"temperature [\u2109]": 95.0}}})
    assert bridged.status_code == 200, bridged.text
    assert bridged.json()["output"][0][0] == pytest.approx(kelvin, rel=1e-9)
    out = tmp_path / "point.json"
    assert main(["evaluate", "--data-dir", str(data_dir), "--model", model, "-o", str(out), "balls=4",
                 "load_N=0.01", "speed_m_s=0.05", "temperature [\u2103]=35"]) == 0
    assert json.loads(out.read_text())["mu"] == pytest.approx(kelvin, rel=1e-9)
