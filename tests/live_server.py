"""A real server for the reliability tests: ``uvicorn service.app:app`` in a subprocess on loopback.

Used by the tests that are about the server as a process (crashes, floods, full disks, scale-out).
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
from jobs_helper import wait_job

REPO = Path(__file__).resolve().parent.parent


def free_port() -> int:
    """A TCP port free on the loopback interface now."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def wait_healthy(url: str, process: subprocess.Popen, log: Path, timeout_s: float = 240.0) -> None:
    """Poll ``url/healthz`` until it answers 200.

    Raises
    ------
    RuntimeError
        With the end of the server's ``log`` when ``process`` exits or ``timeout_s`` [s] pass first.
    """
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            if httpx.get(f"{url}/healthz", timeout=1).status_code == 200:
                return
        except httpx.TransportError:
            pass
        if process.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"the server did not start: {log.read_text(errors='replace')[-2000:]}")
        time.sleep(0.1)


def terminate(process: subprocess.Popen) -> None:
    """SIGTERM to a server process, SIGKILL if it has not ended 20 s later."""
    process.terminate()
    try:
        process.wait(timeout=20)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


class Server:
    """``uvicorn service.app:app`` on a loopback port and a given data folder, in its own process group.

    Parameters
    ----------
    data_dir : pathlib.Path
        ``MICROBEARING_DATA_DIR``.
    log : pathlib.Path
        File receiving the server's output (appended).
    **settings : str
        Other ``MICROBEARING_*`` variables, by setting name (``job_workers="1"``).
    """

    def __init__(self, data_dir: Path, log: Path, **settings: str):
        self.port = free_port()
        self.log_path = log
        env = {**os.environ, "MICROBEARING_DATA_DIR": str(data_dir),
               **{f"MICROBEARING_{name.upper()}": str(value) for name, value in settings.items()}}
        env.pop("PROMETHEUS_MULTIPROC_DIR", None)
        self.log = log.open("ab")
        self.process = subprocess.Popen(self.command(data_dir), cwd=REPO, env=env, stdout=self.log,
                                        stderr=subprocess.STDOUT, start_new_session=True)
        self.url = f"http://127.0.0.1:{self.port}"
        self.client = httpx.Client(base_url=self.url, timeout=60.0)
        try:
            wait_healthy(self.url, self.process, log)
        except RuntimeError:
            self.stop()
            raise

    def command(self, data_dir: Path) -> list[str]:
        """The server's command line (the data folder is also in ``MICROBEARING_DATA_DIR``)."""
        return [sys.executable, "-m", "uvicorn", "microbearing.service.app:app", "--host", "127.0.0.1",
                "--port", str(self.port), "--no-access-log"]

    def kill(self) -> None:
        """SIGKILL: no shutdown handler runs, exactly as in a power cut of the process."""
        os.killpg(self.process.pid, signal.SIGKILL)
        self.process.wait(timeout=30)
        self.client.close()
        self.log.close()

    def stop(self) -> None:
        """SIGTERM (SIGKILL after 30 s) and close the client and the log."""
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGTERM)
            try:
                self.process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(self.process.pid, signal.SIGKILL)
                self.process.wait(timeout=30)
        self.client.close()
        self.log.close()


def wait_for(server: Server, location: str, statuses: tuple[str, ...], timeout_s: float = 120.0,
             headers: dict[str, str] | None = None) -> dict:
    """Poll a job of the live server until its status is one of ``statuses``; fails after ``timeout_s`` [s]
    (:func:`jobs_helper.wait_job`)."""
    return wait_job(server.client, location, headers=headers, until=statuses, timeout_s=timeout_s)
