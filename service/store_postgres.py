"""The store of jobs and models in a PostgreSQL database, shared by server processes on several hosts.

Chosen by ``MICROBEARING_DATABASE_URL=postgresql://user:password@host:5432/dbname`` (SQLite under
the data folder stays the default); needs the ``postgres`` extra (``pip install
'microbearing[postgres]'``: psycopg 3 and its connection pool). The tables, the job and model
methods and the stored formats are those of :class:`service.store.Store` (models' arrays as
``.npz`` bytes in a ``bytea`` column, loaded with ``allow_pickle=False``); what differs is isolated
here:

- ``?`` placeholders become psycopg's ``%s`` (:class:`_Connection`);
- the schema's types: ``DOUBLE PRECISION`` for SQLite's ``REAL`` (a lease's Unix time needs its
  digits), ``BYTEA`` for ``BLOB``, text in the ``"C"`` collation (ids and ISO timestamps sort by
  their bytes, as in SQLite), results and inputs deleted with their job (``ON DELETE CASCADE``);
- admission counts and inserts under a transaction-scoped advisory lock, so a limit holds across
  every process and host; a claim selects ``FOR UPDATE SKIP LOCKED``, so two processes never
  take the same job and never wait for each other;
- schema creation and migration (``ADD COLUMN IF NOT EXISTS``) at start, under an advisory lock
  (several processes may start at once).

Connections come from a bounded pool (``MICROBEARING_DATABASE_POOL_SIZE`` per process), checked
before use (a server restart costs no failed request). A storage fault maps to the same
:class:`~service.store.StorageError` as SQLite's: 507 when the server's disk is full, 503 when the
server cannot be reached, refuses connections or is read-only, or no connection is free within
``MICROBEARING_DATABASE_TIMEOUT_S``.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import psycopg
import psycopg_pool
from psycopg.rows import dict_row

from .store import _ADDED_COLUMNS, _LATE_SCHEMA, _SCHEMA, StorageError, Store, redacted_url, utc_now

__all__ = ["PostgresStore", "classify", "redacted_url"]

#: Keys of the advisory locks (any two distinct 64-bit numbers; these spell "mbschema" and "mbadmit").
_SCHEMA_LOCK, _ADMISSION_LOCK = 0x6D62736368656D61, 0x6D6261646D6974

#: Longest wait for a connection of :meth:`PostgresStore.check_writable` (``/readyz``) [s].
_PROBE_TIMEOUT_S = 2.0

#: SQLite's column types as PostgreSQL's (word by word; see the module's docstring).
_TYPES = {"REAL": "DOUBLE PRECISION", "BLOB": "BYTEA", "TEXT": 'TEXT COLLATE "C"'}


def _postgres_ddl(sql: str) -> str:
    """The SQLite schema ``sql`` in PostgreSQL's types, with child rows deleted with their job."""
    sql = re.sub(r"\b(REAL|BLOB|TEXT)\b", lambda m: _TYPES[m.group(1)], sql)
    return sql.replace("REFERENCES jobs (id)", "REFERENCES jobs (id) ON DELETE CASCADE")


@functools.lru_cache(maxsize=512)
def _placeholders(sql: str) -> str:
    """``sql`` with psycopg's placeholders (``%s`` for ``?``; a literal ``%`` doubled)."""
    return sql.replace("%", "%%").replace("?", "%s")


#: SQLSTATE classes of a storage fault (https://www.postgresql.org/docs/current/errcodes-appendix.html):
#: connection exception, insufficient resources, operator intervention, system error.
_FAULT_CLASSES = {"08": "the database connection failed", "53": "the database server lacks resources",
                  "57": "the database server is stopping or starting", "58": "the database server failed"}


def classify(exc: BaseException, where: str) -> StorageError | None:
    """The storage fault ``exc`` (from psycopg or its pool) stands for, or None when it is something else.

    Parameters
    ----------
    exc : BaseException
        The exception.
    where : str
        The database URL without its password, for the message.
    """
    if isinstance(exc, StorageError):
        return exc
    if isinstance(exc, psycopg_pool.PoolTimeout):
        return StorageError(f"no database connection within the time allowed ({exc}; "
                            "MICROBEARING_DATABASE_TIMEOUT_S): the server is unreachable or every connection "
                            "of MICROBEARING_DATABASE_POOL_SIZE is busy", where)
    if not isinstance(exc, psycopg.Error):
        return None
    state = exc.sqlstate or ""
    if state == "53100":
        return StorageError("the database server's disk is full", where, 507)
    if state == "25006":
        return StorageError("the database is read-only (a standby server?)", where)
    if state[:2] in _FAULT_CLASSES:
        return StorageError(f"{_FAULT_CLASSES[state[:2]]} ({str(exc).strip()})", where)
    if isinstance(exc, psycopg.OperationalError) and not state:  # refused, lost, closed: no SQLSTATE
        return StorageError("the database server cannot be reached or refused the connection "
                            f"({str(exc).strip()})", where)
    return None


class _Connection:
    """A pooled psycopg connection speaking the store's SQL (``?`` placeholders, rows as dicts)."""

    def __init__(self, conn: psycopg.Connection):
        self._conn = conn

    def execute(self, sql: str, args: Any = ()) -> psycopg.Cursor:
        return self._conn.execute(_placeholders(sql), tuple(args))


class PostgresStore(Store):
    """The jobs and models of every server process, on any host, in one PostgreSQL database.

    Parameters
    ----------
    url : str
        ``postgresql://user:password@host:port/dbname`` (any libpq connection string).
    data_dir : pathlib.Path, optional
        The data folder of this host (logs and metrics files; the database is not in it).
    rebuilt_models : int
        Objects rebuilt from stored models kept in memory (:meth:`Store.rebuilt`).
    pool_size : int
        Most connections this process opens [1].
    timeout_s : float
        How long to wait for a connection [s] (to open one, or for one of the pool to be free); then
        :class:`~service.store.StorageError` (503).

    Raises
    ------
    StorageError
        When the server cannot be reached at start (within ``timeout_s``).
    """

    _CLAIM_LOCK = " FOR UPDATE SKIP LOCKED"

    def __init__(self, url: str, data_dir: Path | None = None, rebuilt_models: int = 16, pool_size: int = 8,
                 timeout_s: float = 10.0):
        self._init_cache(rebuilt_models)
        self.path = redacted_url(url)
        self.data_dir = Path(data_dir) if data_dir is not None else Path.cwd()
        self.timeout_s = float(timeout_s)
        self._pool = psycopg_pool.ConnectionPool(
            url, min_size=1, max_size=max(int(pool_size), 1), timeout=self.timeout_s, open=False,
            kwargs={"autocommit": True, "row_factory": dict_row, "connect_timeout": max(int(timeout_s), 1),
                    "application_name": "microbearing"},
            check=psycopg_pool.ConnectionPool.check_connection, name="microbearing")
        try:
            # One connection first, for the server's own reason (a refused password, an unknown
            # database), which the pool would only log while it retries until its timeout.
            psycopg.connect(url, connect_timeout=max(int(timeout_s), 1)).close()
            self._pool.open(wait=True, timeout=self.timeout_s)
            self._create_schema()
        except BaseException as exc:
            self._pool.close()
            fault = classify(exc, self.path)
            if fault is None:
                raise
            raise fault from exc

    def _create_schema(self) -> None:
        """Create the tables, or add the columns a newer version needs; nothing when all are there.

        A schema already complete is left alone, so the service's user needs no right to change it
        (ALTER TABLE needs the table's owner even when the column exists).
        """
        tables = {name for name in re.findall(r"CREATE TABLE IF NOT EXISTS (\w+)", _SCHEMA)}
        needed = {(table, column) for table, columns in _ADDED_COLUMNS.items() for column in columns}
        query = ("SELECT table_name, column_name FROM information_schema.columns "
                 "WHERE table_schema = current_schema()")
        with self._reading() as conn:
            present = {(row["table_name"], row["column_name"]) for row in conn.execute(query).fetchall()}
        if tables <= {table for table, _ in present} and needed <= present:
            return
        with self.transaction() as conn:
            conn.execute("SELECT pg_advisory_xact_lock(?)", (_SCHEMA_LOCK,))  # processes starting at once
            for statement in filter(str.strip, _SCHEMA.split(";")):
                conn.execute(_postgres_ddl(statement))
            for table, columns in _ADDED_COLUMNS.items():
                for name, declaration in columns.items():
                    conn.execute(f"ALTER TABLE {table} ADD COLUMN IF NOT EXISTS {name} "
                                 f"{_postgres_ddl(declaration)}")
            conn.execute(_LATE_SCHEMA)

    @contextmanager
    def _connection(self, timeout_s: float | None = None) -> Iterator[psycopg.Connection]:
        try:
            with self._pool.connection(timeout=timeout_s) as conn:
                yield conn
        except (psycopg.Error, psycopg_pool.PoolTimeout) as exc:
            fault = classify(exc, self.path)
            if fault is None:
                raise
            raise fault from exc

    @contextmanager
    def _reading(self) -> Iterator[_Connection]:
        with self._connection() as conn:
            yield _Connection(conn)

    @contextmanager
    def transaction(self) -> Iterator[_Connection]:
        """A write transaction: committed on success, rolled back on an exception.

        Raises
        ------
        StorageError
            When the server's disk is full, the server cannot be reached or is read-only, or no
            connection is free in time.
        """
        with self._connection() as conn, conn.transaction():
            yield _Connection(conn)

    def _lock_admission(self, conn: Any) -> None:
        conn.execute("SELECT pg_advisory_xact_lock(?)", (_ADMISSION_LOCK,))

    def check_writable(self, min_free_bytes: int = 0) -> str | None:
        """Why the database cannot take writes now, or None when it can.

        Writes one row of a probe table, waiting at most 2 s for a connection (a readiness probe
        must answer while the server is down). The free space of the server's disk cannot be seen
        from here: ``min_free_bytes`` is not checked (a write to a full disk fails with the reason).
        """
        try:
            with self._connection(min(self.timeout_s, _PROBE_TIMEOUT_S)) as conn, conn.transaction():
                conn.execute("INSERT INTO write_probe (id, written_at) VALUES (1, %s) ON CONFLICT (id) "
                             "DO UPDATE SET written_at = excluded.written_at", (utc_now(),))
        except StorageError as exc:
            return exc.cause
        return None

    def close(self) -> None:
        """Close the pool's connections."""
        self._pool.close()
