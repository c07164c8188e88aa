"""``microbearing serve --workers 2``: metrics summed over both worker processes, keys enforced in each."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest
from prometheus_client.parser import text_string_to_metric_families

pytestmark = pytest.mark.skipif(os.name != "posix", reason="process groups are POSIX")

REPO = Path(__file__).resolve().parent.parent
KEY = "workers-test-key-0123"


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def friction_count(text: str) -> float:
    total = 0.0
    for family in text_string_to_metric_families(text):
        if family.name == "microbearing_http_requests":
            total += sum(s.value for s in family.samples if s.name.endswith("_total")
                         and s.labels.get("route") == "/v1/friction" and s.labels.get("status") == "200")
    return total


def test_two_workers_share_metrics_and_keys(tmp_path):
    port = free_port()
    env = {**os.environ, "MICROBEARING_API_KEYS": KEY}
    env.pop("PROMETHEUS_MULTIPROC_DIR", None)
    log = (tmp_path / "server.log").open("wb")
    process = subprocess.Popen(
        [sys.executable, "-m", "microbearing.service.cli", "serve", "--workers", "2", "--port", str(port),
         "--data-dir", str(tmp_path / "data")],
        cwd=REPO, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        # Fresh connections spread the requests over both workers.
        deadline = time.monotonic() + 90
        while True:
            try:
                if httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=5).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            assert process.poll() is None and time.monotonic() < deadline, "the server did not start"
            time.sleep(0.2)
        time.sleep(2.0)  # both workers up
        assert (tmp_path / "data" / "prometheus").is_dir()
        sent = 40
        for _ in range(sent):
            response = httpx.post(f"http://127.0.0.1:{port}/v1/friction", timeout=30,
                                  headers={"Authorization": f"Bearer {KEY}"},
                                  json={"balls": 4, "load_N": 0.01, "speed_m_s": 0.1})
            assert response.status_code == 200
            assert httpx.get(f"http://127.0.0.1:{port}/v1/version", timeout=30).status_code == 401
        # Whichever worker answers the scrape reports the requests of both.
        for _ in range(4):
            text = httpx.get(f"http://127.0.0.1:{port}/metrics", timeout=30).text
            assert friction_count(text) == sent
        files = (tmp_path / "data" / "prometheus").iterdir()
        pids = {path.name.split("_")[-1].split(".")[0] for path in files}
        assert len(pids) == 2, pids  # metric files from two worker processes
    finally:
        os.killpg(process.pid, signal.SIGTERM)
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait(timeout=30)
        log.close()
