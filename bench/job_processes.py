"""Several server processes on one data folder: job throughput, submit latency and take-over times.

Run: ``.venv/bin/python -m bench.job_processes`` (about two minutes; ``--quick`` for less);
``--postgres`` runs the same against PostgreSQL: a throwaway server started in a temporary folder
(tests/postgres_server.py; needs ``initdb``/``pg_ctl`` and the ``postgres`` extra), or the database
of ``--database-url postgresql://...``.

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
import subprocess
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

import numpy as np

from microbearing.service.store import Store, utc_now

REPO = Path(__file__).resolve().parent.parent


def open_store(folder: Path, url: str | None) -> Store:
    """The store of the folder (SQLite), or of the PostgreSQL database ``url``."""
    if url is None:
        return Store(folder)
    from microbearing.service.store_postgres import PostgresStore

    return PostgresStore(url, folder, pool_size=4)


def worker(folder: str, threads: int, url: str | None = None) -> None:
    """A job manager on ``folder`` (or the database ``url``) until stdin closes (run in a child process)."""
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
    store = open_store(Path(folder), url)
    manager = JobManager(store, threads, services="bench")
    print("ready", flush=True)
    sys.stdin.read()
    manager.shutdown(grace_s=0)
    store.close()


def start(folder: Path, count: int, url: str | None) -> list[subprocess.Popen]:
    command = [sys.executable, "-m", "bench.job_processes", "--worker", str(folder)]
    command += ["--database-url", url] if url else []
    processes = [subprocess.Popen(command,
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


def clear(store: Store) -> None:
    with store.transaction() as conn:
        for table in ("job_results", "job_inputs", "jobs"):
            conn.execute(f"DELETE FROM {table}")


def throughput(folder: Path, processes: int, jobs: int, url: str | None) -> str:
    workers = start(folder, processes, url)
    store = open_store(folder, url)
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
        with store.transaction() as conn:
            rows = [tuple(r[c] for c in ("status", "attempts", "owner_pid", "created_at", "finished_at"))
                    for r in conn.execute("SELECT status, attempts, owner_pid, created_at, finished_at "
                                          "FROM jobs WHERE kind = 'noop'").fetchall()]
        clear(store)
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


def owner_of(store: Store, job_id: str) -> tuple[str, int]:
    row = store.get_job(job_id)
    return row["status"], row["owner_pid"]


def take_over(folder: Path, how: signal.Signals, url: str | None) -> str:
    workers = start(folder, 2, url)
    store = open_store(folder, url)
    try:
        job_id = submit(store, "sleep", {"sleep_s": 120})
        while (state := owner_of(store, job_id))[0] != "running":
            time.sleep(0.01)
        os.kill(state[1], how)
        began = time.monotonic()
        while True:
            status, pid = owner_of(store, job_id)
            if status == "running" and pid != state[1]:
                break
            if time.monotonic() - began > 120:
                return f"  {how.name}: not taken over in 120 s"
            time.sleep(0.01)
        took = time.monotonic() - began
        return f"  {how.name} of the process running the job: running again in the other after {took:5.2f} s"
    finally:
        stop(workers)
        clear(store)
        store.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer jobs, fewer process counts")
    parser.add_argument("--postgres", action="store_true",
                        help="PostgreSQL: a throwaway local server (or --database-url) instead of SQLite")
    parser.add_argument("--database-url", help="a PostgreSQL database to use (its jobs tables are emptied)")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(args.worker, 2, args.database_url)
        return
    server = None
    url = args.database_url
    if args.postgres and url is None:
        sys.path.insert(0, str(REPO / "tests"))
        from postgres_server import PostgresServer

        server = PostgresServer()
        url = server.new_database()
    backend = "SQLite (one data folder)" if url is None else "PostgreSQL (one database, local server)"
    print(f"before: {os.cpu_count()} CPUs, load average {', '.join(f'{x:.2f}' for x in os.getloadavg())}; "
          f"{backend}")
    try:
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp)
            open_store(folder, url).close()
            jobs = 200 if args.quick else 600
            print(f"{jobs} jobs that do nothing, submitted one after another into one database; job managers "
                  "of 2 threads each:")
            for processes in ((1, 4) if args.quick else (1, 2, 4, 8, 16)):
                print(throughput(folder, processes, jobs, url), flush=True)
            print("take-over, 2 processes, default lease 15 s (heartbeat 5 s):")
            for how in (signal.SIGKILL, signal.SIGSTOP):
                print(take_over(folder, how, url), flush=True)
    finally:
        if server is not None:
            server.stop()
    print(f"after:  {os.cpu_count()} CPUs, load average {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
