"""Races on one resource answer 404, 204 or 200, never 500: concurrent deletes of jobs and surrogates.

A real server (uvicorn) receives bursts of simultaneous DELETEs of the same queued, running and
finished jobs and of the same surrogate, from separate connections. Each burst ends with the
resource in one state: exactly one request deleted it (204), the others found it gone (404) or
cancelled (200).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import httpx
import pytest
from live_server import Server, wait_for

pytestmark = pytest.mark.skipif(os.name != "posix", reason="process groups are POSIX")

LONG_SURROGATE = {"space": {"load_N": [1e-4, 0.1], "speed_m_s": [0.0, 0.2], "balls": [2, 40],
                            "groove_angle_deg": [30.0, 80.0]},
                  "fixed": {}, "budget": 1000, "target_relative_error": 1e-6, "adaptive": True}
SMALL_SURROGATE = {"space": {"load_N": [1e-3, 0.05]}, "fixed": {"balls": 4, "speed_m_s": 0.05},
                   "budget": 8, "adaptive": False}
BURST = 8


def small_sweep(num: int) -> dict:
    return {"design": "grid", "axes": {"load_N": {"start": 1e-3, "stop": 0.05, "num": num}},
            "fixed": {"balls": 5, "speed_m_s": 0.05}, "outputs": ["mu"]}


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    folder = tmp_path_factory.mktemp("races")
    running = Server(folder / "data", folder / "server.log", sweep_sync_max_points="0", job_workers="1",
                     executor_workers="1", shutdown_grace_s="0")
    yield running
    running.stop()


def burst(url: str, path: str, times: int = BURST) -> list[int]:
    """``times`` simultaneous DELETEs of ``path``, each on its own connection; their statuses."""
    def one(_: int) -> int:
        with httpx.Client(base_url=url, timeout=60) as client:
            return client.delete(path).status_code

    with ThreadPoolExecutor(times) as pool:
        return list(pool.map(one, range(times)))


def test_concurrent_deletes_of_queued_running_and_finished_jobs(server):
    blocker = server.client.post("/v1/surrogates", json=LONG_SURROGATE)
    assert blocker.status_code == 202
    wait_for(server, blocker.headers["location"], ("running",))
    seen = set()
    for round_ in range(10):  # queued jobs: the one worker is held by the training
        job = server.client.post("/v1/sweeps", json=small_sweep(3 + round_)).json()
        statuses = burst(server.url, f"/v1/jobs/{job['id']}")
        seen.update(statuses)
        assert set(statuses) <= {200, 204, 404}, statuses
        # One way or another it ends cancelled then deleted: a last DELETE finds it gone or deletes it.
        assert server.client.delete(f"/v1/jobs/{job['id']}").status_code in (204, 404)
        assert server.client.get(f"/v1/jobs/{job['id']}").status_code == 404
    # The running job: all cancel (200) until it is cancelled; then deletes (204 once, 404 after).
    statuses = burst(server.url, blocker.headers["location"])
    assert set(statuses) <= {200, 204, 404}, statuses
    if server.client.get(blocker.headers["location"]).status_code == 200:  # not deleted yet
        wait_for(server, blocker.headers["location"], ("cancelled",), timeout_s=120)
    for _ in range(5):  # finished jobs
        response = server.client.post("/v1/sweeps", json=small_sweep(4))
        job = wait_for(server, response.headers["location"], ("succeeded",))
        statuses = burst(server.url, f"/v1/jobs/{job['id']}")
        assert sorted(statuses) == [204] + [404] * (BURST - 1), statuses
    assert 200 in seen or 204 in seen


def test_concurrent_deletes_of_one_surrogate(server):
    for _ in range(3):
        response = server.client.post("/v1/surrogates", json=SMALL_SURROGATE)
        job = wait_for(server, response.headers["location"], ("succeeded",), timeout_s=180)
        surrogate_id = server.client.get(f"/v1/jobs/{job['id']}/result").json()["id"]
        statuses = burst(server.url, f"/v1/surrogates/{surrogate_id}")
        assert sorted(statuses) == [204] + [404] * (BURST - 1), statuses
        assert server.client.get(f"/v1/surrogates/{surrogate_id}").status_code == 404


# The interleavings themselves, made to happen every time: another request acts between this
# request's read and its write.

def test_a_cancel_whose_job_is_cancelled_and_deleted_meanwhile_answers_404(tmp_path, monkeypatch):
    from fastapi.testclient import TestClient

    from microbearing.service.app import create_app
    from microbearing.service.deps import get_runtime
    from microbearing.service.jobs import FINISHED
    from microbearing.service.settings import Settings
    from microbearing.service.store import utc_now

    settings = Settings(data_dir=tmp_path, sweep_sync_max_points=0, job_workers=1)
    with TestClient(create_app(settings)) as client:
        jobs = get_runtime(client.app).jobs
        monkeypatch.setattr(jobs, "_claim_one", lambda: False)  # nothing starts: the job stays queued
        job = client.post("/v1/sweeps", json=small_sweep(3)).json()
        original = jobs.cancel

        def after_another_request(job_id: str):
            jobs.store.update_job(job_id, status="cancelled", cancel_requested=1, finished_at=utc_now())
            jobs.store.delete_job(job_id, FINISHED)
            return original(job_id)

        monkeypatch.setattr(jobs, "cancel", after_another_request)
        response = client.delete(f"/v1/jobs/{job['id']}")
        assert response.status_code == 404 and response.headers["content-type"] == "application/problem+json"


def test_a_surrogate_deleted_by_another_request_meanwhile_answers_404(tmp_path, monkeypatch):
    from fastapi.testclient import TestClient

    from microbearing.service.app import create_app
    from microbearing.service.deps import get_runtime
    from microbearing.service.settings import Settings

    with TestClient(create_app(Settings(data_dir=tmp_path))) as client:
        store = get_runtime(client.app).store
        surrogate_id = store.save_model("surrogate", {"model": {}}, {})
        original = store.delete_model

        def after_another_request(model_id: str) -> bool:
            original(model_id)  # the other request's deletion wins the race
            return original(model_id)

        monkeypatch.setattr(store, "delete_model", after_another_request)
        response = client.delete(f"/v1/surrogates/{surrogate_id}")
        assert response.status_code == 404 and response.headers["content-type"] == "application/problem+json"
