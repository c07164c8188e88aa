"""Property-based tests of the whole API against its own OpenAPI spec (schemathesis).

Every operation gets generated valid and invalid requests; the server must never answer 5xx
and every response must match the spec (status code, content type, body schema, headers).
The stateful phase then chains requests through the spec's links (a 202 to its job's routes and
plots, a job's result to the stored surrogate or calibration, a model or a list of models to the
model's routes) under the same checks, prints which operations it reached with which statuses, and
asserts that every route with an ``{id}`` is reached through a link (before the spec said what the
server checks across fields and linked every model route: 1 of 13 in 100 sequences; now 13 of 13,
see bench/RESULTS.md).
"""

from __future__ import annotations

import collections
import os
import tempfile
import time
from typing import ClassVar

import hypothesis
import pytest
import schemathesis
from fastapi.testclient import TestClient
from jobs_helper import finished_job, wait_job
from schemathesis.specs.openapi.checks import (
    content_type_conformance,
    response_headers_conformance,
    response_schema_conformance,
    status_code_conformance,
)

from microbearing.service.app import create_app
from microbearing.service.deps import close_runtime
from microbearing.service.settings import Settings

# Small limits so that generated requests also reach the 413 and job (202) paths quickly.
_DATA_DIR = tempfile.TemporaryDirectory(prefix="microbearing-schemathesis-")
APP = create_app(Settings(data_dir=_DATA_DIR.name, max_batch_points=2_000, max_sweep_points=5_000,
                          sweep_sync_max_points=50, max_body_bytes=1_000_000,
                          max_active_jobs=1_000))  # generated jobs outnumber 64 when they finish slowly
#: Generated requests per operation (25 keeps the suite within its ten minutes; raise it with
#: MICROBEARING_SCHEMATHESIS_EXAMPLES for a deeper search).
MAX_EXAMPLES = int(os.environ.get("MICROBEARING_SCHEMATHESIS_EXAMPLES", "25"))
#: CI draws the same examples on every run (a red build is then reproducible); developers' runs
#: draw new ones each time and so keep exploring.
DERANDOMIZE = os.environ.get("CI", "").lower() == "true"
schema = schemathesis.openapi.from_asgi("/openapi.json", APP)


@pytest.fixture(scope="module", autouse=True)
def _close_app():
    yield
    close_runtime(APP)
    _DATA_DIR.cleanup()


@schema.parametrize()
@hypothesis.settings(max_examples=MAX_EXAMPLES, deadline=None, derandomize=DERANDOMIZE,
                     suppress_health_check=list(hypothesis.HealthCheck))
def test_api_conforms_to_its_spec(case):
    case.call_and_validate(checks=[
        schemathesis.checks.not_a_server_error,
        status_code_conformance,
        content_type_conformance,
        response_schema_conformance,
        response_headers_conformance,
    ])


CHECKS = [schemathesis.checks.not_a_server_error, status_code_conformance, content_type_conformance,
          response_schema_conformance, response_headers_conformance]

#: How long a linked sequence waits for a job it created to finish [s], polling as a client told
#: Retry-After would; a job still running then is cancelled (the chain meets its 409 and follows
#: the spec's retry links) so that it does not hold a job worker for the rest of the run.
JOB_WAIT_S = 5.0
_POLLER = TestClient(APP)
WAITED = [0.0]


def _wait_for_job(job_id: str) -> None:
    started = time.monotonic()
    deadline = started + JOB_WAIT_S
    while _POLLER.get(f"/v1/jobs/{job_id}").json().get("status") in ("queued", "running"):
        if time.monotonic() > deadline:
            _POLLER.delete(f"/v1/jobs/{job_id}")
            break
        time.sleep(0.02)
    WAITED[0] += time.monotonic() - started


def _took_every_value(input) -> bool:
    """Whether a linked request took every value its link names (not one drawn at random instead)."""
    applied = {(location.container_name, name) for location, name in input.applied_parameters}
    named = {(container, name) for container, values in input.transition.parameters.items()
             for name in values}
    body = input.transition.request_body is None or any(container == "body" for container, _ in applied)
    return bool(named or input.transition.request_body is not None) and named <= applied and body


def id_routes(app) -> set[tuple[str, str]]:
    """Every (method, path template) of the app's routes with a path parameter, as the app documents
    them (the spec generated from its routes; a route left out of it is out of schemathesis' reach)."""
    return {(method.upper(), path) for path, item in app.openapi()["paths"].items() if "{" in path
            for method in item}


# The links written in the spec only: schemathesis' own link inference (from names alike in
# requests and answers) is switched off, so what is reached is what the spec's links reach.
schema.config.phases.stateful.inference.algorithms = []


class LinkedRequests(schema.as_state_machine()):
    """Sequences of requests along the spec's links, checked as single requests are.

    ``reached`` counts (method, path template, status, whether the request took a value through a
    link of the spec); a job created on the way is waited for (at most JOB_WAIT_S) before the next
    step, as a client polls it.
    """

    reached: ClassVar[collections.Counter] = collections.Counter()
    scenarios: ClassVar[int] = 0

    def setup(self):
        LinkedRequests.scenarios += 1

    def step(self, input):
        output = super().step(input)
        transition = input.transition
        linked = transition is not None and not transition.is_inferred and _took_every_value(input)
        operation = input.case.operation
        LinkedRequests.reached[(operation.method.upper(), operation.path, output.response.status_code,
                                linked)] += 1
        return output

    def after_call(self, response, case):
        super().after_call(response, case)
        if response.status_code == 202:
            _wait_for_job(response.json()["id"])

    def validate_response(self, response, case, additional_checks=None, **kwargs):
        case.validate_response(response, checks=CHECKS, transport_kwargs=kwargs or None)


def reached_through_links(reached: collections.Counter) -> dict[tuple[str, str], set[int]]:
    """(method, path) -> statuses of the requests that took an id through a link and were neither
    refused as invalid (422) nor aimed at nothing (404)."""
    routes: dict[tuple[str, str], set[int]] = collections.defaultdict(set)
    for (method, path, status, linked), _ in reached.items():
        if linked and status not in (404, 422):
            routes[(method, path)].add(status)
    return dict(routes)


#: Requests per linked sequence: a job's result, then its model, then the model's routes lie four to
#: six links from a request that starts a job, among the other links each answer offers.
STEPS = 16
#: Linked sequences per run of the stateful phase, and the most the reach test runs before it gives up:
#: a route several links deep (the Pareto plot, a calibration's report) is reached a few times in
#: 100 sequences, or not, as the random choices fall; runs continue until every route is reached.
SEQUENCES_PER_RUN = max(MAX_EXAMPLES, 50)
MAX_SEQUENCES = max(MAX_EXAMPLES, 400)


def run_linked_sequences(scenarios: int, seed: int | None) -> None:
    """Run ``scenarios`` sequences of linked requests (Hypothesis' generate phase) from ``seed``.

    The server keeps what earlier sequences stored, so a sequence Hypothesis replays from its
    record can take another branch (a link finds an id where it found none), which Hypothesis
    calls an inconsistent generation (FlakyStrategyDefinition); schemathesis' own runner then
    starts a new run, and so does this, from the next seed (a failed check, even one that does
    not reproduce, fails the test).
    """
    target = LinkedRequests.scenarios + scenarios
    for attempt in range(10):
        left = target - LinkedRequests.scenarios
        if left <= 0:
            return
        LinkedRequests.TestCase.settings = hypothesis.settings(
            max_examples=left, stateful_step_count=STEPS, deadline=None, database=None,
            suppress_health_check=list(hypothesis.HealthCheck), phases=[hypothesis.Phase.generate])
        # What @hypothesis.seed sets, read by Hypothesis' state machine runner (None: a random seed).
        LinkedRequests._hypothesis_internal_use_seed = None if seed is None else seed * 100 + attempt
        try:
            LinkedRequests.TestCase().runTest()
            return
        except hypothesis.errors.FlakyStrategyDefinition:
            continue


def test_linked_requests_reach_every_id_route():
    """The stateful phase, following only the spec's links, reaches every route with an ``{id}``.

    A route counts as reached when a request took its id (or body field) from an earlier answer
    through a link and got neither 404 nor 422. Every request is checked as single requests are
    (no 5xx, status, content type, body and headers as the spec says).
    """
    links = sum(len(answer.get("links", {})) for item in APP.openapi()["paths"].values()
                for operation in item.values() for answer in operation.get("responses", {}).values())
    assert links >= 27  # 202 -> job routes, job -> result -> stored models, list -> surrogate routes
    routes = id_routes(APP)
    assert len(routes) >= 13
    runs = 0
    while LinkedRequests.scenarios < MAX_SEQUENCES:
        # CI: seeds 0, 1, 2, ... (a red build replays); developers: new random choices each time.
        run_linked_sequences(SEQUENCES_PER_RUN, runs if DERANDOMIZE else None)
        runs += 1
        if routes <= set(reached_through_links(LinkedRequests.reached)):
            break
    reached = reached_through_links(LinkedRequests.reached)
    print("stateful phase, statuses by route:")
    for key in sorted({key[:2] for key in LinkedRequests.reached}):
        statuses = {(status, linked): n for (*route, status, linked), n in LinkedRequests.reached.items()
                    if tuple(route) == key}
        print(f"  {key[0]:6} {key[1]:60} {dict(sorted(statuses.items()))}")
    print(f"reached through links: {len(set(reached) & routes)} of {len(routes)} id routes; "
          f"{LinkedRequests.scenarios} sequences, {WAITED[0]:.1f} s waiting for jobs")
    missing = sorted(routes - set(reached))
    assert not missing, f"routes the spec's links never reached: {missing}"


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
