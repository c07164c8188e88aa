"""Two real ``microbearing serve`` processes on one PostgreSQL database, each with its own data folder.

As two hosts would run them: nothing is shared but the database (``MICROBEARING_DATABASE_URL``).
Admission limits count both servers' jobs, a queued job cancelled through the other server frees
its place at once, a model stored by one is served and deleted by the other, and a job of a server
killed with SIGKILL is re-queued by the other. Skipped, with the reason, without PostgreSQL.
"""

from __future__ import annotations

import os
import signal
import sys
import time
from pathlib import Path

import pytest
from live_server import Server, wait_for

pytestmark = pytest.mark.skipif(os.name != "posix", reason="SIGKILL and process groups are POSIX")

KEYS = ("postgres-key-alpha-0123", "postgres-key-beta-45678")
LONG_SURROGATE = {"space": {"load_N": [1e-4, 0.1], "speed_m_s": [0.0, 0.2], "balls": [2, 40],
                            "groove_angle_deg": [30.0, 80.0]},
                  "fixed": {}, "budget": 1000, "target_relative_error": 1e-6, "adaptive": True}
SMALL_SURROGATE = {"space": {"load_N": [0.001, 0.05], "speed_m_s": [0.001, 0.2]}, "fixed": {"balls": 4},
                   "budget": 12}


def auth(key: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {key}"}


class Serve(Server):
    """``microbearing serve`` on a free loopback port, with its own data folder, in its own process group."""

    def command(self, data_dir: Path) -> list[str]:
        return [sys.executable, "-m", "microbearing.service.cli", "serve", "--port", str(self.port),
                "--data-dir", str(data_dir)]


def owner(url: str, job_id: str) -> tuple[str, int, int]:
    """Status, owning pid and started runs of a job, read from the database itself."""
    import psycopg

    with psycopg.connect(url) as conn:
        query = "SELECT status, owner_pid, attempts FROM jobs WHERE id = %s"
        return conn.execute(query, (job_id,)).fetchone()


def test_two_servers_on_one_postgresql_database(postgres_url, tmp_path):
    settings = {"database_url": postgres_url, "api_keys": ",".join(KEYS), "max_active_jobs": "3",
                "max_active_jobs_per_key": "2", "job_workers": "1", "executor_workers": "1",
                "job_lease_s": "3", "shutdown_grace_s": "0", "database_pool_size": "4"}
    first = Serve(tmp_path / "host-a", tmp_path / "a.log", **settings)
    try:
        second = Serve(tmp_path / "host-b", tmp_path / "b.log", **settings)
    except BaseException:
        first.stop()
        raise
    alpha, beta = auth(KEYS[0]), auth(KEYS[1])
    try:
        # A model stored through one server is served, and deleted, through the other.
        made = first.client.post("/v1/surrogates", json=SMALL_SURROGATE, headers=alpha)
        assert made.status_code == 202, made.text
        surrogate = wait_for(first, made.headers["location"], ("succeeded", "failed"), headers=alpha)
        assert surrogate["status"] == "succeeded", surrogate
        surrogate_id = first.client.get(surrogate["result_url"], headers=alpha).json()["id"]
        seen = second.client.get(f"/v1/surrogates/{surrogate_id}", headers=alpha)
        assert seen.status_code == 200 and seen.json()["id"] == surrogate_id
        assert second.client.get(f"/v1/surrogates/{surrogate_id}", headers=beta).status_code == 404
        assert second.client.delete(f"/v1/surrogates/{surrogate_id}", headers=alpha).status_code == 204
        assert first.client.get(f"/v1/surrogates/{surrogate_id}", headers=alpha).status_code == 404

        # The key's limit of 2 counts both servers' jobs.
        on_first = first.client.post("/v1/surrogates", json=LONG_SURROGATE, headers=alpha)
        on_second = second.client.post("/v1/surrogates", json=LONG_SURROGATE, headers=alpha)
        assert on_first.status_code == 202 and on_second.status_code == 202, (on_first.text, on_second.text)
        for server in (first, second):
            refused = server.client.post("/v1/surrogates", json=LONG_SURROGATE, headers=alpha)
            assert refused.status_code == 429 and "MICROBEARING_MAX_ACTIVE_JOBS_PER_KEY=2" in refused.text
        running = [wait_for(s, r.headers["location"], ("running",), headers=alpha)["id"]
                   for s, r in ((first, on_first), (second, on_second))]
        queued = second.client.post("/v1/surrogates", json=LONG_SURROGATE, headers=beta)
        assert queued.status_code == 202
        full = first.client.post("/v1/surrogates", json=LONG_SURROGATE, headers=beta)
        assert full.status_code == 503 and "MICROBEARING_MAX_ACTIVE_JOBS=3" in full.text
        # A queued job cancelled through the other server: cancelled at once, its place free at once.
        assert first.client.delete(queued.headers["location"], headers=beta).json()["status"] == "cancelled"
        again = first.client.post("/v1/surrogates", json=LONG_SURROGATE, headers=beta)
        assert again.status_code == 202, again.text
        assert second.client.delete(again.headers["location"], headers=beta).json()["status"] == "cancelled"

        # Each server runs one job; SIGKILL the first: the second re-queues its job (a job of this host
        # is found by its dead pid at the next heartbeat, 1 s; of another host, when its lease lapses).
        pids = {owner(postgres_url, job_id)[1] for job_id in running}
        assert pids == {first.process.pid, second.process.pid}
        victim = next(job_id for job_id in running if owner(postgres_url, job_id)[1] == first.process.pid)
        os.killpg(first.process.pid, signal.SIGKILL)
        first.process.wait(timeout=30)
        started = time.monotonic()
        while (row := owner(postgres_url, victim))[0] != "queued":  # the second's one worker is busy
            assert time.monotonic() - started < 1 + 0.5 + 5, row
            time.sleep(0.05)
        assert row[2] == 1  # re-queued for its second run, which any server may claim
        job = second.client.get(f"/v1/jobs/{victim}", headers=alpha).json()
        assert job["status"] == "queued" and job.get("error") is None
        # Neither server wrote a SQLite database: the data folders hold no jobs.
        assert not list(tmp_path.glob("host-*/*.sqlite3"))
    finally:
        for server in (first, second):  # killed: a graceful stop would wait for the training's next check
            if server.process.poll() is None:
                os.killpg(server.process.pid, signal.SIGKILL)
            server.stop()
