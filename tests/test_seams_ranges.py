"""A range reads the same in every route (issue 32): ``[low, high]`` and ``{"low", "high"}`` are one range
in a sweep's ``ranges`` and a surrogate's ``space`` as in an optimization's bounds and an experiment's
space; a set of values (``{"values": [...]}``) is refused there in words, naming the field, never read as
a range."""

from __future__ import annotations

import json

import pytest

from microbearing.service.cli import main
from microbearing.service.schemas.surrogates import SurrogateRequest

PROBLEM = "application/problem+json"


def _problem(response, pointer: str) -> str:
    assert response.status_code == 422, response.text
    assert response.headers["content-type"] == PROBLEM
    errors = response.json()["errors"]
    assert pointer in [e["pointer"] for e in errors], errors
    return " ".join(e["detail"] for e in errors)


def _sweep(design: str, load) -> dict:
    return {"design": design, "points": 8, "seed": 3, "outputs": ["mu"],
            "ranges": {"load_N": load, "speed_m_s": {"low": 0.01, "high": 0.1}}, "fixed": {"balls": 4}}


@pytest.mark.parametrize("design", ["sobol", "latin_hypercube"])
def test_a_sweep_s_range_may_be_a_pair(client, design):
    pair = client.post("/v1/sweeps", json=_sweep(design, [0.002, 0.02]))
    named = client.post("/v1/sweeps", json=_sweep(design, {"low": 0.002, "high": 0.02}))
    assert pair.status_code == named.status_code == 200, pair.text
    assert pair.json()["columns"] == named.json()["columns"]
    loads = pair.json()["columns"]["load_N"]
    assert len(loads) == 8 and all(0.002 <= v <= 0.02 for v in loads)
    assert max(loads) - min(loads) > 0.009  # a range sampled, not the two values 0.002 and 0.02
    assert not set(loads) <= {0.002, 0.02}


@pytest.mark.parametrize(("load", "words"), [
    ({"values": [0.002, 0.02]}, "a set of values is no range here"),
    ([0.002, 0.01, 0.02], "a list of 3 values is no range"),
])
def test_a_sweep_s_range_refuses_a_set_in_words(client, load, words):
    detail = _problem(client.post("/v1/sweeps", json=_sweep("sobol", load)), "/ranges/load_N")
    assert words in detail and "[low, high]" in detail, detail


def test_a_grid_axis_spelled_as_a_range_says_what_it_lacks(client):
    body = {"design": "grid", "axes": {"load_N": {"low": 0.002, "high": 0.02}}, "fixed": {"balls": 4,
                                                                                          "speed_m_s": 0.05}}
    detail = _problem(client.post("/v1/sweeps", json=body), "/axes/load_N")
    assert "num" in detail and "sobol" in detail, detail


def test_the_cli_s_sweep_reads_a_pair_as_the_api_does(client, tmp_path, capsys):
    request = tmp_path / "sweep.json"
    request.write_text(json.dumps(_sweep("sobol", [0.002, 0.02])))
    assert main(["sweep", str(request), "--format", "json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    api = client.post("/v1/sweeps", json=_sweep("sobol", {"low": 0.002, "high": 0.02})).json()
    assert printed["columns"] == api["columns"]


def test_a_surrogate_s_space_may_be_spelled_low_high():
    fixed = {"balls": 4, "speed_m_s": 0.05}
    pair = SurrogateRequest.model_validate({"space": {"load_N": [0.002, 0.02], "groove_angle_deg": [40, 60]},
                                            "fixed": fixed})
    named = SurrogateRequest.model_validate({"space": {"load_N": {"low": 0.002, "high": 0.02},
                                                       "groove_angle_deg": {"low": 40, "high": 60}},
                                             "fixed": fixed})
    assert named.space.model_dump(exclude_none=True) == pair.space.model_dump(exclude_none=True) == {
        "load_N": [0.002, 0.02], "groove_angle_deg": [40.0, 60.0]}


def test_a_stored_surrogate_request_reads_back_as_it_was():
    """A queued job's request is stored as its dump (every unset dimension null) and read again when a
    restarted server runs it: the reading of ranges leaves an optional dimension's null to the field (a queued
    surrogate failed after a restart with 12 'null is no range here' before)."""
    space = {"load_N": [0.002, 0.02], "groove_angle_deg": [40, 60]}
    request = SurrogateRequest.model_validate({"space": space, "fixed": {"balls": 4, "speed_m_s": 0.05}})
    again = SurrogateRequest.model_validate(request.model_dump())
    assert again == request and again.space.ball_diameter_m is None


def test_a_surrogate_s_space_refuses_a_set_in_words(client):
    body = {"space": {"load_N": {"values": [0.002, 0.02]}}, "fixed": {"balls": 4, "speed_m_s": 0.05}}
    detail = _problem(client.post("/v1/surrogates", json=body), "/space/load_N")
    assert "a set of values is no range here" in detail, detail
    accepted = client.post("/v1/surrogates", json={**body, "space": {"load_N": {"low": 0.002, "high": 0.02}},
                                                   "budget": 4, "validation_points": 0})
    assert accepted.status_code == 202, accepted.text


# ------------------------------------------------------------------- names with units at these doors


def test_a_sweep_reads_inputs_named_with_their_units_as_the_upload_does(client):
    lab = {"design": "sobol", "points": 6, "seed": 2, "outputs": ["mu"],
           "ranges": {"load [mN]": [1, 10]}, "fixed": {"balls": 4, "speed_mm_s": 50}}
    si = {**lab, "ranges": {"load_N": [0.001, 0.01]}, "fixed": {"balls": 4, "speed_m_s": 0.05}}
    by_unit, by_name = client.post("/v1/sweeps", json=lab), client.post("/v1/sweeps", json=si)
    assert by_unit.status_code == by_name.status_code == 200, by_unit.text
    assert by_unit.json()["columns"] == by_name.json()["columns"]
    assert by_unit.json()["fixed"]["speed_m_s"] == pytest.approx(0.05, rel=1e-15)
    # a grid's given values and evenly spaced ends: 1 and 10 mN, 10 to 100 mm/s
    axes = {"load_mN": {"values": [1, 10]}, "speed [mm/s]": {"start": 10, "stop": 100, "num": 3}}
    grid = client.post("/v1/sweeps", json={"design": "grid", "outputs": ["mu"], "fixed": {"balls": 4},
                                           "axes": axes})
    assert grid.status_code == 200, grid.text
    columns = grid.json()["columns"]
    assert sorted(set(columns["load_N"])) == pytest.approx([0.001, 0.01], rel=1e-15)
    assert sorted(set(columns["speed_m_s"])) == pytest.approx([0.01, 0.055, 0.1], rel=1e-12)
    # a refusal points at the key as sent and says how it was read
    below = {**lab, "ranges": {"load [mN]": {"low": -1, "high": 10}}}
    detail = _problem(client.post("/v1/sweeps", json=below), "/ranges/load [mN]/low")
    assert "sent as load [mN]" in detail, detail


def test_a_surrogate_s_space_and_fixed_read_names_with_units():
    lab = SurrogateRequest.model_validate({"space": {"load [mN]": [1, 10]}, "fixed": {"balls": 4,
                                                                                      "speed [mm/s]": 50}})
    assert lab.space.model_dump(exclude_none=True) == {"load_N": pytest.approx([0.001, 0.01], rel=1e-15)}
    assert lab.fixed.model_dump(exclude_none=True)["speed_m_s"] == pytest.approx(0.05, rel=1e-15)


def test_an_optimization_s_tolerance_may_carry_its_unit(client):
    body = {"bounds": {"balls": [4, 6], "groove_angle_deg": [40, 60], "load_N": [0.001, 0.01]},
            "speed_m_s": [0.01, 0.1]}
    degrees = client.post("/v1/optimizations", json={**body, "tolerances": {"groove_angle_deg": 1.0}})
    radians = client.post("/v1/optimizations", json={**body,
                                                      "tolerances": {"groove angle [rad]": 0.0174532925199}})
    assert degrees.status_code == radians.status_code == 200, radians.text
    assert radians.json()["envelope"]["tolerances"]["groove_angle_deg"] == pytest.approx(1.0, rel=1e-9)
    worst, same = radians.json()["worst_case"], degrees.json()["worst_case"]
    assert worst["mu"] == pytest.approx(same["mu"], rel=1e-9)
    # the worst angle is one degree from the nominal one (0.0174532925199 rad = 1 deg)
    nominal = radians.json()["design"]["groove_angle_deg"]
    assert abs(worst["groove_angle_deg"] - nominal) == pytest.approx(1.0, rel=1e-9)


# ------------------------------------------------------------------------------ unit slips in sweeps


def test_a_sweep_warns_of_a_unit_slip_as_friction_does_in_the_api_and_the_cli(client, tmp_path, capsys):
    # 50 "m/s" is 50 mm/s mistyped: /v1/friction warns; a sweep answered without a word
    body = {"design": "grid", "outputs": ["mu"], "fixed": {"balls": 4, "load_N": 0.01},
            "axes": {"speed_m_s": {"values": [0.05, 50]}}}
    friction = client.post("/v1/friction/batch", json={
        "points": {"balls": 4, "load_N": 0.01, "speed_m_s": [0.05, 50]}})
    answer = client.post("/v1/sweeps", json=body)
    assert answer.status_code == friction.status_code == 200, answer.text
    assert answer.json()["input_warnings"] == friction.json()["input_warnings"]
    assert "look like mm/s" in answer.json()["input_warnings"][0]
    # the speeds are computed as asked: mu at 50 m/s is the physics' own
    assert answer.json()["columns"]["mu"] == pytest.approx(friction.json()["mu"], rel=1e-12)
    # a range's ends and a fixed input sent with its unit are judged as sent: 2000 mN is 2 N
    sampled = client.post("/v1/sweeps", json={"design": "sobol", "points": 4, "outputs": ["mu"],
                                              "ranges": {"speed_m_s": [0.01, 0.1]},
                                              "fixed": {"balls": 4, "load [mN]": 2000}})
    warnings = sampled.json()["input_warnings"]
    assert len(warnings) == 1 and warnings[0].startswith("load [mN] runs 2000 to 2000 mN"), warnings
    assert "input_warnings" not in client.post("/v1/sweeps", json={
        **body, "axes": {"speed_m_s": {"values": [0.05, 0.1]}}}).json()
    request = tmp_path / "sweep.json"
    request.write_text(json.dumps(body))
    assert main(["sweep", str(request), "--format", "csv"]) == 0
    assert f"warning: {answer.json()['input_warnings'][0]}" in capsys.readouterr().err


def test_a_sweep_s_size_bound_counts_its_warnings():
    from pydantic import TypeAdapter

    from microbearing.service.schemas.sweeps import SweepRequest
    from microbearing.service.store import json_bytes
    from microbearing.service.sweeps import design_columns, design_size, result_bytes_bound, run_sweep

    request = TypeAdapter(SweepRequest).validate_python({
        "design": "grid", "outputs": ["mu"], "fixed": {"balls": 4, "load [mN]": 5000},
        "axes": {"speed_m_s": {"values": [0.05, 50]}}})
    count = design_size(request, 1000)
    document = run_sweep(request, design_columns(request, 1000))
    assert len(document["input_warnings"]) == 2  # the load (5 N) and the speed (50 m/s)
    assert len(json_bytes(document)) <= result_bytes_bound(request, count)


def test_a_surrogate_warns_of_a_unit_slip_as_friction_does(client):
    from jobs_helper import job_result

    body = {"space": {"speed_m_s": [0.05, 50]}, "fixed": {"balls": 4, "load [mN]": 10}, "budget": 4,
            "validation_points": 0, "adaptive": False}
    result = job_result(client, client.post("/v1/surrogates", json=body))
    friction = client.post("/v1/friction/batch", json={"points": {"balls": 4, "load_N": 0.01,
                                                                  "speed_m_s": [0.05, 50]}}).json()
    assert friction["input_warnings"][0] in result["warnings"], result["warnings"]
    assert result["fixed"]["load_N"] == pytest.approx(0.01, rel=1e-15)  # 10 mN, and no slip of it said
    assert not [w for w in result["warnings"] if w.startswith("load")], result["warnings"]


def test_an_optimization_warns_of_a_unit_slip_in_the_api_and_on_the_cli_s_stderr(client, tmp_path, capsys):
    # 50 "m/s" and a load range up to 2 N: the API's result warns of both; the CLI wrote them only inside
    # its JSON (to a file with -o: never seen), while evaluate and sweep say them on stderr
    body = {"bounds": {"balls": [4, 6], "groove_angle_deg": [40, 60], "load_N": [0.5, 2.0]}, "speed_m_s": 50}
    friction = client.post("/v1/friction/batch", json={
        "points": {"balls": 4, "load_N": [0.5, 2.0], "speed_m_s": 50}})
    answer = client.post("/v1/optimizations", json=body)
    assert answer.status_code == friction.status_code == 200, answer.text
    warnings = answer.json()["input_warnings"]
    assert sorted(warnings) == sorted(friction.json()["input_warnings"]) and len(warnings) == 2, warnings
    request, output = tmp_path / "optimize.json", tmp_path / "design.json"
    request.write_text(json.dumps(body))
    assert main(["optimize", str(request), "-o", str(output)]) == 0
    err = capsys.readouterr().err
    assert [line for line in err.splitlines() if line.startswith("warning: ")] == [
        f"warning: {w}" for w in warnings]
    assert json.loads(output.read_text())["input_warnings"] == warnings


def test_a_surrogate_s_training_warns_of_a_unit_slip_on_the_cli_s_stderr(client, tmp_path, capsys):
    # 50 "m/s": the API's surrogate warns of it as /v1/friction does; the CLI wrote the warnings only
    # inside its JSON (to a file with -o: never seen), while evaluate, sweep and optimize say them on stderr
    from jobs_helper import job_result

    body = {"space": {"speed_m_s": [0.05, 50]}, "fixed": {"balls": 4, "load_N": 0.01}, "budget": 4,
            "validation_points": 0, "adaptive": False}
    friction = client.post("/v1/friction/batch", json={"points": {"balls": 4, "load_N": 0.01,
                                                                  "speed_m_s": [0.05, 50]}}).json()
    assert friction["input_warnings"][0] in job_result(client, client.post("/v1/surrogates", json=body))[
        "warnings"]
    request, output = tmp_path / "surrogate.json", tmp_path / "trained.json"
    request.write_text(json.dumps(body))
    assert main(["surrogate", "train", str(request), "-o", str(output), "--data-dir", str(tmp_path)]) == 0
    said = [line.removeprefix("warning: ") for line in capsys.readouterr().err.splitlines()
            if line.startswith("warning: ")]
    warnings = json.loads(output.read_text())["warnings"]
    assert friction["input_warnings"][0] in said and said == warnings, (said, warnings)
    # a prediction of that surrogate carries its warnings, said on stderr too
    predicted = tmp_path / "predicted.json"
    model_id = json.loads(output.read_text())["model_id"]
    assert main(["surrogate", "predict", model_id, "speed_m_s=0.05", "-o", str(predicted),
                 "--data-dir", str(tmp_path)]) == 0
    said = [line.removeprefix("warning: ") for line in capsys.readouterr().err.splitlines()
            if line.startswith("warning: ")]
    warnings = json.loads(predicted.read_text())["warnings"]
    assert friction["input_warnings"][0] in said and said == warnings, (said, warnings)


#: Where a range of load is asked for, and nothing else: an optimization's bounds, a surrogate's space, a
#: sweep's ranges (with the pointer of the field).
_RANGE_FIELDS = {
    "bounds": ("/v1/optimizations", lambda load: {
        "bounds": {"balls": [4, 10], "groove_angle_deg": [40, 60], "load [mN]": load},
        "fixed": {"speed_m_s": 0.05}}, "/bounds/load [mN]"),
    "space": ("/v1/surrogates", lambda load: {"space": {"load [mN]": load, "speed_m_s": [0.01, 0.1]},
                                              "fixed": {"balls": 4}, "budget": 12}, "/space/load [mN]"),
    "ranges": ("/v1/sweeps", lambda load: {
        "design": "sobol", "points": 8, "fixed": {"balls": 4, "speed_m_s": 0.05},
        "ranges": {"load [mN]": load}}, "/ranges/load [mN]"),
}


@pytest.mark.parametrize("field", list(_RANGE_FIELDS))
@pytest.mark.parametrize(("load", "words"), [
    (10, "a number is no range here"), ([10], "a list of 1 value is no range here"),
    ([5, 10, 30], "a list of 3 values is no range here"), (True, "is no range here")])
def test_what_is_no_range_is_said_in_one_sentence_in_every_route(client, field, load, words):
    # Issue 32: the same JSON was refused in three routes' words, two of them pydantic's ("Input should be
    # a valid list", "List should have at least 2 items after validation, not 1", "must be an object with
    # named fields ({...}), not a number").
    route, body, pointer = _RANGE_FIELDS[field]
    detail = _problem(client.post(route, json=body(load)), pointer)
    assert words in detail and '[low, high] or {"low": low, "high": high}' in detail, detail
    for noise in ("Input should be", "List should have", "named fields", "valid list"):
        assert noise not in detail, detail


@pytest.mark.parametrize("value", [50, True])
def test_an_experiment_space_says_a_number_is_no_range_or_set(client, value):
    # A number in a space had two sentences, one pydantic's ("must be an object with named fields ({...}),
    # not a number; Input should be a valid list"); one value held in every run goes in fixed.
    body = {"runs": 4, "fit_parameters": ["mu_pivot"],
            "space": {"balls": [4, 12], "load_N": [0.003, 0.024], "speed [mm/s]": value}}
    detail = _problem(client.post("/v1/experiments", json=body), "/space/speed [mm~1s]")
    assert "is no range or set here" in detail and "fixed" in detail, detail
    for noise in ("Input should be", "named fields", "valid list"):
        assert noise not in detail, detail


@pytest.mark.parametrize(("path", "body", "pointer"), [
    ("/v1/optimizations", {"model": "calibrated:0123456789abcdef0123456789abcdef",
                           "bounds": {"balls": [4, 10], "groove_angle_deg": [40, 60],
                                      "load_N": [0.005, 0.03]},
                           "fixed": {"speed_m_s": 0.05},
                           "conditions": {"RH [%]": {"low": 30, "high": 60, "spacing": "log"}}},
     "/conditions/RH [%]"),
    ("/v1/optimizations", {"bounds": {"balls": [4, 10], "groove_angle_deg": [40, 60],
                                      "load [mN]": {"low": 5, "high": 30, "spacing": "log"}},
                           "fixed": {"speed_m_s": 0.05}}, "/bounds/load [mN]"),
    ("/v1/surrogates", {"space": {"load [mN]": {"low": 5, "high": 30, "spacing": "log"},
                                  "speed_m_s": [0.01, 0.1]}, "fixed": {"balls": 4}, "budget": 12},
     "/space/load [mN]"),
])
def test_a_spacing_where_a_range_is_held_whole_is_refused_saying_where_it_applies(client, path, body,
                                                                                 pointer):
    # before: an optimization's conditions answered ".../spacing: Extra inputs are not permitted", its
    # bounds "has the keys low and high, and only those; got low, high, spacing": neither said where
    # spacing is taken (an experiment space's levels)
    detail = _problem(client.post(path, json=body), pointer)
    assert "spacing" in detail and "experiment space" in detail, detail
    assert "Extra inputs" not in detail and "only those" not in detail, detail
