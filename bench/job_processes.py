"""Several server processes on one data folder: job throughput, submit latency and take-over times.

Run: ``.venv/bin/python -m bench.job_processes`` (about two minutes; ``--quick`` for less).

Each "process" is a Python process running a :class:`service.jobs.JobManager` (2 job threads, the
default lease of 15 s) on one temporary data folder, as a server process does; this process
submits jobs into the same folder through :meth:`Store.admit_job`, the transaction a job request
runs (admission counted over the folder). The jobs do nothing (they return their input), so the
figures are the cost of the coordination itself (SQLite in WAL mode: the submit, the claim and
the final write are one write transaction each).

* For 1, 2, 4, 8 and 16 processes: jobs finished per second, the submit transaction's latency
  (median and 99th percentile, what a job request waits for the database) and the time from
  submit to finished (median, 99th percentile), with the check that every job ran exactly once.
* Take-over, with two processes and the default settings: a process holding a running job is
  killed (SIGKILL) — the other finds its pid gone at its next heartbeat (stated: within
  lease/3 = 5 s, plus the claim) — or stopped (SIGSTOP, alive but renewing nothing) — the other
  re-queues the job once the lease lapses (stated: within 4/3 of the lease = 20 s).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

import numpy as np

from microbearing.service.store import DATABASE_NAME, Store, utc_now

REPO = Path(__file__).resolve().parent.parent


def worker(folder: str, threads: int) -> None:
    """A job manager on ``folder`` until stdin closes (run in a child process)."""
    from microbearing.service.jobs import JobManager, register_kind

    def sleep_work(inputs: dict):
        def work(ctx):
            deadline = time.monotonic() + inputs["sleep_s"]
            while time.monotonic() < deadline:
                ctx.progress(0.5)
                time.sleep(0.05)
            return {"slept": inputs["sleep_s"]}
        return work

    register_kind("noop", lambda inputs, services: lambda ctx: {"n": inputs["n"]})
    register_kind("sleep", lambda inputs, services: sleep_work(inputs))
    store = Store(Path(folder))
    manager = JobManager(store, threads, services="bench")
    print("ready", flush=True)
    sys.stdin.read()
    manager.shutdown(grace_s=0)
    store.close()


def start(folder: Path, count: int) -> list[subprocess.Popen]:
    processes = [subprocess.Popen([sys.executable, "-m", "bench.job_processes", "--worker", str(folder)],
                                  cwd=REPO, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
                 for _ in range(count)]
    for process in processes:
        assert process.stdout.readline().strip() == "ready"
    return processes


def stop(processes: list[subprocess.Popen]) -> None:
    for process in processes:
        if process.poll() is None:
            try:
                os.kill(process.pid, signal.SIGCONT)
                process.stdin.close()
            except (OSError, ValueError):
                pass
    for process in processes:
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def submit(store: Store, kind: str, inputs: dict) -> str:
    job_id = os.urandom(16).hex()
    store.admit_job({"id": job_id, "kind": kind, "status": "queued", "progress": 0.0, "request_json": "{}",
                     "owner_pid": os.getpid(), "owner_instance": "bench-submitter", "created_at": utc_now()},
                    inputs_json=json.dumps(inputs), max_active=1_000_000)  # counted, as a server does
    return job_id


def seconds(stamp: str) -> float:
    return datetime.fromisoformat(stamp.replace("Z", "+00:00")).timestamp()


def throughput(folder: Path, processes: int, jobs: int) -> str:
    workers = start(folder, processes)
    store = Store(folder)
    try:
        latencies = []
        began = time.perf_counter()
        ids = []
        for n in range(jobs):
            t0 = time.perf_counter()
            ids.append(submit(store, "noop", {"n": n}))
            latencies.append(time.perf_counter() - t0)
        while store.count_active_jobs():
            time.sleep(0.01)
        elapsed = time.perf_counter() - began
        with sqlite3.connect(folder / DATABASE_NAME) as conn:
            rows = conn.execute("SELECT status, attempts, owner_pid, created_at, finished_at FROM jobs "
                                "WHERE kind = 'noop'").fetchall()
            conn.execute("DELETE FROM jobs")
            conn.execute("DELETE FROM job_inputs")
            conn.execute("DELETE FROM job_results")
        assert len(rows) == jobs and all(r[0] == "succeeded" and r[1] == 1 for r in rows), "a job ran twice"
        waits = [seconds(r[4]) - seconds(r[3]) for r in rows]
        spread = len({r[2] for r in rows})
        ms = 1000 * np.array(latencies)
        return (f"  {processes:2d} processes: {jobs / elapsed:6.0f} jobs/s   submit {np.median(ms):5.2f} / "
                f"{np.percentile(ms, 99):6.2f} ms (median / p99)   submit to finished "
                f"{1000 * np.median(waits):7.0f} / {1000 * np.percentile(waits, 99):7.0f} ms   "
                f"ran by {spread} processes, each job once")
    finally:
        store.close()
        stop(workers)


def owner_of(folder: Path, job_id: str) -> tuple[str, int]:
    with sqlite3.connect(folder / DATABASE_NAME) as conn:
        return conn.execute("SELECT status, owner_pid FROM jobs WHERE id = ?", (job_id,)).fetchone()


def take_over(folder: Path, how: signal.Signals) -> str:
    workers = start(folder, 2)
    store = Store(folder)
    try:
        job_id = submit(store, "sleep", {"sleep_s": 120})
        while (state := owner_of(folder, job_id))[0] != "running":
            time.sleep(0.01)
        os.kill(state[1], how)
        began = time.monotonic()
        while True:
            status, pid = owner_of(folder, job_id)
            if status == "running" and pid != state[1]:
                break
            if time.monotonic() - began > 120:
                return f"  {how.name}: not taken over in 120 s"
            time.sleep(0.01)
        took = time.monotonic() - began
        return f"  {how.name} of the process running the job: running again in the other after {took:5.2f} s"
    finally:
        store.close()
        stop(workers)
        with sqlite3.connect(folder / DATABASE_NAME) as conn:
            for table in ("jobs", "job_inputs", "job_results"):
                conn.execute(f"DELETE FROM {table}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer jobs, fewer process counts")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(args.worker, 2)
        return
    print(f"before: {os.cpu_count()} CPUs, load average {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        Store(folder).close()
        jobs = 200 if args.quick else 600
        print(f"{jobs} jobs that do nothing, submitted one after another into one folder; job managers of "
              "2 threads each:")
        for processes in ((1, 4) if args.quick else (1, 2, 4, 8, 16)):
            print(throughput(folder, processes, jobs), flush=True)
        print("take-over, 2 processes, default lease 15 s (heartbeat 5 s):")
        for how in (signal.SIGKILL, signal.SIGSTOP):
            print(take_over(folder, how), flush=True)
    print(f"after:  {os.cpu_count()} CPUs, load average {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
