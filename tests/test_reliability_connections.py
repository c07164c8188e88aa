"""Bounded connections (service/connections.py) on a live ``microbearing serve``.

A server whose process may open 256 files at most (hard limit) keeps 64 in reserve: a flood of
600 connections that never finish their headers neither exhausts its descriptors nor keeps
``/healthz`` from answering; a connection that does not finish its headers within the time limit
is closed; a request head past the size limit gets 431 (a problem naming the setting), one just
under it and a body arriving with its head in one packet do not. The repeat filter and the
concurrency limit are checked in process.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import resource
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest
from live_server import REPO, free_port, wait_healthy

from microbearing.service.connections import ConcurrencyLimitMiddleware, RepeatFilter, raise_fd_limit

pytestmark = pytest.mark.skipif(os.name != "posix", reason="file-descriptor limits are POSIX")

FD_LIMIT = 256


class Serve:
    """``python -m microbearing serve`` on a loopback port, its open-file limit at ``fd_limit``."""

    def __init__(self, tmp_path: Path, fd_limit: int | None = None, **settings: str):
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.log_path = tmp_path / f"serve-{self.port}.log"
        env = {**os.environ, **{f"MICROBEARING_{name.upper()}": value for name, value in settings.items()}}
        env.pop("PROMETHEUS_MULTIPROC_DIR", None)

        def limit_files() -> None:
            if fd_limit is not None:
                resource.setrlimit(resource.RLIMIT_NOFILE, (fd_limit, fd_limit))

        self.log = self.log_path.open("ab")
        self.process = subprocess.Popen(
            [sys.executable, "-m", "microbearing", "serve", "--host", "127.0.0.1", "--port", str(self.port),
             "--data-dir", str(tmp_path / "data")],
            cwd=REPO, env=env, stdout=self.log, stderr=subprocess.STDOUT, preexec_fn=limit_files)
        wait_healthy(self.url, self.process, self.log_path)

    def stop(self) -> None:
        self.process.terminate()
        try:
            self.process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self.log.close()


def partial_head(port: int) -> socket.socket:
    """A connection that sends the start of a request head and never finishes it."""
    sock = socket.create_connection(("127.0.0.1", port), timeout=10)
    sock.sendall(b"GET /healthz HTTP/1.1\r\nHost: flood\r\nX-Slow: ")
    return sock


def raw_request(port: int, data: bytes) -> bytes:
    """Send ``data`` in one piece and read the answer until the server closes or 10 s pass."""
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        sock.sendall(data)
        answer = b""
        try:
            while chunk := sock.recv(65536):
                answer += chunk
                if b"\r\n\r\n" in answer:
                    head, _, body = answer.partition(b"\r\n\r\n")
                    length = next((int(line.split(b":")[1]) for line in head.split(b"\r\n")
                                   if line.lower().startswith(b"content-length:")), None)
                    if length is not None and len(body) >= length:
                        break
        except TimeoutError:
            pass
    return answer


def test_header_limits_and_a_connection_flood_on_a_live_server(tmp_path):
    server = Serve(tmp_path, fd_limit=FD_LIMIT, fd_reserve="64", header_timeout_s="30",
                   max_header_bytes="8192")
    held: list[socket.socket] = []
    try:
        # 431 past the head limit, answered as a problem naming the setting; the connection closes.
        answer = raw_request(server.port, b"GET /healthz HTTP/1.1\r\nHost: a\r\nX-Big: " + b"a" * 100_000
                             + b"\r\n\r\n")
        head, _, body = answer.partition(b"\r\n\r\n")
        assert head.startswith(b"HTTP/1.1 431"), answer[:200]
        assert b"content-type: application/problem+json" in head.lower()
        problem = json.loads(body)
        assert problem["status"] == 431 and "MICROBEARING_MAX_HEADER_BYTES" in problem["detail"]
        # A head just under the limit passes.
        answer = raw_request(server.port, b"GET /healthz HTTP/1.1\r\nHost: a\r\nX-Big: " + b"a" * 7_900
                             + b"\r\nConnection: close\r\n\r\n")
        assert answer.startswith(b"HTTP/1.1 200"), answer[:200]
        # A small head with a large body in the same packet is not a large head.
        points = json.dumps({"points": {"balls": 4, "load_N": [0.01] * 20_000, "speed_m_s": 0.05},
                             "outputs": ["mu"]}).encode()
        answer = raw_request(server.port, b"POST /v1/friction/batch HTTP/1.1\r\nHost: a\r\nContent-Type: "
                             b"application/json\r\nConnection: close\r\nContent-Length: "
                             + str(len(points)).encode() + b"\r\n\r\n" + points)
        assert answer.startswith(b"HTTP/1.1 200"), answer[:300]

        # 600 connections that never finish their heads, with 256 files allowed: /healthz answers.
        for _ in range(600):
            held.append(partial_head(server.port))
        for _ in range(5):
            assert httpx.get(f"{server.url}/healthz", timeout=5).status_code == 200
        open_files = len(os.listdir(f"/proc/{server.process.pid}/fd"))
        print(f"600 idle connections held against a limit of {FD_LIMIT} files: the server has {open_files} "
              "open, /healthz answered 5 of 5")
        assert open_files <= FD_LIMIT - 16
        # The evicted connections were closed by the server (they read end of file).
        closed = 0
        for sock in held[:100]:
            sock.settimeout(0.5)
            try:
                closed += sock.recv(1) == b""
            except (TimeoutError, ConnectionResetError):
                closed += isinstance(sys.exc_info()[1], ConnectionResetError)
        assert closed >= 90, closed
    finally:
        for sock in held:
            sock.close()
        server.stop()
    log = server.log_path.read_text(errors="replace")
    assert "Too many open files" not in log
    evictions = [line for line in log.splitlines() if "closed the oldest one" in line]
    assert 1 <= len(evictions) <= 30, len(evictions)  # once a second at most, with a count


def test_a_head_not_finished_in_time_closes_the_connection(tmp_path):
    server = Serve(tmp_path, header_timeout_s="1")
    try:
        sock = partial_head(server.port)
        opened = time.monotonic()
        sock.settimeout(15)
        assert sock.recv(1) == b""
        waited = time.monotonic() - opened
        sock.close()
        print(f"an unfinished head was closed after {waited:.2f} s (limit 1 s)")
        assert 0.9 <= waited <= 5
        # A kept-alive connection gets the same limit for its next head, and answers in the meantime.
        with httpx.Client(base_url=server.url) as client:
            assert client.get("/healthz").status_code == 200
            assert client.get("/healthz").status_code == 200
    finally:
        server.stop()


def test_bytes_past_a_bodys_content_length_get_a_problem(tmp_path):
    # a Content-Length smaller than the body: what follows is read as the next request, which is not one
    server = Serve(tmp_path)
    try:
        body = json.dumps({"balls": 4, "load_N": 0.008826, "speed_m_s": 0.05}).encode()
        lying = (b"POST /v1/friction HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                 b"Content-Length: 10\r\n\r\n" + body + b"\r\n")
        answer = raw_request(server.port, lying)
        head, _, problem = answer.partition(b"\r\n\r\n")
        assert head.startswith(b"HTTP/1.1 400"), answer[:300]
        assert b"content-type: application/problem+json" in head.lower(), answer[:300]
        assert json.loads(problem)["status"] == 400 and "Content-Length" in json.loads(problem)["detail"]
        assert raw_request(server.port, b"NOT HTTP AT ALL\r\n\r\n").startswith(b"HTTP/1.1 400")
    finally:
        server.stop()


def test_the_open_file_limit_is_raised_to_the_hard_limit():
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    code = ("import resource; from microbearing.service.connections import raise_fd_limit; "
            "print(raise_fd_limit(), resource.getrlimit(resource.RLIMIT_NOFILE)[0])")

    def lowered() -> None:
        resource.setrlimit(resource.RLIMIT_NOFILE, (64, min(hard, 4096)))

    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         preexec_fn=lowered).stdout.split()
    assert out == [str(min(hard, 4096))] * 2
    assert raise_fd_limit() >= soft


def test_repeated_lines_pass_once_a_second_with_their_count():
    now = [0.0]
    kept = RepeatFilter(clock=lambda: now[0])

    def record(message: str, errno: int) -> logging.LogRecord:
        error = OSError(errno, os.strerror(errno))
        return logging.LogRecord("asyncio", logging.ERROR, __file__, 1, message, None, (OSError, error, None))

    passed = []
    for step in range(3000):  # 3,000 EMFILE lines over 3 s, and one other error at the start
        now[0] = step / 1000
        line = record("socket.accept() out of system resource", 24)
        if kept.filter(line):
            passed.append((now[0], line.getMessage()))
    other = record("socket.accept() out of system resource", 23)
    assert kept.filter(other)  # another errno is another kind of line
    assert [t for t, _ in passed] == [0.0, 1.0, 2.0]
    assert passed[0][1] == "socket.accept() out of system resource"
    assert passed[1][1].endswith("(and 999 more like it in the last 1.0 s)")
    assert passed[2][1].endswith("(and 999 more like it in the last 1.0 s)")


def test_requests_past_the_concurrency_limit_get_503_and_probes_pass():
    release = asyncio.Event()

    async def slow(scope, receive, send):
        if scope["path"] != "/healthz":
            await release.wait()
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b"ok"})

    async def scenario():
        app = ConcurrencyLimitMiddleware(slow, max_requests=2)
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://t") as client:
            first = [asyncio.create_task(client.get("/v1/work")) for _ in range(2)]
            while app.active < 2:
                await asyncio.sleep(0.01)
            refused = await client.get("/v1/work")
            probe = await client.get("/healthz")
            release.set()
            done = await asyncio.gather(*first)
            after = await client.get("/v1/work")
        return refused, probe, done, after

    refused, probe, done, after = asyncio.run(scenario())
    assert refused.status_code == 503 and refused.headers["retry-after"] == "1"
    assert refused.headers["content-type"] == "application/problem+json"
    assert "MICROBEARING_MAX_CONCURRENT_REQUESTS=2" in refused.json()["detail"]
    assert probe.status_code == 200
    assert [r.status_code for r in done] == [200, 200] and after.status_code == 200


def test_the_server_busy_on_umbridge_paths_is_in_umbridge_s_error_form(tmp_path):
    # The stock UM-Bridge client reads {"error": {...}}: the 503 past the concurrency limit is rewritten
    # there as the protocol's other refusals are (the rewriting wraps the limit in the app).
    from microbearing.service.app import create_app
    from microbearing.service.settings import Settings
    from microbearing.service.umbridge import ProtocolErrorMiddleware

    order = [m.cls.__name__ for m in create_app(Settings(data_dir=tmp_path)).user_middleware]
    assert order.index("ProtocolErrorMiddleware") < order.index("ConcurrencyLimitMiddleware")  # outside
    release = asyncio.Event()

    async def slow(scope, receive, send):
        await release.wait()
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b"{}"})

    async def scenario():
        limit = ConcurrencyLimitMiddleware(slow, max_requests=1)
        app = ProtocolErrorMiddleware(limit)
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://t") as client:
            first = asyncio.create_task(client.post("/umbridge/Evaluate", json={}))
            while limit.active < 1:
                await asyncio.sleep(0.01)
            refused = await client.post("/umbridge/Evaluate", json={})
            rest = await client.get("/v1/work")
            release.set()
            await first
        return refused, rest

    refused, rest = asyncio.run(scenario())
    assert refused.status_code == 503 and refused.headers["retry-after"] == "1"
    error = refused.json()["error"]
    assert set(error) == {"type", "message"} and "MICROBEARING_MAX_CONCURRENT_REQUESTS=1" in error["message"]
    assert rest.headers["content-type"] == "application/problem+json"  # elsewhere a problem, as before
