"""Scale-out as users run it: a ``dask scheduler`` and two ``dask worker`` processes on loopback.

A live server pointed at the scheduler answers a batch, a sweep job and a multi-start
optimization job with the same numbers as the local thread pool. Then one worker is killed
(SIGKILL of its process group) in the middle of a sweep: the scheduler moves its chunks to the
other worker and the job finishes, or fails with a reason; it never hangs.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from jobs_helper import wait_job
from live_server import REPO, Server, free_port, wait_for

from microbearing import physics
from microbearing.calibrate import CalibratedModel
from microbearing.service.app import create_app
from microbearing.service.settings import Settings
from microbearing.service.store import Store

DASK = shutil.which("dask", path=str(Path(sys.executable).parent)) or shutil.which("dask")
pytestmark = [pytest.mark.skipif(os.name != "posix", reason="process groups are POSIX"),
              pytest.mark.skipif(DASK is None, reason="the dask command (the 'dask' extra) is not installed")]

RNG = np.random.default_rng(11)
BATCH = {"points": {"balls": 7, "load_N": RNG.uniform(1e-3, 0.05, 70_000).tolist(),
                    "speed_m_s": RNG.uniform(0.0, 0.2, 70_000).tolist()},
         "outputs": ["mu", "contact_radius_m"]}
SWEEP = {"design": "grid", "axes": {"load_N": {"start": 1e-3, "stop": 0.1, "num": 300, "spacing": "log"},
                                    "speed_m_s": {"start": 0.0, "stop": 0.2, "num": 300}},
         "fixed": {"balls": 6}, "outputs": ["mu", "mu_rolling"]}
#: 1.5 million points in 23 chunks: the kill lands while chunks are still out on the workers.
LONG_SWEEP = {"design": "sobol", "points": 1_500_000, "seed": 5, "outputs": ["mu"],
              "ranges": {"load_N": {"low": 1e-3, "high": 0.05}}, "fixed": {"balls": 4, "speed_m_s": 0.05}}


def optimization(model_id: str) -> dict:
    return {"bounds": {"balls": [3, 40], "groove_angle_deg": [40, 60], "load_N": [0.001, 0.05]},
            "speed_m_s": 0.05, "model": f"calibrated:{model_id}", "starts": 2}


class Process:
    """A command in its own process group, its output in a log file."""

    def __init__(self, args: list[str], log: Path):
        self.log = log.open("ab")
        env = {**os.environ, "MICROBEARING_PHYSICS_THREADS": "1"}
        self.process = subprocess.Popen(args, cwd=REPO, env=env, stdout=self.log, stderr=subprocess.STDOUT,
                                        start_new_session=True)

    def kill(self) -> None:
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGKILL)
        self.process.wait(timeout=30)
        self.log.close()


def wait_for_workers(address: str, count: int, timeout_s: float = 120.0) -> None:
    from distributed import Client

    with Client(address, timeout=timeout_s) as client:
        client.wait_for_workers(count, timeout=timeout_s)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    folder = tmp_path_factory.mktemp("dask")
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    scheduler = Process([DASK, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                        folder / "scheduler.log")
    workers = [Process([DASK, "worker", address, "--nthreads", "1", "--no-dashboard", "--no-nanny",
                        "--memory-limit", "0", "--name", f"worker-{i}", "--local-directory",
                        str(folder / f"w{i}")], folder / f"worker-{i}.log") for i in range(2)]
    try:
        wait_for_workers(address, 2)
        yield address, workers, folder
    finally:
        for process in (*workers, scheduler):
            process.kill()


def test_a_real_cluster_answers_as_the_local_pool_and_survives_a_killed_worker(cluster, tmp_path):
    address, workers, folder = cluster
    data_dir = tmp_path / "data"
    store = Store(data_dir)  # a calibrated model (the physics with mu_pivot 0.8) for the optimization
    model_id = store.save_model("calibration", {"model": CalibratedModel(fitted={"mu_pivot": 0.8}).to_json()},
                                {})
    store.close()
    local_dir = tmp_path / "local"
    shutil.copytree(data_dir, local_dir)

    # The local thread pool, in process: the reference answers.
    settings = Settings(data_dir=local_dir, sweep_sync_max_points=0, max_sweep_points=2_000_000)
    with TestClient(create_app(settings)) as client:
        local_batch = client.post("/v1/friction/batch", json=BATCH).content
        status = wait_job(client, client.post("/v1/sweeps", json=SWEEP).headers["location"], timeout_s=600)
        local_sweep = client.get(status["result_url"]).content
        location = client.post("/v1/optimizations", json=optimization(model_id)).headers["location"]
        status = wait_job(client, location, timeout_s=600)
        local_optimization = client.get(status["result_url"]).json()

    server = Server(data_dir, folder / "server.log", dask_scheduler=address, sweep_sync_max_points="0",
                    max_sweep_points="2000000", job_workers="1")
    try:
        batch = server.client.post("/v1/friction/batch", json=BATCH)
        assert batch.status_code == 200, batch.text
        assert batch.content == local_batch  # byte for byte
        expected = physics.evaluate(balls=7, load_N=np.array(BATCH["points"]["load_N"]),
                                    speed_m_s=np.array(BATCH["points"]["speed_m_s"]))
        np.testing.assert_array_equal(json.loads(batch.content)["mu"], expected.mu)

        sweep = server.client.post("/v1/sweeps", json=SWEEP)
        assert sweep.status_code == 202, sweep.text
        done = wait_for(server, sweep.headers["location"], ("succeeded", "failed"))
        assert done["status"] == "succeeded", done
        assert server.client.get(done["result_url"]).content == local_sweep

        response = server.client.post("/v1/optimizations", json=optimization(model_id))
        assert response.status_code == 202, response.text
        done = wait_for(server, response.headers["location"], ("succeeded", "failed"), timeout_s=300)
        assert done["status"] == "succeeded", done
        remote = server.client.get(done["result_url"]).json()
        for field in ("design", "mu", "per_ball_count", "constraints"):
            assert remote.get(field) == local_optimization.get(field), field

        # Kill one worker while it computes chunks of the long sweep (as the scheduler reports).
        from distributed import Client

        with Client(address, timeout=60) as observer:
            response = server.client.post("/v1/sweeps", json=LONG_SWEEP)
            assert response.status_code == 202, response.text
            location = response.headers["location"]
            deadline = time.monotonic() + 120
            while True:
                workers_info = observer.scheduler_info()["workers"]
                names = {worker: info["name"] for worker, info in workers_info.items()}
                busy = {names.get(worker) for worker, tasks in observer.processing().items() if tasks}
                if "worker-0" in busy:
                    break
                job = server.client.get(location).json()
                assert job["status"] in ("queued", "running"), f"the sweep ended before the kill: {job}"
                assert time.monotonic() < deadline, "worker-0 never got a chunk"
                time.sleep(0.005)
        workers[0].kill()
        killed_at = server.client.get(location).json()
        finished = wait_for(server, location, ("succeeded", "failed"), timeout_s=300)
        print(f"killed a worker computing chunks, the job at progress {killed_at['progress']:.2f}: "
              f"it {finished['status']}")
        if finished["status"] == "failed":  # allowed, with a reason
            assert finished["error"]["detail"], finished
        else:
            table = server.client.get(finished["result_url"]).json()["columns"]
            load = np.array(table["load_N"])
            assert len(load) == LONG_SWEEP["points"]
            mu = physics.evaluate(balls=4, speed_m_s=0.05, load_N=load, outputs=["mu"]).mu
            np.testing.assert_array_equal(table["mu"], mu)
        assert server.client.get("/healthz").status_code == 200
    finally:
        server.stop()
