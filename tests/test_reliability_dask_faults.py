"""A dask cluster that fails under a live server: real ``dask scheduler`` / ``dask worker`` processes, killed.

One server (``MICROBEARING_DASK_FAULT_TIMEOUT_S=15``) meets, in turn:

1. the scheduler killed in the middle of a sweep: the job fails within the fault timeout with a
   reason naming the scheduler; ``/readyz`` and ``/v1/friction/batch`` answer 503 naming it;
2. a new scheduler on the same address: ``/readyz`` is ready again and a batch has the physics'
   numbers (the service reconnected on its own);
3. the scheduler killed mid-sweep (its worker stopped first, so that the chunks are still out) and
   back within the fault timeout: the chunks it dropped are submitted again and the sweep succeeds
   with the physics' numbers;
4. the only worker killed: ``/readyz`` 503 (no workers), and a sweep waiting on it fails within
   the fault timeout;
5. SIGTERM while a sweep waits on that worker-less cluster: the server exits within 10 s.
"""

from __future__ import annotations

import os
import signal
import time

import numpy as np
import pytest
from jobs_helper import wait_job
from live_server import Server, free_port, wait_for
from test_reliability_dask import DASK, Process, wait_for_workers

from microbearing import physics
from microbearing.service.sweeps import CHUNK_POINTS

pytestmark = [pytest.mark.skipif(os.name != "posix", reason="process groups are POSIX"),
              pytest.mark.skipif(DASK is None, reason="the dask command (the 'dask' extra) is not installed")]

FAULT_TIMEOUT_S = 15.0
#: Slack for one tick of the wait, one look at the cluster a second, and a loaded machine [s].
SLACK_S = 10.0
#: 1.5 million points in 23 chunks, on one single-threaded worker: several seconds of work.
LONG_SWEEP = {"design": "sobol", "points": 1_500_000, "seed": 5, "outputs": ["mu"],
              "ranges": {"load_N": {"low": 1e-3, "high": 0.05}}, "fixed": {"balls": 4, "speed_m_s": 0.05}}
BATCH = {"points": {"balls": 5, "load_N": np.linspace(1e-3, 0.05, 1000).tolist(), "speed_m_s": 0.02},
         "outputs": ["mu"]}


def start_scheduler(port: int, folder, n: int) -> Process:
    return Process([DASK, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                   folder / f"scheduler-{n}.log")


def start_worker(address: str, folder, n: int) -> Process:
    return Process([DASK, "worker", address, "--nthreads", "1", "--no-dashboard", "--no-nanny",
                    "--memory-limit", "0", "--name", f"worker-{n}",
                    "--local-directory", str(folder / f"w{n}")], folder / f"worker-{n}.log")


def running_with_progress(server: Server, location: str, timeout_s: float = 120.0) -> dict:
    """Wait until the job is running and has finished a chunk (so chunks are out on the cluster)."""
    job = wait_job(server.client, location, timeout_s=timeout_s, interval_s=0.02,
                   until=lambda job: job["status"] not in ("queued", "running") or job["progress"] > 0)
    assert job["status"] == "running", f"the sweep ended too early: {job}"
    return job


def tasks_on_scheduler(address: str, count: int, timeout_s: float = 60.0) -> None:
    """Wait until the scheduler at ``address`` holds ``count`` tasks (a job's chunks are all out)."""
    from distributed import Client

    deadline = time.monotonic() + timeout_s
    with Client(address, timeout=timeout_s) as client:
        while client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks)) < count:
            assert time.monotonic() < deadline, f"fewer than {count} tasks reached the scheduler"
            time.sleep(0.05)


def wait_ready(server: Server, timeout_s: float = 90.0) -> None:
    deadline = time.monotonic() + timeout_s
    while (answer := server.client.get("/readyz")).status_code != 200:
        assert time.monotonic() < deadline, answer.text
        time.sleep(0.5)


def check_sweep(server: Server, job: dict) -> None:
    table = server.client.get(job["result_url"]).json()["columns"]
    load = np.array(table["load_N"])
    assert len(load) == LONG_SWEEP["points"]
    np.testing.assert_array_equal(table["mu"], physics.evaluate(balls=4, speed_m_s=0.05, load_N=load).mu)


def lose_the_scheduler_mid_sweep(server: Server, processes: list, port: int, folder, n: int,
                                 tasks: int) -> list:
    """Stop the worker, start a long sweep, kill scheduler and worker once ``tasks`` of its chunks reached
    the scheduler, start new ones (``n``: their log names); the sweep must succeed with the physics'
    numbers. Returns the new processes."""
    address = f"tcp://127.0.0.1:{port}"
    os.killpg(processes[1].process.pid, signal.SIGSTOP)
    location = server.client.post("/v1/sweeps", json=LONG_SWEEP).headers["location"]
    tasks_on_scheduler(address, tasks)
    for process in processes:
        process.kill()
    processes = [start_scheduler(port, folder, n), start_worker(address, folder, n)]
    done = wait_for(server, location, ("succeeded", "failed", "cancelled"), timeout_s=180)
    assert done["status"] == "succeeded", done
    check_sweep(server, done)
    return processes


def test_a_lost_scheduler_or_worker_fails_in_time_and_the_service_reconnects(tmp_path):
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    processes = [start_scheduler(port, tmp_path, 1), start_worker(address, tmp_path, 1)]
    server = None
    try:
        wait_for_workers(address, 1)
        server = Server(tmp_path / "data", tmp_path / "server.log", dask_scheduler=address,
                        dask_fault_timeout_s=str(FAULT_TIMEOUT_S), sweep_sync_max_points="0",
                        max_sweep_points="2000000", job_workers="1")
        wait_ready(server)

        # 1. The scheduler dies mid-sweep: the job fails in time, naming it; readyz and batches 503.
        location = server.client.post("/v1/sweeps", json=LONG_SWEEP).headers["location"]
        running_with_progress(server, location)
        for process in processes:
            process.kill()
        killed = time.monotonic()
        failed = wait_for(server, location, ("succeeded", "failed", "cancelled"),
                          timeout_s=FAULT_TIMEOUT_S + SLACK_S)
        took = time.monotonic() - killed
        print(f"scheduler killed: the job {failed['status']} after {took:.1f} s: {failed.get('error')}")
        assert failed["status"] == "failed", failed
        assert failed["error"]["status"] == 503 and address in failed["error"]["detail"], failed
        ready = server.client.get("/readyz")
        assert ready.status_code == 503 and address in ready.json()["detail"], ready.text
        assert ready.headers["content-type"] == "application/problem+json"
        batch = server.client.post("/v1/friction/batch", json=BATCH)
        assert batch.status_code == 503 and address in batch.json()["detail"], batch.text

        # 2. A scheduler on the same address again: ready, and batches have the physics' numbers.
        processes = [start_scheduler(port, tmp_path, 2), start_worker(address, tmp_path, 2)]
        wait_for_workers(address, 1)
        wait_ready(server)
        batch = server.client.post("/v1/friction/batch", json=BATCH)
        assert batch.status_code == 200, batch.text
        expected = physics.evaluate(balls=5, speed_m_s=0.02, load_N=np.array(BATCH["points"]["load_N"])).mu
        np.testing.assert_array_equal(batch.json()["mu"], expected)

        # 3. The scheduler dies mid-sweep and is back within the fault timeout: the sweep succeeds.
        # The warm worker would run the 1.5M points in about a second, so it is stopped (SIGSTOP) first:
        # the chunks go out to the scheduler and wait there until the kill, which they cannot outrun.
        processes = lose_the_scheduler_mid_sweep(server, processes, port, tmp_path, 3,
                                                 -(-LONG_SWEEP["points"] // CHUNK_POINTS))  # every chunk out
        assert "submitted again" in server.log_path.read_text(errors="replace")

        # 3b. The same, but the scheduler dies as soon as the first chunk reaches it, while the service may
        # still be submitting the others (a submit then meets the reconnecting connection): the refused
        # chunks go out again with the lost ones, and the sweep succeeds.
        processes = lose_the_scheduler_mid_sweep(server, processes, port, tmp_path, 4, 1)
        refused = server.log_path.read_text(errors="replace").count("could not be submitted")
        print(f"scheduler killed at the first chunk: {refused} submit(s) refused meanwhile, sent again")

        # 4. The only worker dies: not ready (no workers), and a sweep fails within the fault timeout.
        processes[1].kill()
        deadline = time.monotonic() + 60
        while (ready := server.client.get("/readyz")).status_code != 503:
            assert time.monotonic() < deadline, ready.text
            time.sleep(0.5)
        assert "no workers" in ready.json()["detail"] and address in ready.json()["detail"], ready.text
        submitted = time.monotonic()
        location = server.client.post("/v1/sweeps", json=LONG_SWEEP).headers["location"]
        failed = wait_for(server, location, ("succeeded", "failed", "cancelled"),
                          timeout_s=FAULT_TIMEOUT_S + SLACK_S)
        print(f"no workers: the job {failed['status']} after {time.monotonic() - submitted:.1f} s")
        assert failed["status"] == "failed" and "no workers" in failed["error"]["detail"], failed

        # 5. SIGTERM while a sweep waits on the worker-less cluster: the server stops in time.
        location = server.client.post("/v1/sweeps", json=LONG_SWEEP).headers["location"]
        wait_for(server, location, ("running",))
        stopping = time.monotonic()
        os.killpg(server.process.pid, signal.SIGTERM)
        server.process.wait(timeout=30)
        print(f"SIGTERM with a job waiting on the cluster: the server exited after "
              f"{time.monotonic() - stopping:.1f} s")
        assert time.monotonic() - stopping < 10.0
    finally:
        if server is not None:
            server.stop()
        for process in processes:
            process.kill()
