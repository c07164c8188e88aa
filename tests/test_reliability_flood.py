"""A real server under more jobs than it takes, and a client that never finishes its body.

Admission control: a key past its share of queued and running jobs gets 429, a full server 503,
both problems with ``Retry-After``; ``/healthz`` keeps answering; cancelling frees places. A body
that stops arriving gets 408 and the connection is closed, after ``MICROBEARING_BODY_TIMEOUT_S``.
"""

from __future__ import annotations

import os
import socket

import pytest
from live_server import Server

pytestmark = pytest.mark.skipif(os.name != "posix", reason="process groups are POSIX")

ALPHA, BETA = "flood-alpha-0123456789", "flood-beta-9876543210"
#: Adaptive training toward an unreachable target: busy for far longer than the test.
LONG_SURROGATE = {"space": {"load_N": [1e-4, 0.1], "speed_m_s": [0.0, 0.2], "balls": [2, 40],
                            "groove_angle_deg": [30.0, 80.0]},
                  "fixed": {}, "budget": 1000, "target_relative_error": 1e-6, "adaptive": True}


def bearer(key: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {key}"}


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    folder = tmp_path_factory.mktemp("flood")
    running = Server(folder / "data", folder / "server.log", api_keys=f"{ALPHA},{BETA}", job_workers="1",
                     max_active_jobs="3", max_active_jobs_per_key="2", body_timeout_s="1",
                     executor_workers="1")
    yield running
    running.kill()  # a training under way would hold a graceful stop for long; the folder is thrown away


def assert_refused(response, status: int) -> dict:
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == "application/problem+json"
    assert int(response.headers["retry-after"]) > 0
    return response.json()


def test_past_its_share_a_key_gets_429_and_a_full_server_503(server):
    client = server.client
    accepted = []
    try:
        for key in (ALPHA, ALPHA):
            response = client.post("/v1/surrogates", json=LONG_SURROGATE, headers=bearer(key))
            assert response.status_code == 202, response.text
            assert int(response.headers["retry-after"]) >= 1
            accepted.append((response.headers["location"], key))
        refused = client.post("/v1/surrogates", json=LONG_SURROGATE, headers=bearer(ALPHA))
        problem = assert_refused(refused, 429)
        assert "MICROBEARING_MAX_ACTIVE_JOBS_PER_KEY=2" in problem["detail"]
        response = client.post("/v1/surrogates", json=LONG_SURROGATE, headers=bearer(BETA))
        assert response.status_code == 202  # another key still has room in the server
        accepted.append((response.headers["location"], BETA))
        refused = client.post("/v1/surrogates", json=LONG_SURROGATE, headers=bearer(BETA))
        problem = assert_refused(refused, 503)
        assert "MICROBEARING_MAX_ACTIVE_JOBS=3" in problem["detail"]
        assert client.get("/healthz").json() == {"status": "ok"}
        ready = client.get("/readyz")
        assert ready.status_code == 200 and ready.json()["active_jobs"] == 3
        # Cancelling a queued job frees its place at once: Alpha may submit again.
        queued = next(entry for entry in accepted
                      if client.get(entry[0], headers=bearer(entry[1])).json()["status"] == "queued")
        assert client.delete(queued[0], headers=bearer(queued[1])).json()["status"] == "cancelled"
        accepted.remove(queued)
        response = client.post("/v1/surrogates", json=LONG_SURROGATE, headers=bearer(queued[1]))
        assert response.status_code == 202, response.text
        accepted.append((response.headers["location"], queued[1]))
    finally:
        for location, key in accepted:
            client.delete(location, headers=bearer(key))


def test_a_body_that_stops_arriving_gets_408_and_the_connection_closes(server):
    with socket.create_connection(("127.0.0.1", server.port), timeout=60) as sock:
        sock.sendall(b"POST /v1/friction HTTP/1.1\r\nHost: test\r\nContent-Type: application/json\r\n"
                     b"Authorization: Bearer " + ALPHA.encode() + b"\r\nContent-Length: 100\r\n\r\n"
                     b'{"balls"')
        received = b""
        while chunk := sock.recv(65536):  # until the server closes the connection
            received += chunk
    head, _, body = received.partition(b"\r\n\r\n")
    assert head.startswith(b"HTTP/1.1 408"), received[:300]
    assert b"application/problem+json" in head and b"MICROBEARING_BODY_TIMEOUT_S" in body
    assert server.client.get("/healthz").status_code == 200
