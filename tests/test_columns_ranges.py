"""A condition's physical range at every door (issue 32): a time or count run below zero is refused at the
upload, at prediction (read by a term or not), in an optimization's conditions, in an experiment's space,
fixed values and planned runs, over UM-Bridge and by the CLI, by its key and value as sent."""

from __future__ import annotations

import json

import numpy as np
import pytest
from jobs_helper import finished_job

from microbearing.physics.columns import physical_range
from microbearing.service.cli import main

PROBLEM = "application/problem+json"


def _rows(time_s: np.ndarray) -> list[dict]:
    """30 rows of a flat friction (no effect of time: the terms do not read it) with a run time [s] and a
    humidity [%] column."""
    rng = np.random.default_rng(3)
    n = time_s.size
    return [{"balls": int(b), "load_N": float(w), "speed_m_s": float(v), "Time_s": float(t),
             "RH_pct": float(h), "mu_measured": 0.01 * float(np.exp(rng.normal(0.0, 0.03)))}
            for b, w, v, t, h in zip(rng.choice([4, 6, 8], n), rng.uniform(0.005, 0.02, n),
                                     rng.uniform(0.01, 0.1, n), time_s, rng.uniform(20, 60, n), strict=True)]


@pytest.fixture(scope="module")
def model(client) -> str:
    response = client.post("/v1/calibrations", json={"data": _rows(np.linspace(0.0, 600.0, 30)),
                                                     "fit_parameters": ["mu_pivot"], "folds": 3})
    assert response.status_code == 202, response.text
    job = finished_job(client, response.headers["location"], timeout_s=300, interval_s=0.2)
    result = client.get(job["result_url"]).json()
    assert "Time_s" in result["model"]["conditions"], result["model"]
    return result["model_id"]


def _errors(response, status: int = 422) -> dict[str, str]:
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == PROBLEM
    return {e.get("pointer"): e["detail"] for e in response.json()["errors"]}


def test_a_condition_s_physical_range_is_read_from_its_quantity_in_the_unit_its_name_says():
    # hand: 0 K is -273.15 degC and -459.67 degF; a fraction's 1 is 100 %; a time from zero in any unit
    assert physical_range("temperature_K") == (0.0, None)
    assert physical_range("temp_C") == (-273.15, None)
    assert physical_range("temp_F") == (-459.67, None)
    assert physical_range("relative_humidity") == (0.0, 1.0)
    assert physical_range("RH_pct") == (0.0, 100.0)
    assert physical_range("time_min") == physical_range("cycles") == (0.0, None)
    assert physical_range("load_N") == physical_range("specimen") == (None, None)


def test_the_upload_refuses_a_time_run_below_zero(client):
    response = client.post("/v1/calibrations", json={"data": _rows(np.linspace(-60.0, 600.0, 30)),
                                                     "fit_parameters": ["mu_pivot"], "folds": 3})
    assert response.status_code == 422, response.text
    assert "Time_s runs -60 to 600 [s], outside its physical range [0, inf]" in response.text


@pytest.mark.parametrize(("conditions", "pointer", "words"), [
    ({"Time_s": -5, "RH_pct": 40}, "/conditions/Time_s", "value -5 lies outside [0, inf] [s]"),
    # hand: -1 min is -60 s
    ({"time [min]": -1, "RH_pct": 40}, "/conditions/time [min]",
     "sent as time [min]: -1, read as Time_s: -60"),
])
def test_a_condition_the_terms_do_not_read_is_still_refused_below_its_physical_range(
        client, model, conditions, pointer, words):
    point = {"balls": 6, "load_N": 0.01, "speed_m_s": 0.05, "model": model}
    errors = _errors(client.post("/v1/friction", json={**point, "conditions": conditions}))
    assert words in errors[pointer], errors
    batch = {"points": {"balls": [6, 6], "load_N": 0.01, "speed_m_s": 0.05}, "model": model,
             "conditions": {**conditions, "RH_pct": [40, 45]}}
    assert words in _errors(client.post("/v1/friction/batch", json=batch))[pointer]
    fine = client.post("/v1/friction", json={**point, "conditions": {"Time_s": 5, "RH_pct": 40}})
    assert fine.status_code == 200, fine.text


def test_every_other_door_refuses_a_time_below_zero(client, model, data_dir, tmp_path):
    design = {"bounds": {"balls": [4, 8], "groove_angle_deg": [40, 70], "load_N": [0.005, 0.02]},
              "speed_m_s": 0.05, "model": model}
    errors = _errors(client.post("/v1/optimizations", json={**design, "conditions": {"RH_pct": 40,
                                                                                     "Time_s": [-5, 10]}}))
    assert "physical range of Time_s" in errors["/conditions/Time_s"], errors
    umbridge = client.post("/umbridge/Evaluate", json={"name": model, "input": [[6, 0.01, 0.05]], "config": {
        "inputs": ["balls", "load_N", "speed_m_s"], "fixed": {"Time_s": -5, "RH_pct": 40}}})
    assert umbridge.status_code == 400 and "physical range of Time_s" in umbridge.json()["error"]["message"]
    url = f"/v1/calibrations/{model.split(':', 1)[1]}/next-experiments"
    space = {"balls": [4, 8], "load_N": [0.005, 0.02], "speed_m_s": [0.01, 0.1], "RH_pct": [20, 60]}
    run = {"balls": 4, "load_N": 0.01, "speed_m_s": 0.05, "RH_pct": 30}
    for body, pointer in (({"space": {**space, "Time_s": [-10, 100]}}, "/space/Time_s"),
                          ({"space": space, "fixed": {"Time_s": -3}}, "/fixed/Time_s"),
                          ({"space": {**space, "Time_s": [0, 100]}, "planned": [{**run, "Time_s": -1}]},
                           "/planned/0/Time_s")):
        errors = _errors(client.post(url, json={"runs": 4, "goal": "parameters", **body}))
        assert "physical range of Time_s" in errors[pointer], errors
    # the CLI answers as /v1/friction does
    out = tmp_path / "point.json"
    arguments = ["evaluate", "--data-dir", str(data_dir), "--model", model, "-o", str(out), "balls=6",
                 "load_N=0.01", "speed_m_s=0.05", "RH_pct=40"]
    assert main([*arguments, "Time_s=-5"]) != 0 and not out.exists()
    assert main([*arguments, "Time_s=5"]) == 0
    assert json.loads(out.read_text())["mu"] > 0


def test_the_cli_reads_a_file_s_conditions_by_their_headers_as_sent(client, model, data_dir, tmp_path,
                                                                    capsys):
    # the rows' conditions reach the model as /v1/friction's do: a refusal names the header and the value
    # as typed (hand: -1 min is -60 s), and good rows answer as the API does
    table = tmp_path / "points.csv"
    out = tmp_path / "out.csv"
    arguments = ["evaluate", "--data-dir", str(data_dir), "--model", model, "--csv", str(table),
                 "-o", str(out)]
    table.write_text("balls,load [mN],speed_m_s,time [min],RH_pct\n6,10,0.05,1,40\n6,10,0.05,-1,40\n"
                     "6,10,0.05,2,40\n")
    assert main(arguments) != 0
    err = capsys.readouterr().err
    assert "sent as time [min]: [1, -1, 2], read as Time_s: [60, -60, 120]" in err, err
    # at the line of the first row that brings the refusal, as a physics cell's (before: no line)
    assert f"{table}: line 3, column time [min]: -1" in err, err
    table.write_text("balls,load [mN],speed_m_s,time [min],RH_pct\n6,10,0.05,1,40\n")
    assert main(arguments) == 0
    api = client.post("/v1/friction", json={"balls": 6, "load_N": 0.01, "speed_m_s": 0.05, "model": model,
                                            "conditions": {"Time_s": 60, "RH_pct": 40}}).json()
    header, row = out.read_text().splitlines()[:2]
    assert float(dict(zip(header.split(","), row.split(","), strict=True))["mu"]) == pytest.approx(api["mu"])


def test_um_bridge_varies_a_condition_no_term_reads_as_config_fixed_takes_it(client, model):
    # config.fixed took time [min]; config.inputs refused it as no input of the model
    config = {"inputs": ["balls", "load_N", "speed_m_s", "time [min]"], "fixed": {"RH_pct": 40}}
    good = client.post("/umbridge/Evaluate", json={"name": model, "input": [[6, 0.01, 0.05, 10]],
                                                   "config": config})
    assert good.status_code == 200, good.text
    fixed = client.post("/umbridge/Evaluate", json={"name": model, "input": [[6, 0.01, 0.05]], "config": {
        "inputs": ["balls", "load_N", "speed_m_s"], "fixed": {"RH_pct": 40, "time [min]": 10}}})
    assert good.json()["output"] == fixed.json()["output"], (good.text, fixed.text)
    gradient = client.post("/umbridge/Gradient", json={"name": model, "inWrt": 0, "outWrt": 0, "sens": [1.0],
                                                       "input": [[6, 0.01, 0.05, 10]], "config": config})
    assert gradient.status_code == 200 and gradient.json()["output"][3] == 0.0, gradient.text
    bad = client.post("/umbridge/Evaluate", json={"name": model, "input": [[6, 0.01, 0.05, -1]],
                                                  "config": config})
    assert bad.status_code == 400 and "physical range of Time_s" in bad.json()["error"]["message"], bad.text


def test_the_upload_says_a_range_refusal_in_the_header_s_unit(client):
    # a time in minutes below zero had been described in a temperature's terms ("... degC, where a micro
    # ball bearing's test lies between -4.552 and 3.333 min"); hand: -1 min is -60 s
    text = "balls,load_N,speed_m_s,time [min],mu_measured\n" + "".join(
        f"{4 + 2 * (i % 3)},{0.005 + 0.001 * i},{0.02 + 0.005 * i},{i - 1},0.01{i % 7}\n" for i in range(16))
    for url in ("/v1/calibrations/csv/intake", "/v1/calibrations/csv?fit_parameters=mu_pivot"):
        response = client.post(url, content=text, headers={"content-type": "text/csv"})
        assert response.status_code == 422, response.text
        assert "time [min] runs -1 to 14 min (time_s runs -60 to 840 [s]), outside its physical range" \
            in response.text and "degC" not in response.text, response.text
