"""The stateful phase of schemathesis: sequences of requests along the spec's links.

The phase chains requests through the spec's links (a 202 to its job's routes and plots, a job's
result to the stored surrogate or calibration, a model or a list of models to the model's routes),
checks every answer as ``tests/test_service_schemathesis.py`` checks single requests, prints which
operations it reached with which statuses, and asserts that every route with an ``{id}`` is reached
through a link (before the spec said what the server checks across fields and linked every model
route: 1 of 13 in 100 sequences; now 13 of 13, see bench/RESULTS.md).
"""

from __future__ import annotations

import collections
import time
from typing import ClassVar

import hypothesis
import pytest
from fastapi.testclient import TestClient
from schemathesis_app import CHECKS, DERANDOMIZE, MAX_EXAMPLES, SpecApp

SPEC_APP = SpecApp("microbearing-schemathesis-links-")
APP = SPEC_APP.app
schema = SPEC_APP.schema


@pytest.fixture(scope="module", autouse=True)
def _close_app():
    yield
    SPEC_APP.close()


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


def _deref(spec: dict, schema: dict) -> dict:
    """``schema`` with its ``$ref`` to a component schema followed."""
    while "$ref" in schema:
        schema = spec["components"]["schemas"][schema["$ref"].rsplit("/", 1)[1]]
    return schema


def _allowed_values(spec: dict, schema: dict) -> list:
    """The values an enumerated schema allows (empty when it enumerates none)."""
    schema = _deref(spec, schema)
    branches = schema.get("anyOf", [])
    return [*schema.get("enum", []), *[value for b in branches for value in _allowed_values(spec, b)]]


def _resolves(spec: dict, schema: dict, parts: list[str]) -> bool:
    """Whether the JSON pointer ``parts`` can name a value in an instance of ``schema``."""
    schema = _deref(spec, schema)
    if not parts:
        return True
    branches = [*schema.get("anyOf", []), *schema.get("oneOf", []), *schema.get("allOf", [])]
    if any(_resolves(spec, branch, parts) for branch in branches):
        return True
    head, rest = parts[0], parts[1:]
    if head in schema.get("properties", {}):
        return _resolves(spec, schema["properties"][head], rest)
    if head.isdigit() and isinstance(schema.get("items"), dict):
        return _resolves(spec, schema["items"], rest)
    return False


def test_every_id_route_is_the_target_of_a_link_that_resolves():
    """Read from the spec alone (the stateful test below follows the links with requests): every route
    with an ``{id}`` is the target of a link that fills each of its path parameters, and every value
    a link takes names a field of its answer's schema or a path parameter of its request, or is a constant
    its target parameter accepts (one it enumerates, or any for a free string)."""
    spec = APP.openapi()
    operations = {operation["operationId"]: (method.upper(), path, operation)
                  for path, item in spec["paths"].items() for method, operation in item.items()}
    filled: dict[str, set[str]] = collections.defaultdict(set)
    wrong = []
    for path, item in spec["paths"].items():
        for method, operation in item.items():
            sources = {parameter["name"] for parameter in operation.get("parameters", [])
                       if parameter["in"] == "path"}
            for status, answer in operation.get("responses", {}).items():
                body = answer.get("content", {}).get("application/json", {}).get("schema", {})
                for name, link in answer.get("links", {}).items():
                    where = f"{method.upper()} {path} {status} {name}"
                    assert link["operationId"] in operations, where
                    values = {**link.get("parameters", {}), **link.get("requestBody", {})}
                    target = operations[link["operationId"]][2]
                    for key, value in values.items():
                        if not value.startswith("$"):  # a constant: one the target parameter allows
                            allowed = [parameter["schema"] for parameter in target.get("parameters", [])
                                       if parameter["name"] == key]
                            ok = bool(allowed) and (value in _allowed_values(spec, allowed[0])
                                                    or allowed[0].get("type") == "string")
                        elif value.startswith("$response.body#/"):
                            ok = _resolves(spec, body, value.removeprefix("$response.body#/").split("/"))
                        elif value.startswith("$request.path."):
                            ok = value.removeprefix("$request.path.") in sources
                        else:
                            ok = False
                        if not ok:
                            wrong.append(f"{where}: {value}")
                    filled[link["operationId"]] |= set(link.get("parameters", {}))
    assert not wrong, f"link values that name nothing: {wrong}"
    unreached = []
    for operation_id, (method, path, operation) in operations.items():
        needed = {parameter["name"] for parameter in operation.get("parameters", [])
                  if parameter["in"] == "path"}
        if needed and not needed <= filled[operation_id]:
            unreached.append(f"{method} {path}")
    assert len(operations) >= 25 and not unreached, f"routes no link fills: {unreached}"
    assert {(method, path) for method, path, _ in operations.values() if "{" in path} == id_routes(APP)


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
