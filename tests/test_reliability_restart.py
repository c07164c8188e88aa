"""Restarts lose no submitted work: a real server stopped by SIGTERM or SIGKILL with jobs queued and running.

A job that never started is still queued after the restart and runs then (its inputs are
stored); a job interrupted while running is queued again (SIGTERM: after the grace period, the
run not counted; SIGKILL: found by the next start, counted as its first run). A job that ends
within the grace period of a SIGTERM finishes before the process exits.
"""

from __future__ import annotations

import os
import signal
import sqlite3
import time

import numpy as np
import pytest
from live_server import Server, wait_for

from microbearing.service.store import DATABASE_NAME

pytestmark = pytest.mark.skipif(os.name != "posix", reason="SIGKILL and process groups are POSIX")

SETTINGS = {"sweep_sync_max_points": "0", "job_workers": "1", "executor_workers": "1",
            "max_sweep_points": "4000000", "max_result_bytes": str(2**31)}
#: A tight target and the largest budget keep the adaptive training busy for long.
LONG_SURROGATE = {"space": {"load_N": [1e-4, 0.1], "speed_m_s": [0.0, 0.2], "balls": [2, 40],
                            "groove_angle_deg": [30.0, 80.0]},
                  "fixed": {}, "budget": 1000, "target_relative_error": 1e-6, "adaptive": True}
#: 4 million points: seconds of work.
BIG_SWEEP = {"design": "grid", "axes": {"load_N": {"start": 1e-3, "stop": 0.05, "num": 2000},
                                        "speed_m_s": {"start": 0.0, "stop": 0.2, "num": 2000}},
             "fixed": {"balls": 5}, "outputs": ["mu"]}


def small_sweep(num: int) -> dict:
    return {"design": "grid", "axes": {"load_N": {"start": 1e-3, "stop": 0.05, "num": num}},
            "fixed": {"balls": 5, "speed_m_s": 0.05}, "outputs": ["mu"]}


def rows(database, *job_ids: str) -> dict[str, tuple[str, int]]:
    """Status and number of started runs of each job, read from the database."""
    with sqlite3.connect(database) as conn:
        marks = ", ".join("?" for _ in job_ids)
        found = conn.execute(f"SELECT id, status, attempts FROM jobs WHERE id IN ({marks})", job_ids)
        return {job_id: (status, attempts) for job_id, status, attempts in found}


@pytest.mark.parametrize("how", ["SIGTERM", "SIGKILL"])
def test_queued_jobs_stay_queued_and_run_after_a_restart(tmp_path, how):
    data_dir = tmp_path / "data"
    log = tmp_path / "server.log"
    server = Server(data_dir, log, shutdown_grace_s="1", **SETTINGS)
    try:
        long = server.client.post("/v1/surrogates", json=LONG_SURROGATE)
        assert long.status_code == 202, long.text
        long_id = wait_for(server, long.headers["location"], ("running",))["id"]
        sweeps = {}
        for num in (3, 4, 5, 6, 7):  # one worker, held by the training: all five wait
            response = server.client.post("/v1/sweeps", json=small_sweep(num))
            assert response.status_code == 202, response.text
            sweeps[response.json()["id"]] = num
        for job_id in sweeps:
            assert server.client.get(f"/v1/jobs/{job_id}").json()["status"] == "queued"
    except BaseException:
        server.stop()
        raise
    started = time.monotonic()
    if how == "SIGTERM":
        server.stop()
        # The grace period (1 s) passes, the training is stopped at its next progress check.
        assert time.monotonic() - started < 25
    else:
        server.kill()

    database = data_dir / DATABASE_NAME
    after = rows(database, long_id, *sweeps)
    assert all(after[job_id] == ("queued", 0) for job_id in sweeps), after
    if how == "SIGTERM":  # re-queued by the shutdown, the interrupted run not counted
        assert after[long_id] == ("queued", 0), after
    else:  # left running by the killed process; the next start re-queues it
        assert after[long_id] == ("running", 1), after

    restarted = Server(data_dir, log, **{**SETTINGS, "job_workers": "2"})
    try:
        for job_id, num in sweeps.items():
            job = wait_for(restarted, f"/v1/jobs/{job_id}", ("succeeded", "failed", "cancelled"))
            assert job["status"] == "succeeded", job
            result = restarted.client.get(f"/v1/jobs/{job_id}/result").json()
            assert result["count"] == num
            assert np.allclose(result["columns"]["load_N"], np.linspace(1e-3, 0.05, num), rtol=1e-15)
            assert all(0 < mu < 1 for mu in result["columns"]["mu"])
        training = wait_for(restarted, f"/v1/jobs/{long_id}", ("running",))
        assert rows(database, long_id)[long_id] == ("running", 1 if how == "SIGTERM" else 2)
        assert restarted.client.delete(f"/v1/jobs/{long_id}").json()["cancel_requested"] is True
        assert wait_for(restarted, f"/v1/jobs/{training['id']}", ("cancelled",))["status"] == "cancelled"
    finally:
        restarted.stop()


def test_a_job_that_ends_within_the_grace_period_finishes_before_the_process_exits(tmp_path):
    data_dir = tmp_path / "data"
    server = Server(data_dir, tmp_path / "server.log", shutdown_grace_s="120", **SETTINGS)
    try:
        response = server.client.post("/v1/sweeps", json=BIG_SWEEP)
        assert response.status_code == 202, response.text
        job_id = wait_for(server, response.headers["location"], ("running",))["id"]
    except BaseException:
        server.stop()
        raise
    os.killpg(server.process.pid, signal.SIGTERM)
    server.process.wait(timeout=150)
    server.stop()
    assert rows(data_dir / DATABASE_NAME, job_id)[job_id] == ("succeeded", 1)
