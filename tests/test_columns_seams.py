"""Issue 32, item 1: one column registry at every door (units, spellings, slips), through the API."""

from __future__ import annotations

import json

import numpy as np
import pytest
from jobs_helper import job_result, wait_job
from labs_helper import lab_header_rows

from microbearing.calibrate.experiments import candidate_points
from microbearing.calibrate.tabular import read_csv
from microbearing.optimize.robust import Envelope
from microbearing.service.cli import main

PROBLEM = "application/problem+json"


@pytest.fixture(scope="module")
def calibration(client) -> dict:
    response = client.post("/v1/calibrations", json={"data": lab_header_rows(),
                                                     "fit_parameters": ["mu_pivot"], "folds": 3})
    result = job_result(client, response, timeout_s=300, interval_s=0.1)
    # the upload read the lab's headers as SI columns: the fraction and kelvin
    conditions = result["model"]["conditions"]
    assert {"relative_humidity", "temp_K"} <= set(conditions), conditions
    return result


def _point(model: str, conditions: dict) -> dict:
    return {"balls": 4, "load_N": 0.01, "speed_m_s": 0.05, "model": model, "conditions": conditions}


def _problem(response, pointer: str) -> str:
    assert response.status_code == 422, response.text
    assert response.headers["content-type"] == PROBLEM
    problem = response.json()
    assert pointer in [e.get("pointer") for e in problem["errors"]], problem
    return " ".join(e["detail"] for e in problem["errors"])


def test_percent_humidity_at_prediction_is_refused_as_the_upload_refuses_it(client, calibration):
    model = calibration["model_id"]
    point = _point(model, {"relative_humidity": 50, "temp_K": 300})
    detail = _problem(client.post("/v1/friction", json=point), "/conditions/relative_humidity")
    assert "look like percent" in detail and "relative humidity [%]" in detail, detail
    batch = {"points": {"balls": 4, "load_N": [0.01, 0.02], "speed_m_s": 0.05}, "model": model,
             "conditions": {"relative_humidity": [0.5, 50.0], "temp_K": 300.0}}
    detail = _problem(client.post("/v1/friction/batch", json=batch), "/conditions/relative_humidity")
    assert "look like percent" in detail
    # the upload's own rule: the same values as a data column are refused with the same words
    rows = [{("relative_humidity" if key == "relative humidity [%]" else key): value
             for key, value in row.items()} for row in lab_header_rows()]
    response = client.post("/v1/calibrations", json={"data": rows, "fit_parameters": ["mu_pivot"]})
    assert response.status_code == 422 and "look like percent" in response.text, response.text


def test_the_upload_s_headers_and_other_units_are_converted_at_prediction(client, calibration):
    model = calibration["model_id"]
    reference = client.post("/v1/friction", json=_point(model, {"relative_humidity": 0.5, "temp_K": 303.15}))
    assert reference.status_code == 200, reference.text
    expected = reference.json()
    assert expected["in_domain"] is True
    # 50 % is 0.5; 86 degF, 30 degC and 303.15 K are one temperature
    for conditions in ({"relative humidity [%]": 50, "temp_F": 86.0},
                       {"relative_humidity_pct": 50, "temperature [degC]": 30.0},
                       {"relative_humidity [%]": 50, "temp_C": 30.0}):
        answer = client.post("/v1/friction", json=_point(model, conditions))
        assert answer.status_code == 200, (conditions, answer.text)
        for name in ("mu", "mu_lower", "mu_upper", "in_domain"):
            assert answer.json()[name] == pytest.approx(expected[name], rel=1e-9), (conditions, name)
    # a temperature outside the data (5 degC = 41 degF) is flagged the same whichever unit says it
    cold = [client.post("/v1/friction", json=_point(model, {"relative_humidity": 0.5, **t})).json()
            for t in ({"temp_K": 278.15}, {"temp_F": 41.0}, {"temperature_C": 5.0})]
    assert [c["in_domain"] for c in cold] == [False] * 3, cold
    batch = {"points": {"balls": 4, "load_N": [0.01, 0.02], "speed_m_s": 0.05}, "model": model,
             "conditions": {"relative humidity [%]": [50.0, 60.0], "temp_F": 86.0}}
    by_key = client.post("/v1/friction/batch", json=batch)
    batch["conditions"] = {"relative_humidity": [0.5, 0.6], "temp_K": 303.15}
    by_name = client.post("/v1/friction/batch", json=batch)
    assert by_key.status_code == by_name.status_code == 200, by_key.text
    np.testing.assert_allclose(by_key.json()["mu_upper"], by_name.json()["mu_upper"], rtol=1e-9)


def test_an_unknown_condition_lists_the_columns_and_the_spellings(client, calibration):
    detail = _problem(client.post("/v1/friction", json=_point(calibration["model_id"], {
        "relative_humidity": 0.5, "temp_K": 300.0, "humidity_typo": 0.5})), "/conditions/humidity_typo")
    assert "relative_humidity" in detail and "temp_K" in detail and "speed [mm/s]" in detail, detail


@pytest.mark.parametrize(("header", "value", "name", "si"), [
    ("temp_F", 212.0, "temp_K", 373.15),
    ("temperature_F", 32.0, "temperature_K", 273.15),
    ("temperature [degF]", 212.0, "temperature_K", 373.15),
    ("temp_C", 25.0, "temp_C", 25.0),       # read in degC by the terms: stays
    ("temp_K", 300.0, "temp_K", 300.0),
])
def test_a_temperature_name_is_never_read_in_another_unit(header, value, name, si):
    dataset, intake = read_csv(f"balls,load_N,speed_m_s,{header},mu_measured\n4,0.01,0.05,{value},0.01\n"
                               .replace(f",{header},", f",\"{header}\","))
    assert intake.to_dict()["columns"][header] == name
    assert float(dataset.conditions[name][0]) == pytest.approx(si, rel=1e-12)


# --- unit slips of physics inputs: the upload refuses, the API and the CLI answer and warn alike ---------
def test_a_speed_that_looks_like_mm_s_is_warned_by_the_api_and_the_cli_in_the_upload_s_words(
        client, tmp_path, capsys):
    slow = client.post("/v1/friction", json={"balls": 4, "load_N": 0.01, "speed_m_s": 0.05}).json()
    assert "input_warnings" not in slow
    fast = client.post("/v1/friction", json={"balls": 4, "load_N": 0.01, "speed_m_s": 50.0})
    assert fast.status_code == 200, fast.text
    warnings = fast.json()["input_warnings"]
    assert len(warnings) == 1 and "look like mm/s" in warnings[0] and warnings[0].startswith("speed_m_s")
    batch = client.post("/v1/friction/batch", json={"points": {"balls": 4, "load_N": 0.01,
                                                               "speed_m_s": [0.05, 50.0]}, "outputs": ["mu"]})
    batch_warnings = batch.json()["input_warnings"]
    assert len(batch_warnings) == 1 and batch_warnings[0].startswith("speed_m_s runs 0.05 to 50 m/s")
    assert "look like mm/s" in batch_warnings[0]
    assert batch.json()["mu"] == pytest.approx([slow["mu"], fast.json()["mu"]], rel=1e-12)
    # the upload refuses the same value with the same words
    rows = [{"balls": 4, "load_N": 0.01, "speed_m_s": v, "mu_measured": 0.01} for v in (0.05, 50.0)]
    refused = client.post("/v1/calibrations", json={"data": rows, "fit_parameters": ["mu_pivot"]})
    assert refused.status_code == 422 and "look like mm/s" in refused.text
    out = tmp_path / "point.json"
    assert main(["evaluate", "balls=4", "load_N=0.01", "speed_m_s=50", "-o", str(out)]) == 0
    answer = json.loads(out.read_text())
    assert answer["input_warnings"] == warnings and answer["mu"] == fast.json()["mu"]
    assert "look like mm/s" in capsys.readouterr().err
    # an optimization warns alike (a range's every value judged), and not when the speed looks right
    design = {"bounds": {"balls": [4, 6], "groove_angle_deg": [45, 60], "load_N": [0.005, 0.02]}}
    ranged = client.post("/v1/optimizations", json={**design, "speed_m_s": [0.05, 50.0]})
    assert ranged.status_code == 200, ranged.text
    assert ranged.json()["input_warnings"] == batch_warnings
    right = client.post("/v1/optimizations", json={**design, "speed_m_s": 0.05}).json()
    assert right.get("input_warnings") is None


def test_the_cli_takes_names_with_units_as_the_upload_reads_them(client, tmp_path):
    out = tmp_path / "point.json"
    assert main(["evaluate", "balls=4", "load [mN]=10", "speed_mm_s=50", "-o", str(out)]) == 0
    expected = client.post("/v1/friction", json={"balls": 4, "load_N": 0.01, "speed_m_s": 0.05}).json()
    assert json.loads(out.read_text())["mu"] == pytest.approx(expected["mu"], rel=1e-12)
    table = tmp_path / "points.csv"
    table.write_text("balls,speed [mm/s]\n4,50\n4,100\n")
    assert main(["evaluate", "load_N=0.01", "--csv", str(table), "-o", str(tmp_path / "out.csv"),
                 "--outputs", "mu"]) == 0
    lines = (tmp_path / "out.csv").read_text().splitlines()
    # the answer speaks the file's header and unit: 50 mm/s as typed
    assert lines[0].split(",")[:2] == ["balls", "speed [mm/s]"] and float(lines[1].split(",")[1]) == 50.0
    assert float(lines[1].split(",")[-1]) == pytest.approx(expected["mu"], rel=1e-12)
    assert main(["evaluate", "balls=4", "load_N=0.01", "sped=5"]) != 0


# --- a range reads the same in every route ---------------------------------------------------------------
def test_a_pair_is_a_range_and_a_set_is_spelled_as_one_in_experiment_spaces(client):
    ranged = candidate_points({"balls": [4, 8], "load_N": [0.002, 0.02]})
    assert sorted(set(ranged["balls"])) == [4, 5, 6, 7, 8]             # every whole count in the range
    assert len(set(ranged["load_N"])) > 2
    assert min(ranged["load_N"]) == pytest.approx(0.002) and max(ranged["load_N"]) == pytest.approx(0.02)
    as_object = candidate_points({"balls": {"low": 4, "high": 8}, "load_N": {"low": 0.002, "high": 0.02}})
    assert {k: v.tolist() for k, v in as_object.items()} == {k: v.tolist() for k, v in ranged.items()}
    chosen = candidate_points({"balls": {"values": [4, 8]}, "load_N": {"values": [0.002, 0.02]}})
    assert sorted(set(chosen["balls"])) == [4, 8] and sorted(set(chosen["load_N"])) == [0.002, 0.02]
    # the same JSON is a range in an optimization's envelope
    envelope = Envelope(speed_m_s={"low": 0.01, "high": 0.1}, conditions={"relative_humidity": [0.3, 0.7]})
    assert envelope.speed_m_s == (0.01, 0.1) and envelope.conditions == {"relative_humidity": (0.3, 0.7)}
    with pytest.raises(ValueError, match="no worst case over a range"):
        Envelope(speed_m_s=0.05, conditions={"relative_humidity": {"values": [0.3, 0.7]}})
    # a plain list of three numbers is refused with both spellings
    body = {"runs": 4, "fit_parameters": ["mu_pivot"],
            "space": {"balls": [4, 8], "load_N": [0.001, 0.01, 0.05], "speed_m_s": [0.05]}}
    detail = _problem(client.post("/v1/experiments", json=body), "/space/load_N")
    assert "[low, high]" in detail and '{"values": [' in detail, detail
    # an optimization's conditions refuse a set and a longer list in words, at the condition's key
    design = {"bounds": {"balls": [4, 6], "groove_angle_deg": [50, 55], "load_N": [0.008, 0.012]},
              "speed_m_s": 0.05, "model": "calibrated:0123456789abcdef0123456789abcdef"}
    for value, words in (({"values": [0.3, 0.7]}, "a set of values is no envelope"),
                         ([0.3, 0.5, 0.7], "a list of 3 values is ambiguous")):
        answer = client.post("/v1/optimizations", json={**design, "conditions": {"RH": value}})
        assert words in _problem(answer, "/conditions/RH"), answer.text


def test_um_bridge_reads_fixed_inputs_with_units_as_the_upload_does(client, calibration):
    def evaluate(name: str, fixed: dict, inputs=("balls", "load_N")) -> dict:
        return client.post("/umbridge/Evaluate", json={"name": name, "input": [[4, 0.01]], "config": {
            "inputs": list(inputs), "fixed": fixed}})

    by_unit, by_name = evaluate("physics", {"speed [mm/s]": 50}), evaluate("physics", {"speed_m_s": 0.05})
    assert by_unit.status_code == by_name.status_code == 200, by_unit.text
    assert by_unit.json()["output"] == by_name.json()["output"]
    model = calibration["model_id"]
    si = evaluate(model, {"speed_m_s": 0.05, "relative_humidity": 0.5})   # UM-Bridge reads the terms' columns
    lab = evaluate(model, {"speed_mm_s": 50, "relative humidity [%]": 50})
    assert si.status_code == lab.status_code == 200, lab.text
    assert lab.json()["output"][0] == pytest.approx(si.json()["output"][0], rel=1e-9)
    slipped = evaluate(model, {"speed_m_s": 0.05, "relative_humidity": 50})
    assert slipped.status_code == 400 and "look like percent" in slipped.text, slipped.text
    # text or a flag for a number is refused in words (it was a 500), naming the key as sent
    for value in ("x", "60", True):
        refused = evaluate(model, {"speed_m_s": 0.05, "RH [%]": value})
        message = refused.json()["error"]["message"]
        assert refused.status_code == 400, message
        assert message.startswith("config.fixed.RH [%]: must be a number"), message
    flag = evaluate("physics", {"speed_m_s": 0.05, "balls_touching": True})
    assert flag.status_code == 200, flag.text
    # a refusal names the key as it was sent, not the column it was read as
    for fixed, key in (({"speed_m_s": 0.05, "RH [%]": 5000}, "config.fixed.RH [%]"),
                       ({"speed [mm/s]": -50, "relative_humidity": 0.5}, "config.fixed.speed [mm/s]")):
        refused = evaluate(model, fixed)
        assert refused.status_code == 400 and refused.json()["error"]["message"].startswith(key), refused.text
    # and gives the value as typed beside the one judged (it gave -0.05 alone for -50 mm/s)
    refused = evaluate("physics", {"speed [mm/s]": -50})
    assert refused.json()["error"]["message"].endswith("got -0.05 (sent as speed [mm/s]: -50)"), refused.text


def test_an_experiment_space_may_name_columns_with_units():
    from microbearing.service.schemas.experiments import FirstExperimentsRequest

    lab = FirstExperimentsRequest.model_validate({
        "runs": 4, "fit_parameters": ["mu_pivot"], "fixed": {"speed [mm/s]": 50},
        "space": {"balls": {"values": [4, 8]}, "load [mN]": {"low": 1, "high": 50, "spacing": "log"}}})
    # kept as sent, for the route to read against the model and to name in a refusal (the same plan as
    # from SI keys: tests/test_experiments_api.py, test_a_first_design_reads_the_upload_s_spellings_...)
    assert lab.model_dump()["fixed"] == {"speed [mm/s]": 50.0}
    assert lab.model_dump()["space"]["load [mN]"] == {"low": 1.0, "high": 50.0, "spacing": "log"}
    # the keys are checked at once: a unit of another kind, or two keys of one input
    for space in ({"balls": [4, 8], "load [mm]": [1, 50]},
                  {"balls": [4, 8], "load [mN]": [1, 50], "load_N": [0.1, 1]}):
        with pytest.raises(ValueError, match="load"):
            FirstExperimentsRequest.model_validate({"runs": 4, "fit_parameters": ["mu_pivot"],
                                                    "space": space})


@pytest.mark.parametrize(("sent", "value", "si", "unit"), [
    ("speed [mm/s]", 50.0, 0.05, "mm/s"), ("load_mN", 8.8, 0.0088, "mN"), ("temp_F", 86.0, 303.15, "degF"),
    ("relative humidity [%]", 45.0, 0.45, "%"), ("load [g]", 0.9, 0.9e-3 * 9.80665, "g"),
])
def test_a_column_reads_back_in_the_unit_it_was_sent_in(sent, value, si, unit):
    from microbearing.physics.columns import read_name

    reading = read_name(sent)
    assert reading.convert(value) == pytest.approx(si, rel=1e-12)
    assert reading.sent_value(si) == pytest.approx(value, rel=1e-12) and reading.sent_unit == unit


def test_an_optimization_envelope_reads_the_upload_s_names_and_both_range_spellings(client, calibration):
    # The keys are read against the calibration's own columns (relative_humidity, temp_K): the lab's names
    # and units give the same job as the SI ones, and the job reads what the submit checked.
    base = {"bounds": {"balls": [4, 6], "groove_angle_deg": [50, 55], "load_N": [0.008, 0.012]},
            "speed_m_s": 0.05, "model": calibration["model_id"], "time_limit_s": 20}
    results = []
    for conditions in ({"relative humidity [%]": {"low": 30, "high": 70}, "temp_F": [68.0, 104.0]},
                       {"relative_humidity": [0.3, 0.7], "temp_K": [293.15, 313.15]}):
        response = client.post("/v1/optimizations", json={**base, "conditions": conditions})
        assert response.status_code == 202, response.text
        job = wait_job(client, response)
        assert job["status"] == "succeeded", job
        results.append(client.get(job["result_url"]).json())
    lab, si = results
    assert lab["envelope"]["conditions"].keys() == {"relative_humidity", "temp_K"}
    for name, ends in si["envelope"]["conditions"].items():
        assert lab["envelope"]["conditions"][name] == pytest.approx(ends, rel=1e-12)
    assert lab["worst_case"]["mu"] == pytest.approx(si["worst_case"]["mu"], rel=1e-9)
    assert lab["worst_case"]["conditions"] == pytest.approx(si["worst_case"]["conditions"], rel=1e-9)


def test_conditions_are_read_against_the_model_s_own_columns_at_every_door(client, calibration):
    # The calibration's columns are relative_humidity and temp_K (its upload said relative humidity [%]
    # and temp_F). Other spellings of their quantities, with a unit, read the same at prediction.
    model = calibration["model_id"]

    def mu(conditions: dict) -> float:
        response = client.post("/v1/friction", json=_point(model, conditions))
        assert response.status_code == 200, response.text
        return response.json()["mu"]

    reference = mu({"relative_humidity": 0.5, "temp_K": 300.15})
    assert mu({"RH [%]": 50, "temp_K": 300.15}) == pytest.approx(reference, rel=1e-12)
    assert mu({"humidity_pct": 50, "temp_degC": 27.0}) == pytest.approx(reference, rel=1e-12)
    # Rankine (degR = K x 9/5) read once, by a suffix as by brackets: 540.27 degR is 300.15 K
    assert mu({"relative_humidity": 0.5, "temp_R": 540.27}) == pytest.approx(reference, rel=1e-9)
    assert mu({"relative_humidity": 0.5, "temperature [degR]": 540.27}) == pytest.approx(reference, rel=1e-9)


def test_a_condition_outside_its_law_s_domain_is_named_as_sent(client, calibration):
    # 100 % is the fraction 1, outside the domain [0, 1) of the Kelvin menisci: refused at the key sent
    model = calibration["model_id"]
    detail = _problem(client.post("/v1/friction", json=_point(model, {"RH [%]": 100, "temp_K": 300})),
                      "/conditions/RH [%]")
    assert "[0, 1)" in detail, detail
    batch = {"points": {"balls": 4, "load_N": [0.01, 0.02], "speed_m_s": 0.05}, "model": model,
             "conditions": {"RH [%]": [50.0, 100.0], "temp_K": 300.0}}
    assert "[0, 1)" in _problem(client.post("/v1/friction/batch", json=batch), "/conditions/RH [%]")
    # the problem's summary says the same; UM-Bridge names the input or fixed key as sent
    summary = client.post("/v1/friction", json=_point(model, {"RH [%]": 100, "temp_K": 300})).json()["detail"]
    assert "/conditions/RH [%]" in summary and "sent as RH [%]: 100" in summary, summary
    # temp_K, a column of the data no term reads, is taken at UM-Bridge as at /v1/friction
    fixed = {"speed_m_s": 0.05, "temp_K": 300}
    for config, field in (({"inputs": ["balls", "load_N", "RH [%]"], "fixed": fixed}, "input[*][2] (RH [%])"),
                          ({"inputs": ["balls", "load_N"], "fixed": {**fixed, "RH [%]": 100}},
                           "config.fixed.RH [%]")):
        vector = [4, 0.01, 100] if len(config["inputs"]) == 3 else [4, 0.01]
        answer = client.post("/umbridge/Evaluate", json={"name": model, "input": [vector], "config": config})
        assert answer.status_code == 400, answer.text
        message = answer.json()["error"]["message"]
        assert message.startswith(field) and "[0, 1)" in message and "sent as RH [%]" in message, message


def test_a_dry_run_is_the_menisci_law_s_edge(client, calibration):
    # before: RH 0 % was refused as outside (0, 1) though 1/ln(1/h) -> 0 there (a dry run condenses no
    # meniscus) and 1e-6 % was answered: the law now holds at its edge, where it adds nothing
    model = calibration["model_id"]
    menisci = next(e for e in calibration["effects"] if e["name"] == "humidity_meniscus")
    assert menisci, calibration["effects"]
    answers = [client.post("/v1/friction", json=_point(model, {"RH [%]": h, "temp_K": 300})) for h in
               (0.0, 1e-9, 1e-20)]
    assert [a.status_code for a in answers] == [200, 200, 200], answers[0].text
    dry, a, b = (answer.json()["mu"] for answer in answers)
    # the term is p / ln(1/h) (h the fraction): its increments over the dry run at h = 1e-11 and 1e-22 are in
    # the ratio ln(1e22) / ln(1e11) = 2 exactly when the dry run is the law's limit, nothing added
    assert (a - dry) / (b - dry) == pytest.approx(2.0, rel=1e-6)
    batch = client.post("/v1/friction/batch", json={
        "points": {"balls": 4, "load_N": 0.01, "speed_m_s": 0.05}, "model": model,
        "conditions": {"RH [%]": [0.0, 1e-9], "temp_K": 300.0}})
    assert batch.status_code == 200, batch.text
    assert batch.json()["mu"] == pytest.approx([dry, a], rel=1e-12)


def test_a_value_is_judged_for_a_unit_slip_in_the_unit_its_key_states(client, calibration):
    # 300 under a degC name is kelvin by the upload's rule, though 300 degC (573 K) is no slip of the
    # model's kelvin column; the refusal names the key as sent.
    model = calibration["model_id"]
    point = _point(model, {"relative_humidity": 0.5, "temperature_C": 300})
    detail = _problem(client.post("/v1/friction", json=point), "/conditions/temperature_C")
    assert "look like kelvin" in detail, detail
    from microbearing.physics.columns import match_column
    from microbearing.physics.slips import read_slip

    assert "look like degC" in read_slip(match_column("temperature_K", ["temp_degC"]), [27.0])
    assert read_slip(match_column("temperature_K", ["temp_degC"]), [300.0]) is None


def test_every_value_of_a_range_is_judged_at_submit(client, calibration):
    # A slip at the high end of a range is refused at submit (it was read at its low end only), in an
    # optimization's envelope and in an experiment space alike.
    model = calibration["model_id"]
    body = {"bounds": {"balls": [4, 6], "groove_angle_deg": [50, 55], "load_N": [0.008, 0.012]},
            "speed_m_s": 0.05, "model": model,
            "conditions": {"relative_humidity": [0.3, 50.0], "temp_K": 300}}
    assert "look like percent" in _problem(client.post("/v1/optimizations", json=body),
                                           "/conditions/relative_humidity")
    # a range's ends in the wrong order, and a unit of another kind, at the key as sent
    upside_down = {**body, "conditions": {"RH [%]": [80, 40], "temp_K": 300}}
    detail = _problem(client.post("/v1/optimizations", json=upside_down), "/conditions/RH [%]")
    assert "low must not exceed high" in detail and "(sent as RH [%]: [80, 40]" in detail, detail
    wrong_kind = _point(model, {"RH [mm]": 600, "temp_K": 300})
    assert "whose unit is [%] or [1], not 'mm'" in _problem(client.post("/v1/friction", json=wrong_kind),
                                                "/conditions/RH [mm]")
    space = {"balls": [4, 8], "load_N": [0.002, 0.02], "speed_m_s": [0.05], "relative_humidity": [0.3, 50.0],
             "temp_K": [300.0]}
    response = client.post(f"/v1/calibrations/{calibration['model_id'].split(':')[1]}/next-experiments",
                           json={"runs": 4, "goal": "parameters", "space": space})
    assert "look like percent" in _problem(response, "/space/relative_humidity")


def test_an_experiment_request_s_refusals_name_the_keys_as_sent(client, calibration):
    route = f"/v1/calibrations/{calibration['model_id'].split(':')[1]}/next-experiments"
    space = {"balls": [4, 8], "load_N": [0.002, 0.02], "speed_m_s": [0.05], "relative_humidity": [0.3, 0.7],
             "temp_K": [300.0]}
    unknown = client.post(route, json={"runs": 4, "goal": "parameters",
                                       "space": {**space, "pressure [kPa]": [90, 110]}})
    assert "not a physics input nor a condition" in _problem(unknown, "/space/pressure [kPa]")
    clash = client.post(route, json={"runs": 4, "goal": "parameters", "space": space,
                                     "fixed": {"RH [%]": 50}})
    assert "also a column of the space" in _problem(clash, "/fixed/RH [%]")


def test_an_experiment_space_reads_conditions_against_the_model_s_columns(client, calibration):
    space = {"balls": [4, 8], "load_N": [0.002, 0.02], "speed_m_s": [0.05], "RH [%]": [25, 75],
             "temp_degC": {"values": [20.0, 40.0]}}
    response = client.post(f"/v1/calibrations/{calibration['model_id'].split(':')[1]}/next-experiments",
                           json={"runs": 6, "goal": "parameters", "space": space})
    assert response.status_code == 202, response.text
    job = wait_job(client, response)
    assert job["status"] == "succeeded", job
    runs = client.get(job["result_url"]).json()["runs"]
    humidity = [run["conditions"]["relative_humidity"] for run in runs]
    assert min(humidity) >= 0.25 - 1e-12 and max(humidity) <= 0.75 + 1e-12, humidity
    assert {round(run["conditions"]["temp_K"], 9) for run in runs} <= {293.15, 313.15}, runs
    # and each run says its settings under the keys as sent, in their units: what a technician sets
    for run in runs:
        assert set(run["as_sent"]) == set(space), run
        assert run["as_sent"]["RH [%]"] == pytest.approx(100 * run["conditions"]["relative_humidity"])
        assert run["as_sent"]["temp_degC"] == pytest.approx(run["conditions"]["temp_K"] - 273.15)
        assert run["as_sent"]["load_N"] == run["load_N"] and run["as_sent"]["balls"] == run["balls"]


def test_an_experiment_s_runs_speak_the_units_of_the_space_s_keys(client, calibration):
    # before: a space in the upload's names ('load [mN]', 'relative humidity [%]') got runs only as load_N in
    # N and the humidity as a fraction, which a technician could set as 0.85 %RH
    space = {"balls": [4, 8], "load [mN]": [2, 20], "speed [mm/s]": [50], "relative humidity [%]": [25, 75],
             "temp_F": [68, 104]}
    response = client.post(f"/v1/calibrations/{calibration['model_id'].split(':')[1]}/next-experiments",
                           json={"runs": 4, "goal": "parameters", "space": space,
                                 "fixed": {"groove angle [rad]": 0.95}})
    job = wait_job(client, response)
    assert job["status"] == "succeeded", job
    for run in client.get(job["result_url"]).json()["runs"]:
        sent = run["as_sent"]
        assert sent["load [mN]"] == pytest.approx(1000 * run["load_N"]) and 2 <= sent["load [mN]"] <= 20
        assert sent["speed [mm/s]"] == pytest.approx(1000 * run["speed_m_s"]) == pytest.approx(50)
        assert 25 <= sent["relative humidity [%]"] <= 75
        assert sent["relative humidity [%]"] == pytest.approx(100 * run["conditions"]["relative_humidity"])
        assert 68 <= sent["temp_F"] <= 104
        assert sent["groove angle [rad]"] == pytest.approx(0.95)
        assert run["inputs"]["groove_angle_deg"] == pytest.approx(0.95 * 180 / np.pi)


def test_t_with_a_temperature_unit_is_the_temperature():
    from microbearing.physics.columns import read_name
    from microbearing.physics.slips import slip

    assert read_name("T [K]").name == "temperature_K" and read_name("T [degC]").name == "temperature_K"
    assert "look like degC" in slip("T_K", [27.0])


# --- physics inputs under names with units, at every door ------------------------------------------------
def test_physics_inputs_may_be_named_with_their_units_at_friction_and_batch(client, calibration):
    si = client.post("/v1/friction", json={"balls": 4, "load_N": 0.01, "speed_m_s": 0.05})
    lab = client.post("/v1/friction", json={"balls": 4, "load [mN]": 10, "speed_mm_s": 50})
    assert si.status_code == lab.status_code == 200, lab.text
    assert lab.json() == si.json()
    # a slider mass in g is read as its weight, as the upload reads it
    weight = client.post("/v1/friction", json={"balls": 4, "load [g]": 1.0, "speed_m_s": 0.05}).json()
    by_hand = client.post("/v1/friction", json={"balls": 4, "load_N": 1e-3 * 9.80665, "speed_m_s": 0.05})
    assert weight["mu"] == pytest.approx(by_hand.json()["mu"], rel=1e-12)
    batch_si = client.post("/v1/friction/batch", json={
        "points": {"balls": 4, "load_N": [0.01, 0.02], "speed_m_s": 0.05}, "outputs": ["mu"]})
    batch_lab = client.post("/v1/friction/batch", json={
        "points": {"balls": 4, "load [mN]": [10, 20], "speed [mm/s]": 50}, "outputs": ["mu"]})
    assert batch_lab.status_code == 200, batch_lab.text
    assert batch_lab.json()["mu"] == pytest.approx(batch_si.json()["mu"], rel=1e-12)
    # a calibrated model: inputs and conditions in the upload's units answer as in SI
    model = calibration["model_id"]
    reference = client.post("/v1/friction", json=_point(model, {"relative_humidity": 0.5, "temp_K": 303.15}))
    asked = client.post("/v1/friction", json={"balls": 4, "load [mN]": 10, "speed_mm_s": 50, "model": model,
                                              "conditions": {"relative humidity [%]": 50, "temp_F": 86.0}})
    assert asked.status_code == 200, asked.text
    for name in ("mu", "mu_lower", "mu_upper"):
        assert asked.json()[name] == pytest.approx(reference.json()[name], rel=1e-9)
    # a speed in mm/s named so is no unit slip; the same number as speed_m_s is warned
    assert "input_warnings" not in client.post("/v1/friction", json={
        "balls": 4, "load_N": 0.01, "speed [mm/s]": 50}).json()


@pytest.mark.parametrize(("body", "pointer", "words"), [
    ({"balls": 4, "load_N": 0.01, "speed_m_s": 0.05, "sped_m_s": 1}, "/sped_m_s", "Extra"),
    # a condition is not a physics input: under conditions only, never read as something else
    ({"balls": 4, "load_N": 0.01, "speed_m_s": 0.05, "temp_F": 86}, "/temp_F", "Extra"),
    # a unit of another kind than the input's
    ({"balls": 4, "load_N": 0.01, "speed_m_s": 0.05, "speed [mm]": 50}, "/speed [mm]", "Extra"),
])
def test_a_name_no_door_reads_is_refused_naming_it(client, body, pointer, words):
    response = client.post("/v1/friction", json=body)
    assert response.status_code == 422 and response.headers["content-type"] == PROBLEM, response.text
    errors = response.json()["errors"]
    assert any(e.get("pointer") == pointer and words in e["detail"] for e in errors), errors


def test_two_names_of_one_input_are_refused(client):
    for path, body in (("/v1/friction", {"balls": 4, "load_N": 0.01, "load [mN]": 10, "speed_m_s": 0.05}),
                       ("/v1/friction/batch", {"points": {"balls": 4, "load_mN": [10], "load_N": [0.01],
                                                          "speed_m_s": 0.05}})):
        response = client.post(path, json=body)
        assert response.status_code == 422 and response.headers["content-type"] == PROBLEM, response.text
        assert "read as load_N too" in response.text, response.text


def test_um_bridge_varies_inputs_named_with_their_units(client, calibration):
    def call(route: str, inputs: list[str], vector: list[float], **extra) -> dict:
        body = {"name": calibration["model_id"], "input": [vector],
                "config": {"inputs": inputs, "fixed": {"balls": 4}}, **extra}
        response = client.post(f"/umbridge/{route}", json=body)
        assert response.status_code == 200, response.text
        return response.json()

    si_inputs, lab_inputs = ["load_N", "speed_m_s", "relative_humidity"], ["load [mN]", "speed_mm_s",
                                                                           "relative humidity [%]"]
    si, lab = [0.01, 0.05, 0.5], [10.0, 50.0, 50.0]
    assert call("Evaluate", lab_inputs, lab)["output"][0][0] == pytest.approx(
        call("Evaluate", si_inputs, si)["output"][0][0], rel=1e-12)
    # d mu / d (load in mN) = d mu / d load_N x 1e-3 (chain rule), and so on
    wrt = {"outWrt": 0, "inWrt": 0, "sens": [1.0]}
    gradient_si = np.array(call("Gradient", si_inputs, si, **wrt)["output"])
    gradient_lab = np.array(call("Gradient", lab_inputs, lab, **wrt)["output"])
    np.testing.assert_allclose(gradient_lab, gradient_si * [1e-3, 1e-3, 1e-2], rtol=1e-9)
    assert np.all(gradient_si != 0)
    # a varied condition is judged for a unit slip as config.fixed is: percent under a fraction's name
    slipped = client.post("/umbridge/Evaluate", json={
        "name": calibration["model_id"], "input": [[*si[:2], 50.0]],
        "config": {"inputs": si_inputs, "fixed": {"balls": 4}}})
    assert slipped.status_code == 400 and "look like percent" in slipped.text, slipped.text


def test_the_report_s_sentences_give_a_column_s_values_in_the_upload_s_unit():
    from microbearing.calibrate import Dataset
    from microbearing.calibrate.prose import in_sent_units
    from microbearing.calibrate.tabular import read_rows

    rows = [{"balls": 4, "load_N": 0.01, "speed [mm/s]": v, "relative humidity [%]": h, "temp_F": t,
             "mu_measured": 0.01} for v, h, t in ((50.0, 30.0, 68.0), (100.0, 60.0, 86.0))]
    dataset, _ = read_rows(rows)
    dataset = Dataset.from_columns(dataset.to_columns(), dataset.fixed)  # as the job and the store keep it
    where = {"driver": "relative_humidity", "range": [0.3, 0.4], "data_range": [0.3, 0.6]}
    assert in_sent_units(dataset, where) == {"driver": "relative humidity [%]", "range": [30.0, 40.0],
                                             "data_range": [30.0, 60.0]}
    hot = in_sent_units(dataset, {"driver": "temp_K", "data_range": [293.15, 303.15],
                                  "differ": [[293.15, 298.15]]})
    assert hot["driver"] == "temp_F"
    np.testing.assert_allclose(hot["data_range"], [68.0, 86.0], rtol=1e-12)
    np.testing.assert_allclose(hot["differ"], [[68.0, 77.0]], rtol=1e-12)
    # a column sent in its own unit is named and valued as it is
    assert in_sent_units(dataset, {"driver": "load_N", "range": [0.01, 0.01]}) == {
        "driver": "load_N", "range": [0.01, 0.01]}


def test_a_physics_input_named_with_its_own_si_unit_or_another_is_read_at_every_field(client):
    # load [N] is load_N (no conversion, still a rename): it had been refused as an extra input at
    # /v1/friction, though the upload reads it; optimization bounds and fixed values read units too
    si = client.post("/v1/friction", json={"balls": 4, "load_N": 0.01, "speed_m_s": 0.08})
    lab = client.post("/v1/friction", json={"balls": 4, "load [N]": 0.01, "speed [m/s]": 0.08})
    assert si.status_code == lab.status_code == 200, lab.text
    assert lab.json()["mu"] == si.json()["mu"]
    body = {"bounds": {"balls": [4, 12], "groove_angle_deg": [40, 60], "load_N": [0.005, 0.02]},
            "fixed": {"speed_m_s": 0.05}}
    spelled = {"bounds": {"balls": [4, 12], "groove_angle_deg": [40, 60], "load [mN]": [5, 20]},
               "fixed": {"speed_mm_s": 50}}
    results = []
    for request in (body, spelled):
        response = client.post("/v1/optimizations", json=request)  # the physics answers at once
        assert response.status_code == 200, response.text
        results.append(response.json())
    assert results[0]["design"] == results[1]["design"] and results[0]["mu"] == results[1]["mu"]
    # a value out of range is refused at the key as sent (the schema reads it as load_N first)
    # with the value as sent and as read, and the range in the unit sent (1e-9 N is 1e-6 mN)
    detail = _problem(client.post("/v1/friction", json={"balls": 4, "load [mN]": -10, "speed_m_s": 0.08}),
                      "/load [mN]")
    assert "(sent as load [mN]: -10, read as load_N: -0.01; in mN it must be in [1e-06, " in detail, detail
    batch = {"points": {"balls": 4, "load [mN]": [10, -10], "speed_m_s": 0.08}}
    detail = _problem(client.post("/v1/friction/batch", json=batch), "/points/load [mN]/1")
    assert "(sent as load [mN]: -10, read as load_N: -0.01; in mN it must be in [1e-06, " in detail, detail
    # a range's end in the optimizations likewise: 5e7 mm/s is 5e4 m/s, the limit 1e6 mm/s
    ranged = {**spelled, "fixed": {}, "speed [mm/s]": [10, 5e7]}
    detail = _problem(client.post("/v1/optimizations", json=ranged), "/speed [mm~1s]/1")
    assert "(sent as speed [mm/s]: 5e+07, read as speed_m_s: 50000; in mm/s it must be in [0, 1e+06])" \
        in detail, detail
    # two names of one input are refused, naming the key
    both = client.post("/v1/optimizations", json={**body, "fixed": {"speed_m_s": 0.05, "speed_mm_s": 50}})
    assert both.status_code == 422 and "read as speed_m_s too" in both.text, both.text


# --- refusals in the user's words: the sweep of 2026-11-30 (issue 32) -------------------------------------
def test_refusals_name_keys_and_values_as_sent_at_prediction(client, calibration):
    model = calibration["model_id"]
    # lists of unequal length: named by the keys sent, not the model's columns
    batch = {"points": {"balls": [4, 4, 4], "load_N": 0.01, "speed_m_s": 0.05}, "model": model,
             "conditions": {"relative humidity [%]": [50, 50, 50], "temp_F": [86, 86]}}
    detail = _problem(client.post("/v1/friction/batch", json=batch), "/conditions/temp_F")
    assert "has 2 values but relative humidity [%] has 3" in detail, detail
    # a temperature judged in degC says the value as sent first (hand: -500 degF = -295.6 degC)
    detail = _problem(client.post("/v1/friction", json=_point(model, {"relative_humidity": 0.5,
                                                                        "temperature [degF]": -500})),
                      "/conditions/temperature [degF]")
    assert "-500 to -500 degF (-295.6 to -295.6 degC), at or below absolute zero" in detail, detail
    # a humidity whose key states percent is judged in percent, not as a fraction that "looks like percent"
    detail = _problem(client.post("/v1/friction", json=_point(model, {"relative humidity [%]": 120,
                                                                        "temp_K": 303.15})),
                      "/conditions/relative humidity [%]")
    assert "relative humidity [%] runs 120 to 120 %" in detail and "look like percent" not in detail, detail
    # a key's case is not a different column
    upper = client.post("/v1/friction", json=_point(model, {"RELATIVE_HUMIDITY": 0.5, "TEMP_K": 303.15}))
    lower = client.post("/v1/friction", json=_point(model, {"relative_humidity": 0.5, "temp_K": 303.15}))
    assert upper.status_code == 200 and upper.json()["mu"] == lower.json()["mu"], upper.text


def test_an_optimization_names_a_renamed_input_and_never_a_schema_tag(client):
    design = {"balls": [4, 8], "groove_angle_deg": [40, 70]}
    detail = _problem(client.post("/v1/optimizations", json={"bounds": {**design, "load [mN]": [20, 5]},
                                                             "speed_m_s": 0.05}), "/bounds/load [mN]")
    assert "(sent as load [mN]: [20, 5], read as load_N)" in detail, detail
    detail = _problem(client.post("/v1/optimizations", json={"bounds": {**design, "load_N": [0.005, 0.02]},
                                                             "speed [mm/s]": [80, 30]}), "/speed [mm~1s]")
    assert "sent as speed [mm/s]: [80, 30]" in detail, detail
    # a flag for a condition's range: the pointer names the key, not pydantic's ConditionSpan
    response = client.post("/v1/optimizations", json={"bounds": {**design, "load_N": [0.005, 0.02]},
                                                      "speed_m_s": 0.05, "model": "calibrated:" + "0" * 32,
                                                      "conditions": {"RH": True}})
    assert [e["pointer"] for e in response.json()["errors"]] == ["/conditions/RH"], response.text
    assert response.json()["errors"][0]["detail"].startswith("must be a number, a range"), response.text
    # UM-Bridge names both keys of an input given twice
    answer = client.post("/umbridge/Evaluate", json={"name": "physics", "input": [[6, 10, 0.05]], "config": {
        "inputs": ["balls", "load [mN]", "speed_m_s"], "fixed": {"load_N": 0.01}}}).json()
    assert "'load [mN]' and 'load_N' (read as load_N) given twice" in answer["error"]["message"], answer


def test_the_csv_intake_refuses_what_the_calibration_would(client):
    # a humidity fraction column holding percent: the upload refuses it, so does the intake (it said
    # nothing before), in the same words
    text = "balls,load_N,speed_m_s,humidity,mu_measured\n" + "".join(
        f"{4 + 2 * (i % 3)},{0.005 + 0.001 * i},{0.02 + 0.005 * i},{30 + 2 * i},0.0{3 + i % 5}\n"
        for i in range(16))
    headers = {"content-type": "text/csv"}
    intake = client.post("/v1/calibrations/csv/intake", content=text, headers=headers)
    upload = client.post("/v1/calibrations/csv?fit_parameters=mu_pivot", content=text, headers=headers)
    assert intake.status_code == upload.status_code == 422, intake.text
    assert "values look like percent" in intake.text and "values look like percent" in upload.text


def test_a_slip_is_judged_in_the_unit_a_key_states_and_said_as_sent(client, calibration):
    model = calibration["model_id"]
    # -200 degC is 73.15 K: not a kelvin value that "looks like degC" (the K column's rule)
    cold = client.post("/v1/friction", json=_point(model, {"relative_humidity": 0.5, "temp [degC]": -200}))
    assert "look like degC" not in cold.text and "temp_K runs" not in cold.text, cold.text
    # below absolute zero in the unit sent, said in it (not as 0 K "looks like degC")
    detail = _problem(client.post("/v1/friction", json=_point(model, {"relative_humidity": 0.5,
                                                                        "temp [degC]": -300})),
                      "/conditions/temp [degC]")
    assert "temp [degC] runs -300 to -300 degC, at or below absolute zero" in detail, detail
    # text is read unconverted: the refusal says which column, never a converted value it does not have
    detail = _problem(client.post("/v1/friction", json=_point(model, {"relative_humidity": 0.5,
                                                                        "temp [degF]": "86"})),
                      "/conditions/temp [degF]")
    assert "(sent as temp [degF]: '86', read as the column temp_K)" in detail, detail
    # a physics input of a planned run beyond its slip limit, in the unit its key states (1e6 gf = 9807 N)
    route = f"/v1/calibrations/{model.split(':')[1]}/next-experiments"
    space = {"balls": [4, 8], "load_N": [0.002, 0.02], "speed_m_s": [0.05], "relative_humidity": [0.3, 0.7],
             "temp_K": [300.0]}
    run = {"balls": 6, "load (gf)": 1e6, "speed_m_s": 0.05, "relative_humidity": 0.5, "temp_K": 300.0}
    detail = _problem(client.post(route, json={"runs": 2, "goal": "parameters", "space": space,
                                               "planned": [run]}), "/planned/0/load (gf)")
    assert "load (gf) runs 1e+06 to 1e+06 gf (load_N 9807 to 9807 N)" in detail, detail
    envelope = {"balls": [6], "load [lbf]": [-1, 1], "speed_m_s": [0.05], "relative_humidity": [0.4, 0.6],
                "temp_K": [300.0]}
    detail = _problem(client.post(route, json={"runs": 2, "goal": "predict", "space": space,
                                               "envelope": envelope}), "/envelope/load [lbf]")
    assert "not negative" in detail and "look like mN" not in detail, detail


def test_a_first_design_for_parameters_no_run_moves_is_refused_at_submit(client):
    # mu_ball (ball-ball friction) moves no run of this space: the job had been accepted, then failed
    space = {"balls": [4, 8], "load_N": [0.003, 0.03], "speed_m_s": [0.02, 0.15]}
    response = client.post("/v1/experiments", json={"runs": 2, "fit_parameters": ["mu_pivot", "mu_ball"],
                                                    "space": space})
    assert "cannot identify the parameters" in _problem(response, "/space")
    assert "mu_ball" in response.text, response.text
    alone = client.post("/v1/experiments", json={"runs": 2, "fit_parameters": ["mu_pivot"], "space": space})
    assert alone.status_code == 202, alone.text
    assert wait_job(client, alone)["status"] == "succeeded"


def _intake(client, header: str, values: list[float]):
    text = f"balls,load_N,speed_m_s,{header},mu_measured\n" + "".join(
        f"{4 + 2 * (i % 3)},{0.005 + 0.001 * i},{0.02 + 0.005 * i},{v},0.0{3 + i % 5}\n"
        for i, v in enumerate(values))
    return client.post("/v1/calibrations/csv/intake", content=text, headers={"content-type": "text/csv"})


def test_the_upload_judges_a_stated_unit_as_every_other_door(client, calibration):
    # 250 under [degC] looks like kelvin at prediction, so the upload refuses it too (it had stored it,
    # and then its own model could not be asked at its data with the same key); -200 degC (73 K) is a
    # cold test at both (the upload had refused it in kelvin's words)
    hot = [250.0 + i for i in range(16)]
    assert "look like kelvin" in _intake(client, "temp [degC]", hot).text
    point = _point(calibration["model_id"], {"relative_humidity": 0.5, "temp [degC]": 255})
    assert "look like kelvin" in _problem(client.post("/v1/friction", json=point), "/conditions/temp [degC]")
    assert _intake(client, "temp [degC]", [-200.0 + i for i in range(16)]).status_code == 200
    # said as sent, advised in the header's own spelling
    detail = _intake(client, "temp [K]", [100.0 + i for i in range(16)]).text
    assert "temp [K] runs 100 to 115 K" in detail and "send them as 'temp [degC]'" in detail, detail


def test_json_rows_give_quantities_as_numbers_and_every_key_a_name(client):
    rows = [{"balls": 4 + 2 * (i % 3), "load_N": 0.005 + 0.001 * i, "speed_m_s": 0.02 + 0.005 * i,
             "cycles [kcycles]": str(1 + i), "mu_measured": 0.03 + 0.001 * i} for i in range(16)]
    # text under a unit had been stored unconverted (cycles 1..16 for 1000..16000)
    response = client.post("/v1/calibrations", json={"data": rows, "fit_parameters": ["mu_pivot"]})
    assert response.status_code == 422 and "takes a number, not text ('1')" in response.text, response.text
    assert "/data/0/cycles [kcycles]" in response.text
    # an unnamed index column: refused at submit (its job had failed with a 500)
    unnamed = [{"": i, **{k: v for k, v in row.items() if k != "cycles [kcycles]"}}
               for i, row in enumerate(rows)]
    response = client.post("/v1/calibrations", json={"data": unnamed, "fit_parameters": ["mu_pivot"]})
    assert response.status_code == 422 and "every key must name its column" in response.text, response.text


def test_prediction_doors_agree_on_stated_units_lists_and_absolute_zero(client, calibration):
    model = calibration["model_id"]
    # a slip warning says the key and value as typed (2000 mN, not "load_N runs 2 N ... look like mN")
    warned = client.post("/v1/friction", json={"balls": 4, "load [mN]": 2000, "speed_m_s": 0.05}).json()
    assert warned["input_warnings"][0].startswith("load [mN] runs 2000 to 2000 mN (load_N 2 to 2 N)"), warned
    # two units in one key are refused, never converted twice (30 degC had been read again as degF)
    two = _point(model, {"relative_humidity": 0.5, "temp (degF) [degC]": 30})
    detail = _problem(client.post("/v1/friction", json=two), "/conditions/temp (degF) [degC]")
    assert "states two units" in detail, detail
    # absolute zero is no temperature, whatever the unit it is sent in
    for key, value in (("temp [degC]", -273.15), ("temp_K", 0.0)):
        zero = _point(model, {"relative_humidity": 0.5, key: value})
        assert client.post("/v1/friction", json=zero).status_code == 422, (key, value)
    # a list mixing numbers and text gets one sentence at its key, not pydantic's per member
    batch = {"points": {"balls": [4, 4], "load_N": 0.01, "speed_m_s": 0.05}, "model": model,
             "conditions": {"relative_humidity": ["0.5", 0.6], "temp_K": 300.0}}
    detail = _problem(client.post("/v1/friction/batch", json=batch), "/conditions/relative_humidity")
    assert "not both" in detail and "valid string" not in detail, detail
    # [v] is one value at optimizations as in experiment spaces; -200 degC is not re-judged in kelvin
    body = {"bounds": {"balls": [4, 6], "groove_angle_deg": [50, 55], "load_N": [0.008, 0.012]},
            "speed_m_s": 0.05, "model": model, "time_limit_s": 5, "starts": 1}
    for conditions in ({"relative_humidity": [0.5], "temp_K": 300.0},
                       {"relative_humidity": 0.5, "temp [degC]": -200}):
        response = client.post("/v1/optimizations", json={**body, "conditions": conditions})
        assert response.status_code in (200, 202), response.text
        if response.status_code == 202:
            client.delete(response.headers["location"])
    # UM-Bridge names a varied input by its key as sent, unconverted or not
    slipped = client.post("/umbridge/Evaluate", json={
        "name": model, "input": [[0.01, 0.05, 1.5]],
        "config": {"inputs": ["load_N", "speed_m_s", "relative_humidity [1]"], "fixed": {"balls": 4}}})
    assert slipped.status_code == 400 and "(relative_humidity [1])" in slipped.text, slipped.text


def test_experiment_requests_a_job_would_refuse_are_refused_at_submit(client):
    space = {"balls": [4, 8], "load_N": [0.003, 0.03], "speed_m_s": [0.02, 0.15]}
    # an envelope without a column of the space
    envelope = {"balls": [6], "load_N": [0.01]}
    partial = client.post("/v1/experiments", json={"runs": 2, "fit_parameters": ["mu_pivot"], "space": space,
                                                   "goal": "predict", "envelope": envelope})
    assert "give the columns of the space too (speed_m_s)" in _problem(partial, "/envelope")
    # a fitted parameter the space also sets ("widen the space" could not help)
    fitted = ["mu_pivot", "groove_angle_deg"]
    both = client.post("/v1/experiments", json={"runs": 2, "fit_parameters": fitted,
                                                "space": {**space, "groove_angle_deg": [30, 60]}})
    assert "is a fitted parameter" in _problem(both, "/space/groove_angle_deg")


@pytest.mark.parametrize(("key", "replaces", "value", "pointer", "words"), [
    ("load (normal) [mN]", "load_N", 5.0, "/data/0/load (normal) [mN]", "send it as 'load [mN]'"),
    ("temp [degC]", None, 300.0, "/data/0/temp [degC]", "look like kelvin"),
    ("speed [mm/s]", "speed_m_s", 5e4, "/data/0/speed [mm~1s]", "check the values")])
def test_a_json_upload_s_column_problem_points_at_its_key(client, key, replaces, value, pointer, words):
    # a JSON pointer names a key, not a column: the column's key in the first row (before: /data)
    rows = [{"balls": 4, "load_N": 0.005, "speed_m_s": 0.05, "mu_measured": 0.03, key: value + i}
            for i in range(20)]
    for row in rows:
        row.pop(replaces, None)
    response = client.post("/v1/calibrations", json={"data": rows})
    assert response.status_code == 422 and response.headers["content-type"] == PROBLEM, response.text
    (error,) = response.json()["errors"]
    assert error["pointer"] == pointer and words in error["detail"], error


def test_a_range_may_be_spelled_low_high_for_every_range_of_an_optimization(client):
    # before: {low, high} was a range under 'speed [mm/s]' and in conditions, a 422 under speed_m_s and in
    # bounds; a range now reads the same under every name of the route
    listed = {"bounds": {"balls": [4, 8], "groove_angle_deg": [40, 70], "load_N": [0.005, 0.02]},
              "speed_m_s": [0.02, 0.1]}
    spelled = {"bounds": {"balls": {"low": 4, "high": 8}, "groove_angle_deg": {"low": 40, "high": 70},
                          "load_N": {"low": 0.005, "high": 0.02}}, "speed_m_s": {"low": 0.02, "high": 0.1}}
    answers = [client.post("/v1/optimizations", json=body) for body in (listed, spelled)]
    assert [a.status_code for a in answers] == [200, 200], answers[1].text
    assert answers[0].json()["design"] == answers[1].json()["design"]
    assert answers[0].json()["worst_case"] == answers[1].json()["worst_case"]
    for value, words in (({"values": [0.02, 0.1]}, "a set of values is no range"),
                         ({"low": 0.02}, "the keys low and high")):
        detail = _problem(client.post("/v1/optimizations", json={**listed, "speed_m_s": value}), "/speed_m_s")
        assert words in detail, detail
    # under a name with a unit as under its own: a range in the envelope and bounds, and no batch column (a
    # batch had read 'speed [mm/s]': {low: 20, high: 50} as two points)
    in_units = {"bounds": {**spelled["bounds"], "load [mN]": {"low": 5, "high": 20}},
                "speed [mm/s]": {"low": 20, "high": 100}}
    in_units["bounds"].pop("load_N")
    answer = client.post("/v1/optimizations", json=in_units)
    assert answer.status_code == 200 and answer.json()["design"] == answers[0].json()["design"], answer.text
    batch = client.post("/v1/friction/batch", json={"points": {"balls": 4, "load_N": 0.01,
                                                               "speed [mm/s]": {"low": 20, "high": 50}}})
    assert batch.status_code == 422, batch.text
    assert any(e["pointer"] == "/points/speed [mm~1s]" for e in batch.json()["errors"]), batch.text


@pytest.mark.parametrize(("value", "words"), [
    ([40, 60], "not a list of 2: several points go to /v1/friction/batch"),
    ({"low": 40, "high": 60}, "not a range"), (True, "not true"), (None, "not null")])
def test_a_condition_of_one_point_is_one_value_said_in_one_sentence(client, calibration, value, words):
    # before: pydantic's union noise, "Input should be a valid number; Input should be a valid string"
    detail = _problem(client.post("/v1/friction", json=_point(calibration["model_id"], {
        "RH [%]": value, "temp_K": 300})), "/conditions/RH [%]")
    assert words in detail and "valid string" not in detail, detail


def test_a_condition_of_one_point_may_be_a_one_element_list(client, calibration):
    one = [client.post("/v1/friction", json=_point(calibration["model_id"], {"RH [%]": v, "temp_K": 300}))
           for v in (50, [50])]
    assert [a.status_code for a in one] == [200, 200], one[1].text
    assert one[0].json()["mu_upper"] == one[1].json()["mu_upper"]


@pytest.mark.parametrize(("value", "words"), [
    ({"values": []}, "a list of at least one"), ({"values": [0.05], "low": 0.01}, "the key values only"),
    ({"low": 0.01}, "the keys low and high")])
def test_a_space_s_set_or_range_object_is_refused_in_one_sentence(client, value, words):
    # before: {"values": []} answered four errors that contradicted each other (low and high required,
    # values not permitted, at least one item)
    response = client.post("/v1/experiments", json={"runs": 4, "fit_parameters": ["mu_pivot"], "space": {
        "balls": [4, 8], "load_N": [0.005, 0.02], "speed_m_s": value}})
    assert response.status_code == 422, response.text
    (error,) = response.json()["errors"]
    assert error["pointer"] == "/space/speed_m_s" and words in error["detail"], error


def test_a_unit_glued_to_a_temperature_s_name_is_read_in_that_unit_at_every_door(client, calibration):
    # tempF said 86 degF = 303.15 K, as temp_F: it was read as 86 degC (359.15 K) without a word
    model = calibration["model_id"]
    reference = client.post("/v1/friction", json=_point(model, {"relative_humidity": 0.5, "temp_K": 303.15}))
    glued = client.post("/v1/friction", json=_point(model, {"relative_humidity": 0.5, "tempF": 86.0}))
    assert reference.status_code == glued.status_code == 200, glued.text
    assert glued.json()["mu"] == pytest.approx(reference.json()["mu"], rel=1e-9)
    # the upload: a tempF column is converted to kelvin, (F - 32) x 5/9 + 273.15
    dataset, intake = read_csv("balls,load_N,speed_m_s,tempF,mu_measured\n4,0.01,0.05,86,0.01\n")
    assert intake.to_dict()["columns"]["tempF"] == "temp_K"
    assert float(dataset.conditions["temp_K"][0]) == pytest.approx(303.15, rel=1e-12)
    # an optimization's envelope: the range is checked (and read) in degF
    base = {"bounds": {"balls": [4, 6], "groove_angle_deg": [50, 55], "load_N": [0.008, 0.012]},
            "speed_m_s": 0.05, "model": model}
    detail = _problem(client.post("/v1/optimizations", json={
        **base, "conditions": {"relative_humidity": 0.5, "tempF": [-500.0, 90.0]}}), "/conditions/tempF")
    assert "absolute zero" in detail, detail


def test_an_export_s_temperature_c_and_humidity_rh_headers_are_read_at_upload_and_prediction(client,
                                                                                             calibration):
    dataset, intake = read_csv("balls,load_N,speed_m_s,Humidity (%RH),Temperature (F),mu_measured\n"
                               "4,0.01,0.05,45,86,0.01\n")
    columns = intake.to_dict()["columns"]
    assert float(dataset.conditions[columns["Humidity (%RH)"]][0]) == pytest.approx(0.45, rel=1e-12)
    assert float(dataset.conditions[columns["Temperature (F)"]][0]) == pytest.approx(303.15, rel=1e-12)
    model = calibration["model_id"]
    reference = client.post("/v1/friction", json=_point(model, {"relative_humidity": 0.45, "temp_K": 303.15}))
    lab = client.post("/v1/friction", json=_point(model, {"Humidity (%RH)": 45, "Temp (C)": 30.0}))
    assert reference.status_code == lab.status_code == 200, lab.text
    assert lab.json()["mu"] == pytest.approx(reference.json()["mu"], rel=1e-9)


def test_a_slip_of_some_rows_is_pointed_at_the_first_of_them(client):
    # 3 of 30 loads sent in mN beside rows in N (rows 7, 12 and 25): the refusal points at row 7's cell (it
    # pointed at row 0, which is in N); a whole column slipped is pointed at its first row, as before
    rows = [{"balls": 4 + 2 * (i % 3), "load_N": 0.004 + 0.0008 * i, "speed_m_s": 0.02 + 0.004 * i,
             "mu_measured": 0.03 + 0.001 * i} for i in range(30)]
    for i in (7, 12, 25):
        rows[i]["load_N"] *= 1000.0
    response = client.post("/v1/calibrations", json={"data": rows, "fit_parameters": ["mu_pivot"]})
    assert response.status_code == 422, response.text
    errors = response.json()["errors"]
    assert [e["pointer"] for e in errors] == ["/data/7/load_N"], errors
    assert "3 of 30 values lie beyond it" in errors[0]["detail"], errors
    whole = [{**row, "load_N": row["load_N"] * (1.0 if i in (7, 12, 25) else 1000.0)}  # every row in mN
             for i, row in enumerate(rows)]
    whole = client.post("/v1/calibrations", json={"data": whole, "fit_parameters": ["mu_pivot"]})
    errors = whole.json()["errors"]
    assert [e["pointer"] for e in errors] == ["/data/0/load_N"], errors
    assert errors[0]["detail"].startswith("column load_N: ") and "values look like mN" in errors[0]["detail"]


def test_the_report_names_terms_by_the_upload_s_headers(calibration):
    # the upload sent "relative humidity [%]" and "temp_F", stored as relative_humidity and temp_K: the
    # report's words name them as sent (the plots do), its identifiers (label, drivers) stay the columns
    import re

    sent = {"relative_humidity": "relative humidity [%]", "temp_K": "temp_F"}
    effects = calibration["effects"]
    assert effects, calibration["decision"]
    for effect in effects:
        expected = effect["label"]
        for name, header in sent.items():
            expected = re.sub(rf"(?<!\w){name}(?!\w)", header, expected)
        assert effect["label_as_sent"] == expected, effect
    words = [calibration["decision"], calibration["domain"]["summary"],
             *(r["statement"] for r in calibration["rivals"]),
             *(r["label_as_sent"] for r in calibration["rivals"]),
             *(u["statement"] for u in calibration["undecided"])]
    for text in words:
        for name in sent:
            assert not re.search(rf"(?<!\w){name}(?!\w)", text), (name, text)
    assert any(header in text for text in words for header in sent.values()), words


def test_the_report_gives_each_column_s_range_under_its_header_in_its_unit(calibration):
    # what a form pre-fills: 30-80 % under "relative humidity [%]", degF under "temp_F" (by hand:
    # F = (K - 273.15) * 9/5 + 32), a column sent in SI under its own name
    domain, as_sent = calibration["model"]["domain"], calibration["domain"]["as_sent"]
    humidity = as_sent["relative humidity [%]"]
    assert humidity["column"] == "relative_humidity" and humidity["unit"] == "%"
    assert np.allclose(humidity["range"], 100 * np.asarray(domain["relative_humidity"]))
    temperature = as_sent["temp_F"]
    assert temperature["column"] == "temp_K"
    assert np.allclose(temperature["range"], (np.asarray(domain["temp_K"]) - 273.15) * 9 / 5 + 32)
    assert as_sent["load_N"] == {"column": "load_N", "range": domain["load_N"], "unit": "N"}
    assert {entry["column"] for entry in as_sent.values()} == set(domain)


def test_a_domain_warning_speaks_the_key_and_unit_a_condition_was_sent_in(client, calibration):
    # 95 % sent as "relative humidity [%]" beyond the data: the warning names that key and gives the value
    # and the data's range in percent (by hand: 100 x the stored fraction's range); sent as the fraction,
    # it speaks the fraction
    model, domain = calibration["model_id"], calibration["model"]["domain"]
    low, high = (100 * v for v in domain["relative_humidity"])
    temp_F = (domain["temp_K"][0] - 273.15) * 9 / 5 + 32 + 1.0  # inside the data
    single = client.post("/v1/friction", json=_point(model, {"relative humidity [%]": 95, "temp_F": temp_F}))
    batch = client.post("/v1/friction/batch", json={
        "points": {"balls": 4, "load_N": [0.01, 0.02], "speed_m_s": 0.05}, "model": model,
        "conditions": {"relative humidity [%]": 95, "temp_F": temp_F}})
    for answer in (single, batch):
        assert answer.status_code == 200, answer.text
        words = [w for w in answer.json()["domain_warnings"] if "range" in w]
        said = f"relative humidity [%] = 95 is outside the calibration data's range [{low:.6g}, {high:.6g}]:"
        assert words and words[0].startswith(said), words
    fraction = client.post("/v1/friction", json=_point(model, {"relative_humidity": 0.95, "temp_K": 300.0}))
    words = fraction.json()["domain_warnings"]
    assert any(w.startswith("relative_humidity = 0.95 is outside the calibration data's range "
                            f"[{low / 100:.6g}, {high / 100:.6g}]") for w in words), words


def test_an_optimization_s_domain_warning_speaks_the_keys_as_sent(client, calibration):
    # the worst case of a robust design at 95 % RH sent in percent, and a design at one point: the domain
    # warning names the key and gives percent (by hand: 100 x the stored fraction's range)
    low, high = (100 * v for v in calibration["model"]["domain"]["relative_humidity"])
    temp_F = (calibration["model"]["domain"]["temp_K"][0] - 273.15) * 9 / 5 + 32 + 1.0
    said = f"relative humidity [%] = 95 is outside the calibration data's range [{low:.6g}, {high:.6g}]"
    base = {"bounds": {"balls": [4, 6], "groove_angle_deg": [50, 55], "load_N": [0.008, 0.012]},
            "speed_m_s": 0.05, "model": calibration["model_id"], "time_limit_s": 20}
    for conditions in ({"relative humidity [%]": [90, 95], "temp_F": temp_F},
                       {"relative humidity [%]": 95, "temp_F": temp_F}):
        job = wait_job(client, client.post("/v1/optimizations", json={**base, "conditions": conditions}))
        assert job["status"] == "succeeded", job
        result = client.get(job["result_url"]).json()
        warnings = result.get("domain_warnings") or []
        assert any(w.startswith(said) for w in warnings), (conditions, warnings)


def test_a_physics_input_s_domain_warning_speaks_its_key_as_sent(client, calibration):
    # a load of 80 mN sent as "load [mN]", beyond the data's loads: the warning gives mN (by hand: the
    # data's range in N x 1000), as the batch does; sent as load_N it stays in N
    model, domain = calibration["model_id"], calibration["model"]["domain"]
    low, high = (1e3 * v for v in domain["load_N"])
    conditions = {name: sum(domain[name]) / 2 for name in ("relative_humidity", "temp_K")}
    said = f"load [mN] = 80 is outside the calibration data's range [{low:.6g}, {high:.6g}]"
    single = client.post("/v1/friction", json={"balls": 4, "load [mN]": 80, "speed_m_s": 0.05,
                                               "model": model, "conditions": conditions})
    batch = client.post("/v1/friction/batch", json={"points": {"balls": 4, "load [mN]": [80.0, 10.0],
                                                               "speed_m_s": 0.05},
                                                    "model": model, "conditions": conditions})
    for answer in (single, batch):
        assert answer.status_code == 200, answer.text
        words = answer.json()["domain_warnings"]
        assert any(w.startswith(said) for w in words), words
    in_newtons = client.post("/v1/friction", json={"balls": 4, "load_N": 0.08, "speed_m_s": 0.05,
                                                   "model": model, "conditions": conditions}).json()
    assert any(w.startswith("load_N = 0.08 [N] is outside the calibration data's range "
                            f"[{low / 1e3:.6g}, {high / 1e3:.6g}] [N]") for w in in_newtons["domain_warnings"]
               ), in_newtons["domain_warnings"]


# --- issue 32's leftovers: the user's names and units shown back, a bare name never read in another unit -
def _fahrenheit(kelvin: float) -> float:
    return (kelvin - 273.15) * 9 / 5 + 32


def test_an_optimization_s_envelope_and_worst_case_speak_the_keys_as_sent(client, calibration):
    # before: the result gave the envelope and its worst case only as the model's columns in SI
    # (relative_humidity [0.3, 0.6], temp_K [294.26111111111027, 310.9277777777766]), not as sent
    base = {"bounds": {"balls": [4, 6], "groove_angle_deg": [50, 55], "load_N": [0.008, 0.012]},
            "speed_m_s": 0.05, "model": calibration["model_id"], "time_limit_s": 20}
    conditions = {"relative humidity [%]": [30, 60], "temp_F": {"low": 70, "high": 100}}
    job = wait_job(client, client.post("/v1/optimizations", json={**base, "conditions": conditions}))
    assert job["status"] == "succeeded", job
    result = client.get(job["result_url"]).json()
    envelope, worst = result["envelope"], result["worst_case"]
    # the ends as typed, not their round trip through kelvin (69.9999999998)
    assert envelope["as_sent"] == {"speed_m_s": [0.05, 0.05], "relative humidity [%]": [30, 60],
                                   "temp_F": [70, 100]}, envelope
    sent = worst["as_sent"]
    assert set(sent) == {"speed_m_s", "groove_angle_deg", *conditions}, worst  # the angle made: sent in deg
    assert sent["groove_angle_deg"] == worst["groove_angle_deg"]
    # by hand: % = 100 x the fraction, degF = (K - 273.15) x 9/5 + 32
    assert sent["relative humidity [%]"] == pytest.approx(100 * worst["conditions"]["relative_humidity"])
    assert sent["temp_F"] == pytest.approx(_fahrenheit(worst["conditions"]["temp_K"]))
    assert 30 <= sent["relative humidity [%]"] <= 60 and 70 <= sent["temp_F"] <= 100, sent
    # a condition held at one value is its envelope's both ends; one sent in the model's unit stays
    job = wait_job(client, client.post("/v1/optimizations", json={
        **base, "conditions": {"relative_humidity": [0.3, 0.6], "temp_F": 80}}))
    result = client.get(job["result_url"]).json()
    assert result["envelope"]["as_sent"] == {"speed_m_s": [0.05, 0.05], "relative_humidity": [0.3, 0.6],
                                             "temp_F": [80, 80]}, result
    assert result["worst_case"]["as_sent"]["temp_F"] == 80, result["worst_case"]


def test_an_experiment_s_runs_give_a_sent_end_as_typed(client, calibration):
    # before: a run at the low end of temp_F {low: 70, high: 100} said temp_F 69.9999999998 (70 degF through
    # kelvin at 12 digits and back), and one between the ends 84.9999999992
    space = {"balls": [4, 8], "load [mN]": [2, 20], "speed_m_s": [0.05], "relative humidity [%]": [25, 75],
             "temp_F": {"low": 70, "high": 100}}
    response = client.post(f"/v1/calibrations/{calibration['model_id'].split(':')[1]}/next-experiments",
                           json={"runs": 4, "goal": "parameters", "space": space})
    job = wait_job(client, response)
    assert job["status"] == "succeeded", job
    runs = client.get(job["result_url"]).json()["runs"]
    shown = [run["as_sent"]["temp_F"] for run in runs]
    for run, value in zip(runs, shown, strict=True):
        assert value == pytest.approx(_fahrenheit(run["conditions"]["temp_K"]), abs=1e-6), run
        assert value == round(value, 6), shown  # no round-trip digits
        assert run["as_sent"]["load [mN]"] == round(run["as_sent"]["load [mN]"], 6), run
    assert set(shown) & {70, 100}, shown  # a design for the parameters uses the ends


def test_a_bare_temperature_is_refused_where_the_upload_gave_another_unit(client, calibration, data_dir,
                                                                          tmp_path, capsys):
    # The upload said temp_F. Before, a bare "temperature": 80 was read in degC (353.15 K) with only a
    # domain warning; every door now refuses it, naming the key, the upload's unit and header.
    model = calibration["model_id"]
    words = ("states no unit", "degF", "temp_F")
    detail = _problem(client.post("/v1/friction", json=_point(model, {"relative_humidity": 0.5,
                                                                      "temperature": 80})),
                      "/conditions/temperature")
    assert all(w in detail for w in words), detail
    batch = {"points": {"balls": 4, "load_N": [0.01, 0.02], "speed_m_s": 0.05}, "model": model,
             "conditions": {"relative_humidity": 0.5, "temperature": [80.0, 90.0]}}
    detail = _problem(client.post("/v1/friction/batch", json=batch), "/conditions/temperature")
    assert all(w in detail for w in words), detail
    for config, vector in (({"inputs": ["balls", "load_N", "temperature"],
                             "fixed": {"speed_m_s": 0.05, "relative_humidity": 0.5}}, [4, 0.01, 80]),
                           ({"inputs": ["balls", "load_N"],
                             "fixed": {"speed_m_s": 0.05, "relative_humidity": 0.5, "temperature": 80}},
                            [4, 0.01])):
        answer = client.post("/umbridge/Evaluate", json={"name": model, "input": [vector], "config": config})
        assert answer.status_code == 400, answer.text
        message = answer.json()["error"]["message"]
        assert "temperature" in message and all(w in message for w in words), message
    assert main(["evaluate", "--data-dir", str(data_dir), "--model", model, "balls=4", "load_N=0.01",
                 "speed_m_s=0.05", "relative_humidity=0.5", "temperature=80", "-o",
                 str(tmp_path / "out.json")]) != 0
    err = capsys.readouterr().err
    assert "temperature" in err and all(w in err for w in words), err
    # a name stating its unit is read in it, the upload's header too: 80 degF = 26.67 degC
    kelvin = {key: client.post("/v1/friction", json=_point(model, {"relative_humidity": 0.5, key: value}))
              for key, value in (("temp_F", 80.0), ("temperature_C", (80.0 - 32) * 5 / 9))}
    assert {key: r.status_code for key, r in kelvin.items()} == {"temp_F": 200, "temperature_C": 200}
    assert kelvin["temp_F"].json()["mu"] == pytest.approx(kelvin["temperature_C"].json()["mu"], rel=1e-12)
