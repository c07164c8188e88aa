"""Crashes: SIGKILL a real server during a sweep job and a surrogate training, restart it, lose nothing.

After the restart on the same data folder the interrupted jobs run again (their inputs are
stored; the run is counted), and a job interrupted a second time is failed with the reason.
SQLite's integrity check passes, the journal is WAL, no half-written model is listed, and every
result completed before the crash is still there, byte for byte. A second test kills a process
in the middle of writing models to the store.
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time

import pytest
from live_server import REPO, Server, wait_for

from microbearing.service.jobs import INTERRUPTED_DETAIL
from microbearing.service.store import DATABASE_NAME, Store

pytestmark = pytest.mark.skipif(os.name != "posix", reason="SIGKILL and process groups are POSIX")

SERVER_SETTINGS = {"sweep_sync_max_points": "0",  # every sweep is a job
                   "max_sweep_points": "4000000", "max_result_bytes": str(2**31), "job_workers": "2",
                   "executor_workers": "1"}


def small_sweep(num: int) -> dict:
    return {"design": "grid", "axes": {"load_N": {"start": 1e-3, "stop": 0.05, "num": num}},
            "fixed": {"balls": 5, "speed_m_s": 0.05}, "outputs": ["mu", "mu_pivoting"]}


#: 4 million points: seconds of work, so that the kill lands while it runs.
BIG_SWEEP = {"design": "grid", "axes": {"load_N": {"start": 1e-3, "stop": 0.05, "num": 2000},
                                        "speed_m_s": {"start": 0.0, "stop": 0.2, "num": 2000}},
             "fixed": {"balls": 5}, "outputs": ["mu"]}
SMALL_SURROGATE = {"space": {"load_N": [1e-3, 0.05]}, "fixed": {"balls": 4, "speed_m_s": 0.05},
                   "budget": 8, "adaptive": False}
#: A tight target and the largest budget keep the adaptive training busy for long.
LONG_SURROGATE = {"space": {"load_N": [1e-4, 0.1], "speed_m_s": [0.0, 0.2], "balls": [2, 40],
                            "groove_angle_deg": [30.0, 80.0]},
                  "fixed": {}, "budget": 1000, "target_relative_error": 1e-6, "adaptive": True}


def attempts(database, job_id: str) -> int:
    """How many runs of the job were started (claims), read from the database."""
    with sqlite3.connect(database) as conn:
        return conn.execute("SELECT attempts FROM jobs WHERE id = ?", (job_id,)).fetchone()[0]


def test_sigkill_during_jobs_loses_nothing(tmp_path):
    data_dir = tmp_path / "data"
    log = tmp_path / "server.log"
    server = Server(data_dir, log, **SERVER_SETTINGS)
    try:
        done = {}
        for num in (5, 7):
            response = server.client.post("/v1/sweeps", json=small_sweep(num))
            assert response.status_code == 202, response.text
            job = wait_for(server, response.headers["location"], ("succeeded",))
            done[job["id"]] = server.client.get(f"/v1/jobs/{job['id']}/result").content
        response = server.client.post("/v1/surrogates", json=SMALL_SURROGATE)
        assert response.status_code == 202, response.text
        trained = wait_for(server, response.headers["location"], ("succeeded",))
        trained_result = server.client.get(f"/v1/jobs/{trained['id']}/result").json()
        surrogate_id = trained_result["id"]
        surrogate_before = server.client.get(f"/v1/surrogates/{surrogate_id}").content
        done[trained["id"]] = server.client.get(f"/v1/jobs/{trained['id']}/result").content

        long_training = server.client.post("/v1/surrogates", json=LONG_SURROGATE)
        big_sweep = server.client.post("/v1/sweeps", json=BIG_SWEEP)
        assert long_training.status_code == 202 and big_sweep.status_code == 202
        wait_for(server, long_training.headers["location"], ("running",))
        sweep_job = wait_for(server, big_sweep.headers["location"], ("running",))
        time.sleep(0.5)  # into the middle of the work
        for location in (long_training.headers["location"], big_sweep.headers["location"]):
            assert server.client.get(location).json()["status"] == "running", "finished before the kill"
    except BaseException:
        server.stop()
        raise
    server.kill()

    database = data_dir / DATABASE_NAME
    restarted = Server(data_dir, log, **SERVER_SETTINGS)
    try:
        # Both interrupted jobs run again from their stored requests, as their second run.
        rerun = wait_for(restarted, big_sweep.headers["location"], ("succeeded", "failed"), timeout_s=300)
        assert rerun["status"] == "succeeded", rerun
        assert attempts(database, sweep_job["id"]) == 2
        assert restarted.client.get(f"/v1/jobs/{sweep_job['id']}").json()["progress"] == 1.0
        training = wait_for(restarted, long_training.headers["location"], ("running",))
        assert attempts(database, training["id"]) == 2
    except BaseException:
        restarted.stop()
        raise
    restarted.kill()  # the second interruption of the training: it is not re-queued again
    restarted = Server(data_dir, log, **SERVER_SETTINGS)
    try:
        job = restarted.client.get(long_training.headers["location"]).json()
        assert job["status"] == "failed" and job["finished_at"], job
        assert job["error"]["detail"].startswith(INTERRUPTED_DETAIL)
        assert "not re-queued again" in job["error"]["detail"]
        for job_id, content in done.items():
            assert restarted.client.get(f"/v1/jobs/{job_id}").json()["status"] == "succeeded"
            assert restarted.client.get(f"/v1/jobs/{job_id}/result").content == content
        listed = restarted.client.get("/v1/surrogates").json()["surrogates"]
        assert [s["id"] for s in listed] == [surrogate_id]  # the interrupted training stored nothing
        assert restarted.client.get(f"/v1/surrogates/{surrogate_id}").content == surrogate_before
        prediction = restarted.client.post(f"/v1/surrogates/{surrogate_id}/predict",
                                           json={"points": {"load_N": [0.01, 0.02]}})
        assert prediction.status_code == 200 and len(prediction.json()["mu"]) == 2
        # The restarted server still does work.
        response = restarted.client.post("/v1/sweeps", json=small_sweep(3))
        assert wait_for(restarted, response.headers["location"], ("succeeded",))["progress"] == 1.0
        with sqlite3.connect(database) as conn:
            assert conn.execute("PRAGMA integrity_check").fetchone() == ("ok",)
            assert conn.execute("PRAGMA journal_mode").fetchone() == ("wal",)
            active = "SELECT COUNT(*) FROM jobs WHERE status IN ('queued', 'running')"
            assert conn.execute(active).fetchone() == (0,)
    finally:
        restarted.stop()


WRITER = textwrap.dedent("""
    import hashlib, json, sys
    import numpy as np
    from microbearing.service.store import Store

    store = Store(sys.argv[1])
    rng = np.random.default_rng(0)
    while True:
        weights = rng.random(200_000)  # ~1.6 MB per model: the kill lands inside a write
        digest = hashlib.sha256(weights.tobytes()).hexdigest()
        model_id = store.save_model("crash-test", {"sha256": digest}, {"weights": weights})
        print(json.dumps({"id": model_id, "sha256": digest}), flush=True)
""")


def test_sigkill_while_writing_models_leaves_only_whole_models(tmp_path):
    process = subprocess.Popen([sys.executable, "-c", WRITER, str(tmp_path)], cwd=REPO,
                               stdout=subprocess.PIPE, text=True, start_new_session=True)
    committed = []
    try:
        for line in process.stdout:
            committed.append(json.loads(line))
            if len(committed) == 12:
                break
    finally:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait(timeout=30)
        process.stdout.close()
    assert len(committed) == 12, "the writer stopped early"
    with sqlite3.connect(tmp_path / DATABASE_NAME) as conn:
        assert conn.execute("PRAGMA integrity_check").fetchone() == ("ok",)
    store = Store(tmp_path)
    try:
        listed = store.list_models("crash-test")
        assert {m["id"] for m in committed} <= {m["id"] for m in listed}  # every commit survived
        for entry in listed:  # and whatever is listed is whole
            model = store.load_model(entry["id"])
            digest = hashlib.sha256(model.arrays["weights"].tobytes()).hexdigest()
            assert digest == model.metadata["sha256"]
    finally:
        store.close()
