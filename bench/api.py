"""Speed of the REST service, measured side by side against references in one run.

Run: ``cd /work/main && .venv/bin/python -m bench.api`` (a few minutes; ``--quick`` for less). Run it as
a module: as a script, ``bench/physics.py`` would shadow the ``physics`` package.

Starts ``microbearing serve`` on a free loopback port with a temporary data folder, then:

* single-point requests per second on ``POST /v1/friction`` against ``GET /healthz`` on the same
  server, one keep-alive client alternating the two, request by request (target ratio >= 0.85,
  issue 17); min / median / max over the rounds; then, per round, the CPU time per request of
  the server process and the client together (Linux ``/proc``), which other work on a shared
  machine does not inflate the way it inflates wall-clock time;
* the same alternation from a raw keep-alive socket sending pre-encoded HTTP/1.1 requests and
  reading each answer by its Content-Length, as a load generator (wrk, ab) does: httpx spends more
  of the client's own time on a POST than on a GET, which the first figure counts against
  ``/v1/friction`` although the server does none of it;
* points per second through ``POST /v1/friction/batch`` with 100,000-point requests (load and
  speed as lists, the rest scalars) against ``physics.evaluate`` on the same arrays in this
  process, with only ``mu`` returned and with every output. The request body is encoded once,
  so client-side JSON encoding is not counted; the response is received but not decoded.

The machine's CPU count and load average are printed before and after.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np

from microbearing import physics

REPO = Path(__file__).resolve().parent.parent
JSON = {"content-type": "application/json"}
POINT = {"balls": 4, "load_N": 0.008826, "speed_m_s": 0.05}


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def start_server(data_dir: str) -> tuple[subprocess.Popen, str]:
    port = free_port()
    process = subprocess.Popen(
        [sys.executable, "-m", "microbearing.service.cli", "serve",
         "--port", str(port), "--data-dir", data_dir],
        cwd=REPO, env={**os.environ}, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"{url}/healthz", timeout=1).status_code == 200:
                return process, url
        except httpx.TransportError:
            time.sleep(0.1)
    process.terminate()
    raise RuntimeError("the server did not start")


def cpu_seconds(pid: int) -> float:
    """CPU time (user + system) a process has used so far, from ``/proc`` (Linux). [s]"""
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def single_point(client: httpx.Client, rounds: int, per_round: int,
                 server_pid: int) -> tuple[list[float], list[float], dict[str, list[float]]]:
    """Requests per second of /healthz and /v1/friction per round, sent alternately (the same load).

    Also the CPU time per request of the server process and of this client, per endpoint and
    round, in blocks of requests of one kind (preemption by other work does not inflate it).
    """
    body = json.dumps(POINT).encode()
    health, friction = [], []
    cpu: dict[str, list[float]] = {"health": [], "friction": []}
    calls = {"health": lambda: client.get("/healthz").raise_for_status(),
             "friction": lambda: client.post("/v1/friction", content=body, headers=JSON).raise_for_status()}
    for round_index in range(rounds + 1):  # the first round warms up
        spent = {"health": 0.0, "friction": 0.0}
        for _ in range(per_round):
            start = time.perf_counter()
            calls["health"]()
            middle = time.perf_counter()
            calls["friction"]()
            spent["health"] += middle - start
            spent["friction"] += time.perf_counter() - middle
        if round_index:
            health.append(per_round / spent["health"])
            friction.append(per_round / spent["friction"])
            for name, call in calls.items():
                server, own = cpu_seconds(server_pid), time.process_time()
                for _ in range(per_round):
                    call()
                cpu[name].append((cpu_seconds(server_pid) - server + time.process_time() - own) / per_round)
    return health, friction, cpu


class RawClient:
    """A keep-alive HTTP/1.1 connection sending pre-encoded requests; the same client work for any of them."""

    def __init__(self, url: str):
        host, port = url.removeprefix("http://").split(":")
        self.host = f"{host}:{port}"
        self.sock = socket.create_connection((host, int(port)))
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.buffer = b""

    def encode(self, method: str, path: str, body: bytes = b"") -> bytes:
        """The request's bytes, built once."""
        headers = f"{method} {path} HTTP/1.1\r\nHost: {self.host}\r\n"
        if body:
            headers += f"Content-Type: application/json\r\nContent-Length: {len(body)}\r\n"
        return (headers + "\r\n").encode() + body

    def send(self, request: bytes) -> None:
        """Send one request and read its whole answer; a status other than 200 raises."""
        self.sock.sendall(request)
        while (end := self.buffer.find(b"\r\n\r\n")) < 0:
            self.buffer += self.sock.recv(65536)
        head, self.buffer = self.buffer[:end], self.buffer[end + 4:]
        if not head.startswith(b"HTTP/1.1 200"):
            raise RuntimeError(head.decode(errors="replace"))
        length = int(next(line.split(b":", 1)[1] for line in head.split(b"\r\n")
                          if line.lower().startswith(b"content-length:")))
        while len(self.buffer) < length:
            self.buffer += self.sock.recv(65536)
        self.buffer = self.buffer[length:]

    def close(self) -> None:
        self.sock.close()


def raw_single_point(url: str, rounds: int, per_round: int) -> tuple[list[float], list[float]]:
    """Requests per second of /healthz and /v1/friction per round from :class:`RawClient`, alternating."""
    client = RawClient(url)
    requests = {"health": client.encode("GET", "/healthz"),
                "friction": client.encode("POST", "/v1/friction", json.dumps(POINT).encode())}
    health, friction = [], []
    try:
        for round_index in range(rounds + 1):  # the first round warms up
            spent = {"health": 0.0, "friction": 0.0}
            for _ in range(per_round):
                for name, request in requests.items():
                    start = time.perf_counter()
                    client.send(request)
                    spent[name] += time.perf_counter() - start
            if round_index:
                health.append(per_round / spent["health"])
                friction.append(per_round / spent["friction"])
    finally:
        client.close()
    return health, friction


def batch(client: httpx.Client, points: int, repeats: int, outputs: list[str] | None) -> tuple[float, float]:
    rng = np.random.default_rng(0)
    loads = rng.uniform(1e-3, 1e-2, points)
    speeds = rng.uniform(0.0, 0.15, points)
    request: dict = {"points": {"balls": 4, "load_N": loads.tolist(), "speed_m_s": speeds.tolist()}}
    if outputs:
        request["outputs"] = outputs
    body = json.dumps(request).encode()
    api, local = [], []
    for _ in range(repeats):
        start = time.perf_counter()
        response = client.post("/v1/friction/batch", content=body, headers=JSON)
        response.raise_for_status()
        api.append(points / (time.perf_counter() - start))
        start = time.perf_counter()
        physics.evaluate(balls=4, load_N=loads, speed_m_s=speeds)
        local.append(points / (time.perf_counter() - start))
    return float(np.median(api)), float(np.median(local))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer rounds")
    args = parser.parse_args()
    rounds, per_round, repeats = (3, 100, 2) if args.quick else (7, 300, 5)
    print(f"before: {machine()}")
    with tempfile.TemporaryDirectory(prefix="microbearing-bench-") as data_dir:
        process, url = start_server(data_dir)
        try:
            with httpx.Client(base_url=url, timeout=300) as client:
                health, friction, cpu = single_point(client, rounds, per_round, process.pid)
                ratios = [f / h for f, h in zip(friction, health, strict=True)]
                cpu_ratios = [h / f for h, f in zip(cpu["health"], cpu["friction"], strict=True)]
                extra = [1e3 / f - 1e3 / h for f, h in zip(friction, health, strict=True)]
                print(f"single point, one keep-alive client alternating the two, {rounds} rounds x "
                      f"{per_round}; min / median / max")
                print(f"  GET  /healthz       {spread(health, 0)} req/s")
                print(f"  POST /v1/friction   {spread(friction, 0)} req/s")
                print(f"  ratio friction / healthz, per round: {spread(ratios, 2)}  (target >= 0.85)")
                print(f"  CPU time per request, server and client together: healthz "
                      f"{spread([c * 1e3 for c in cpu['health']], 3)} ms, friction "
                      f"{spread([c * 1e3 for c in cpu['friction']], 3)} ms; ratio healthz / friction "
                      f"{spread(cpu_ratios, 2)} (what the req/s ratio is on a machine with cores to spare)")
                costs = []
                for _ in range(rounds):
                    start = time.perf_counter()
                    for _ in range(per_round):
                        physics.evaluate(**POINT)
                    costs.append((time.perf_counter() - start) / per_round * 1e3)
                print(f"  friction costs {spread(extra, 3)} ms more per request than healthz; "
                      f"physics.evaluate of one point in process takes {spread(costs, 3)} ms of it")
                raw_health, raw_friction = raw_single_point(url, rounds, per_round)
                raw_ratios = [f / h for f, h in zip(raw_friction, raw_health, strict=True)]
                print(f"single point, a raw keep-alive socket sending pre-encoded requests (the same client "
                      f"work for both), {rounds} rounds x {per_round}; min / median / max")
                print(f"  GET  /healthz       {spread(raw_health, 0)} req/s")
                print(f"  POST /v1/friction   {spread(raw_friction, 0)} req/s")
                print(f"  ratio friction / healthz, per round: {spread(raw_ratios, 2)}  (target >= 0.85)")
                print(f"batch, 100,000 points per request, median of {repeats}")
                for label, outputs in (("mu only", ["mu"]), ("all 21 outputs", None)):
                    api, local = batch(client, 100_000, repeats, outputs)
                    print(f"  {label:15s} API {api:12,.0f} points/s   in-process physics.evaluate "
                          f"{local:12,.0f} points/s   ratio {api / local:.3f}")
        finally:
            process.terminate()
            process.wait(timeout=30)
    print(f"after:  {machine()}")


def machine() -> str:
    """CPU count and the 1, 5 and 15 minute load averages."""
    return f"{os.cpu_count()} CPUs, load average {', '.join(f'{v:.2f}' for v in os.getloadavg())}"


def spread(values: list[float], digits: int) -> str:
    """'min / median / max' of ``values``."""
    return " / ".join(f"{v:.{digits}f}" for v in (min(values), float(np.median(values)), max(values)))


if __name__ == "__main__":
    main()
