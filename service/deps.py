"""FastAPI dependencies: the settings, database and job manager of the running app.

Use the annotated aliases as route parameters::

    @router.get("/v1/things/{thing_id}")
    def get_thing(thing_id: str, store: StoreDep) -> Thing: ...

The database and job manager are opened on first use (or at startup under a server), so
importing :mod:`service.app` or building an app touches no files.
"""

from __future__ import annotations

import threading
from concurrent.futures import Executor
from typing import Annotated

from fastapi import Depends, FastAPI, Request

from .executor import create_executor
from .jobs import JobManager
from .settings import Settings
from .store import Store

__all__ = ["ExecutorDep", "JobsDep", "Runtime", "SettingsDep", "StoreDep", "get_executor", "get_jobs",
           "get_runtime", "get_settings", "get_store"]


class Runtime:
    """The open database and job manager of one app.

    Parameters
    ----------
    settings : Settings
        Configuration of the app.
    """

    def __init__(self, settings: Settings):
        self.store = Store(settings.data_dir)
        self.jobs = JobManager(self.store, settings.job_workers)
        self.executor = create_executor(settings)  # sweep/batch chunks, optimization groups (executor.py)

    def close(self) -> None:
        """Stop the jobs and close the database."""
        self.jobs.shutdown()
        self.executor.shutdown(wait=False, cancel_futures=True)
        self.store.close()


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
