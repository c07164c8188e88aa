"""Persistence in one SQLite file under the data folder: jobs and stored models.

SQLite in WAL mode lets several server processes (uvicorn workers) share the folder: readers
never block the writer. Each thread gets its own connection (sqlite3 connections are not
shared across threads); every write is one ``BEGIN IMMEDIATE`` transaction. Data is stored as
JSON text and NumPy ``.npz`` bytes loaded with ``allow_pickle=False``, never as pickles, so a
stored row cannot run code when it is read.

Stored models (surrogates, calibrations, ...)::

    model_id = store.save_model("surrogate", {"inputs": [...], "score": 0.99},
                                {"weights": w, "bias": b})
    stored = store.load_model(model_id)      # StoredModel(id, kind, name, metadata, arrays, created_at)
"""

from __future__ import annotations

import io
import json
import sqlite3
import threading
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pydantic_core

__all__ = ["DATABASE_NAME", "Store", "StoredModel", "json_bytes", "to_json", "utc_now"]

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
    created_at TEXT NOT NULL,
    started_at TEXT,
    finished_at TEXT
);
CREATE INDEX IF NOT EXISTS jobs_status ON jobs (status);
CREATE TABLE IF NOT EXISTS job_results (
    id TEXT PRIMARY KEY REFERENCES jobs (id),
    result_json TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS models (
    id TEXT PRIMARY KEY,
    kind TEXT NOT NULL,
    name TEXT NOT NULL,
    metadata_json TEXT NOT NULL,
    arrays_npz BLOB NOT NULL,
    created_at TEXT NOT NULL
);
CREATE INDEX IF NOT EXISTS models_kind ON models (kind);
"""

_JOB_COLUMNS = ("id", "kind", "status", "progress", "request_json", "result_json", "error_json",
                "cancel_requested", "owner_pid", "owner_instance", "created_at", "started_at", "finished_at")
#: The columns of a job's status: all but the request and the result, which can be tens of megabytes.
#: Results are kept in their own table, job_results: SQLite walks a large value's overflow pages to
#: reach the columns stored after it, so a result in the jobs row slowed every status read (a
#: database written before keeps its older results in jobs.result_json; they are still read).
_STATUS_COLUMNS = ", ".join(c for c in _JOB_COLUMNS if c not in ("request_json", "result_json"))
_FULL_COLUMNS = ", ".join(f"jobs.{c}" for c in _JOB_COLUMNS if c != "result_json") + (
    ", COALESCE(job_results.result_json, jobs.result_json) AS result_json")


def utc_now() -> str:
    """The current time as an ISO 8601 UTC timestamp."""
    return datetime.now(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _numpy_to_python(value: Any) -> Any:
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON serializable")


def json_bytes(value: Any) -> bytes:
    """Compact strict JSON of ``value``; NumPy arrays become lists, numbers keep every digit.

    pydantic-core's serializer writes a million floats about ten times faster than the
    standard library; it cannot refuse NaN or infinities, so output that may contain them is
    redone by :func:`json.dumps`, which raises for a real one and accepts the word inside a string.

    Raises
    ------
    ValueError
        For NaN or infinite numbers, which JSON cannot represent.
    TypeError
        For values that are not JSON data or NumPy arrays.
    """
    try:
        text = pydantic_core.to_json(value, fallback=_numpy_to_python)
    except pydantic_core.PydanticSerializationError as exc:
        raise TypeError(str(exc)) from None
    if b"NaN" in text or b"Infinity" in text:
        return json.dumps(value, allow_nan=False, separators=(",", ":"), default=_numpy_to_python).encode()
    return text


def to_json(value: Any) -> str:
    """Strict JSON text of ``value`` (see :func:`json_bytes`)."""
    return json_bytes(value).decode()


@dataclass(frozen=True)
class StoredModel:
    """A model saved by :meth:`Store.save_model`.

    Attributes
    ----------
    id : str
        Identifier.
    kind : str
        What it is, e.g. ``"surrogate"`` or ``"calibration"``.
    name : str
        Human label.
    metadata : dict
        JSON-ready description (inputs, units, scores, ...).
    arrays : dict of numpy.ndarray
        Numeric payload.
    created_at : str
        ISO 8601 UTC timestamp.
    """

    id: str
    kind: str
    name: str
    metadata: dict[str, Any]
    arrays: dict[str, np.ndarray]
    created_at: str


class Store:
    """The SQLite database of one data folder.

    Parameters
    ----------
    data_dir : pathlib.Path
        Folder of the database file; created when missing.
    """

    def __init__(self, data_dir: Path):
        self.data_dir = Path(data_dir)
        self.data_dir.mkdir(parents=True, exist_ok=True)
        self.path = self.data_dir / DATABASE_NAME
        self._local = threading.local()
        self._connections: list[sqlite3.Connection] = []
        self._lock = threading.Lock()
        with self.transaction() as conn:
            for statement in filter(str.strip, _SCHEMA.split(";")):
                conn.execute(statement)

    def connection(self) -> sqlite3.Connection:
        """This thread's connection (autocommit; use :meth:`transaction` to write)."""
        conn = getattr(self._local, "conn", None)
        if conn is None:
            conn = sqlite3.connect(self.path, isolation_level=None, timeout=30.0, check_same_thread=False)
            conn.row_factory = sqlite3.Row
            conn.execute("PRAGMA journal_mode=WAL")
            conn.execute("PRAGMA synchronous=NORMAL")
            conn.execute("PRAGMA busy_timeout=30000")
            self._local.conn = conn
            with self._lock:
                self._connections.append(conn)
        return conn

    @contextmanager
    def transaction(self) -> Iterator[sqlite3.Connection]:
        """A write transaction: committed on success, rolled back on an exception."""
        conn = self.connection()
        conn.execute("BEGIN IMMEDIATE")
        try:
            yield conn
        except BaseException:
            conn.execute("ROLLBACK")
            raise
        conn.execute("COMMIT")

    def close(self) -> None:
        """Close every connection opened by this store."""
        with self._lock:
            for conn in self._connections:
                conn.close()
            self._connections.clear()
        self._local = threading.local()

    # jobs -----------------------------------------------------------------------------------

    def insert_job(self, **row: Any) -> None:
        """Insert a job row (column names as keywords)."""
        names = ", ".join(row)
        marks = ", ".join("?" for _ in row)
        with self.transaction() as conn:
            conn.execute(f"INSERT INTO jobs ({names}) VALUES ({marks})", tuple(row.values()))

    def update_job(self, job_id: str, *, only_if_status: tuple[str, ...] = (),
                   unless_cancel_requested: bool = False, **changes: Any) -> bool:
        """Change columns of a job, optionally only while it has one of ``only_if_status``.

        With ``unless_cancel_requested`` the change happens only if no cancellation was requested,
        in the same transaction (a job that finishes as it is cancelled is either one or the other).

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
        with self.transaction() as conn:
            changed = conn.execute(sql, args).rowcount > 0
            if changed and result_json is not None:
                conn.execute("INSERT OR REPLACE INTO job_results (id, result_json) VALUES (?, ?)",
                             (job_id, result_json))
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
            sql = (f"SELECT {_FULL_COLUMNS} FROM jobs LEFT JOIN job_results ON job_results.id = jobs.id "
                   "WHERE jobs.id = ?")
        else:
            sql = f"SELECT {_STATUS_COLUMNS} FROM jobs WHERE id = ?"
        row = self.connection().execute(sql, (job_id,)).fetchone()
        return dict(row) if row else None

    def jobs_with_status(self, *statuses: str) -> list[dict[str, Any]]:
        """Status columns of every job with one of ``statuses``, oldest first (no request or result)."""
        marks = ", ".join("?" for _ in statuses)
        rows = self.connection().execute(
            f"SELECT {_STATUS_COLUMNS} FROM jobs WHERE status IN ({marks}) ORDER BY created_at",
            statuses).fetchall()
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
        ValueError
            For object arrays, which only pickle could store.
        """
        plain = {key: np.asarray(value) for key, value in arrays.items()}
        pickled = sorted(key for key, value in plain.items() if value.dtype.hasobject)
        if pickled:
            raise ValueError(f"arrays must have numeric or string dtypes, not object: {', '.join(pickled)}")
        buffer = io.BytesIO()
        np.savez_compressed(buffer, **plain)
        model_id = uuid.uuid4().hex
        with self.transaction() as conn:
            conn.execute(
                "INSERT INTO models (id, kind, name, metadata_json, arrays_npz, created_at) "
                "VALUES (?, ?, ?, ?, ?, ?)",
                (model_id, kind, name, to_json(metadata), buffer.getvalue(), utc_now()))
        return model_id

    def load_model(self, model_id: str) -> StoredModel | None:
        """The stored model, or None when there is no such id."""
        row = self.connection().execute("SELECT * FROM models WHERE id = ?", (model_id,)).fetchone()
        if row is None:
            return None
        with np.load(io.BytesIO(row["arrays_npz"]), allow_pickle=False) as npz:
            arrays = {key: npz[key] for key in npz.files}
        return StoredModel(row["id"], row["kind"], row["name"], json.loads(row["metadata_json"]), arrays,
                           row["created_at"])

    def list_models(self, kind: str | None = None) -> list[dict[str, Any]]:
        """Id, kind, name, metadata and creation time of stored models, newest first."""
        sql = "SELECT id, kind, name, metadata_json, created_at FROM models"
        args: tuple[str, ...] = ()
        if kind is not None:
            sql += " WHERE kind = ?"
            args = (kind,)
        rows = self.connection().execute(sql + " ORDER BY created_at DESC", args).fetchall()
        return [{"id": r["id"], "kind": r["kind"], "name": r["name"],
                 "metadata": json.loads(r["metadata_json"]), "created_at": r["created_at"]} for r in rows]

    def delete_model(self, model_id: str) -> bool:
        """Delete a stored model; returns whether it existed."""
        with self.transaction() as conn:
            return conn.execute("DELETE FROM models WHERE id = ?", (model_id,)).rowcount > 0
