"""A law's domain is checked when a request is submitted, naming the field, not when its job runs.

Issue 32: condition values outside a law's domain (relative humidity [30, 70] by mistake for [0.3, 0.7],
or [0.3, 1.0] where the law stops below 1) were accepted with 202 by ``/v1/optimizations`` and the job
then failed with the law's 422. The routes now read the domain each term's law declares
(:func:`calibrate.domain.outside_law_domains`).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from fastapi.testclient import TestClient
from jobs_helper import wait_job

from microbearing import physics
from microbearing.calibrate.candidates import DriftTerm, EffectTerm
from microbearing.calibrate.domain import law_domains, outside_law_domains
from microbearing.physics.effects import Domain
from microbearing.service.cli import main

PROBLEM = "application/problem+json"
N_ROWS = 120


# ------------------------------------------------------------------------------------- the library


def test_the_domains_of_a_model_s_laws_in_its_columns_units():
    terms = [(EffectTerm("humidity_meniscus", ("rh_pct",)), [1e-5]),
             (DriftTerm("viscosity_Pa_s", "arrhenius", "temperature_C", {}), [1.6e4]),
             (EffectTerm("run_in", ("cycles",)), [0.5, 100.0]),
             (EffectTerm("generic_linear", ("load_N",), {"centre": 0.01, "scale": 0.005}), [0.1])]
    domains = {d.column: d.domain for d in law_domains(terms)}
    assert domains == {"rh_pct": Domain(0.0, 100.0, False, True),  # a dry run adds no meniscus
                       "temperature_C": Domain(-273.15, np.inf, True, False),
                       "cycles": Domain(0.0)}  # a generic term declares none
    # A number, a range's ends, {low, high} and a set of values, each checked against the domain.
    inside = {"rh_pct": 50, "temperature_C": [20, 40], "cycles": {"low": 0, "high": 500}}
    assert outside_law_domains(terms, inside) == {}
    outside = outside_law_domains(terms, {"rh_pct": [30, 100], "temperature_C": -300.0,
                                          "cycles": {"values": [-1, 0, 5]}, "load_N": -1})
    assert sorted(outside) == ["cycles", "rh_pct", "temperature_C"]
    assert outside["rh_pct"].startswith("value 100 lies outside [0, 100)")
    assert "humidity_meniscus on rh_pct" in outside["rh_pct"]
    assert outside["cycles"].startswith("value -1 lies outside [0, inf)")
    assert outside["temperature_C"].startswith("value -300 lies outside (-273.15, inf)")


# ---------------------------------------------------------------------------------- through the API


def measurements() -> list[dict]:
    """Physics with mu_pivot 0.7, menisci growing with relative humidity (a fraction), 2 % noise."""
    rng = np.random.default_rng(11)
    c = {"balls": rng.choice([4, 8, 12], N_ROWS).astype(float),
         "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), N_ROWS)),
         "speed_m_s": rng.uniform(0.01, 0.15, N_ROWS),
         "relative_humidity": rng.uniform(0.2, 0.8, N_ROWS)}
    mu = physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"], mu_pivot=0.7).mu
    mu = (mu + c["balls"] * 2e-5 / (c["load_N"] * np.log(1 / c["relative_humidity"]))) * np.exp(
        rng.normal(0.0, 0.02, N_ROWS))
    return [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(N_ROWS)]


def wait(client: TestClient, location: str) -> dict:
    return wait_job(client, location, timeout_s=600, interval_s=0.1)


@pytest.fixture(scope="module")
def model(client) -> str:
    response = client.post("/v1/calibrations", json={"data": measurements(), "fit_parameters": ["mu_pivot"],
                                                     "folds": 3})
    assert response.status_code == 202, response.text
    job = wait(client, response.headers["location"])
    assert job["status"] == "succeeded", job
    result = client.get(job["result_url"]).json()
    assert [e["name"] for e in result["effects"]] == ["humidity_meniscus"], result["decision"]
    return result["model_id"]


def optimization(model: str, humidity) -> dict:
    return {"bounds": {"balls": [4, 12], "groove_angle_deg": [40, 70], "load_N": [0.005, 0.02]},
            "speed_m_s": 0.05, "model": model, "conditions": {"relative_humidity": humidity},
            "time_limit_s": 5}


def assert_refused(response, pointer: str) -> str:
    assert response.status_code == 422, response.text
    assert response.headers["content-type"] == PROBLEM
    errors = response.json()["errors"]
    assert [e["pointer"] for e in errors] == [pointer], errors
    return errors[0]["detail"]


@pytest.mark.parametrize(("humidity", "words"), [
    ([0.3, 1.0], ("[0, 1)", "humidity_meniscus")), (1.0, ("[0, 1)", "humidity_meniscus")),
    # values no humidity fraction has are the upload's unit slips, refused in its words before the law's
    ([30, 70], ("look like percent",)), (50, ("look like percent",)),
    ([-0.1, 0.5], ("a fraction in [0, 1]",))])
def test_an_optimization_outside_the_law_s_domain_is_refused_at_submit(client, model, humidity, words):
    detail = assert_refused(client.post("/v1/optimizations", json=optimization(model, humidity)),
                            "/conditions/relative_humidity")
    assert all(w in detail for w in words), detail


def test_an_optimization_inside_the_law_s_domain_runs(client, model):
    response = client.post("/v1/optimizations", json=optimization(model, 0.5))
    assert response.status_code == 202, response.text
    job = wait(client, response.headers["location"])
    assert job["status"] == "succeeded", job


def test_the_cli_refuses_the_same_request(client, model, data_dir, tmp_path, capsys):
    request = tmp_path / "request.json"
    request.write_text(json.dumps(optimization(model, [0.3, 1.0])))
    assert main(["optimize", str(request), "--data-dir", str(data_dir)]) == 2
    err = capsys.readouterr().err
    assert "/conditions/relative_humidity" in err and "[0, 1)" in err
    request.write_text(json.dumps(optimization(model, [30, 70])))
    assert main(["optimize", str(request), "--data-dir", str(data_dir)]) == 2
    err = capsys.readouterr().err
    assert "/conditions/relative_humidity" in err and "look like percent" in err


def test_friction_outside_the_law_s_domain_is_refused_naming_the_condition(client, model):
    point = {"balls": 8, "load_N": 0.01, "speed_m_s": 0.05, "model": model}
    # 50 is a unit slip (percent), refused as the upload refuses it; 1.0 is a fraction outside the domain
    for humidity, words in ((50, "look like percent"), (1.0, "[0, 1)")):
        detail = assert_refused(client.post("/v1/friction", json={
            **point, "conditions": {"relative_humidity": humidity}}), "/conditions/relative_humidity")
        assert words in detail
    points = {k: [v, v] for k, v in point.items() if k != "model"}
    batch = client.post("/v1/friction/batch", json={"points": points, "model": model,
                                                    "conditions": {"relative_humidity": [0.5, 50]}})
    assert_refused(batch, "/conditions/relative_humidity")


def test_next_experiments_outside_the_law_s_domain_are_refused_at_submit(client, model):
    calibration = model.split(":", 1)[1]
    space = {"balls": {"values": [4, 8, 12]}, "load_N": {"low": 0.005, "high": 0.02},
             "speed_m_s": {"low": 0.02, "high": 0.1}}
    for field, humidity in (("space", {"low": 30, "high": 70}), ("envelope", {"low": 0.3, "high": 1.0})):
        body = {"runs": 4, "space": {**space, "relative_humidity": {"low": 0.3, "high": 0.7}}}
        body[field] = {**body.get(field, {}), "relative_humidity": humidity}
        if field == "envelope":
            body["goal"] = "predict"
            body["envelope"] = {**space, **body["envelope"]}
        response = client.post(f"/v1/calibrations/{calibration}/next-experiments", json=body)
        assert_refused(response, f"/{field}/relative_humidity")


def test_the_cli_refuses_next_experiments_outside_the_law_s_domain(model, data_dir, tmp_path, capsys,
                                                                    monkeypatch):
    monkeypatch.setenv("MICROBEARING_DATA_DIR", str(data_dir))
    request = tmp_path / "next.json"
    request.write_text(json.dumps({"runs": 4, "space": {
        "balls": [4, 8], "load_N": {"low": 0.005, "high": 0.02}, "speed_m_s": {"values": [0.05]},
        "relative_humidity": {"low": 0.3, "high": 1.0}}}))
    assert main(["experiments", str(request), "--calibration", model]) == 2
    err = capsys.readouterr().err
    assert "space.relative_humidity: value 1 lies outside [0, 1)" in err, err
    # percent where the model reads a fraction: the upload's unit slip, in its words
    request.write_text(request.read_text().replace('"low": 0.3, "high": 1.0', '"low": 30, "high": 70'))
    assert main(["experiments", str(request), "--calibration", model]) == 2
    assert "/space/relative_humidity" in (err := capsys.readouterr().err) and "look like percent" in err


def test_a_law_domain_refusal_gives_the_value_as_sent_when_read_in_another_unit(client, model):
    # 100 % is the fraction 1, outside [0, 1): the words give the value in the model's unit and as sent,
    # at every door that reads the key
    as_sent = "(sent as relative humidity [%]: 100, read as relative_humidity: 1)"
    point = {"balls": 8, "load_N": 0.01, "speed_m_s": 0.05, "model": model}
    detail = assert_refused(client.post("/v1/friction", json={
        **point, "conditions": {"relative humidity [%]": 100}}), "/conditions/relative humidity [%]")
    assert "[0, 1)" in detail and as_sent in detail, detail
    body = {**optimization(model, 0.5), "conditions": {"relative humidity [%]": [30, 100]}}
    detail = assert_refused(client.post("/v1/optimizations", json=body), "/conditions/relative humidity [%]")
    assert "[0, 1)" in detail and "(sent as relative humidity [%]: [30, 100]" in detail, detail
    space = {"balls": {"values": [4, 8, 12]}, "load_N": {"low": 0.005, "high": 0.02},
             "speed_m_s": {"low": 0.02, "high": 0.1}, "relative humidity [%]": {"low": 30, "high": 100}}
    response = client.post(f"/v1/calibrations/{model.split(':', 1)[1]}/next-experiments",
                           json={"runs": 4, "space": space})
    detail = assert_refused(response, "/space/relative humidity [%]")
    assert "[0, 1)" in detail and "(sent as relative humidity [%]: {low: 30, high: 100}" in detail, detail
    # a planned run outside the law's domain is refused at submit too, at its key as sent
    planned = [{"balls": 8, "load_N": 0.01, "speed_m_s": 0.05, "relative humidity [%]": 100}]
    space["relative humidity [%]"] = {"low": 30, "high": 70}
    response = client.post(f"/v1/calibrations/{model.split(':', 1)[1]}/next-experiments",
                           json={"runs": 4, "space": space, "planned": planned})
    detail = assert_refused(response, "/planned/0/relative humidity [%]")
    assert "[0, 1)" in detail and "(sent as relative humidity [%]: 100" in detail, detail
    # a key sent as the model's own column is not restated
    detail = assert_refused(client.post("/v1/friction", json={
        **point, "conditions": {"relative_humidity": 1.0}}), "/conditions/relative_humidity")
    assert "sent as" not in detail, detail


@pytest.mark.parametrize(("key", "value"), [("relative_humidity", 1.0), ("relative humidity [%]", 100)])
def test_a_surrogate_outside_the_law_s_domain_is_refused_at_its_condition(client, model, key, value):
    # it was refused at /conditions alone, in the law's words about relative_humidity, whatever the key
    body = {"model": model, "space": {"load_N": [0.005, 0.02], "speed_m_s": [0.01, 0.1]},
            "fixed": {"balls": 4}, "budget": 12, "conditions": {key: value}}
    detail = assert_refused(client.post("/v1/surrogates", json=body), f"/conditions/{key}")
    assert "[0, 1)" in detail and "humidity_meniscus" in detail, detail
    if key != "relative_humidity":
        assert f"sent as {key}: 100" in detail, detail
    inside = client.post("/v1/surrogates", json={**body, "conditions": {key: value / 2}})
    assert inside.status_code == 202, inside.text
    client.delete(inside.headers["location"])


@pytest.mark.parametrize("key", ["temp_K_C", "RH_pct [1]"])
def test_the_cli_refuses_a_condition_stating_two_units_as_the_api_does(client, model, data_dir, capsys, key):
    # the API's schema refuses the key in words; the CLI called it an unknown condition column
    point = {"balls": 8, "load_N": 0.01, "speed_m_s": 0.05}
    answer = client.post("/v1/friction", json={**point, "model": model, "conditions": {key: 0.5}})
    detail = assert_refused(answer, f"/conditions/{key}")
    assert "states two units" in detail, detail
    items = [f"{k}={v}" for k, v in point.items()] + [f"{key}=0.5"]
    assert main(["evaluate", "--model", model, *items, "--data-dir", str(data_dir)]) == 2
    err = capsys.readouterr().err
    assert f"/conditions/{key}: {detail}" in err, err
