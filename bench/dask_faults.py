"""Dask fault times: a worker that stops answering (SIGSTOP) fails its job, side by side with the timeout.

For each ``--timeouts`` value: starts a ``dask scheduler`` and one ``dask worker`` on loopback and
``microbearing serve`` on them (``MICROBEARING_DASK_FAULT_TIMEOUT_S`` set to the value), submits a long sweep,
stops the worker with SIGSTOP once the sweep runs, and reports the seconds from the stop to the job's
``failed`` (the target: at most twice the timeout), to ``/readyz`` answering 503, and how long a batch sent
then, and one sent after the job failed, take to be refused; then wakes the worker (SIGCONT) and reports
when the service is ready again.
Needs the ``dask`` extra (POSIX)::

    .venv/bin/python bench/dask_faults.py --timeouts 10,30
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
from load import free_port

REPO = Path(__file__).resolve().parents[1]
SWEEP = {"design": "sobol", "points": 1_500_000, "seed": 5, "outputs": ["mu"],
         "ranges": {"load_N": {"low": 1e-3, "high": 0.05}}, "fixed": {"balls": 4, "speed_m_s": 0.05}}
BATCH = {"points": {"balls": 5, "load_N": [0.001, 0.01, 0.05], "speed_m_s": 0.02}, "outputs": ["mu"]}


def start(args: list[str], log: Path, env: dict[str, str] | None = None) -> subprocess.Popen:
    """A command in its own process group (stopped and killed whole), its output in ``log``."""
    return subprocess.Popen(args, cwd=REPO, env={**os.environ, **(env or {})}, stdout=log.open("ab"),
                            stderr=subprocess.STDOUT, start_new_session=True)


def until(condition, timeout_s: float, what: str) -> float:
    """Seconds until ``condition()`` holds, polled every 0.1 s; raises after ``timeout_s``."""
    started = time.monotonic()
    while not condition():
        if time.monotonic() - started > timeout_s:
            raise TimeoutError(f"{what}: not within {timeout_s} s")
        time.sleep(0.1)
    return time.monotonic() - started


def status(http: httpx.Client, path: str) -> int:
    try:
        return http.get(path, timeout=5.0).status_code
    except httpx.HTTPError:
        return 0


def one_timeout(timeout_s: float, folder: Path) -> str:
    dask = shutil.which("dask", path=str(Path(sys.executable).parent)) or shutil.which("dask")
    if dask is None:
        raise SystemExit("the dask command is not installed (pip install -e '.[dask]')")
    port, http_port = free_port(), free_port()
    address = f"tcp://127.0.0.1:{port}"
    processes = [start([dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                       folder / "scheduler.log"),
                 start([dask, "worker", address, "--nthreads", "1", "--no-dashboard", "--no-nanny",
                        "--memory-limit", "0", "--local-directory", str(folder / "worker")],
                       folder / "worker.log", {"MICROBEARING_PHYSICS_THREADS": "1"})]
    env = {"MICROBEARING_DASK_SCHEDULER": address, "MICROBEARING_DASK_FAULT_TIMEOUT_S": str(timeout_s),
           "MICROBEARING_SWEEP_SYNC_MAX_POINTS": "0", "MICROBEARING_JOB_WORKERS": "1"}
    processes.append(start([sys.executable, "-m", "microbearing.service.cli", "serve", "--host", "127.0.0.1",
                            "--port", str(http_port), "--data-dir", str(folder / "data")],
                           folder / "server.log", env))
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{http_port}", timeout=120.0) as http:
            until(lambda: status(http, "/readyz") == 200, 120, "the service never became ready")
            location = http.post("/v1/sweeps", json=SWEEP).headers["location"]
            until(lambda: http.get(location).json()["status"] != "queued", 120, "the sweep never started")
            os.killpg(processes[1].pid, signal.SIGSTOP)
            stopped = time.monotonic()
            readyz = until(lambda: status(http, "/readyz") == 503, 4 * timeout_s + 60, "readyz stayed 200")
            sent = time.monotonic()
            batch = http.post("/v1/friction/batch", json=BATCH).status_code
            refused = time.monotonic() - sent
            until(lambda: http.get(location).json()["status"] in ("failed", "succeeded", "cancelled"),
                  4 * timeout_s + 60, "the job never ended")
            failed = time.monotonic() - stopped
            job = http.get(location).json()
            sent = time.monotonic()
            later = http.post("/v1/friction/batch", json=BATCH).status_code
            later_s = time.monotonic() - sent
            os.killpg(processes[1].pid, signal.SIGCONT)
            woken = until(lambda: status(http, "/readyz") == 200 or processes[1].poll() is not None, 120,
                          "neither ready nor the worker gone after SIGCONT")
            after = (f"ready {woken:.1f} s after SIGCONT" if processes[1].poll() is None else
                     "the scheduler had removed the worker, which exited when woken (the manual's "
                     "worker loop starts another)")
        reason = str((job.get("error") or {}).get("detail", ""))[:90]
        return (f"timeout {timeout_s:5.1f} s: job {job['status']} {failed:5.1f} s after the stop "
                f"({failed / timeout_s:.2f} x the timeout; target <= 2); /readyz 503 after {readyz:4.1f} s; "
                f"a batch sent then answered {batch} in {refused:.1f} s, one sent after the job's failure "
                f"{later} in {later_s:.1f} s; {after}\n"
                f"    reason: {reason}")
    finally:
        for process in processes:
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGCONT)
                os.killpg(process.pid, signal.SIGKILL)
            process.wait(timeout=30)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--timeouts", default="10,30", help="comma-separated fault timeouts [s]")
    args = parser.parse_args()
    for timeout_s in (float(value) for value in args.timeouts.split(",")):
        with tempfile.TemporaryDirectory() as folder:
            print(one_timeout(timeout_s, Path(folder)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
