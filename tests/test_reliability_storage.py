"""Storage faults against a real server: a full disk, a read-only or unusable data folder.

The full disk is a small tmpfs, which needs root (mount); without it those tests are skipped and
the in-process fault injection of tests/test_service_jobs.py (SQLite's own page limit, a store
refusing every write) still runs. A bad data folder at start-up needs no privilege.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import pytest
from live_server import REPO, Server, free_port, wait_for

from microbearing.service.deps import DataFolderError, open_store
from microbearing.service.store import DATABASE_NAME

pytestmark = pytest.mark.skipif(os.name != "posix", reason="process groups are POSIX")

CAN_MOUNT = os.name == "posix" and os.geteuid() == 0 and shutil.which("mount") is not None
needs_mount = pytest.mark.skipif(not CAN_MOUNT, reason="mounting a small tmpfs needs root and mount(8)")


@contextmanager
def tmpfs(path: Path, size: str):
    """A tmpfs of ``size`` mounted at ``path`` for the duration."""
    path.mkdir(parents=True, exist_ok=True)
    subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)], check=True)
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], check=False)


def sweep(points: int) -> dict:
    return {"design": "sobol", "points": points, "seed": 1, "outputs": ["mu"],
            "ranges": {"load_N": {"low": 1e-3, "high": 0.05}, "speed_m_s": {"low": 0.0, "high": 0.2}},
            "fixed": {"balls": 4}}


def error_lines(log: Path) -> list[dict]:
    lines = []
    for line in log.read_text(errors="replace").splitlines():
        try:
            record = json.loads(line)
        except ValueError:
            continue
        if isinstance(record, dict) and record.get("level") == "ERROR":
            lines.append(record)
    return lines


@needs_mount
def test_a_full_disk_fails_the_job_with_the_reason_and_readiness_turns_503(tmp_path):
    with tmpfs(tmp_path / "disk", "3m") as disk:
        log = tmp_path / "server.log"
        server = Server(disk, log, sweep_sync_max_points="0", min_free_bytes=str(512 * 1024),
                        job_workers="1", executor_workers="1")
        try:
            ready = server.client.get("/readyz")
            assert ready.status_code == 200 and ready.json()["status"] == "ready", ready.text
            small = server.client.post("/v1/sweeps", json=sweep(2_000))
            assert wait_for(server, small.headers["location"], ("succeeded",))["progress"] == 1.0
            # 200,000 points of 3 columns: about 12 MB of JSON on a 3 MB disk.
            response = server.client.post("/v1/sweeps", json=sweep(200_000))
            assert response.status_code == 202, response.text
            started = time.monotonic()
            job = wait_for(server, response.headers["location"], ("succeeded", "failed"), timeout_s=60)
            waited = time.monotonic() - started
            assert job["status"] == "failed", job
            assert job["error"]["status"] == 507 and "the disk is full" in job["error"]["detail"], job
            assert str(disk) in job["error"]["detail"]
            logged = [r for r in error_lines(log) if job["id"] in r.get("message", "")]
            assert logged and "disk is full" in logged[0]["message"]
            not_ready = server.client.get("/readyz")
            assert not_ready.status_code == 503
            assert not_ready.headers["content-type"] == "application/problem+json"
            assert server.client.get("/healthz").json() == {"status": "ok"}  # liveness unchanged
            # The earlier result is intact and still served.
            assert server.client.get(f"{small.headers['location']}/result").status_code == 200
            print(f"full disk: the job failed {waited:.1f} s after it was accepted")
        finally:
            server.stop()


@pytest.mark.parametrize("fault", ["file", "corrupt", "read-only"])
def test_a_bad_data_folder_is_refused_naming_the_path_and_the_fix(tmp_path, fault):
    if fault == "read-only" and not CAN_MOUNT:
        pytest.skip("a read-only file system needs root and mount(8)")
    data_dir = tmp_path / "data"
    if fault == "file":
        data_dir.write_text("not a folder")
    elif fault == "corrupt":
        data_dir.mkdir()
        (data_dir / DATABASE_NAME).write_bytes(b"this is not an SQLite database" * 100)
    else:
        data_dir.mkdir()
        subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m,ro", "tmpfs", str(data_dir)], check=True)
    try:
        with pytest.raises(DataFolderError) as refused:
            open_store(data_dir)
    finally:
        if fault == "read-only":
            subprocess.run(["umount", "-l", str(data_dir)], check=False)
    message = str(refused.value)
    assert str(data_dir) in message and "MICROBEARING_DATA_DIR" in message, message
    expected = {"file": "cannot be used", "corrupt": "not a usable SQLite database", "read-only": "read-only"}
    assert expected[fault] in message, message


def test_the_server_exits_non_zero_on_a_bad_data_folder(tmp_path):
    data_dir = tmp_path / "data"
    data_dir.mkdir()
    (data_dir / DATABASE_NAME).write_bytes(b"this is not an SQLite database" * 100)
    env = {**os.environ, "MICROBEARING_DATA_DIR": str(data_dir)}
    env.pop("PROMETHEUS_MULTIPROC_DIR", None)
    process = subprocess.run(
        [sys.executable, "-m", "uvicorn", "microbearing.service.app:app", "--host", "127.0.0.1", "--port",
         str(free_port())],
        cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
    output = process.stdout + process.stderr
    assert process.returncode != 0, output
    critical = [line for line in output.splitlines() if '"CRITICAL"' in line]
    assert critical, output
    message = json.loads(critical[0])["message"]
    assert str(data_dir) in message and "MICROBEARING_DATA_DIR" in message, message


def test_readiness_reports_free_space_and_refused_writes_in_process(tmp_path, monkeypatch):
    from fastapi.testclient import TestClient

    from microbearing.service.app import create_app
    from microbearing.service.deps import get_runtime
    from microbearing.service.settings import Settings
    from microbearing.service.store import StorageError

    settings = Settings(data_dir=tmp_path, min_free_bytes=2**62, sweep_sync_max_points=0)
    with TestClient(create_app(settings)) as client:
        short = client.get("/readyz")
        assert short.status_code == 503 and "MICROBEARING_MIN_FREE_BYTES" in short.json()["detail"]
        assert client.get("/healthz").status_code == 200
    with TestClient(create_app(Settings(data_dir=tmp_path, sweep_sync_max_points=0))) as client:
        ready = client.get("/readyz").json()
        assert ready["status"] == "ready" and ready["free_bytes"] > 0 and ready["active_jobs"] == 0
        store = get_runtime(client.app).store

        def read_only(*args, **kwargs):
            raise StorageError("the database is read-only", store.path)

        monkeypatch.setattr(store, "transaction", read_only)
        not_ready = client.get("/readyz")
        assert not_ready.status_code == 503 and "read-only" in not_ready.json()["detail"]
        refused = client.post("/v1/sweeps", json=sweep(20_000))  # a job must be recorded: refused
        assert refused.status_code == 503 and refused.headers["content-type"] == "application/problem+json"
        assert "read-only" in refused.json()["detail"] and int(refused.headers["retry-after"]) > 0
        assert get_runtime(client.app).jobs.active_count() == 0  # its place was given back
