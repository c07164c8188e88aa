"""Persistence of jobs and stored models: one SQLite file under the data folder, or PostgreSQL.

:class:`Store` is the interface and the SQL both backends share; ``Store(data_dir)`` opens the
default, SQLite (:class:`SqliteStore`). SQLite in WAL mode lets several server processes (uvicorn
workers) of one host share the folder: readers never block the writer. Each thread gets its own
connection (sqlite3 connections are not shared across threads); every write is one ``BEGIN
IMMEDIATE`` transaction. Several hosts share one PostgreSQL database instead
(:class:`service.store_postgres.PostgresStore`, chosen by ``MICROBEARING_DATABASE_URL``). Data is stored as
JSON text and NumPy ``.npz`` bytes loaded with ``allow_pickle=False``, never as pickles, so a
stored row cannot run code when it is read. The values a store takes and gives (who asks, stored
models, rows as JSON, storage faults) are declared in :mod:`service.store_types` and re-exported here.

Stored models (surrogates, calibrations, ...)::

    model_id = store.save_model("surrogate", {"inputs": [...], "score": 0.99},
                                {"weights": w, "bias": b})
    stored = store.load_model(model_id)      # StoredModel(id, kind, name, metadata, arrays, created_at)
    model = store.rebuilt(model_id, "surrogate", rebuild)   # rebuild(stored), kept for the next call

Ownership: every job and model row records the id of the API key that created it (``owner_key``,
see :mod:`service.security`; never the key). The reads and deletions a client can reach
(:meth:`Store.get_job`, :meth:`Store.delete_job`, :meth:`Store.load_model`,
:meth:`Store.list_models`, :meth:`Store.delete_model`) see only the rows of the
:data:`REQUESTER` of the current context, which the API-key middleware sets per request (a job's
thread runs in a copy of its request's context, so what a job stores belongs to its key). The
default requester, used without keys, by the admin key and by the server's own housekeeping,
sees every row. Rows without an owner (written before keys were configured) are seen by all.

Storage faults: a write the disk cannot take (full, read-only, I/O error) raises
:class:`StorageError`, a problem (507 for a full disk, 503 otherwise) naming the cause.
"""

from __future__ import annotations

import io
import json
import logging
import shutil
import sqlite3
import threading
import uuid
from collections import OrderedDict
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from .store_types import (
    REQUESTER,
    ModelLimitError,
    Requester,
    StorageError,
    StoredModel,
    UnstorableError,
    json_bytes,
    redacted_url,
    to_json,
    utc_now,
)

__all__ = ["DATABASE_NAME", "REQUESTER", "ModelLimitError", "Requester", "SqliteStore", "StorageError",
           "Store", "StoredModel", "UnstorableError", "json_bytes", "redacted_url", "to_json", "utc_now"]

DATABASE_NAME = "microbearing.sqlite3"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS jobs (
    id TEXT PRIMARY KEY,
    kind TEXT NOT NULL,
    status TEXT NOT NULL,
    progress REAL NOT NULL DEFAULT 0,
    request_json TEXT NOT NULL,
    result_json TEXT,
    error_json TEXT,
    cancel_requested INTEGER NOT NULL DEFAULT 0,
    owner_pid INTEGER NOT NULL,
    owner_instance TEXT NOT NULL,
    owner_key TEXT,
    created_at TEXT NOT NULL,
    started_at TEXT,
    finished_at TEXT
);
CREATE INDEX IF NOT EXISTS jobs_status ON jobs (status);
CREATE TABLE IF NOT EXISTS job_results (
    id TEXT PRIMARY KEY REFERENCES jobs (id),
    result_json TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS job_inputs (
    id TEXT PRIMARY KEY REFERENCES jobs (id),
    inputs_json TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS models (
    id TEXT PRIMARY KEY,
    kind TEXT NOT NULL,
    name TEXT NOT NULL,
    metadata_json TEXT NOT NULL,
    arrays_npz BLOB NOT NULL,
    owner_key TEXT,
    created_at TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS models_kind ON models (kind);
CREATE TABLE IF NOT EXISTS write_probe (
    id INTEGER PRIMARY KEY,
    written_at TEXT NOT NULL
);
"""
#: Columns added since the first release, with their declaration: databases written before get them
#: by ALTER TABLE at open (NULL owner: visible to every key).
_ADDED_COLUMNS = {"jobs": {"owner_key": "TEXT", "owner_sees_all": "INTEGER NOT NULL DEFAULT 0",
                           "replayable": "INTEGER NOT NULL DEFAULT 0",
                           "attempts": "INTEGER NOT NULL DEFAULT 0", "lease_token": "TEXT",
                           "lease_expires": "REAL", "erased_at": "TEXT"},
                  "models": {"owner_key": "TEXT"}}
#: Index on a column that older databases gain by ALTER TABLE, so it is created after the migration.
_LATE_SCHEMA = "CREATE INDEX IF NOT EXISTS jobs_finished ON jobs (status, finished_at)"

logger = logging.getLogger("microbearing.service.store")

#: A job's statuses once it has ended (:data:`service.jobs.FINISHED`).
FINISHED_STATUSES = ("succeeded", "failed", "cancelled")

_JOB_COLUMNS = ("id", "kind", "status", "progress", "request_json", "result_json", "error_json",
                "cancel_requested", "owner_pid", "owner_instance", "owner_key", "created_at", "started_at",
                "finished_at", "owner_sees_all", "replayable", "attempts", "lease_token", "lease_expires",
                "erased_at")
#: The columns of a job's status: all but the request and the result, which can be tens of megabytes.
#: Results are kept in their own table, job_results: SQLite walks a large value's overflow pages to
#: reach the columns stored after it, so a result in the jobs row slowed every status read (a
#: database written before keeps its older results in jobs.result_json; they are still read).
_STATUS_COLUMNS = ", ".join(c for c in _JOB_COLUMNS if c not in ("request_json", "result_json"))
_FULL_COLUMNS = ", ".join(f"jobs.{c}" for c in _JOB_COLUMNS if c != "result_json") + (
    ", COALESCE(job_results.result_json, jobs.result_json) AS result_json")


class Store:
    """Jobs and stored models in one SQL database: the interface every backend shares.

    ``Store(data_dir)`` opens the SQLite database of a data folder (a :class:`SqliteStore`, as
    ``pathlib.Path(...)`` gives a ``PosixPath``); :class:`service.store_postgres.PostgresStore` keeps the
    same tables in a PostgreSQL database shared by several hosts. The job and model methods below
    are written once, in the SQL both understand (``?`` placeholders, ``ON CONFLICT`` upserts); a
    backend provides the connections (:meth:`transaction`, :meth:`_reading`) and the few statements
    that differ (:meth:`_lock_admission`, :attr:`_CLAIM_LOCK`).

    Attributes
    ----------
    path : pathlib.Path or str
        Where the data is, for messages: the SQLite file, or the PostgreSQL URL without its password.
    data_dir : pathlib.Path
        The data folder (SQLite: the database's folder).
    """

    path: Path | str
    data_dir: Path
    #: Appended to the SELECT of :meth:`claim_job` inside its write transaction.
    _CLAIM_LOCK = ""

    def __new__(cls, *args: Any, **kwargs: Any) -> Store:
        return super().__new__(SqliteStore if cls is Store else cls)

    #: Most stored models (calibrations, surrogates) the database holds, or None for no limit [1]; the
    #: service sets it from ``MICROBEARING_MAX_STORED_MODELS`` (:func:`service.deps.open_database`).
    max_models: int | None = None

    def _init_cache(self, rebuilt_models: int) -> None:
        self._rebuilt: OrderedDict[str, Any] = OrderedDict()
        self._rebuilt_size = int(rebuilt_models)
        self._lock = threading.Lock()

    @contextmanager
    def transaction(self) -> Iterator[Any]:
        """A write transaction yielding a connection (``execute(sql, args)``, ``?`` placeholders).

        Committed on success, rolled back on an exception.

        Raises
        ------
        StorageError
            When the database cannot take the write (full disk, read-only, unreachable server).
        """
        raise NotImplementedError
        yield

    @contextmanager
    def _reading(self) -> Iterator[Any]:
        """A connection for reads outside a transaction (rows fetched inside the ``with``)."""
        raise NotImplementedError
        yield

    def _lock_admission(self, conn: Any) -> None:
        """Serialize :meth:`admit_job`'s count and insert with other processes (in ``conn``'s transaction)."""

    def check_writable(self, min_free_bytes: int = 0) -> str | None:
        """Why the store cannot take writes now, or None when it can (``/readyz``)."""
        raise NotImplementedError

    def close(self) -> None:
        """Close every connection opened by this store."""
        raise NotImplementedError

    def _probe_write(self) -> str | None:
        """Write one row of the probe table: None, or why the database refused it."""
        try:
            with self.transaction() as conn:
                conn.execute("INSERT INTO write_probe (id, written_at) VALUES (1, ?) "
                             "ON CONFLICT (id) DO UPDATE SET written_at = excluded.written_at", (utc_now(),))
        except StorageError as exc:
            return exc.cause
        return None

    @staticmethod
    def _visible(table: str = "") -> tuple[str, tuple[str, ...]]:
        """SQL condition (`` AND ...``) and argument keeping the rows the requester may see."""
        requester = REQUESTER.get()
        if requester.sees_all:
            return "", ()
        prefix = f"{table}." if table else ""
        return f" AND ({prefix}owner_key IS NULL OR {prefix}owner_key = ?)", (requester.key_id or "",)

    # jobs -----------------------------------------------------------------------------------

    def insert_job(self, **row: Any) -> None:
        """Insert a job row (column names as keywords); its owner is the current requester's key."""
        with self.transaction() as conn:
            self._insert_job(conn, row)

    @staticmethod
    def _insert_job(conn: Any, row: dict[str, Any]) -> None:
        requester = REQUESTER.get()
        row = {**row, "owner_key": requester.key_id, "owner_sees_all": int(requester.sees_all)}
        names = ", ".join(row)
        marks = ", ".join("?" for _ in row)
        conn.execute(f"INSERT INTO jobs ({names}) VALUES ({marks})", tuple(row.values()))

    # claiming, leases and admission (several processes share one database) -------------------

    def admit_job(self, row: dict[str, Any], inputs_json: str | None = None, max_active: int | None = None,
                  max_active_per_key: int | None = None) -> tuple[str, int] | None:
        """Insert a queued job unless the folder's limits of active jobs are reached, in one transaction.

        The counts are read and the row written under a lock every process takes (SQLite's write
        lock, a PostgreSQL advisory lock: :meth:`_lock_admission`), so the limits hold across every
        process sharing the database.

        Parameters
        ----------
        row : dict
            The job's columns (as :meth:`insert_job`).
        inputs_json : str, optional
            What any process needs to run the job again (see :meth:`claim_job`); the job is
            ``replayable`` when given.
        max_active : int, optional
            Most queued and running jobs in the database [1].
        max_active_per_key : int, optional
            Most queued and running jobs of the current requester's key [1] (when it has one).

        Returns
        -------
        tuple of (str, int) or None
            None when admitted; else ``("server", n)`` or ``("key", n)``: which limit was reached
            and how many active jobs it counts.
        """
        key_id = REQUESTER.get().key_id
        with self.transaction() as conn:
            self._lock_admission(conn)
            if max_active is not None:
                active = conn.execute("SELECT COUNT(*) AS n FROM jobs WHERE status IN ('queued', 'running')"
                                      ).fetchone()["n"]
                if active >= max_active:
                    return "server", active
            if max_active_per_key is not None and key_id is not None:
                mine = conn.execute("SELECT COUNT(*) AS n FROM jobs WHERE status IN ('queued', 'running') "
                                    "AND owner_key = ?", (key_id,)).fetchone()["n"]
                if mine >= max_active_per_key:
                    return "key", mine
            self._insert_job(conn, {**row, "replayable": int(inputs_json is not None)})
            if inputs_json is not None:
                conn.execute("INSERT INTO job_inputs (id, inputs_json) VALUES (?, ?)",
                             (row["id"], inputs_json))
        return None

    def count_active_jobs(self, key_id: str | None = None) -> int:
        """Queued and running jobs in the database, of every process [1]; only ``key_id``'s when given."""
        sql = "SELECT COUNT(*) AS n FROM jobs WHERE status IN ('queued', 'running')"
        with self._reading() as conn:
            if key_id is None:
                return conn.execute(sql).fetchone()["n"]
            return conn.execute(sql + " AND owner_key = ?", (key_id,)).fetchone()["n"]

    def claim_job(self, instance: str, pid: int, kinds: tuple[str, ...], lease_expires: float,
                  token: str) -> dict[str, Any] | None:
        """Take the oldest queued job this process can run and mark it running, leased to it.

        A process can run the jobs it queued itself (it holds their work in memory) and the
        ``replayable`` jobs of ``kinds`` (their inputs are stored). The selection and the update
        are one write transaction: two processes never claim the same job.

        Parameters
        ----------
        instance, pid : str, int
            The claiming job manager and its process.
        kinds : tuple of str
            Kinds whose work this process can rebuild from stored inputs.
        lease_expires : float
            Unix time [s] until which the claim holds unless renewed (:meth:`renew_leases`).
        token : str
            Identifies this claim; writes of the running job name it (``update_job(only_if_token=...)``),
            so a claim that lapsed cannot overwrite the job's next run.

        Returns
        -------
        dict or None
            The job's status columns and ``inputs_json`` (None for work held in memory), or None
            when there is nothing to claim.
        """
        condition = "owner_instance = ?"
        args: list[Any] = [instance]
        if kinds:
            condition += f" OR (replayable = 1 AND kind IN ({', '.join('?' for _ in kinds)}))"
            args.extend(kinds)
        select = f"SELECT id FROM jobs WHERE status = 'queued' AND ({condition}) ORDER BY created_at LIMIT 1"
        with self._reading() as conn:
            if conn.execute(select, args).fetchone() is None:
                return None  # a read: an idle process polling does not take the write lock
        with self.transaction() as conn:
            # Again under the lock (or, with PostgreSQL, skipping rows another claim holds).
            row = conn.execute(select + self._CLAIM_LOCK, args).fetchone()
            if row is None:
                return None
            conn.execute("UPDATE jobs SET status = 'running', started_at = ?, owner_pid = ?, "
                         "owner_instance = ?, lease_token = ?, lease_expires = ?, attempts = attempts + 1 "
                         "WHERE id = ?",
                         (utc_now(), pid, instance, token, lease_expires, row["id"]))
            claimed = dict(conn.execute(f"SELECT {_STATUS_COLUMNS} FROM jobs WHERE id = ?",
                                        (row["id"],)).fetchone())
            inputs = conn.execute("SELECT inputs_json FROM job_inputs WHERE id = ?", (row["id"],)).fetchone()
        claimed["inputs_json"] = inputs["inputs_json"] if inputs else None
        return claimed

    def renew_leases(self, tokens: list[str], lease_expires: float) -> dict[str, bool]:
        """Extend the leases of the running jobs claimed under ``tokens``; the heartbeat of a process.

        Returns
        -------
        dict
            For each token still holding its running job: whether a cancellation was requested.
            A token missing from it has lost its job (the lease lapsed and another process took it).
        """
        if not tokens:
            return {}
        marks = ", ".join("?" for _ in tokens)
        with self.transaction() as conn:
            conn.execute(f"UPDATE jobs SET lease_expires = ? WHERE status = 'running' "
                         f"AND lease_token IN ({marks})", (lease_expires, *tokens))
            rows = conn.execute(f"SELECT lease_token, cancel_requested FROM jobs WHERE status = 'running' "
                                f"AND lease_token IN ({marks})", tokens).fetchall()
        return {row["lease_token"]: bool(row["cancel_requested"]) for row in rows}

    def job_statuses(self, job_ids: list[str]) -> dict[str, str]:
        """Status of each of ``job_ids`` that still exists (housekeeping: ignores the requester)."""
        if not job_ids:
            return {}
        marks = ", ".join("?" for _ in job_ids)
        with self._reading() as conn:
            rows = conn.execute(f"SELECT id, status FROM jobs WHERE id IN ({marks})", job_ids).fetchall()
        return {row["id"]: row["status"] for row in rows}

    def update_job(self, job_id: str, *, only_if_status: tuple[str, ...] = (),
                   unless_cancel_requested: bool = False, only_if_token: str | None = None,
                   **changes: Any) -> bool:
        """Change columns of a job, optionally only while it has one of ``only_if_status``.

        With ``unless_cancel_requested`` the change happens only if no cancellation was requested,
        in the same transaction (a job that finishes as it is cancelled is either one or the other).
        With ``only_if_token`` it happens only while the job is held by that claim (its ``lease_token``,
        see :meth:`claim_job`).

        Returns
        -------
        bool
            Whether a row changed.
        """
        unknown = set(changes) - set(_JOB_COLUMNS)
        if unknown:
            raise ValueError(f"unknown job column(s) {sorted(unknown)}; known: {', '.join(_JOB_COLUMNS)}")
        result_json = changes.pop("result_json", None)
        sets = ", ".join(f"{name} = ?" for name in changes) or "id = id"
        sql = f"UPDATE jobs SET {sets} WHERE id = ?"
        args: list[Any] = [*changes.values(), job_id]
        if only_if_status:
            sql += f" AND status IN ({', '.join('?' for _ in only_if_status)})"
            args.extend(only_if_status)
        if unless_cancel_requested:
            sql += " AND cancel_requested = 0"
        if only_if_token is not None:
            sql += " AND lease_token = ?"
            args.append(only_if_token)
        with self.transaction() as conn:
            changed = conn.execute(sql, args).rowcount > 0
            if changed and result_json is not None:
                conn.execute("INSERT INTO job_results (id, result_json) VALUES (?, ?) ON CONFLICT (id) "
                             "DO UPDATE SET result_json = excluded.result_json", (job_id, result_json))
            return changed

    def get_job(self, job_id: str, with_result: bool = False) -> dict[str, Any] | None:
        """The job row as a dict, or None.

        Parameters
        ----------
        job_id : str
            The job.
        with_result : bool, default False
            Also read ``request_json`` and ``result_json``; the status alone (polled often) does
            not read them, since a large sweep's result is tens of megabytes.
        """
        if with_result:
            visible, args = self._visible("jobs")
            sql = (f"SELECT {_FULL_COLUMNS} FROM jobs LEFT JOIN job_results ON job_results.id = jobs.id "
                   f"WHERE jobs.id = ?{visible}")
        else:
            visible, args = self._visible()
            sql = f"SELECT {_STATUS_COLUMNS} FROM jobs WHERE id = ?{visible}"
        with self._reading() as conn:
            row = conn.execute(sql, (job_id, *args)).fetchone()
        return dict(row) if row else None

    def delete_job(self, job_id: str, statuses: tuple[str, ...]) -> bool:
        """Delete a job the requester sees, and its result, if it has one of ``statuses``.

        Returns
        -------
        bool
            Whether it was deleted.
        """
        visible, args = self._visible()
        marks = ", ".join("?" for _ in statuses)
        with self.transaction() as conn:
            deleted = conn.execute(f"DELETE FROM jobs WHERE id = ? AND status IN ({marks}){visible}",
                                   (job_id, *statuses, *args)).rowcount > 0
            if deleted:
                conn.execute("DELETE FROM job_results WHERE id = ?", (job_id,))
                conn.execute("DELETE FROM job_inputs WHERE id = ?", (job_id,))
            return deleted

    def delete_jobs_finished_before(self, statuses: tuple[str, ...], before: str) -> int:
        """Delete every job with one of ``statuses`` that finished before ``before`` (ISO 8601 UTC).

        Housekeeping: ignores the requester. Returns how many were deleted.
        """
        marks = ", ".join("?" for _ in statuses)
        where = f"status IN ({marks}) AND finished_at < ?"
        with self.transaction() as conn:
            for table in ("job_results", "job_inputs"):
                conn.execute(f"DELETE FROM {table} WHERE id IN (SELECT id FROM jobs WHERE {where})",
                             (*statuses, before))
            return conn.execute(f"DELETE FROM jobs WHERE {where}", (*statuses, before)).rowcount

    def list_jobs(self, kinds: tuple[str, ...] = (), statuses: tuple[str, ...] = (), limit: int = 20,
                  before: tuple[str, str] | None = None) -> list[dict[str, Any]]:
        """Status columns of the jobs the requester sees, newest first, filtered and paginated.

        Parameters
        ----------
        kinds, statuses : tuple of str
            Keep jobs of one of these kinds / statuses (empty: any).
        limit : int
            Most rows returned [1].
        before : (str, str), optional
            ``(created_at, id)`` of the last row of the previous page: rows after it in the order.

        Returns
        -------
        list of dict
            Job rows without request and result.
        """
        visible, args = self._visible()
        sql = f"SELECT {_STATUS_COLUMNS} FROM jobs WHERE 1 = 1{visible}"
        arguments: list[Any] = list(args)
        for column, values in (("kind", kinds), ("status", statuses)):
            if values:
                sql += f" AND {column} IN ({', '.join('?' for _ in values)})"
                arguments.extend(values)
        if before is not None:
            sql += " AND (created_at < ? OR (created_at = ? AND id < ?))"
            arguments.extend((before[0], before[0], before[1]))
        sql += " ORDER BY created_at DESC, id DESC LIMIT ?"
        arguments.append(int(limit))
        with self._reading() as conn:
            return [dict(row) for row in conn.execute(sql, arguments).fetchall()]

    def jobs_with_status(self, *statuses: str) -> list[dict[str, Any]]:
        """Status columns of every job with one of ``statuses``, oldest first (no request or result)."""
        marks = ", ".join("?" for _ in statuses)
        with self._reading() as conn:
            rows = conn.execute(f"SELECT {_STATUS_COLUMNS} FROM jobs WHERE status IN ({marks}) "
                                "ORDER BY created_at", statuses).fetchall()
        return [dict(row) for row in rows]

    # models ---------------------------------------------------------------------------------

    def save_model(self, kind: str, metadata: dict[str, Any], arrays: dict[str, np.ndarray],
                   name: str = "") -> str:
        """Store a model; returns its new id.

        Parameters
        ----------
        kind : str
            What it is, e.g. ``"surrogate"``.
        metadata : dict
            JSON-ready description (finite numbers only).
        arrays : dict of array_like
            Numeric arrays.
        name : str, optional
            Human label.

        Returns
        -------
        str
            The model id.

        Raises
        ------
        UnstorableError
            A ValueError: for object arrays, which only pickle could store, or metadata that are not strict
            JSON (NaN, infinities).
        """
        plain = {key: np.asarray(value) for key, value in arrays.items()}
        pickled = sorted(key for key, value in plain.items() if value.dtype.hasobject)
        if pickled:
            raise UnstorableError(f"arrays must have numeric or string dtypes, not object: "
                                  f"{', '.join(pickled)}")
        try:
            metadata_json = to_json(metadata)
        except ValueError as exc:
            raise UnstorableError(f"the model's metadata are not strict JSON: {exc}") from None
        buffer = io.BytesIO()
        np.savez_compressed(buffer, **plain)
        model_id = uuid.uuid4().hex
        with self.transaction() as conn:
            if self.max_models is not None:
                # Counted and written under the lock admissions take, so the limit holds across processes.
                self._lock_admission(conn)
                stored = conn.execute("SELECT COUNT(*) AS n FROM models").fetchone()["n"]
                if stored >= self.max_models:
                    raise ModelLimitError(stored, self.max_models)
            conn.execute(
                "INSERT INTO models (id, kind, name, metadata_json, arrays_npz, owner_key, created_at) "
                "VALUES (?, ?, ?, ?, ?, ?, ?)",
                (model_id, kind, name, metadata_json, buffer.getvalue(), REQUESTER.get().key_id,
                 utc_now()))
        return model_id

    def check_model_room(self) -> None:
        """Raise :class:`ModelLimitError` when the database already holds :attr:`max_models` models (a
        request that would store one is refused before its work starts; :meth:`save_model` checks again)."""
        if self.max_models is None:
            return
        with self._reading() as conn:
            stored = conn.execute("SELECT COUNT(*) AS n FROM models").fetchone()["n"]
        if stored >= self.max_models:
            raise ModelLimitError(stored, self.max_models)

    def has_model(self, model_id: str, kind: str) -> bool:
        """Whether a model of ``kind`` with this id exists and the requester sees it."""
        visible, args = self._visible()
        with self._reading() as conn:
            return conn.execute(f"SELECT 1 FROM models WHERE id = ? AND kind = ?{visible}",
                                (model_id, kind, *args)).fetchone() is not None

    def load_model(self, model_id: str) -> StoredModel | None:
        """The stored model, or None when there is no such id (or the requester does not see it)."""
        visible, args = self._visible()
        with self._reading() as conn:
            row = conn.execute(f"SELECT * FROM models WHERE id = ?{visible}", (model_id, *args)).fetchone()
        if row is None:
            return None
        with np.load(io.BytesIO(row["arrays_npz"]), allow_pickle=False) as npz:
            arrays = {key: npz[key] for key in npz.files}
        return StoredModel(row["id"], row["kind"], row["name"], json.loads(row["metadata_json"]), arrays,
                           row["created_at"])

    def rebuilt(self, model_id: str, kind: str, rebuild: Callable[[StoredModel], Any]) -> Any | None:
        """The object ``rebuild(stored)`` makes of a stored model of ``kind``, kept for the next call.

        Rebuilding a model from its row (JSON, ``.npz`` arrays, refitting a GP's factors) costs
        milliseconds; a client sending one point per request would pay it every time. The
        :data:`REQUESTER`'s right to see the row is checked on every call (an indexed lookup), so
        a kept object never answers another key, nor a model deleted since (by this or another
        process).

        Parameters
        ----------
        model_id : str
            Identifier.
        kind : str
            The stored kind, e.g. ``"surrogate"`` or ``"calibration"``.
        rebuild : callable
            Makes the object of a :class:`StoredModel`; stored models never change, so neither
            does the object.

        Returns
        -------
        object or None
            None when there is no such model of that kind the requester sees.
        """
        if not self.has_model(model_id, kind):
            return None
        with self._lock:
            if model_id in self._rebuilt:
                self._rebuilt.move_to_end(model_id)
                return self._rebuilt[model_id]
        stored = self.load_model(model_id)
        if stored is None:  # deleted since the check above
            return None
        model = rebuild(stored)
        with self._lock:
            self._rebuilt[model_id] = model
            while len(self._rebuilt) > self._rebuilt_size:
                self._rebuilt.popitem(last=False)
        return model

    def list_models(self, kind: str | None = None, limit: int | None = None,
                    before: tuple[str, str] | None = None) -> list[dict[str, Any]]:
        """Id, kind, name, metadata and creation time of the models the requester sees, newest first.

        Parameters
        ----------
        kind : str, optional
            Keep models of this kind (default: any).
        limit : int, optional
            Most rows returned [1] (default: all).
        before : (str, str), optional
            ``(created_at, id)`` of the last row of the previous page: rows after it in the order
            (``created_at``, then ``id``, both descending, as :meth:`list_jobs`).
        """
        visible, args = self._visible()
        sql = f"SELECT id, kind, name, metadata_json, created_at FROM models WHERE 1 = 1{visible}"
        arguments: list[Any] = list(args)
        if kind is not None:
            sql += " AND kind = ?"
            arguments.append(kind)
        if before is not None:
            sql += " AND (created_at < ? OR (created_at = ? AND id < ?))"
            arguments.extend((before[0], before[0], before[1]))
        sql += " ORDER BY created_at DESC, id DESC"
        if limit is not None:
            sql += " LIMIT ?"
            arguments.append(int(limit))
        with self._reading() as conn:
            rows = conn.execute(sql, arguments).fetchall()
        return [{"id": r["id"], "kind": r["kind"], "name": r["name"],
                 "metadata": json.loads(r["metadata_json"]), "created_at": r["created_at"]} for r in rows]

    def delete_model(self, model_id: str) -> bool:
        """Delete a stored model the requester sees, and erase its data from the jobs that name it.

        Every finished job whose request, inputs or result names the model (the job that made it,
        and those that used it), whoever submitted it, keeps its status and loses its request, inputs
        and result; ``erased_at`` says when (its result then answers 410). A job still running keeps
        what it has: it fails when it next reads the model, or ends with a result that holds no row of
        the model's data. The database then returns the freed space (:meth:`_reclaim`).

        Returns
        -------
        bool
            Whether the model existed (and was deleted).
        """
        visible, args = self._visible()
        with self.transaction() as conn:
            deleted = conn.execute(f"DELETE FROM models WHERE id = ?{visible}", (model_id, *args)).rowcount
            if deleted:
                self._erase_jobs_naming(conn, model_id)
        if deleted:
            with self._lock:
                self._rebuilt.pop(model_id, None)
            self._reclaim()
        return deleted > 0

    @staticmethod
    def _erase_jobs_naming(conn: Any, model_id: str) -> list[str]:
        """Erase the request, inputs and result of every finished job naming ``model_id``; their ids."""
        pattern = f"%{model_id}%"
        finished = ", ".join("?" for _ in FINISHED_STATUSES)
        ids = [row["id"] for row in conn.execute(
            "SELECT jobs.id FROM jobs LEFT JOIN job_results ON job_results.id = jobs.id "
            "LEFT JOIN job_inputs ON job_inputs.id = jobs.id "
            f"WHERE jobs.status IN ({finished}) AND (jobs.request_json LIKE ? OR jobs.result_json LIKE ? "
            "OR job_results.result_json LIKE ? OR job_inputs.inputs_json LIKE ?)",
            (*FINISHED_STATUSES, *[pattern] * 4)).fetchall()]
        for job_id in ids:
            conn.execute("UPDATE jobs SET request_json = ?, result_json = NULL, erased_at = ? WHERE id = ?",
                         (to_json({"erased_with_model": model_id}), utc_now(), job_id))
            conn.execute("DELETE FROM job_results WHERE id = ?", (job_id,))
            conn.execute("DELETE FROM job_inputs WHERE id = ?", (job_id,))
        return ids

    def _reclaim(self) -> None:
        """After an erasure: make deleted rows unreadable in the database's files, a backend's own way
        (PostgreSQL's dead rows, unreachable by any query, are overwritten after its next vacuum)."""


class SqliteStore(Store):
    """The SQLite database of one data folder (what ``Store(data_dir)`` opens).

    SQLite serializes every write with a file lock (``BEGIN IMMEDIATE``), which makes the
    admission counts and claims hold across the processes of one host; it is not for a data folder
    shared over a network file system (README, "Jobs across restarts and processes"; several hosts
    share a PostgreSQL database instead).

    Parameters
    ----------
    data_dir : pathlib.Path
        Folder of the database file; created when missing.
    rebuilt_models : int
        How many objects rebuilt from stored models :meth:`rebuilt` keeps (the most recently
        used); 0 keeps none.
    """

    def __init__(self, data_dir: Path, rebuilt_models: int = 16):
        self.data_dir = Path(data_dir)
        self._init_cache(rebuilt_models)
        self.data_dir.mkdir(parents=True, exist_ok=True)
        self.path = self.data_dir / DATABASE_NAME
        self._local = threading.local()
        self._connections: list[sqlite3.Connection] = []
        with self.transaction() as conn:
            for statement in filter(str.strip, _SCHEMA.split(";")):
                conn.execute(statement)
            for table, columns in _ADDED_COLUMNS.items():
                present = {row["name"] for row in conn.execute(f"PRAGMA table_info({table})")}
                for name, declaration in columns.items():
                    if name not in present:
                        conn.execute(f"ALTER TABLE {table} ADD COLUMN {name} {declaration}")
            conn.execute(_LATE_SCHEMA)

    def connection(self) -> sqlite3.Connection:
        """This thread's connection (autocommit; use :meth:`transaction` to write)."""
        conn = getattr(self._local, "conn", None)
        if conn is None:
            conn = sqlite3.connect(self.path, isolation_level=None, timeout=30.0, check_same_thread=False)
            conn.row_factory = sqlite3.Row
            conn.execute("PRAGMA journal_mode=WAL")
            conn.execute("PRAGMA synchronous=NORMAL")
            conn.execute("PRAGMA busy_timeout=30000")
            # Deleted content is overwritten with zeros, not left in free pages (erasure, delete_model).
            conn.execute("PRAGMA secure_delete=ON")
            self._local.conn = conn
            with self._lock:
                self._connections.append(conn)
        return conn

    @contextmanager
    def _reading(self) -> Iterator[sqlite3.Connection]:
        yield self.connection()

    @contextmanager
    def transaction(self) -> Iterator[sqlite3.Connection]:
        """A write transaction: committed on success, rolled back on an exception.

        Raises
        ------
        StorageError
            When the disk is full, the database read-only or the file system fails.
        """
        try:
            conn = self.connection()
            conn.execute("BEGIN IMMEDIATE")
            try:
                yield conn
            except BaseException:
                if conn.in_transaction:  # SQLite may already have rolled back after a full disk
                    conn.execute("ROLLBACK")
                raise
            conn.execute("COMMIT")
        except (sqlite3.Error, OSError) as exc:
            fault = StorageError.classify(exc, self.path)
            if fault is None:
                raise
            raise fault from exc

    def check_writable(self, min_free_bytes: int = 0) -> str | None:
        """Why the store cannot take writes now, or None when it can.

        Writes one row of a probe table (a real write: a read-only file or a full disk fails
        it) and compares the free space of the data folder's file system with ``min_free_bytes``.

        Parameters
        ----------
        min_free_bytes : int, default 0
            Least free space [bytes].

        Returns
        -------
        str or None
            The reason, e.g. ``"the disk is full"``, or None.
        """
        try:
            free = shutil.disk_usage(self.data_dir).free
        except OSError as exc:
            return f"the data folder {self.data_dir} cannot be read: {exc.strerror or exc}"
        if free < min_free_bytes:
            return (f"only {free} bytes are free in {self.data_dir}; at least {min_free_bytes} are needed "
                    "(MICROBEARING_MIN_FREE_BYTES)")
        return self._probe_write()

    def _reclaim(self) -> None:
        """Copy the write-ahead log into the database and truncate it: with ``secure_delete`` on, the
        erased rows are then zeros in the database file and gone from the log (a reader holding an
        older snapshot delays this to the next erasure)."""
        try:
            self.connection().execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchone()
        except sqlite3.Error as exc:  # a busy or failing database: the next checkpoint does it
            logger.warning("the write-ahead log was not truncated after an erasure: %s", exc)

    def close(self) -> None:
        """Close every connection opened by this store."""
        with self._lock:
            for conn in self._connections:
                conn.close()
            self._connections.clear()
        self._local = threading.local()
