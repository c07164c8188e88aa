"""FastAPI dependencies: the settings, database and job manager of the running app.

Use the annotated aliases as route parameters::

    @router.get("/v1/things/{thing_id}")
    def get_thing(thing_id: str, store: StoreDep) -> Thing: ...

The database and job manager are opened on first use (or at startup under a server), so
importing :mod:`service.app` or building an app touches no files.
"""

from __future__ import annotations

import os
import sqlite3
import threading
from concurrent.futures import Executor
from pathlib import Path
from typing import Annotated

from fastapi import Depends, FastAPI, Request

from .executor import create_executor
from .jobs import JobManager
from .settings import Settings
from .store import DATABASE_NAME, StorageError, Store

__all__ = ["DataFolderError", "ExecutorDep", "JobsDep", "Runtime", "SettingsDep", "StoreDep", "get_executor",
           "get_jobs", "get_runtime", "get_settings", "get_store", "open_database", "open_store"]


class Runtime:
    """The open database and job manager of one app.

    Parameters
    ----------
    settings : Settings
        Configuration of the app.
    """

    def __init__(self, settings: Settings):
        self.settings = settings
        self.store = open_database(settings)
        self.executor = create_executor(settings)  # sweep/batch chunks, optimization groups (executor.py)
        # Last: its dispatcher may start a stored job at once, whose work uses the store and executor.
        self.jobs = JobManager(self.store, settings.job_workers, max_active=settings.max_active_jobs,
                               max_active_per_key=settings.max_active_jobs_per_key,
                               max_result_bytes=settings.max_result_bytes,
                               retention_s=settings.job_retention_s, services=self,
                               lease_s=settings.job_lease_s, shutdown_grace_s=settings.shutdown_grace_s)

    def close(self) -> None:
        """Stop the jobs and close the database."""
        self.jobs.shutdown()
        self.executor.shutdown(wait=False, cancel_futures=True)
        self.store.close()


class DataFolderError(RuntimeError):
    """The database cannot be opened (data folder or PostgreSQL); the message names it and what to do."""


def open_database(settings: Settings) -> Store:
    """The store the settings name: PostgreSQL with ``MICROBEARING_DATABASE_URL``, else SQLite (data folder).

    Raises
    ------
    DataFolderError
        Naming the database and the fix: the driver is missing, the server cannot be reached, or
        the data folder cannot hold the SQLite database (:func:`open_store`).
    """
    store = _open_database(settings)
    store.max_models = settings.max_stored_models
    return store


def _open_database(settings: Settings) -> Store:
    url = settings.database_url.get_secret_value()
    if not url:
        return open_store(settings.data_dir, settings.model_cache_size)
    try:
        from .store_postgres import PostgresStore
    except ImportError as exc:
        raise DataFolderError(
            f"MICROBEARING_DATABASE_URL names a PostgreSQL database, but its driver is not installed "
            f"({exc}): pip install 'microbearing[postgres]' (psycopg 3 and psycopg-pool), or unset "
            "MICROBEARING_DATABASE_URL to use SQLite in the data folder.") from None
    try:
        return PostgresStore(url, settings.data_dir, settings.model_cache_size,
                             pool_size=settings.database_pool_size, timeout_s=settings.database_timeout_s)
    except StorageError as exc:
        raise DataFolderError(
            f"microbearing cannot open its PostgreSQL database {exc.path}: {exc.cause}. Check that the "
            "server runs and accepts this user (MICROBEARING_DATABASE_URL), and "
            "MICROBEARING_DATABASE_TIMEOUT_S.") from None


def open_store(data_dir: Path, rebuilt_models: int = 16) -> Store:
    """The store of ``data_dir``, or a :class:`DataFolderError` naming the path and the fix.

    Parameters
    ----------
    data_dir : pathlib.Path
        The data folder (``MICROBEARING_DATA_DIR``).
    rebuilt_models : int
        Rebuilt models the store keeps (``MICROBEARING_MODEL_CACHE_SIZE``, :meth:`Store.rebuilt`).
    """
    database = Path(data_dir) / DATABASE_NAME
    try:
        return Store(data_dir, rebuilt_models)
    except StorageError as exc:
        cause = exc.cause
        if Path(data_dir).is_dir() and not os.access(data_dir, os.W_OK):  # SQLite says only "cannot open"
            cause = f"the folder is read-only or not writable ({cause})"
    except sqlite3.DatabaseError as exc:  # not a database, or a database newer or damaged beyond reading
        cause = f"{database} is not a usable SQLite database ({exc})"
    except OSError as exc:  # the folder cannot be created or is a file
        cause = f"the folder {data_dir} cannot be used ({exc.strerror or exc})"
    raise DataFolderError(
        f"microbearing cannot open its data folder {data_dir}: {cause}. Point MICROBEARING_DATA_DIR (or "
        f"--data-dir) at a writable folder with free space, or move {database} away (`sqlite3 <file> "
        ".recover` rebuilds what it can of a damaged one).")


_runtime_lock = threading.Lock()


def get_runtime(app: FastAPI) -> Runtime:
    """The runtime of ``app``, opened on first use."""
    runtime = getattr(app.state, "runtime", None)
    if runtime is None:
        with _runtime_lock:
            runtime = getattr(app.state, "runtime", None)
            if runtime is None:
                runtime = app.state.runtime = Runtime(app.state.settings)
    return runtime


def close_runtime(app: FastAPI) -> None:
    """Close the runtime of ``app`` if it was opened."""
    with _runtime_lock:
        runtime = getattr(app.state, "runtime", None)
        app.state.runtime = None
    if runtime is not None:
        runtime.close()


async def get_settings(request: Request) -> Settings:
    """The settings of the app serving ``request``."""
    return request.app.state.settings


async def get_store(request: Request) -> Store:
    """The database of the app serving ``request``."""
    return get_runtime(request.app).store


async def get_jobs(request: Request) -> JobManager:
    """The job manager of the app serving ``request``."""
    return get_runtime(request.app).jobs


async def get_executor(request: Request) -> Executor:
    """The executor running sweep and batch chunks and optimization groups of the app serving ``request``."""
    return get_runtime(request.app).executor


# The dependencies above are coroutines although they never wait: FastAPI runs a plain function
# dependency in a worker thread, and that hop cost more than a whole friction evaluation.

#: Route parameter annotations: ``settings: SettingsDep``, ``store: StoreDep``, ``jobs: JobsDep``,
#: ``executor: ExecutorDep``.
SettingsDep = Annotated[Settings, Depends(get_settings)]
StoreDep = Annotated[Store, Depends(get_store)]
JobsDep = Annotated[JobManager, Depends(get_jobs)]
ExecutorDep = Annotated[Executor, Depends(get_executor)]
