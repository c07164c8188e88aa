"""A dask worker that stops answering without dying, under ``microbearing serve``.

A worker stopped with SIGSTOP keeps its connections open: the scheduler keeps it (and the tasks
it was given) until its ``worker-ttl``, five minutes by default. The server reads the workers'
heartbeats itself (:meth:`DaskExecutor.fault`), on the scheduler's clock:

1. the only worker stopped mid-sweep: ``/readyz`` answers 503 naming the silent worker, and the
   job fails within twice ``MICROBEARING_DASK_FAULT_TIMEOUT_S``, with a reason saying so;
2. two workers, one stopped just before a sweep is submitted (the scheduler has not missed a
   heartbeat yet, so it hands the stopped worker chunks): the same (those chunks wait on it);
3. the worker woken again (SIGCONT): ready again, and a batch has the physics' numbers;
4. the scheduler killed under the connected server: every line the server wrote, dask's and
   tornado's included, is one JSON object, and some of them are dask's.

The README's worker command, a loop around ``dask worker``, outlives a restart of its scheduler:
the service is ready again without anyone starting a worker by hand.
"""

from __future__ import annotations

import json
import os
import re
import signal
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from live_server import Server, free_port, wait_for
from test_reliability_dask import DASK, Process, wait_for_workers
from test_reliability_dask_faults import BATCH, LONG_SWEEP, start_scheduler, start_worker

from microbearing import physics

pytestmark = [pytest.mark.skipif(os.name != "posix", reason="process groups and SIGSTOP are POSIX"),
              pytest.mark.skipif(DASK is None, reason="the dask command (the 'dask' extra) is not installed")]

FAULT_TIMEOUT_S = 10.0
#: Slack for one look at the cluster a second and a loaded machine [s].
SLACK_S = 10.0


class ServedServer(Server):
    """The server as ``microbearing serve`` runs it: uvicorn with the service's JSON logging."""

    def command(self, data_dir: Path) -> list[str]:
        return [sys.executable, "-m", "microbearing.service.cli", "serve", "--host", "127.0.0.1",
                "--port", str(self.port)]


def signal_group(process: Process, sig: int) -> None:
    os.killpg(process.process.pid, sig)


def ready(server: Server) -> bool:
    return server.client.get("/readyz").status_code == 200


def wait_until(condition, timeout_s: float, what: str) -> float:
    """Poll ``condition()`` every 0.2 s; returns the seconds it took, fails after ``timeout_s``."""
    start = time.monotonic()
    while not condition():
        assert time.monotonic() - start < timeout_s, f"{what}: not within {timeout_s} s"
        time.sleep(0.2)
    return time.monotonic() - start


def sweep_on_cluster(server: Server) -> str:
    """Submit the long sweep and wait until it runs (its chunks are out, or about to be).

    Not until it has made progress: on two warm workers the whole sweep takes about a second
    (the physics' numpy path), less than the polls between two looks at the job.
    """
    location = server.client.post("/v1/sweeps", json=LONG_SWEEP).headers["location"]
    wait_until(lambda: server.client.get(location).json()["status"] != "queued", 120,
               "the sweep never started")
    return location


def fails_in_time(server: Server, location: str, stopped: float) -> dict:
    failed = wait_for(server, location, ("succeeded", "failed", "cancelled"),
                      timeout_s=2 * FAULT_TIMEOUT_S + SLACK_S)
    took = time.monotonic() - stopped
    print(f"worker stopped: the job {failed['status']} after {took:.1f} s: {failed.get('error')}")
    assert took <= 2 * FAULT_TIMEOUT_S + SLACK_S
    return failed


def test_a_stopped_worker_fails_its_job_in_time_and_readyz_says_so(tmp_path):
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    processes = [start_scheduler(port, tmp_path, 1), start_worker(address, tmp_path, 1)]
    server = None
    try:
        wait_for_workers(address, 1)
        server = ServedServer(tmp_path / "data", tmp_path / "server.log", dask_scheduler=address,
                              dask_fault_timeout_s=str(FAULT_TIMEOUT_S), sweep_sync_max_points="0",
                              max_sweep_points="2000000", job_workers="1")
        wait_until(lambda: ready(server), 90, "the server never became ready")

        # 1. The only (cold) worker stops as the sweep starts: readyz names it, the job fails within
        # twice the timeout.
        location = sweep_on_cluster(server)
        signal_group(processes[1], signal.SIGSTOP)
        stopped = time.monotonic()
        failed = fails_in_time(server, location, stopped)
        assert failed["status"] == "failed" and failed["error"]["status"] == 503, failed
        assert address in failed["error"]["detail"] and "answering" in failed["error"]["detail"], failed
        answer = server.client.get("/readyz")
        assert answer.status_code == 503 and "answering" in answer.json()["detail"], answer.text

        # 3. Woken again: ready, and a batch has the physics' numbers.
        signal_group(processes[1], signal.SIGCONT)
        wait_until(lambda: ready(server), 60, "not ready after SIGCONT")
        batch = server.client.post("/v1/friction/batch", json=BATCH)
        assert batch.status_code == 200, batch.text
        expected = physics.evaluate(balls=5, speed_m_s=0.02, load_N=np.array(BATCH["points"]["load_N"])).mu
        np.testing.assert_array_equal(batch.json()["mu"], expected)

        # 2. A second worker; the first stops just before a sweep: the chunks it was handed wait on
        # it, and the job fails in time, naming it (not "no worker answering": the other one does).
        processes.append(start_worker(address, tmp_path, 2))
        wait_for_workers(address, 2)
        signal_group(processes[1], signal.SIGSTOP)
        stopped = time.monotonic()
        location = sweep_on_cluster(server)
        failed = fails_in_time(server, location, stopped)
        assert failed["status"] == "failed" and failed["error"]["status"] == 503, failed
        assert "stopped answering while it holds work" in failed["error"]["detail"], failed
        signal_group(processes[1], signal.SIGCONT)
        wait_until(lambda: ready(server), 60, "not ready after the second SIGCONT")

        # The scheduler killed under a connected client: dask's and tornado's complaints are logged.
        processes[0].kill()
        wait_until(lambda: not ready(server), 60, "still ready without a scheduler")
        time.sleep(3.0)
    finally:
        if server is not None:
            server.stop()
        for process in processes:
            if process.process.poll() is None:
                signal_group(process, signal.SIGCONT)
            process.kill()

    # 4. Every line the server wrote is one JSON object, dask's and tornado's included.
    lines = [line for line in (tmp_path / "server.log").read_text(errors="replace").splitlines() if line]
    records = [json.loads(line) for line in lines]
    assert all(isinstance(record, dict) and "message" in record for record in records)
    assert any(record["logger"].startswith(("distributed", "tornado")) for record in records), lines[-20:]


def readme_worker_loop() -> str:
    """The manual's command that keeps a worker running across scheduler restarts (how-to/operations.md)."""
    from docs_pages import page

    loop = re.search(r"^(while true; do dask worker .*)$", page("how-to/operations.md"), flags=re.M)
    assert loop, "the manual shows no worker loop"
    return loop.group(1)


def test_the_readme_worker_outlives_a_scheduler_restart(tmp_path):
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    command = readme_worker_loop().replace("tcp://10.0.0.5:8786", address).replace("--nthreads 4",
                                                                                  "--nthreads 1")
    command = command.split("#")[0].strip()
    scheduler = start_scheduler(port, tmp_path, 1)
    env_path = f"{Path(DASK).parent}:{os.environ.get('PATH', '')}"
    worker = Process(["bash", "-c", f"export PATH={env_path}; {command}"], tmp_path / "worker-loop.log")
    try:
        wait_for_workers(address, 1)
        scheduler.kill()
        time.sleep(2.0)
        scheduler = start_scheduler(port, tmp_path, 2)
        wait_for_workers(address, 1, timeout_s=90)
    finally:
        worker.kill()
        scheduler.kill()
