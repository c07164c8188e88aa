"""Several server processes on one data folder: one truth for admission, claiming, leases and cancellation.

Two real servers (``uvicorn`` on two ports) share a folder; ``microbearing serve --workers 2``
runs two worker processes behind one port. Limits count every process's jobs; a cancellation sent
to any process reaches the process running the job and frees a queued job's place at once; a job
whose process stops renewing its lease (SIGSTOP) is taken over by another process within the
stated time, and the stopped process, resumed, gives up its run; a job whose process is killed is
found at once by the pid check.
"""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time

import httpx
import pytest
from live_server import REPO, Server, free_port, wait_for

from microbearing.service.store import DATABASE_NAME

pytestmark = pytest.mark.skipif(os.name != "posix", reason="SIGSTOP, SIGKILL and process groups are POSIX")

KEYS = ("scaleout-key-alpha-0123", "scaleout-key-beta-45678")
#: A tight target and the largest budget keep the adaptive training busy for long.
LONG_SURROGATE = {"space": {"load_N": [1e-4, 0.1], "speed_m_s": [0.0, 0.2], "balls": [2, 40],
                            "groove_angle_deg": [30.0, 80.0]},
                  "fixed": {}, "budget": 1000, "target_relative_error": 1e-6, "adaptive": True}


def auth(key: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {key}"}


def owner(database, job_id: str) -> tuple[str, int, int]:
    """Status, owning pid and started runs of a job, from the database."""
    with sqlite3.connect(database) as conn:
        return conn.execute("SELECT status, owner_pid, attempts FROM jobs WHERE id = ?", (job_id,)).fetchone()


def wait_owner(database, job_id: str, status: str, not_pid: int | None,
               timeout_s: float) -> tuple[float, tuple]:
    """Seconds until the job has ``status`` in a process other than ``not_pid``, and its row."""
    started = time.monotonic()
    while True:
        row = owner(database, job_id)
        if row[0] == status and row[1] != not_pid:
            return time.monotonic() - started, row
        assert time.monotonic() - started < timeout_s, f"job {job_id} stayed {row}"
        time.sleep(0.05)


@pytest.fixture
def two_servers(tmp_path):
    data_dir = tmp_path / "data"
    settings = {"api_keys": ",".join(KEYS), "max_active_jobs": "3", "max_active_jobs_per_key": "2",
                "job_workers": "1", "executor_workers": "1", "job_lease_s": "3", "shutdown_grace_s": "0"}
    first = Server(data_dir, tmp_path / "first.log", **settings)
    try:
        second = Server(data_dir, tmp_path / "second.log", **settings)
    except BaseException:
        first.stop()
        raise
    try:
        yield first, second, data_dir / DATABASE_NAME
    finally:
        for server in (first, second):
            if server.process.poll() is None:
                os.killpg(server.process.pid, signal.SIGCONT)
            server.stop()


def test_limits_and_cancellation_hold_across_two_servers(two_servers):
    first, second, database = two_servers
    alpha, beta = auth(KEYS[0]), auth(KEYS[1])
    on_first = first.client.post("/v1/surrogates", json=LONG_SURROGATE, headers=alpha)
    on_second = second.client.post("/v1/surrogates", json=LONG_SURROGATE, headers=alpha)
    assert on_first.status_code == 202 and on_second.status_code == 202, (on_first.text, on_second.text)
    # The key's limit of 2 counts both servers' jobs: a third is refused by either.
    for server in (first, second):
        refused = server.client.post("/v1/surrogates", json=LONG_SURROGATE, headers=alpha)
        assert refused.status_code == 429 and "MICROBEARING_MAX_ACTIVE_JOBS_PER_KEY=2" in refused.text
    # Each server has one worker: both run one job, so beta's waits queued (wherever it was sent).
    running = [wait_for(s, r.headers["location"], ("running",), headers=alpha)
               for s, r in ((first, on_first), (second, on_second))]
    queued = second.client.post("/v1/surrogates", json=LONG_SURROGATE, headers=beta)
    assert queued.status_code == 202
    full = first.client.post("/v1/surrogates", json=LONG_SURROGATE, headers=beta)
    assert full.status_code == 503 and "MICROBEARING_MAX_ACTIVE_JOBS=3" in full.text  # 3 in the folder
    assert first.client.get(queued.headers["location"], headers=beta).json()["status"] == "queued"

    # A queued job cancelled through the other server: cancelled at once, its place free at once.
    cancelled = first.client.delete(queued.headers["location"], headers=beta).json()
    assert cancelled["status"] == "cancelled"
    again = first.client.post("/v1/surrogates", json=LONG_SURROGATE, headers=beta)
    assert again.status_code == 202, again.text
    assert first.client.delete(again.headers["location"], headers=beta).json()["status"] == "cancelled"

    # A running job cancelled through the server that does not run it.
    job_on_first = running[0]["id"]
    assert owner(database, job_on_first)[1] == first.process.pid
    assert second.client.delete(f"/v1/jobs/{job_on_first}", headers=alpha).json()["cancel_requested"] is True
    # Seen by the first server at its next heartbeat (1 s here); the training stops at its next
    # progress check (a Gaussian-process fit of seconds on a busy host).
    assert wait_for(first, f"/v1/jobs/{job_on_first}", ("cancelled",), headers=alpha, timeout_s=60)
    second.client.delete(f"/v1/jobs/{running[1]['id']}", headers=alpha)
    wait_for(second, f"/v1/jobs/{running[1]['id']}", ("cancelled",), headers=alpha, timeout_s=60)


def test_a_stopped_servers_job_is_taken_over_within_the_lease_and_a_killed_ones_at_once(two_servers):
    first, second, database = two_servers
    alpha = auth(KEYS[0])
    response = first.client.post("/v1/surrogates", json=LONG_SURROGATE, headers=alpha)
    assert response.status_code == 202
    job_id = wait_for(first, response.headers["location"], ("running",), headers=alpha)["id"]
    assert owner(database, job_id)[1] == first.process.pid

    # SIGSTOP: the process is alive (its pid answers) but renews nothing; the lease (3 s) lapses.
    os.killpg(first.process.pid, signal.SIGSTOP)
    taken, row = wait_owner(database, job_id, "running", first.process.pid, timeout_s=30)
    assert row[1] == second.process.pid and row[2] == 2  # the second run, on the other server
    assert taken <= 3 * 4 / 3 + 0.5 + 1.5, taken  # lease + heartbeat + claim poll, + slack for a busy host
    # Resumed, the first server finds it lost the lease and stops its own run; it writes nothing.
    os.killpg(first.process.pid, signal.SIGCONT)
    time.sleep(3.0)
    assert owner(database, job_id)[:2] == ("running", second.process.pid)
    assert first.client.get(f"/v1/jobs/{job_id}", headers=alpha).json()["status"] == "running"

    # SIGKILL: the pid check finds the dead owner at the next heartbeat (1 s); this was the job's
    # second run, so it is failed with the reason rather than re-queued a second time.
    started = time.monotonic()
    os.killpg(second.process.pid, signal.SIGKILL)
    second.process.wait(timeout=30)
    job = wait_for(first, f"/v1/jobs/{job_id}", ("failed",), headers=alpha, timeout_s=30)
    assert time.monotonic() - started < 1 + 0.5 + 2.0
    assert "its server process is gone" in job["error"]["detail"]
    assert "not re-queued again" in job["error"]["detail"]


def test_two_uvicorn_workers_share_limits_and_recover_a_killed_workers_job(tmp_path):
    port = free_port()
    data_dir = tmp_path / "data"
    env = {**os.environ, "MICROBEARING_API_KEYS": KEYS[0], "MICROBEARING_MAX_ACTIVE_JOBS_PER_KEY": "4",
           "MICROBEARING_JOB_WORKERS": "1", "MICROBEARING_EXECUTOR_WORKERS": "1",
           "MICROBEARING_SHUTDOWN_GRACE_S": "0"}
    env.pop("PROMETHEUS_MULTIPROC_DIR", None)
    log = (tmp_path / "server.log").open("wb")
    process = subprocess.Popen(
        [sys.executable, "-m", "microbearing.service.cli", "serve", "--workers", "2", "--port", str(port),
         "--data-dir", str(data_dir)],
        cwd=REPO, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    url = f"http://127.0.0.1:{port}"
    alpha = auth(KEYS[0])
    try:
        deadline = time.monotonic() + 90
        while True:
            try:
                if httpx.get(f"{url}/healthz", timeout=5).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            assert process.poll() is None and time.monotonic() < deadline, "the server did not start"
            time.sleep(0.2)
        time.sleep(2.0)  # both workers up
        # Fresh connections spread the requests over both workers; the key's 4 places are shared.
        answers = [httpx.post(f"{url}/v1/surrogates", json=LONG_SURROGATE, headers=alpha, timeout=30)
                   for _ in range(10)]
        assert [a.status_code for a in answers].count(202) == 4, [a.status_code for a in answers]
        assert {a.status_code for a in answers} == {202, 429}
        ids = [a.json()["id"] for a in answers if a.status_code == 202]
        database = data_dir / DATABASE_NAME
        deadline = time.monotonic() + 60
        while sum(owner(database, i)[0] == "running" for i in ids) < 2:  # one per worker
            assert time.monotonic() < deadline
            time.sleep(0.1)
        running = [i for i in ids if owner(database, i)[0] == "running"]
        pids = {owner(database, i)[1] for i in running}
        assert len(pids) == 2, pids  # claimed by both workers
        victim = running[0]
        killed = owner(database, victim)[1]
        os.kill(killed, signal.SIGKILL)
        # The other worker (or the one uvicorn starts instead) re-queues it within a heartbeat.
        wait_owner(database, victim, "running", killed, timeout_s=30)
        assert owner(database, victim)[2] == 2
        for job_id in ids:
            httpx.delete(f"{url}/v1/jobs/{job_id}", headers=alpha, timeout=30)
        deadline = time.monotonic() + 60
        while any(owner(database, i)[0] != "cancelled" for i in ids):
            assert time.monotonic() < deadline, [owner(database, i) for i in ids]
            time.sleep(0.1)
    finally:
        os.killpg(process.pid, signal.SIGTERM)
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait(timeout=30)
        log.close()
