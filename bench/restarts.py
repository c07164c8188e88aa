"""The issue-27 scenarios on real servers: queued jobs across SIGTERM and SIGKILL, a key's limit over workers.

Run: ``.venv/bin/python -m bench.restarts`` (a few minutes).

* Restart: ``microbearing serve`` with one job thread, a long surrogate training running and five
  sweeps queued behind it; the server is stopped (SIGTERM, grace period 2 s; or SIGKILL) and
  started again on the same folder, with two job threads (the training, queued first, takes one).
  Counted: how many of the five queued sweeps succeed after the restart, what became of the
  training, and how long the SIGTERM took.
* Admission over processes: ``microbearing serve --workers 2`` with one API key whose limit is 16;
  40 long jobs submitted over fresh connections (spread over both workers). Counted: how many are
  admitted (202) and how many refused (429); then all are cancelled and the time until every one
  reads cancelled.
"""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import httpx

from microbearing.service.store import DATABASE_NAME

REPO = Path(__file__).resolve().parent.parent
KEY = "bench-restarts-key-0123456789"
LONG_SURROGATE = {"space": {"load_N": [1e-4, 0.1], "speed_m_s": [0.0, 0.2], "balls": [2, 40],
                            "groove_angle_deg": [30.0, 80.0]},
                  "fixed": {}, "budget": 1000, "target_relative_error": 1e-6, "adaptive": True}


def free_port() -> int:
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def serve(folder: Path, workers: int = 1, **settings: str) -> tuple[subprocess.Popen, str]:
    port = free_port()
    env = {**os.environ, **{f"MICROBEARING_{k.upper()}": v for k, v in settings.items()}}
    env.pop("PROMETHEUS_MULTIPROC_DIR", None)
    process = subprocess.Popen([sys.executable, "-m", "microbearing.service.cli", "serve", "--workers",
                                str(workers), "--port", str(port), "--data-dir", str(folder)],
                               cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               start_new_session=True)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 90
    while True:
        try:
            if httpx.get(f"{url}/healthz", timeout=2).status_code == 200:
                break
        except httpx.TransportError:
            pass
        if process.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError("the server did not start")
        time.sleep(0.2)
    time.sleep(2.0 if workers > 1 else 0.0)  # every worker up
    return process, url


def status(url: str, job_id: str, headers: dict | None = None) -> str:
    return httpx.get(f"{url}/v1/jobs/{job_id}", headers=headers, timeout=30).json()["status"]


def wait(url: str, job_id: str, wanted: tuple[str, ...], timeout_s: float = 300) -> str:
    deadline = time.monotonic() + timeout_s
    while (now := status(url, job_id)) not in wanted and time.monotonic() < deadline:
        time.sleep(0.1)
    return now


def restart(how: signal.Signals) -> str:
    settings = {"job_workers": "1", "executor_workers": "1", "sweep_sync_max_points": "0",
                "shutdown_grace_s": "2"}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        process, url = serve(folder, **settings)
        training = httpx.post(f"{url}/v1/surrogates", json=LONG_SURROGATE, timeout=30).json()["id"]
        wait(url, training, ("running",))
        sweeps = [httpx.post(f"{url}/v1/sweeps", timeout=30, json={
            "design": "grid", "axes": {"load_N": {"start": 1e-3, "stop": 0.05, "num": 1000 + i}},
            "fixed": {"balls": 5, "speed_m_s": 0.05}, "outputs": ["mu"]}).json()["id"] for i in range(5)]
        queued = sum(status(url, i) == "queued" for i in sweeps)
        began = time.monotonic()
        os.killpg(process.pid, how)
        process.wait(timeout=120)
        stopped_s = time.monotonic() - began
        with sqlite3.connect(folder / DATABASE_NAME) as conn:
            stored = Counter(conn.execute("SELECT status FROM jobs").fetchall())
        process, url = serve(folder, **{**settings, "job_workers": "2"})  # the training takes one thread
        try:
            ends = Counter(wait(url, i, ("succeeded", "failed", "cancelled")) for i in sweeps)
            again = wait(url, training, ("running", "failed"))
            httpx.delete(f"{url}/v1/jobs/{training}", timeout=30)
        finally:
            os.killpg(process.pid, signal.SIGTERM)
            process.wait(timeout=120)
    return (f"  {how.name}: {queued} of 5 sweeps queued before; process ended {stopped_s:.1f} s after the "
            f"signal; in the database then: {dict((k[0], v) for k, v in stored.items())}; after the restart "
            f"the 5 sweeps ended {dict(ends)}, the training is {again} again")


def admission() -> str:
    with tempfile.TemporaryDirectory() as tmp:
        process, url = serve(Path(tmp), workers=2, api_keys=KEY, max_active_jobs_per_key="16",
                             job_workers="1", executor_workers="1", shutdown_grace_s="0")
        headers = {"Authorization": f"Bearer {KEY}"}
        try:
            answers = [httpx.post(f"{url}/v1/surrogates", json=LONG_SURROGATE, headers=headers, timeout=30)
                       for _ in range(40)]
            counts = Counter(a.status_code for a in answers)
            ids = [a.json()["id"] for a in answers if a.status_code == 202]
            began = time.monotonic()
            for job_id in ids:
                httpx.delete(f"{url}/v1/jobs/{job_id}", headers=headers, timeout=30)
            while any(status(url, i, headers) != "cancelled" for i in ids):
                time.sleep(0.1)
            cancelled_s = time.monotonic() - began
            again = httpx.post(f"{url}/v1/surrogates", json=LONG_SURROGATE, headers=headers, timeout=30)
            if again.status_code == 202:
                httpx.delete(f"{url}/v1/jobs/{again.json()['id']}", headers=headers, timeout=30)
        finally:
            os.killpg(process.pid, signal.SIGTERM)
            process.wait(timeout=120)
    return (f"  --workers 2, key limit 16, 40 submitted: {counts[202]} admitted, {counts[429]} refused "
            "(429), "
            f"other {sum(v for k, v in counts.items() if k not in (202, 429))}; all {len(ids)} cancelled "
            f"through either worker in {cancelled_s:.1f} s; a new job after: {again.status_code}")


def main() -> None:
    print(f"before: {os.cpu_count()} CPUs, load average {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print("restart with a training running and five sweeps queued (one job thread, grace 2 s):")
    for how in (signal.SIGTERM, signal.SIGKILL):
        print(restart(how), flush=True)
    print("admission over two uvicorn workers:")
    print(admission(), flush=True)
    print(f"after:  {os.cpu_count()} CPUs, load average {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
