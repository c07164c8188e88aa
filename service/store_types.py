"""What every store takes and gives: who asks, stored models, rows as JSON, timestamps, storage faults.

:mod:`service.store` (the SQL both backends share, and SQLite) and :mod:`service.store_postgres` build on
these; callers import them from :mod:`service.store`, which re-exports them.
"""

from __future__ import annotations

import contextvars
import errno
import json
import re
import sqlite3
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pydantic_core

from .problems import ProblemError

__all__ = ["EVERYONE", "REQUESTER", "STORAGE_TYPE", "ModelLimitError", "Requester", "StorageError",
           "StoredModel", "UnstorableError", "json_bytes", "redacted_url", "to_json", "utc_now"]

@dataclass(frozen=True)
class Requester:
    """Who is asking, for the ownership of rows.

    Attributes
    ----------
    key_id : str or None
        Id of the API key (recorded as the owner of new rows); None without keys.
    sees_all : bool
        Whether every row is visible (no keys configured, the admin key, the server itself).
    """

    key_id: str | None = None
    sees_all: bool = True


#: Who sees every row: requests without keys, and the server's own housekeeping.
EVERYONE = Requester()
#: The requester of the current context; set per request by :mod:`service.security`.
REQUESTER: contextvars.ContextVar[Requester] = contextvars.ContextVar("microbearing_requester",
                                                                     default=EVERYONE)

STORAGE_TYPE = "urn:microbearing:problem:storage"

#: SQLite's primary result codes of a storage fault (https://sqlite.org/rescode.html).
_SQLITE_READONLY, _SQLITE_IOERR, _SQLITE_CORRUPT, _SQLITE_FULL, _SQLITE_CANTOPEN = 8, 10, 11, 13, 14


class ModelLimitError(ProblemError):
    """The database holds ``MICROBEARING_MAX_STORED_MODELS`` models: 507, naming the setting and the way out.

    Parameters
    ----------
    stored : int
        Models stored now [1].
    limit : int
        The setting's value [1].
    """

    def __init__(self, stored: int, limit: int):
        detail = (f"The service holds {stored} stored models, its limit (MICROBEARING_MAX_STORED_MODELS = "
                  f"{limit}). Delete models no longer needed (DELETE /v1/calibrations/{{id}}, "
                  "DELETE /v1/surrogates/{id}) or raise the setting; the request can be repeated then.")
        super().__init__(507, detail, title="Stored-model limit reached")
        self.stored = stored
        self.limit = limit


class UnstorableError(ValueError):
    """What the server's own code handed the store cannot be kept: a number JSON cannot hold, an array
    only pickle could. A fault of the code, not of a request: a job reports it as 500, where another
    ValueError of its work is the request's 422."""


class StorageError(ProblemError):
    """The data folder cannot take a write: 507 for a full disk, 503 otherwise, with ``Retry-After``.

    Parameters
    ----------
    cause : str
        What failed, e.g. ``"the disk is full"``.
    path : pathlib.Path or str
        The database file (or the PostgreSQL URL without its password).
    status : int
        507 or 503.
    """

    def __init__(self, cause: str, path: Path | str, status: int = 503):
        super().__init__(status, f"The service cannot store data: {cause} ({path}). Free space or fix the "
                                 "data folder; the request can be repeated then.",
                         title="Storage unavailable", type_=STORAGE_TYPE, headers={"Retry-After": "60"})
        self.cause = cause
        self.path = path

    @classmethod
    def classify(cls, exc: BaseException, path: Path | str) -> StorageError | None:
        """The storage fault ``exc`` stands for, or None when it is something else.

        Parameters
        ----------
        exc : BaseException
            An exception raised by sqlite3 or the file system.
        path : pathlib.Path
            The database file, for the message.
        """
        if isinstance(exc, StorageError):
            return exc
        if isinstance(exc, sqlite3.Error):
            code = (getattr(exc, "sqlite_errorcode", None) or 0) & 0xFF
            causes = {_SQLITE_FULL: ("the disk is full", 507),
                      _SQLITE_READONLY: ("the database is read-only", 503),
                      _SQLITE_IOERR: (f"an I/O error ({exc})", 503),
                      _SQLITE_CANTOPEN: (f"the database cannot be opened ({exc})", 503),
                      _SQLITE_CORRUPT: (f"the database is corrupt ({exc})", 503)}
            if code in causes:
                cause, status = causes[code]
                return cls(cause, path, status)
        if isinstance(exc, OSError) and exc.errno is not None:
            if exc.errno == errno.ENOSPC:
                return cls("the disk is full", path, 507)
            if exc.errno in (errno.EROFS, errno.EACCES, errno.EPERM, errno.EIO):
                return cls(f"{exc.strerror or exc}", path, 503)
        return None


def redacted_url(url: str) -> str:
    """A database URL (or libpq ``key=value`` string) without its password, for messages and logs."""
    url = re.sub(r"(://[^/:@]*):[^/]*@", r"\1:***@", url)
    return re.sub(r"(password\s*=\s*)('[^']*'|\S+)", r"\1***", url)


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
