"""A real PostgreSQL server for the tests: ``initdb`` and ``pg_ctl`` in a temporary folder, on a free port.

Found on the PATH or in Debian's ``/usr/lib/postgresql/<version>/bin`` (the ``postgresql`` package,
which .ci/run installs when it runs as root). PostgreSQL refuses to run as root: as root the
server runs as the ``postgres`` user (or ``nobody``). Trust authentication on loopback only;
fsync off (the tests need no durability across a power cut of the machine).
"""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import subprocess
import tempfile
import uuid
from pathlib import Path

from live_server import free_port


def binaries() -> Path | None:
    """The folder of ``initdb``, ``pg_ctl`` and ``postgres``, or None when PostgreSQL is not installed."""
    found = shutil.which("initdb")
    if found and shutil.which("pg_ctl"):
        return Path(os.path.realpath(found)).parent
    def version(initdb: str) -> int:
        name = Path(initdb).parent.parent.name
        return int(name) if name.isdigit() else 0

    versions = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"), key=version)
    return Path(versions[-1]).parent if versions else None


def _run_as() -> str | None:
    """The user running the server: None (this one) unless we are root."""
    if os.geteuid() != 0:
        return None
    for name in ("postgres", "nobody"):
        try:
            pwd.getpwnam(name)
            return name
        except KeyError:
            continue
    raise RuntimeError("running as root and neither a postgres nor a nobody user exists to run PostgreSQL")


class PostgresServer:
    """A PostgreSQL cluster of its own, started in a temporary folder; :meth:`stop` removes it."""

    def __init__(self):
        bin_dir = binaries()
        if bin_dir is None:
            raise RuntimeError("PostgreSQL is not installed")
        self.user = _run_as()
        self.folder = Path(tempfile.mkdtemp(prefix="microbearing-pg-"))
        if self.user is not None:
            entry = pwd.getpwnam(self.user)
            os.chown(self.folder, entry.pw_uid, entry.pw_gid)
        self.data = self.folder / "data"
        self.log = self.folder / "server.log"
        self.port = free_port()
        self._pg_ctl = str(bin_dir / "pg_ctl")
        self._run([str(bin_dir / "initdb"), "-D", str(self.data), "-U", "microbearing", "--auth=trust",
                   "-E", "UTF8", "--locale=C", "--no-sync"])
        self.base_url = f"postgresql://microbearing@127.0.0.1:{self.port}"
        self.start()

    def start(self) -> None:
        """Start the server (again, after :meth:`halt`), on the same port."""
        options = (f"-p {self.port} -k {self.folder} -c listen_addresses=127.0.0.1 -c fsync=off "
                   "-c synchronous_commit=off -c full_page_writes=off -c max_connections=300")
        self._run([self._pg_ctl, "-D", str(self.data), "-l", str(self.log), "-o", options, "-w", "-t", "60",
                   "start"])

    def halt(self) -> None:
        """Stop the server (open connections are cut), keeping its data for :meth:`start`.

        A fast shutdown, not an immediate one: with synchronous_commit off, an immediate stop may
        lose the last commits, which a test then misreads.
        """
        self._run([self._pg_ctl, "-D", str(self.data), "-m", "fast", "-w", "-t", "60", "stop"])

    def _run(self, command: list[str]) -> None:
        done = subprocess.run(command, user=self.user, cwd=self.folder, capture_output=True, text=True,
                              timeout=120, check=False)
        if done.returncode != 0:
            log = self.log.read_text(errors="replace")[-2000:] if self.log.exists() else ""
            raise RuntimeError(f"{' '.join(command[:2])} failed ({done.returncode}): "
                               f"{done.stderr[-2000:]}{log}")

    def new_database(self) -> str:
        """The URL of a new, empty database of this server."""
        import psycopg

        name = f"test_{uuid.uuid4().hex[:12]}"
        with psycopg.connect(f"{self.base_url}/postgres", autocommit=True) as conn:
            conn.execute(f"CREATE DATABASE {name}")
        return f"{self.base_url}/{name}"

    def stop(self) -> None:
        """Stop the server (fast shutdown) and remove its folder."""
        try:
            self._run([self._pg_ctl, "-D", str(self.data), "-m", "fast", "-w", "-t", "60", "stop"])
        finally:
            shutil.rmtree(self.folder, ignore_errors=True)
