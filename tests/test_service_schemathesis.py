"""Property-based tests of the whole API against its own OpenAPI spec (schemathesis).

The spec's own examples and the fields it documents are checked here; every operation's generated
valid and invalid requests (the server must never answer 5xx and every response must match the
spec) are ``tests/test_service_schemathesis_fuzz.py``, and the stateful phase, which chains
requests through the spec's links, is ``tests/test_service_schemathesis_links.py`` (files of their
own, so that pytest-xdist runs them in parallel and the quick tier need not collect the fuzz test).
"""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient
from jobs_helper import finished_job, wait_job
from schemathesis_app import SpecApp

SPEC_APP = SpecApp("microbearing-schemathesis-")
APP = SPEC_APP.app
schema = SPEC_APP.schema


@pytest.fixture(scope="module", autouse=True)
def _close_app():
    yield
    SPEC_APP.close()


def request_examples(spec: dict) -> list[tuple[str, str, object]]:
    """(method, path, body) of every JSON request example of the spec: the named examples of the
    media type, any ``examples`` list of its schema and those of the body's component schema."""
    found = []
    for path, item in spec["paths"].items():
        for verb, operation in item.items():
            media = operation.get("requestBody", {}).get("content", {}).get("application/json", {})
            bodies = [example["value"] for example in media.get("examples", {}).values()]
            bodies += media.get("schema", {}).get("examples", [])
            reference = media.get("schema", {}).get("$ref", "")  # the body model's own examples
            bodies += spec["components"]["schemas"].get(reference.rsplit("/", 1)[-1], {}).get("examples", [])
            found += [(verb.upper(), path, body) for body in bodies]
    return found


def test_every_request_example_of_the_spec_is_accepted():
    examples = request_examples(APP.openapi())
    assert {path for _, path, _ in examples} >= {
        "/v1/sweeps", "/v1/optimizations", "/v1/surrogates", "/v1/calibrations", "/v1/experiments",
        "/v1/surrogates/{surrogate_id}/predict", "/v1/calibrations/{calibration_id}/next-experiments"}
    # The examples on a stored model's routes go to the model the others made (those come first).
    examples.sort(key=lambda example: "{" in example[1])
    made: dict[str, str] = {}
    with TestClient(APP) as client:
        for verb, template, example in examples:
            path = template.format(**made)
            answer = client.request(verb, path, json=example)
            assert answer.status_code in (200, 202), (path, answer.text)
            if answer.status_code == 202:
                location = answer.headers["location"]
                job = finished_job(client, location)
                if job["kind"] in ("surrogate", "calibration"):
                    made[f"{job['kind']}_id"] = client.get(f"{location}/result").json()["id"]


def test_a_surrogates_space_sent_back_as_points_is_predicted_at_its_ends():
    # The spec's link from a surrogate to its predictions sends {"points": <its space>}: every
    # dimension's [low, high] as a column, whole-number dimensions as whole numbers.
    request = {"space": {"balls": [3, 12], "load_N": [0.002, 0.04]}, "fixed": {"speed_m_s": 0.05},
               "budget": 12, "validation_points": 0, "adaptive": False}
    with TestClient(APP) as client:
        location = client.post("/v1/surrogates", json=request).headers["location"]
        wait_job(client, location)
        made = client.get(f"{location}/result").json()
        assert made["space"] == request["space"]
        linked = client.post(f"/v1/surrogates/{made['id']}/predict", json={"points": made["space"]})
        ends = client.post(f"/v1/surrogates/{made['id']}/predict",
                           json={"points": {"balls": [3, 12], "load_N": [0.002, 0.04]}})
    assert linked.status_code == 200, linked.text
    assert linked.json() == ends.json() and len(linked.json()["mu"]) == 2
    assert linked.json()["outside_space"] == [False, False]


SOBOL = {"design": "sobol", "points": 60, "outputs": ["mu"], "fixed": {"balls": 4, "speed_m_s": 0.05},
         "ranges": {"load_N": {"low": 0.001, "high": 0.05}}}


@pytest.mark.parametrize(("path", "body", "field"), [
    ("/v1/sweeps", {**SOBOL, "seed": 2}, "seed"),
    ("/v1/sweeps", SOBOL, "points"),
    ("/v1/friction", {"balls": 4, "load_N": 0.01, "speed_m_s": 0.05}, "balls"),
])
def test_integers_written_with_a_fraction_are_integers_as_the_spec_says(path, body, field):
    # JSON Schema's "integer" is any number without a fraction: 2.0 is one, 2.5 and "2" are not.
    with TestClient(APP) as client:
        plain = client.post(path, json=body)
        written = client.post(path, json={**body, field: float(body[field])})
        fraction = client.post(path, json={**body, field: body[field] + 0.5})
        text = client.post(path, json={**body, field: str(body[field])})
    assert plain.status_code in (200, 202) and written.status_code == plain.status_code, written.text
    if plain.status_code == 200:
        assert written.content == plain.content
    assert fraction.status_code == 422 and text.status_code == 422

