"""The service as users meet it: a live uvicorn server started by ``microbearing serve``,
driven by the curl examples of the README and of the manual (tests/test_service_client.py drives it
through a generated client)."""

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
from docs_pages import README, code_blocks, page, section
from live_server import free_port, terminate, wait_healthy

REPO = Path(__file__).resolve().parent.parent
#: Where the curl examples are: the README's quickstart, and pages of the manual (whole, or a section).
#: The quickstart and the tutorial run too (issue 28: a designer follows them as written).
EXAMPLES = (("README.md", "## Quickstart: ten minutes"), ("tutorial.md", None),
            ("reference/rest-api.md", "## REST API examples"), ("how-to/labs.md", None))


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
        wait_healthy(url, process, log_path)
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


def example_blocks() -> list[tuple[str, str]]:
    """``(where, block)`` for each distinct ```bash block of :data:`EXAMPLES` (the README's quickstart repeats
    the tutorial's blocks: each runs once)."""
    blocks: dict[str, str] = {}
    for name, heading in EXAMPLES:
        text = README.read_text(encoding="utf-8") if name == "README.md" else page(name)
        found = code_blocks(section(text, heading) if heading else text, "bash")
        assert found, f"no bash blocks in {name} {heading or ''}"
        for block in found:
            blocks.setdefault(block, name)
    return [(name, block) for block, name in blocks.items()]


def test_the_examples_use_the_port_variable():
    # Every example reads the port from PORT, which the quickstart sets once (issue 34: the service may
    # run on another port); none hard-codes one.
    assert all("127.0.0.1:$PORT" in block and "127.0.0.1:8000" not in block
               for _, block in example_blocks() if "curl" in block)
    assert any(re.search(r"^PORT=8000$", block, flags=re.M) for _, block in example_blocks())


def _collapse(codes: list[str]) -> list[str]:
    return [code for i, code in enumerate(codes) if i == 0 or code != codes[i - 1]]


@pytest.mark.skipif(shutil.which("curl") is None, reason="curl is not installed")
@pytest.mark.parametrize(("where", "block"), example_blocks(),
                         ids=[f"{name}:" + re.sub(r"\W+", "-", block.split("\n")[1])[:40]
                              for name, block in example_blocks()])
def test_curl_examples(server, where, block, tmp_path):
    expected = re.findall(r"^# (\d{3})\b", block, flags=re.M)
    assert expected, block
    # Each curl call writes its status code to stderr, leaving stdout to the example's pipes.
    port = server.rsplit(":", 1)[1]
    script = ("set -e\ncurl() { command curl --write-out '%{stderr}%{http_code}\\n' \"$@\"; }\n"
              + f"PORT={port}\n" + re.sub(r"^PORT=8000$", f"PORT={port}", block, flags=re.M))
    run = subprocess.run(["bash", "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, (where, run.stderr)
    codes = re.findall(r"^(\d{3})$", run.stderr, flags=re.M)
    # A polling loop repeats a status, so compare the sequences without repeats.
    assert _collapse(codes) == _collapse(expected), (codes, run.stdout[-500:])


def test_the_polling_loop_stops_when_a_job_fails(tmp_path):
    # The quickstart's loop polls while the job is queued or running, then says how it ended: a failed
    # job ends it too (issue 34: the loop that waited for "succeeded" spun forever on a failure).
    loop = re.search(r"^while STATUS=.*\n.*done; echo \"job \$STATUS\"$", README.read_text(), flags=re.M)
    assert loop, "the README's quickstart has no polling loop"
    for statuses, last in ((["queued", "running", "failed"], "job failed"),
                           (["queued", "running", "running", "succeeded"], "job succeeded")):
        answers = tmp_path / "answers"
        answers.write_text("".join(f'{{"id":"j","status":"{s}","error":{{"status":422}}}}\n'
                                   for s in statuses))
        # curl answers the next line of the file each time, as the service would answer each poll
        fake = 'curl() { head -1 answers; sed -i 1d answers; }\nsleep() { :; }\nPORT=1\nJOB=/v1/jobs/j\n'
        run = subprocess.run(["bash", "-c", fake + loop.group(0)], cwd=tmp_path, capture_output=True,
                             text=True, timeout=30)
        assert run.stdout.strip() == last, run
        assert answers.read_text() == ""  # polled until the last answer, not beyond


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
