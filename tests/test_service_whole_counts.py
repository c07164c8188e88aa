"""A count written with a fraction (``"balls": 4.0``, as JSON clients, spreadsheets and numpy send it)
is the count, wherever a count is an input; ``4.5``, NaN, infinities, ``"4"``, ``true`` and negative
counts stay 422 problems naming the field (UM-Bridge: the protocol's 400 naming it)."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest
from fastapi.testclient import TestClient
from jobs_helper import finished_job

from microbearing import physics
from microbearing.service.schemas import examples

PROBLEM = "application/problem+json"
JSON_HEADERS = {"content-type": "application/json"}
#: Counts that are not counts, as JSON text: a fraction, not numbers, text, a boolean, negative ones.
NOT_COUNTS = ["4.5", "NaN", "Infinity", "-Infinity", '"4"', "true", "-4", "-4.0", "0"]
#: Where the bad count goes in a body (a string no field holds).
HOLE = "__count__"


def with_count(body: dict, token: str) -> bytes:
    """``body`` as JSON with the raw text ``token`` where it holds :data:`HOLE`."""
    return json.dumps(body).replace(json.dumps(HOLE), token).encode()


def floats(body, key: str = "balls"):
    """``body`` with every ball count written with a fraction (``4`` -> ``4.0``)."""
    if isinstance(body, dict):
        return {k: (float(v) if k == key and isinstance(v, int) else
                    [float(x) for x in v] if k == key and isinstance(v, list) else floats(v, key))
                for k, v in body.items()}
    if isinstance(body, list):
        return [floats(item, key) for item in body]
    return body


def assert_refused(response, pointer: str) -> None:
    assert response.status_code == 422, response.text
    assert response.headers["content-type"] == PROBLEM
    problem = response.json()
    assert problem["status"] == 422
    assert pointer in [e.get("pointer") for e in problem["errors"]], problem


def finished(client: TestClient, response, timeout_s: float = 120.0) -> dict:
    """The finished job of a 202 answer, and its result."""
    assert response.status_code == 202, response.text
    location = response.headers["location"]
    finished_job(client, location, timeout_s=timeout_s, interval_s=0.05)
    return client.get(f"{location}/result").json()


# /v1/friction and /v1/friction/batch ---------------------------------------------------------------

BATCH = {"points": {"balls": [4, 6, 12], "load_N": 0.01, "speed_m_s": [0.05, 0.1, 0.1]}}


def test_a_batch_column_of_counts_written_with_fractions_is_the_column_of_counts(client):
    plain = client.post("/v1/friction/batch", json=BATCH)
    written = client.post("/v1/friction/batch", json=floats(BATCH))
    mixed = client.post("/v1/friction/batch", json={"points": {**BATCH["points"], "balls": [4, 6.0, 12]}})
    assert plain.status_code == 200, plain.text
    assert written.status_code == 200 and written.content == plain.content, written.text
    assert mixed.content == plain.content
    # the answer is the physics' at the whole counts, computed here independently
    expected = physics.evaluate(balls=np.array([4, 6, 12]), load_N=0.01, speed_m_s=np.array([0.05, 0.1, 0.1]))
    np.testing.assert_allclose(written.json()["mu"], expected.mu, rtol=1e-12)


def test_a_point_and_a_batch_scalar_written_with_a_fraction_are_the_count(client):
    point = {"balls": 4, "load_N": 0.01, "speed_m_s": 0.1}
    assert client.post("/v1/friction", json=floats(point)).content == client.post("/v1/friction",
                                                                                  json=point).content
    batch = {"points": {**BATCH["points"], "balls": 4}}
    assert client.post("/v1/friction/batch", json=floats(batch)).content == client.post(
        "/v1/friction/batch", json=batch).content


@pytest.mark.parametrize("token", NOT_COUNTS)
@pytest.mark.parametrize(("path", "body", "pointer"), [
    ("/v1/friction", {"balls": HOLE, "load_N": 0.01, "speed_m_s": 0.1}, "/balls"),
    ("/v1/friction/batch", {"points": {**BATCH["points"], "balls": [4, HOLE, 12]}}, "/points/balls/1"),
    ("/v1/friction/batch", {"points": {**BATCH["points"], "balls": HOLE}}, "/points/balls"),
])
def test_friction_refuses_what_is_not_a_count_naming_it(client, path, body, pointer, token):
    assert_refused(client.post(path, content=with_count(body, token), headers=JSON_HEADERS), pointer)


# /v1/sweeps and /v1/optimizations -------------------------------------------------------------------

AXIS_SWEEP = {"design": "grid", "fixed": {"load_N": 0.01}, "outputs": ["mu"],
              "axes": {"balls": {"start": 4, "stop": 12, "num": 3},
                       "speed_m_s": {"start": 0.01, "stop": 0.1, "num": 2}}}


@pytest.mark.parametrize("body", [examples.SWEEP, AXIS_SWEEP], ids=["fixed", "axis"])
def test_a_sweep_takes_counts_written_with_fractions(client, body):
    plain = client.post("/v1/sweeps", json=body)
    assert plain.status_code == 200, plain.text
    axis = {"start": 4.0, "stop": 12.0, "num": 3.0}
    written = client.post("/v1/sweeps", json=floats(body) if body is examples.SWEEP else
                          {**body, "axes": {**body["axes"], "balls": axis}})
    assert written.status_code == 200 and written.content == plain.content, written.text


@pytest.mark.parametrize("token", NOT_COUNTS)
def test_a_sweep_refuses_a_fixed_count_that_is_not_one(client, token):
    body = {**examples.SWEEP, "fixed": {"balls": HOLE}}
    assert_refused(client.post("/v1/sweeps", content=with_count(body, token), headers=JSON_HEADERS),
                   "/fixed/balls")


def test_an_optimization_takes_bounds_on_the_count_written_with_fractions(client):
    plain = client.post("/v1/optimizations", json=examples.OPTIMIZATION)
    written = client.post("/v1/optimizations", json=floats(examples.OPTIMIZATION))
    assert plain.status_code == 200 and written.status_code == 200, written.text
    assert written.json()["design"] == plain.json()["design"] and written.json()["mu"] == plain.json()["mu"]


@pytest.mark.parametrize("token", NOT_COUNTS)
def test_an_optimization_refuses_a_bound_that_is_not_a_count(client, token):
    body = copy.deepcopy(examples.OPTIMIZATION)
    body["bounds"]["balls"] = [HOLE, 24]
    assert_refused(client.post("/v1/optimizations", content=with_count(body, token), headers=JSON_HEADERS),
                   "/bounds/balls/0")


# /v1/surrogates ------------------------------------------------------------------------------------

SURROGATE = {"space": {"balls": [4, 8], "load_N": [0.001, 0.05]}, "fixed": {"speed_m_s": 0.05},
             "budget": 12, "validation_points": 0}


@pytest.fixture(scope="module")
def surrogate(client) -> dict:
    """A surrogate trained on a space whose ball range was written with fractions."""
    return finished(client, client.post("/v1/surrogates", json=floats(SURROGATE)))


def test_a_surrogate_space_and_its_predictions_take_counts_written_with_fractions(client, surrogate):
    assert surrogate["space"]["balls"] == [4, 8]
    path = f"/v1/surrogates/{surrogate['id']}/predict"
    points = {"points": {"balls": [4, 5, 8], "load_N": [0.002, 0.01, 0.04]}}
    plain = client.post(path, json=points)
    assert plain.status_code == 200, plain.text
    assert client.post(path, json=floats(points)).content == plain.content


@pytest.mark.parametrize("token", NOT_COUNTS)
def test_surrogates_refuse_counts_that_are_not_counts(client, surrogate, token):
    space = {**SURROGATE, "space": {**SURROGATE["space"], "balls": [HOLE, 8]}}
    assert_refused(client.post("/v1/surrogates", content=with_count(space, token), headers=JSON_HEADERS),
                   "/space/balls/0")
    fixed = {**examples.SURROGATE, "fixed": {"balls": HOLE}}
    assert_refused(client.post("/v1/surrogates", content=with_count(fixed, token), headers=JSON_HEADERS),
                   "/fixed/balls")
    points = {"points": {"balls": [4, HOLE], "load_N": [0.002, 0.01]}}
    assert_refused(client.post(f"/v1/surrogates/{surrogate['id']}/predict", content=with_count(points, token),
                               headers=JSON_HEADERS), "/points/balls/1")


# /v1/calibrations and /v1/experiments --------------------------------------------------------------

def test_calibration_rows_with_counts_written_with_fractions_fit_as_the_counts(client):
    plain = finished(client, client.post("/v1/calibrations", json=examples.CALIBRATION))
    written = finished(client, client.post("/v1/calibrations", json=floats(examples.CALIBRATION)))
    assert written["fitted_parameters"] == plain["fitted_parameters"]
    assert written["error_after"] == plain["error_after"]


@pytest.mark.parametrize("token", NOT_COUNTS)
def test_calibrations_refuse_counts_that_are_not_counts(client, token):
    body = copy.deepcopy(examples.CALIBRATION)
    body["data"][3]["balls"] = HOLE
    assert_refused(client.post("/v1/calibrations", content=with_count(body, token), headers=JSON_HEADERS),
                   "/data/3/balls")
    body = copy.deepcopy(examples.CALIBRATION)
    for row in body["data"]:
        del row["balls"]
    body["fixed"] = {"balls": HOLE}
    assert_refused(client.post("/v1/calibrations", content=with_count(body, token), headers=JSON_HEADERS),
                   "/fixed/balls")


def test_a_first_design_takes_counts_written_with_fractions(client):
    space = {**examples.FIRST_EXPERIMENTS["space"], "balls": {"values": [4, 8, 12]}}
    body = {**examples.FIRST_EXPERIMENTS, "space": space,
            "planned": [{"balls": 4, "load_N": 0.01, "speed_m_s": 0.01}]}
    plain = finished(client, client.post("/v1/experiments", json=body))
    written = finished(client, client.post("/v1/experiments", json=floats(body)))
    assert written["runs"] == plain["runs"]
    assert {run["balls"] for run in written["runs"]} <= {4, 8, 12}


@pytest.mark.parametrize("token", NOT_COUNTS)
def test_a_first_design_refuses_counts_that_are_not_counts(client, token):
    # a planned run's count was met only inside the job, as a failure of the space
    body = {**examples.FIRST_EXPERIMENTS, "planned": [{"balls": 4, "load_N": 0.01, "speed_m_s": 0.01},
                                                      {"balls": HOLE, "load_N": 0.01, "speed_m_s": 0.01}]}
    assert_refused(client.post("/v1/experiments", content=with_count(body, token), headers=JSON_HEADERS),
                   "/planned/1/balls")
    body = {**examples.FIRST_EXPERIMENTS, "fixed": {"balls": HOLE},
            "space": {k: v for k, v in examples.FIRST_EXPERIMENTS["space"].items() if k != "balls"}}
    assert_refused(client.post("/v1/experiments", content=with_count(body, token), headers=JSON_HEADERS),
                   "/fixed/balls")


# /umbridge -----------------------------------------------------------------------------------------

def test_umbridge_takes_counts_written_with_fractions(client):
    point = {"name": "physics", "input": [[4, 0.01, 0.05], [6, 0.02, 0.1]], "config": {"points": 2}}
    plain = client.post("/umbridge/Evaluate", json=point)
    assert plain.status_code == 200, plain.text
    written = client.post("/umbridge/Evaluate", json={**point, "input": [[4.0, 0.01, 0.05], [6.0, 0.02, 0.1]],
                                                      "config": {"points": 2.0}})
    assert written.content == plain.content, written.text
    fixed = {"name": "physics", "input": [[0.01, 0.05]],
             "config": {"inputs": ["load_N", "speed_m_s"], "fixed": {"balls": 4.0}}}
    assert client.post("/umbridge/Evaluate", json=fixed).json()["output"] == [plain.json()["output"][0]]
    gradient = {**fixed, "outWrt": 0, "inWrt": 0, "sens": [1.0]}
    plain = client.post("/umbridge/Gradient", json=gradient)
    assert plain.status_code == 200, plain.text
    written = client.post("/umbridge/Gradient", json={**gradient, "outWrt": 0.0, "inWrt": 0.0})
    assert written.content == plain.content


@pytest.mark.parametrize("token", ["4.5", "NaN", '"4"', "true", "-4"])
def test_umbridge_refuses_counts_that_are_not_counts_naming_them(client, token):
    body = {"name": "physics", "input": [[HOLE, 0.01, 0.05]]}
    response = client.post("/umbridge/Evaluate", content=with_count(body, token), headers=JSON_HEADERS)
    assert response.status_code == 400, response.text
    assert response.json()["error"]["message"].startswith("input[0][0]")
    body = {"name": "physics", "input": [[4, 0.01, 0.05]], "config": {"points": HOLE}}
    response = client.post("/umbridge/Evaluate", content=with_count(body, token), headers=JSON_HEADERS)
    assert response.status_code == 400, response.text
    assert response.json()["error"]["message"].startswith("config.points")
