"""Fixtures shared by several test files: a service app on its own data folder per test file (``data_dir``,
``client``), and the database backends of the store.

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


def _skips_slow(config) -> bool:
    """Whether the run's ``-m`` expression deselects the slow tier (e.g. ``-m "not slow"``)."""
    markexpr = config.getoption("markexpr", "")
    if not markexpr:
        return False
    try:
        from _pytest.mark.expression import Expression

        return not Expression.compile(markexpr).evaluate(lambda name, **kwargs: name == "slow")
    except Exception:  # another pytest's expression API: collect everything, -m still deselects
        return False


def pytest_ignore_collect(collection_path, config):
    """A file of the slow tier is not even collected by a run that deselects that tier."""
    from tiers import SLOW_FILES

    if collection_path.name in SLOW_FILES and _skips_slow(config):
        return True
    return None


@pytest.hookimpl(tryfirst=True)  # before -m and -k deselect: the slow marks must be on by then
def pytest_collection_modifyitems(session, config, items):
    """Refuse a collection in which two tests share a node id: pytest-xdist knows tests by their ids and
    would run one of each such group, silently (pytest 9.2 with schemathesis 4.32 did this to the
    spec's 30 operations). Mark the slow tier (tests/tiers.py), and on a whole-suite collection refuse
    an entry or a stand-in that names no collected test, or a stand-in that is itself slow."""
    counts = Counter(item.nodeid for item in items)
    repeated = sorted(nodeid for nodeid, count in counts.items() if count > 1)
    if repeated:
        raise pytest.UsageError(f"{len(repeated)} test id(s) collected more than once (pytest-xdist would "
                                f"run one test of each): {', '.join(repeated[:5])}")
    from tiers import SLOW, SLOW_FILES, slow_key

    here = Path(__file__).parent
    ids = {}
    for item in items:
        file = item.nodeid.split("::")[0]
        local = Path(str(item.path)).relative_to(here).as_posix() + item.nodeid[len(file):]
        ids[local] = item
        if slow_key(local) is not None:
            item.add_marker(pytest.mark.slow)
    if [Path(arg).resolve() for arg in config.args] != [here.resolve()]:
        return  # a part of the suite: entries of files not collected cannot be checked
    keys = {slow_key(local) for local in ids} - {None}
    entries = {**SLOW, **{file: quick for file, quick in SLOW_FILES.items() if not _skips_slow(config)}}
    problems = [f"{key} names no collected test" for key in entries if key not in keys]
    problems += [f"the stand-in {quick} (for {key}) names no collected test" for key, quick in entries.items()
                 if quick not in ids]
    problems += [f"the stand-in {quick} (for {key}) is itself slow" for key, quick in entries.items()
                 if quick in ids and slow_key(quick) is not None]
    if problems:
        raise pytest.UsageError("tests/tiers.py: " + "; ".join(problems))


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


@pytest.fixture(scope="module")
def data_dir(request, tmp_path_factory) -> Path:
    """The data folder of one test file's app (:func:`client`), named after the file; a file that needs
    another defines its own ``data_dir``."""
    return tmp_path_factory.mktemp(request.module.__name__.rpartition(".")[2].removeprefix("test_"))


@pytest.fixture(scope="module")
def client(data_dir):
    """The service with its default settings on ``data_dir``, one for the whole test file (a
    ``fastapi.testclient.TestClient``, started and shut down once); a file that needs other settings
    defines its own ``client``."""
    from fastapi.testclient import TestClient

    from microbearing.service.app import create_app
    from microbearing.service.settings import Settings

    with TestClient(create_app(Settings(data_dir=data_dir))) as test_client:
        yield test_client
