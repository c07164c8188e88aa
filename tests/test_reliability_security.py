"""API keys, request ids, JSON logs and Prometheus metrics of the service, in process."""

from __future__ import annotations

import hmac
import json
import logging
import re
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from jobs_helper import finished_job
from prometheus_client.parser import text_string_to_metric_families

from microbearing.service import security
from microbearing.service.app import create_app
from microbearing.service.observability import JsonFormatter
from microbearing.service.settings import Settings

PROBLEM = "application/problem+json"
KEYS = ("alpha-key-0123456789", "beta-key-9876543210", "gamma-key-5555555555")
POINT = {"balls": 4, "load_N": 0.01, "speed_m_s": 0.1}


@pytest.fixture(scope="module")
def keyed(tmp_path_factory):
    settings = Settings(data_dir=tmp_path_factory.mktemp("keyed"), api_keys=",".join(KEYS))
    with TestClient(create_app(settings)) as client:
        yield client


@pytest.fixture(scope="module")
def open_client(tmp_path_factory):
    with TestClient(create_app(Settings(data_dir=tmp_path_factory.mktemp("open")))) as client:
        yield client


def bearer(key: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {key}"}


# API keys ------------------------------------------------------------------------------------

SPEC = json.loads((Path(__file__).parents[1] / "openapi" / "openapi.json").read_text())
#: Every operation of the committed spec under /v1, with the methods it declares (ids in the path).
V1_OPERATIONS = [(method.upper(), re.sub(r"\{[^}]+\}", "0123abcd", path))
                 for path, item in SPEC["paths"].items() if path.startswith("/v1/")
                 for method in item if method in ("get", "post", "put", "patch", "delete")]


def test_the_spec_lists_the_v1_operations():
    assert len(V1_OPERATIONS) >= 15 and ("POST", "/v1/friction") in V1_OPERATIONS
    assert ("DELETE", "/v1/jobs/0123abcd") in V1_OPERATIONS


@pytest.mark.parametrize("method, path, body", [
    *[(method, path, POINT if method in ("POST", "PUT", "PATCH") else None)
      for method, path in V1_OPERATIONS],
    *[("HEAD", path, None) for method, path in V1_OPERATIONS if method == "GET"],
    ("GET", "/v1/no-such-resource", None),
])
def test_every_v1_path_needs_a_key(keyed, method, path, body):
    response = keyed.request(method, path, json=body)
    assert response.status_code == 401
    assert response.headers["content-type"] == PROBLEM
    assert response.headers["www-authenticate"].startswith("Bearer")
    assert "invalid_token" not in response.headers["www-authenticate"]
    if method == "HEAD":
        assert response.content == b""
        return
    problem = response.json()
    assert problem["status"] == 401 and problem["instance"] == path


@pytest.mark.parametrize("authorization", [
    "Bearer wrong-key", f"Bearer {KEYS[0]}x", f"Bearer {KEYS[0][:-1]}", f"Basic {KEYS[0]}", KEYS[0],
    "Bearer ", f"Bearer {KEYS[0]},{KEYS[1]}",
])
def test_a_wrong_key_is_refused(keyed, authorization):
    response = keyed.post("/v1/friction", json=POINT, headers={"Authorization": authorization})
    assert response.status_code == 401
    assert response.headers["content-type"] == PROBLEM
    assert response.headers["www-authenticate"].startswith("Bearer")


@pytest.mark.parametrize("key", KEYS)
def test_each_configured_key_is_accepted(keyed, key):
    response = keyed.post("/v1/friction", json=POINT, headers=bearer(key))
    assert response.status_code == 200, response.text
    assert response.json()["mu"] > 0
    # The scheme is case-insensitive (RFC 7235).
    assert keyed.get("/v1/version", headers={"Authorization": f"bearer {key}"}).status_code == 200


def test_health_metrics_and_spec_stay_open(keyed):
    assert keyed.get("/healthz").json() == {"status": "ok"}
    assert keyed.get("/metrics").status_code == 200
    assert keyed.get("/openapi.json").status_code == 200


def test_without_keys_the_api_is_open(open_client):
    assert open_client.post("/v1/friction", json=POINT).status_code == 200


def test_every_key_is_compared_even_after_a_match(monkeypatch):
    compared = []
    original = hmac.compare_digest

    def counting(a, b):
        compared.append((len(a), len(b)))
        return original(a, b)

    monkeypatch.setattr(security.hmac, "compare_digest", counting)
    middleware = security.ApiKeyMiddleware(app=None, keys=KEYS)
    assert middleware._requester(KEYS[0].encode()).key_id == security.key_id(KEYS[0])
    assert middleware._requester(b"short") is None
    assert middleware._requester(None) is None
    # Three keys, three comparisons each time, always of equal-length digests.
    assert len(compared) == 9
    assert {pair for pair in compared} == {(32, 32)}


def test_keys_that_a_header_cannot_carry_are_refused():
    assert security.parse_api_keys(" a-1 , ,b_2,") == ("a-1", "b_2")
    with pytest.raises(ValueError, match="MICROBEARING_API_KEYS"):
        security.parse_api_keys("good,with space")
    with pytest.raises(ValueError, match="MICROBEARING_API_KEYS"):
        security.parse_api_keys("clé")


def test_keys_never_reach_the_logs(tmp_path, caplog):
    settings = Settings(data_dir=tmp_path, api_keys=",".join(KEYS))
    caplog.set_level(logging.DEBUG)
    with TestClient(create_app(settings)) as client:
        client.get("/v1/version", headers=bearer(KEYS[1]))
        client.get("/v1/version", headers=bearer("not-" + KEYS[2]))
        client.get("/v1/version")
        client.post("/v1/friction", json=POINT, headers=bearer(KEYS[0]))
        client.get(f"/v1/jobs/{KEYS[2][:3]}", headers=bearer(KEYS[2]))
    formatter = JsonFormatter()
    lines = [formatter.format(record) for record in caplog.records]
    assert any('"status": 401' in line for line in lines)  # the refusals were logged ...
    assert any('"status": 200' in line for line in lines)
    for key in KEYS:
        assert all(key not in line for line in lines)  # ... without any key
    assert all(key not in repr(settings) for key in KEYS)


def test_the_spec_declares_the_bearer_scheme(open_client):
    spec = open_client.get("/openapi.json").json()
    scheme = spec["components"]["securitySchemes"][security.SECURITY_SCHEME_NAME]
    assert (scheme["type"], scheme["scheme"]) == ("http", "bearer")
    friction = spec["paths"]["/v1/friction"]["post"]
    assert friction["security"] == [{security.SECURITY_SCHEME_NAME: []}]
    assert PROBLEM in friction["responses"]["401"]["content"]
    assert "security" not in spec["paths"]["/healthz"]["get"]


# Request ids and logs -----------------------------------------------------------------------------

def test_a_client_request_id_is_echoed_and_logged(open_client, caplog):
    caplog.set_level(logging.INFO, logger="microbearing")
    response = open_client.get("/v1/version", headers={"X-Request-ID": "trace-42.a:b_c"})
    assert response.headers["x-request-id"] == "trace-42.a:b_c"
    access = [r for r in caplog.records if r.name == "microbearing.access"]
    entry = json.loads(JsonFormatter().format(access[-1]))
    assert entry["request_id"] == "trace-42.a:b_c"
    assert entry["route"] == "/v1/version" and entry["status"] == 200 and entry["method"] == "GET"
    assert entry["duration_ms"] >= 0 and entry["level"] == "INFO"


@pytest.mark.parametrize("sent", [None, "", "has space", "x" * 129, "new\nline", "ünï"])
def test_a_missing_or_unsafe_request_id_is_replaced(open_client, sent):
    headers = {} if sent is None else {"X-Request-ID": sent.encode("utf-8")}
    first = open_client.get("/healthz", headers=headers).headers["x-request-id"]
    second = open_client.get("/healthz", headers=headers).headers["x-request-id"]
    assert first != second
    assert len(first) == 32 and int(first, 16) >= 0  # a fresh uuid4 in hex


def test_errors_carry_the_request_id_too(open_client):
    response = open_client.post("/v1/friction", content=b"{", headers={"X-Request-ID": "bad-body-1",
                                                                        "content-type": "application/json"})
    assert response.status_code == 400
    assert response.headers["x-request-id"] == "bad-body-1"


def test_an_unexpected_error_is_logged_with_the_request_id(tmp_path, caplog):
    app = create_app(Settings(data_dir=tmp_path))

    def fail() -> None:
        raise RuntimeError("boom")

    app.add_api_route("/v1/failing", fail)
    caplog.set_level(logging.INFO, logger="microbearing")
    with TestClient(app, raise_server_exceptions=False) as client:
        response = client.get("/v1/failing", headers={"X-Request-ID": "failing-request-7"})
    assert response.status_code == 500 and response.headers["content-type"] == PROBLEM
    logged = [r for r in caplog.records if r.exc_info]
    assert logged and all(r.request_id == "failing-request-7" for r in logged)
    access = [r for r in caplog.records if r.name == "microbearing.access"]
    assert access[-1].status == 500 and access[-1].request_id == "failing-request-7"


def test_a_jobs_log_lines_name_the_request_that_created_it(tmp_path, caplog):
    caplog.set_level(logging.INFO, logger="microbearing")
    sweep = {"design": "grid", "outputs": ["mu"], "fixed": {"balls": 4, "load_N": 0.01},
             "axes": {"speed_m_s": {"start": 0.0, "stop": 0.1, "num": 5}}}
    with TestClient(create_app(Settings(data_dir=tmp_path, sweep_sync_max_points=0))) as client:
        response = client.post("/v1/sweeps", json=sweep, headers={"X-Request-ID": "sweep-request-9"})
        assert response.status_code == 202
        job_id = response.json()["id"]
        finished_job(client, f"/v1/jobs/{job_id}", timeout_s=30, interval_s=0.02)
    lines = [r for r in caplog.records if getattr(r, "job_id", None) == job_id]
    assert [r.getMessage().split()[-1] for r in lines] == ["queued", "started", "succeeded"]
    in_job_thread = {r.threadName.startswith("microbearing-job") for r in lines}
    assert in_job_thread == {False, True}  # queued by the request, run in a job thread
    assert all(r.request_id == "sweep-request-9" for r in lines), [r.request_id for r in lines]
    entry = json.loads(JsonFormatter().format(lines[-1]))
    assert entry["request_id"] == "sweep-request-9" and entry["job_id"] == job_id


# Metrics -----------------------------------------------------------------------------------------

def request_count(client: TestClient, method: str, route: str, status: str) -> float:
    text = client.get("/metrics").text
    for family in text_string_to_metric_families(text):
        if family.name == "microbearing_http_requests":
            for sample in family.samples:
                if sample.name.endswith("_total") and sample.labels == {
                        "method": method, "route": route, "status": status}:
                    return sample.value
    return 0.0


def latency_count(client: TestClient, method: str, route: str, status: str) -> float:
    text = client.get("/metrics").text
    for family in text_string_to_metric_families(text):
        if family.name == "microbearing_http_request_duration_seconds":
            for sample in family.samples:
                if sample.name.endswith("_count") and sample.labels == {
                        "method": method, "route": route, "status": status}:
                    return sample.value
    return 0.0


def test_metrics_count_the_requests_made(open_client):
    response = open_client.get("/metrics")
    assert response.headers["content-type"].startswith("text/plain")
    before = request_count(open_client, "POST", "/v1/friction", "200")
    before_latency = latency_count(open_client, "POST", "/v1/friction", "200")
    for _ in range(3):
        assert open_client.post("/v1/friction", json=POINT).status_code == 200
    assert request_count(open_client, "POST", "/v1/friction", "200") == before + 3
    assert latency_count(open_client, "POST", "/v1/friction", "200") == before_latency + 3


def test_metrics_label_by_route_template_and_bound_unknown_paths(open_client):
    before = request_count(open_client, "GET", "/v1/jobs/{job_id}", "404")
    open_client.get("/v1/jobs/first-unknown")
    open_client.get("/v1/jobs/second-unknown")
    assert request_count(open_client, "GET", "/v1/jobs/{job_id}", "404") == before + 2
    unmatched = request_count(open_client, "GET", "<unmatched>", "404")
    open_client.get("/random/path/one")
    open_client.get("/random/path/two")
    assert request_count(open_client, "GET", "<unmatched>", "404") == unmatched + 2
    assert "/random/path" not in open_client.get("/metrics").text


def test_refused_requests_are_counted(keyed):
    before = request_count(keyed, "GET", "<unmatched>", "401")
    keyed.get("/v1/version")
    assert request_count(keyed, "GET", "<unmatched>", "401") == before + 1
