"""Load test: concurrent clients against a live server, per endpoint, for a bounded time.

Starts ``microbearing serve --workers N`` on a free loopback port with a temporary data folder
(or uses ``--url`` of a running server), then for each endpoint runs ``--clients`` concurrent
clients (asyncio + httpx, one keep-alive connection each) for ``--duration`` seconds and
reports requests per second, p50 and p99 latency and the errors (any answer other than 200,
or a transport error). ``/healthz`` does no work, so its rate is the ceiling of the server and
client stack; ``/v1/friction`` parses, validates and evaluates one design point.

Client and server share the machine: on a small one the client's own CPU use caps the
figures. Exits with status 1 if any request failed::

    .venv/bin/python bench/load.py --workers 2 --clients 32 --duration 10
"""

from __future__ import annotations

import argparse
import asyncio
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

REPO = Path(__file__).resolve().parent.parent
POINT = {"balls": 4, "load_N": 0.01, "speed_m_s": 0.1}
#: (method, path, JSON body) of each endpoint under load
ENDPOINTS = [("GET", "/healthz", None), ("POST", "/v1/friction", POINT)]


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def start_server(workers: int, data_dir: str) -> tuple[subprocess.Popen, str]:
    """``microbearing serve`` on 127.0.0.1; returns the process and its base URL once healthy."""
    port = free_port()
    env = {key: value for key, value in os.environ.items()
           if key != "PROMETHEUS_MULTIPROC_DIR" and not key.startswith("MICROBEARING_")}
    process = subprocess.Popen(
        [sys.executable, "-m", "microbearing.service.cli", "serve",
         "--host", "127.0.0.1", "--port", str(port), "--workers", str(workers), "--data-dir", data_dir],
        cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        try:
            if httpx.get(url + "/healthz", timeout=5).status_code == 200:
                time.sleep(2.0 if workers > 1 else 0.2)  # let every worker finish starting
                return process, url
        except httpx.TransportError:
            time.sleep(0.2)
        if process.poll() is not None:
            break
    stop_server(process)
    raise SystemExit("the server did not start")


def stop_server(process: subprocess.Popen) -> None:
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGTERM)
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait(timeout=30)


async def run_load(url: str, method: str, path: str, body: dict | None, clients: int,
                   duration_s: float) -> tuple[np.ndarray, int, float]:
    """Latencies [s] of the successful requests, the error count and the elapsed time [s]."""
    latencies: list[float] = []
    errors = 0

    async def client_loop(deadline: float) -> None:
        nonlocal errors
        async with httpx.AsyncClient(base_url=url, timeout=30.0) as client:
            while time.perf_counter() < deadline:
                started = time.perf_counter()
                try:
                    response = await client.request(method, path, json=body)
                    ok = response.status_code == 200
                except httpx.HTTPError:
                    ok = False
                if ok:
                    latencies.append(time.perf_counter() - started)
                else:
                    errors += 1

    started = time.perf_counter()
    await asyncio.gather(*(client_loop(started + duration_s) for _ in range(clients)))
    return np.asarray(latencies), errors, time.perf_counter() - started


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--workers", type=int, default=2, help="server processes (default: %(default)s)")
    parser.add_argument("--clients", type=int, default=32, help="concurrent clients (default: %(default)s)")
    parser.add_argument("--duration", type=float, default=10.0,
                        help="seconds of load per endpoint (default: %(default)s)")
    parser.add_argument("--url", help="base URL of a running server instead of starting one (loopback only)")
    args = parser.parse_args(argv)
    if args.url and not args.url.startswith(("http://127.0.0.1", "http://localhost", "http://[::1]")):
        parser.error("--url must be a loopback address")

    with tempfile.TemporaryDirectory(prefix="microbearing-load-") as data_dir:
        process, url = (None, args.url) if args.url else start_server(args.workers, data_dir)
        try:
            server = "external server" if args.url else f"{args.workers} worker(s)"
            print(f"{args.clients} clients, {args.duration:g} s per endpoint, {server}, "
                  f"{os.cpu_count()} CPU(s)")
            print(f"{'endpoint':<22}{'requests':>10}{'errors':>8}{'req/s':>10}{'p50 ms':>9}{'p99 ms':>9}")
            failed = 0
            for method, path, body in ENDPOINTS:
                asyncio.run(run_load(url, method, path, body, args.clients, 1.0))  # warm-up
                latencies, errors, elapsed = asyncio.run(
                    run_load(url, method, path, body, args.clients, args.duration))
                failed += errors
                p50, p99 = (np.percentile(latencies, [50, 99]) * 1e3 if latencies.size else (np.nan, np.nan))
                label = f"{method} {path}"
                print(f"{label:<22}{latencies.size + errors:>10}{errors:>8}{latencies.size / elapsed:>10.0f}"
                      f"{p50:>9.1f}{p99:>9.1f}")
        finally:
            if process is not None:
                stop_server(process)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
