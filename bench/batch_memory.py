"""Memory of concurrent large batches: ``--clients`` batches of ``--points`` points with all outputs at once.

Starts ``microbearing serve`` (one process, default settings) on a free loopback port with a
temporary data folder, then ``--clients`` threads each send the same batch (``balls`` 4, ``load_N``
and ``speed_m_s`` columns of ``--points`` random values, every output) at once and read the answer
as it streams, counting its bytes; a 503 is retried after its ``Retry-After`` (a connection the
server closed while the body was still being sent, after 5 s). Reports each
client's status, retries, answer size and time, whether the answers agree (same length, the first
``mu`` values equal to the physics), and the server's peak resident memory (``VmHWM`` from /proc,
Linux)::

    .venv/bin/python bench/batch_memory.py --clients 8 --points 2000000
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import threading
import time

import httpx
import numpy as np
from flood import rss_mib
from load import start_server, stop_server

from microbearing import physics


def body(points: int) -> tuple[bytes, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(3)
    load = rng.uniform(1e-3, 0.05, points)
    speed = rng.uniform(0.0, 0.2, points)
    text = json.dumps({"points": {"balls": 4, "load_N": load.tolist(), "speed_m_s": speed.tolist()}})
    return text.encode(), load, speed


def attempt(http: httpx.Client, content: bytes, report: dict) -> bool:
    """One request; False when it was refused with 503 and should be retried after Retry-After."""
    with http.stream("POST", "/v1/friction/batch", content=content,
                     headers={"Content-Type": "application/json"}) as response:
        if response.status_code == 503 and "retry-after" in response.headers:
            response.read()
            report["retries"] = report.get("retries", 0) + 1
            time.sleep(float(response.headers["retry-after"]))
            return False
        size, head, tail = 0, b"", b""
        for chunk in response.iter_bytes(1 << 20):
            if len(head) < 200_000:
                head += chunk[:200_000]
            tail = (tail + chunk)[-16:]
            size += len(chunk)
        report.update(status=response.status_code, bytes=size, head=head, tail=tail,
                      transfer=response.headers.get("transfer-encoding", ""))
        return True


def client(url: str, content: bytes, report: dict) -> None:
    started = time.perf_counter()
    with httpx.Client(base_url=url, timeout=httpx.Timeout(600.0)) as http:
        while True:
            try:
                if attempt(http, content, report):
                    break
            except httpx.TransportError:  # closed while the body was still being sent: retry later
                report["dropped"] = report.get("dropped", 0) + 1
                time.sleep(5)
    report["seconds"] = time.perf_counter() - started


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--clients", type=int, default=8)
    parser.add_argument("--points", type=int, default=2_000_000)
    args = parser.parse_args()
    content, load, speed = body(args.points)
    print(f"request body: {len(content) / 2**20:.0f} MiB ({args.points} points, all outputs)")
    with tempfile.TemporaryDirectory() as data_dir:
        process, url = start_server(1, data_dir)
        try:
            baseline = rss_mib(process.pid)
            reports = [{} for _ in range(args.clients)]
            threads = [threading.Thread(target=client, args=(url, content, report)) for report in reports]
            started = time.perf_counter()
            for thread in threads:
                thread.start()
            for thread in threads:
                thread.join()
            elapsed = time.perf_counter() - started
            peak = rss_mib(process.pid, "VmHWM")
        finally:
            stop_server(process)
    for index, report in enumerate(reports):
        print(f"client {index}: {report.get('status')} after {report.get('retries', 0)} retries (503) and "
              f"{report.get('dropped', 0)} dropped connections, "
              f"{report.get('bytes', 0) / 2**20:.0f} MiB in {report.get('seconds', 0):.1f} s "
              f"{report.get('transfer', '')}")
    good = [r for r in reports if r.get("status") == 200]
    agree = len({r["bytes"] for r in good}) == 1 and all(r["tail"].endswith(b"]}") for r in good)
    if good:
        head = good[0]["head"].decode()
        assert head.startswith('{"mu":['), head[:50]
        first = [float(x) for x in head[len('{"mu":['):].split(",")[:1000]]
        expected = physics.evaluate(balls=4, load_N=load[:1000], speed_m_s=speed[:1000]).mu
        agree = agree and np.array_equal(first, expected)
    print(f"{len(good)} of {args.clients} answered 200 in {elapsed:.1f} s; answers agree and match the "
          f"physics: {agree}")
    print(f"server RSS: {baseline:.0f} MiB at start, peak {peak:.0f} MiB (VmHWM)")
    return 0 if len(good) == args.clients and agree else 1


if __name__ == "__main__":
    sys.exit(main())
