"""Fixtures shared by several test files: the database backends of the store.

``database`` runs a test against both backends: SQLite in the test's folder, and PostgreSQL on a
real server started once per session (tests/postgres_server.py). Without PostgreSQL installed (or
without psycopg) the PostgreSQL cases are skipped with the reason; with
``MICROBEARING_TEST_POSTGRES=required`` (set by .ci/run once it installed the server) they fail instead.
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import pytest


def pytest_collection_modifyitems(session, config, items):
    """Refuse a collection in which two tests share a node id: pytest-xdist knows tests by their ids and
    would run one of each such group, silently (pytest 9.2 with schemathesis 4.32 did this to the
    spec's 30 operations)."""
    counts = Counter(item.nodeid for item in items)
    repeated = sorted(nodeid for nodeid, count in counts.items() if count > 1)
    if repeated:
        raise pytest.UsageError(f"{len(repeated)} test id(s) collected more than once (pytest-xdist would "
                                f"run one test of each): {', '.join(repeated[:5])}")


def _unavailable(reason: str):
    if os.environ.get("MICROBEARING_TEST_POSTGRES") == "required":
        pytest.fail(f"PostgreSQL is required (MICROBEARING_TEST_POSTGRES=required) but {reason}")
    pytest.skip(f"PostgreSQL tests skipped: {reason}")


@pytest.fixture(scope="session")
def postgres_server():
    """A real PostgreSQL server for the session (skipped, with the reason, when it cannot be had)."""
    try:
        import psycopg  # noqa: F401
        import psycopg_pool  # noqa: F401
    except ImportError:
        _unavailable("psycopg is not installed (pip install -e '.[postgres]')")
    from postgres_server import PostgresServer, binaries

    if binaries() is None:
        _unavailable("no initdb/pg_ctl on the PATH or in /usr/lib/postgresql/*/bin "
                     "(apt-get install postgresql)")
    server = PostgresServer()
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
def postgres_url(postgres_server) -> str:
    """The URL of a new, empty database on the session's PostgreSQL server."""
    return postgres_server.new_database()


class Database:
    """One database as several server processes see it: :meth:`store` opens another connection to it.

    Attributes
    ----------
    backend : str
        ``"sqlite"`` or ``"postgresql"``.
    url : str or None
        The PostgreSQL URL (``MICROBEARING_DATABASE_URL``), None for SQLite.
    folder : pathlib.Path
        The data folder (SQLite's database is in it).
    """

    def __init__(self, backend: str, folder: Path, url: str | None):
        self.backend, self.folder, self.url = backend, folder, url
        self._stores: list = []

    def store(self, **options):
        """A new store of this database (as another process would open it); closed after the test."""
        from microbearing.service.store import Store

        if self.url is None:
            store = Store(self.folder, **options)
        else:
            from microbearing.service.store_postgres import PostgresStore

            store = PostgresStore(self.url, self.folder, **options)
        self._stores.append(store)
        return store

    def settings(self) -> dict[str, str]:
        """The server settings naming this database (``MICROBEARING_*`` by setting name)."""
        return {} if self.url is None else {"database_url": self.url}

    def close(self) -> None:
        for store in self._stores:
            store.close()


@pytest.fixture(params=["sqlite", "postgresql"])
def database(request, tmp_path) -> Callable:
    """The test runs once per backend: SQLite in ``tmp_path``, and a new PostgreSQL database."""
    url = request.getfixturevalue("postgres_url") if request.param == "postgresql" else None
    db = Database(request.param, tmp_path, url)
    try:
        yield db
    finally:
        db.close()
