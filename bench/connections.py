"""Connection floods against ``microbearing serve``: idle connections, huge headers; /healthz watched.

Starts ``microbearing serve`` (one process, default settings) on a free loopback port with its
open-file limit at ``--fd-limit`` (soft and hard, as a shell's ``ulimit -n``), then:

1. opens ``--idle`` connections that send the start of a request head and never finish it, and
   asks ``/healthz`` 20 times while they are held (each with a 2 s timeout);
2. sends ``--big-headers`` requests at once, each with one header of ``--header-mib`` MiB.

Reports how many idle connections the server still holds open, how many probes answered and
their slowest time, the statuses of the huge-header requests and how long they took, the server's
peak resident memory (``VmHWM``) and the size of its log::

    .venv/bin/python bench/connections.py --fd-limit 1024 --idle 1100 --big-headers 8 --header-mib 64
"""

from __future__ import annotations

import argparse
import os
import resource
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

import httpx
from flood import rss_mib
from load import REPO, free_port


def big_header(port: int, mib: int, out: list) -> None:
    started = time.perf_counter()
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=120) as sock:
            sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: a\r\nX-Big: ")
            block = b"a" * 2**20
            for _ in range(mib):
                sock.sendall(block)
            sock.sendall(b"\r\n\r\n")
            answer = sock.recv(200)
    except OSError as exc:  # the server answered 431 and closed while the header was still being sent
        answer = f"closed while sending ({type(exc).__name__})".encode()
    out.append((answer.split(b"\r\n")[0].decode(errors="replace"), time.perf_counter() - started))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--fd-limit", type=int, default=1024)
    parser.add_argument("--idle", type=int, default=1100)
    parser.add_argument("--big-headers", type=int, default=8)
    parser.add_argument("--header-mib", type=int, default=64)
    args = parser.parse_args()
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    env = {k: v for k, v in os.environ.items()
           if k != "PROMETHEUS_MULTIPROC_DIR" and not k.startswith("MICROBEARING_")}

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_NOFILE, (args.fd_limit, args.fd_limit))

    with tempfile.TemporaryDirectory() as data_dir:
        log_path = Path(data_dir) / "server.log"
        with log_path.open("wb") as log:
            process = subprocess.Popen(
                [sys.executable, "-m", "microbearing", "serve", "--host", "127.0.0.1", "--port", str(port),
                 "--data-dir", data_dir], cwd=REPO, env=env, stdout=log, stderr=subprocess.STDOUT,
                preexec_fn=limit, start_new_session=True)
            try:
                deadline = time.monotonic() + 60
                while True:
                    try:
                        if httpx.get(url + "/healthz", timeout=2).status_code == 200:
                            break
                    except httpx.TransportError:
                        pass
                    if time.monotonic() > deadline or process.poll() is not None:
                        raise SystemExit("the server did not start")
                    time.sleep(0.2)
                held = []
                for _ in range(args.idle):
                    try:
                        sock = socket.create_connection(("127.0.0.1", port), timeout=5)
                        sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: flood\r\nX-Slow: ")
                        held.append(sock)
                    except OSError:
                        break
                probes: Counter[str] = Counter()
                slowest = 0.0
                for _ in range(20):
                    started = time.perf_counter()
                    try:
                        status = str(httpx.get(url + "/healthz", timeout=2).status_code)
                    except httpx.TransportError as exc:
                        status = type(exc).__name__
                    slowest = max(slowest, time.perf_counter() - started)
                    probes[status] += 1
                    time.sleep(0.1)
                server_fds = len(os.listdir(f"/proc/{process.pid}/fd"))
                for sock in held:
                    sock.close()
                print(f"open-file limit {args.fd_limit}: {len(held)} idle connections opened and held; the "
                      f"server has {server_fds} files open; /healthz {dict(probes)} of 20, slowest "
                      f"{slowest:.3f} s")
                results: list = []
                threads = [threading.Thread(target=big_header, args=(port, args.header_mib, results))
                           for _ in range(args.big_headers)]
                started = time.perf_counter()
                for thread in threads:
                    thread.start()
                for thread in threads:
                    thread.join()
                statuses = Counter(status for status, _ in results)
                print(f"{args.big_headers} requests with a {args.header_mib} MiB header at once: "
                      f"{dict(statuses)}, slowest {max(t for _, t in results):.2f} s, all in "
                      f"{time.perf_counter() - started:.2f} s")
                print(f"server peak RSS {rss_mib(process.pid, 'VmHWM'):.0f} MiB; /healthz after: "
                      f"{httpx.get(url + '/healthz', timeout=5).status_code}")
            finally:
                process.terminate()
                process.wait(timeout=30)
        text = log_path.read_text(errors="replace")
        print(f"server log: {len(text.encode()) / 1024:.1f} KiB, {text.count('Too many open files')} "
              "mentions of 'Too many open files'")
    return 0


if __name__ == "__main__":
    sys.exit(main())
