"""Errors in the user's words (no pydantic tags, model names or union dumps); given axis values in sweeps."""

from __future__ import annotations

import platform
import warnings

import numpy as np
import pytest

from microbearing import physics

POINT = {"balls": 4, "load_N": 0.01}


def only_error(response) -> dict:
    assert response.status_code == 422, response.text
    assert response.headers["content-type"] == "application/problem+json"
    (error,) = response.json()["errors"]
    for jargon in ("discriminator", "tag", "instance of", "GridAxis", "dictionary", "Value error"):
        assert jargon not in error["detail"], error
    return error


@pytest.mark.parametrize("body, pointer, words", [
    ({"axes": {"load_N": {"start": 0.001, "stop": 0.01, "num": 3}}}, "/design", "design is required"),
    ({"design": "gird", "axes": {}}, "/design", "'gird' is not a known design; choose one of 'grid'"),
    ({"design": "grid", "axes": {"speed_m_s": [0.01, 0.05]}}, "/axes/speed_m_s", '{"values": [...]}'),
    ({"design": "grid", "axes": {"speed_m_s": 5}}, "/axes/speed_m_s", "an object with named fields"),
    ({"design": "grid", "axes": {"speed_m_s": {"values": [0.01, -0.05]}}, "fixed": POINT},
     "/axes/speed_m_s/values/1", "speed_m_s must be in [0, 1000] [m/s]; got -0.05"),
    ({"design": "grid", "axes": {"balls": {"values": [3, 4.5]}}, "fixed": {"load_N": 0.01, "speed_m_s": 0.1}},
     "/axes/balls/values/1", "whole number"),
])
def test_sweep_errors_name_the_field_in_plain_words(client, body, pointer, words):
    error = only_error(client.post("/v1/sweeps", json=body))
    assert error["pointer"] == pointer and words in error["detail"], error


def test_a_grid_axis_takes_given_values_in_their_order(client):
    body = {"design": "grid", "axes": {"speed_m_s": {"values": [0.1, 0.01, 0.05]},
                                       "balls": {"start": 3, "stop": 4, "num": 2}},
            "fixed": {"load_N": 0.01}, "outputs": ["mu"]}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no serializer warning for the second form of an axis
        answer = client.post("/v1/sweeps", json=body)
    assert answer.status_code == 200, answer.text
    columns = answer.json()["columns"]
    assert columns["speed_m_s"] == [0.1, 0.01, 0.05] * 2 and columns["balls"] == [3, 3, 3, 4, 4, 4]
    expected = physics.evaluate(balls=np.array(columns["balls"]), load_N=0.01,
                                speed_m_s=np.array(columns["speed_m_s"])).mu
    np.testing.assert_array_equal(columns["mu"], expected)


def test_a_large_body_refused_by_its_schema_names_the_field_without_parsing_it_again(client):
    # Past 16 MiB the refusal does not parse the body a second time to name its keys as sent (that doubled
    # the memory of a 228 MiB batch); the field is still named, and each error's input is only its kind.
    from microbearing.service import limits

    column = "[" + ", ".join(["0.012345678901"] * 1_300_000) + "]"  # ~20 MB
    body = f'{{"points": {{"balls": 4, "speed_m_s": 0.1, "load_N": {column}, "ball_radius_m": {column}}}}}'
    assert len(body) > 16 * 2**20
    response = client.post("/v1/friction/batch", content=body, headers={"content-type": "application/json"})
    error = only_error(response)
    assert error["pointer"] == "/points/ball_radius_m" and "not permitted" in error["detail"].lower()
    # a list where an object belongs is said in words, from the stand-in of the 1.3e6-number list
    response = client.post("/v1/friction/batch", content=f'{{"points": {column}}}',
                           headers={"content-type": "application/json"})
    assert only_error(response)["detail"].endswith("not a list")
    # what a large request freed goes back to the system where the C library can (glibc's malloc_trim)
    if platform.system() == "Linux" and platform.libc_ver()[0] == "glibc":
        assert limits.return_freed_memory() is True


_BOUNDS = {"balls": [4, 10], "load_N": [0.005, 0.03], "groove_angle_deg": [40, 60]}


@pytest.mark.parametrize(("body", "route", "pointer"), [
    ({"bounds": {**_BOUNDS, "RH [%]": [30, 60]}, "fixed": {"speed_m_s": 0.05}}, "/v1/optimizations",
     "/bounds/RH [%]"),
    ({"bounds": _BOUNDS, "fixed": {"speed_m_s": 0.05, "RH [%]": 40}}, "/v1/optimizations", "/fixed/RH [%]"),
    ({"bounds": _BOUNDS, "fixed": {"speed_m_s": 0.05}, "tolerances": {"humidity_pct": 5}},
     "/v1/optimizations", "/tolerances/humidity_pct"),
    ({"space": {"load_N": [0.005, 0.03], "temp [degF]": [60, 90]}, "fixed": {"balls": 4, "speed_m_s": 0.05},
      "budget": 12}, "/v1/surrogates", "/space/temp [degF]"),
    ({"space": {"load_N": [0.005, 0.03]}, "fixed": {"balls": 4, "speed_m_s": 0.05, "specimen": 3},
      "budget": 12}, "/v1/surrogates", "/fixed/specimen"),
])
def test_a_condition_where_physics_inputs_go_is_pointed_to_conditions(client, body, route, pointer):
    # Issue 32: a lab's condition column (humidity, temperature, a specimen) in an optimization's or a
    # surrogate's bounds, fixed, tolerances or space was answered "Extra inputs are not permitted".
    error = only_error(client.post(route, json=body))
    assert error["pointer"] == pointer
    key = pointer.split("/")[-1]
    assert error["detail"].startswith(f"{key} is no physics input"), error
    assert "conditions" in error["detail"] and "Extra inputs" not in error["detail"], error


@pytest.mark.parametrize("value", [[30, 60], {"low": 30, "high": 60}, {"values": [30, 60]}, None])
def test_an_experiment_s_fixed_value_is_one_value_said_in_one_sentence(client, value):
    # A range in an experiment's fixed values was answered with each member of the union: "Input should be
    # a valid number; Input should be a valid boolean; Input should be a valid string".
    body = {"runs": 4, "fit_parameters": ["mu_pivot"], "fixed": {"RH [%]": value},
            "space": {"balls": [4, 12], "load_N": [0.003, 0.024], "speed_m_s": [0.01, 0.1]}}
    error = only_error(client.post("/v1/experiments", json=body))
    assert error["pointer"] == "/fixed/RH [%]"
    assert "fixed holds one value per column" in error["detail"] and "space" in error["detail"], error
    assert "Input should be" not in error["detail"], error


@pytest.mark.parametrize(("value", "words"), [
    ([30, 60], "one value each"), ({"low": 30, "high": 60}, "one value each"),
    ("S2", "a group label is no condition of a surrogate")])
def test_a_surrogate_s_condition_is_one_number_said_in_one_sentence(client, value, words):
    # A range or a label in a surrogate's conditions was answered "Input should be a valid number".
    body = {"model": "calibrated:" + "0" * 32, "space": {"load_N": [0.005, 0.03]},
            "fixed": {"balls": 4, "speed_m_s": 0.05}, "conditions": {"RH [%]": value}, "budget": 12}
    error = only_error(client.post("/v1/surrogates", json=body))
    assert error["pointer"] == "/conditions/RH [%]"
    assert words in error["detail"] and "Input should be" not in error["detail"], error


@pytest.mark.parametrize("value", [["S1", "S2"], {"values": ["S1", "S2"]}])
def test_an_experiment_space_of_labels_is_said_in_one_sentence(client, value):
    # Labels in a space were answered with four of pydantic's errors ("/space/specimen/low: Field required;
    # ... /values/0: Input should be a valid number").
    body = {"runs": 3, "goal": "parameters", "space": {"balls": [4, 10], "load_N": [0.005, 0.03],
                                                       "speed_m_s": [0.03, 0.1], "specimen": value}}
    error = only_error(client.post("/v1/calibrations/" + "0" * 32 + "/next-experiments", json=body))
    assert error["pointer"] == "/space/specimen"
    assert "factor column" in error["detail"] and "Input should be" not in error["detail"], error
