"""The service as users meet it: a live uvicorn server started by ``microbearing serve``,
driven by the README's curl examples (tests/test_service_client.py drives it through a generated client)."""

from __future__ import annotations

import json
import os
import re
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from live_server import free_port, terminate, wait_healthy

REPO = Path(__file__).resolve().parent.parent
README = REPO / "README.md"
README_EXAMPLES_HEADING = "### REST API examples"
#: The quickstart's blocks run too (issue 28: a designer follows them as written).
README_QUICKSTART_HEADING = "## Quickstart"
README_URL = "http://127.0.0.1:8000"


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """Base URL of a server run by ``microbearing serve`` on a free loopback port and a tmp data dir."""
    port = free_port()
    data_dir = tmp_path_factory.mktemp("live-data")
    env = {**os.environ, "MICROBEARING_SWEEP_SYNC_MAX_POINTS": "10000"}
    log_path = tmp_path_factory.mktemp("live-log") / "server.log"
    log = log_path.open("wb")  # a file, not a pipe nobody reads while the server runs
    process = subprocess.Popen(
        [sys.executable, "-m", "microbearing.service.cli", "serve",
         "--port", str(port), "--data-dir", str(data_dir)],
        cwd=REPO, env=env, stdout=log, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(url, process, log_path, timeout_s=60)
        yield url
    finally:
        terminate(process)
        log.close()
    assert (data_dir / "microbearing.sqlite3").exists()  # the data dir given on the command line
    # every line the server wrote is a JSON object: uvicorn's startup and shutdown lines too
    lines = log_path.read_text().splitlines()
    entries = [json.loads(line) for line in lines]
    loggers = {entry["logger"] for entry in entries}
    assert {"uvicorn.error", "microbearing.access"} <= loggers, loggers
    assert any("Uvicorn running on" in entry["message"] for entry in entries)


def readme_blocks() -> list[str]:
    """The ```bash blocks of the README's quickstart and of its section of curl examples."""
    text = README.read_text(encoding="utf-8")
    blocks = []
    for heading in (README_QUICKSTART_HEADING, README_EXAMPLES_HEADING):
        start = text.index(heading)
        end = text.find("\n## ", start + 1)
        section = text[start:] if end < 0 else text[start:end]
        found = re.findall(r"```bash\n(.*?)```", section, flags=re.S)
        assert found, f"no bash blocks under the README heading {heading!r}"
        blocks += found
    return blocks


def _collapse(codes: list[str]) -> list[str]:
    return [code for i, code in enumerate(codes) if i == 0 or code != codes[i - 1]]


@pytest.mark.skipif(shutil.which("curl") is None, reason="curl is not installed")
@pytest.mark.parametrize("block", readme_blocks(), ids=lambda b: re.sub(r"\W+", "-", b.split("\n")[1])[:48])
def test_readme_curl_examples(server, block, tmp_path):
    expected = re.findall(r"^# (\d{3})\b", block, flags=re.M)
    assert expected, block
    # Each curl call writes its status code to stderr, leaving stdout to the example's pipes.
    script = ("set -e\ncurl() { command curl --write-out '%{stderr}%{http_code}\\n' \"$@\"; }\n"
              + block.replace(README_URL, server))
    run = subprocess.run(["bash", "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    codes = re.findall(r"^(\d{3})$", run.stderr, flags=re.M)
    # A polling loop repeats a status, so compare the sequences without repeats.
    assert _collapse(codes) == _collapse(expected), (codes, run.stdout[-500:])


def test_two_content_types_on_a_raw_socket_get_a_400_problem(server):
    # 100,000 nested brackets declared twice (JSON, then text): refused whole, after the body is read
    body = b"[" * 100_000 + b"]" * 100_000
    host, port = server.removeprefix("http://").split(":")
    head = (f"POST /v1/friction HTTP/1.1\r\nHost: {host}\r\nContent-Length: {len(body)}\r\n"
            "Content-Type: application/json\r\nContent-Type: text/plain\r\nConnection: close\r\n\r\n")
    with socket.create_connection((host, int(port)), timeout=30) as sock:
        sock.sendall(head.encode() + body)
        answer = b""
        while chunk := sock.recv(65536):
            answer += chunk
    status_line, _, rest = answer.partition(b"\r\n")
    headers, _, content = rest.partition(b"\r\n\r\n")
    assert status_line.startswith(b"HTTP/1.1 400"), answer[:300]
    assert b"content-type: application/problem+json" in headers.lower()
    assert json.loads(content)["title"] == "Ambiguous content type"
