"""Scale-out through :class:`concurrent.futures.Executor`: a local thread pool, or a dask cluster.

Sweeps and batch evaluations are cut into chunks of points and mapped over the executor of the
running app (:func:`evaluate_in_chunks`); the results do not depend on the executor, because
every point is evaluated independently. Multi-start optimizations of calibrated and surrogate
models map their groups of ball counts over the same executor
(:func:`optimize.optimize_model` with ``map_calls=`` :func:`map_chunks` on the executor); the
groups do not depend on it either.

* Default: a :class:`~concurrent.futures.ThreadPoolExecutor` of ``MICROBEARING_EXECUTOR_WORKERS``
  threads (one per CPU when 0). NumPy releases the GIL inside the vectorized physics, so the
  threads run in parallel.
* ``MICROBEARING_DASK_SCHEDULER=tcp://host:8786``: the chunks run on that dask.distributed
  cluster (``pip install 'microbearing[dask]'``; the workers need microbearing installed too,
  since tasks name functions and models of :mod:`service`).
* ``MICROBEARING_DASK_SCHEDULER=local``: an embedded :class:`distributed.LocalCluster` in the
  server process (threads, no extra processes), mostly to try the dask path.

The dask connection is made on first use, in the worker thread that needs it, not at startup:
a scheduler that is down makes sweeps fail with a 503 problem while the rest of the API works.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import Executor, Future, ThreadPoolExecutor
from typing import Any

import numpy as np

from .models import InputError, Model
from .problems import ProblemError, validation_problem
from .settings import Settings

__all__ = ["DEFAULT_CHUNK_POINTS", "DaskExecutor", "chunk_bounds", "create_executor", "evaluate_in_chunks",
           "map_chunks"]

#: Points per chunk: bounds the memory of one task and sets how often progress is reported.
DEFAULT_CHUNK_POINTS = 65_536


class DaskExecutor(Executor):
    """A :class:`concurrent.futures.Executor` running on dask.distributed, connected on first use.

    Parameters
    ----------
    scheduler : str
        Address of a scheduler (``tcp://host:8786``), or ``"local"`` for an embedded
        :class:`distributed.LocalCluster` of ``threads`` threads in this process.
    threads : int
        Threads of the embedded cluster [1]; ignored for a remote scheduler.
    """

    #: How long a connection to a remote scheduler is tried before the request gets a 503. [s]
    connect_timeout_s = 10.0

    def __init__(self, scheduler: str, threads: int):
        self.scheduler = scheduler
        self.threads = threads
        self._lock = threading.Lock()
        self._client: Any = None
        self._cluster: Any = None
        self._executor: Executor | None = None

    def _connected(self) -> Executor:
        with self._lock:
            if self._executor is None:
                try:
                    from distributed import Client, LocalCluster
                except ImportError as exc:
                    raise ProblemError(503, "MICROBEARING_DASK_SCHEDULER is set but dask.distributed is not "
                                       "installed: pip install 'microbearing[dask]'.") from exc
                try:
                    if self.scheduler == "local":
                        # The scheduler always serves HTTP (health, metrics); a free loopback port.
                        self._cluster = LocalCluster(processes=False, n_workers=1,
                                                     threads_per_worker=self.threads,
                                                     dashboard_address="127.0.0.1:0")
                        self._client = Client(self._cluster)
                    else:
                        self._client = Client(self.scheduler, timeout=self.connect_timeout_s)
                except OSError as exc:
                    raise ProblemError(503, f"The dask scheduler {self.scheduler} cannot be reached: "
                                       f"{exc}") from exc
                self._executor = self._client.get_executor()
            return self._executor

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:
        """Run ``fn(*args, **kwargs)`` on the cluster; returns a concurrent.futures Future."""
        return self._connected().submit(fn, *args, **kwargs)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Close the connection, and the embedded cluster if there is one."""
        with self._lock:
            if self._executor is not None:
                self._executor.shutdown(wait=wait)
                self._client.close()
                if self._cluster is not None:
                    self._cluster.close()
            self._executor = self._client = self._cluster = None


def create_executor(settings: Settings) -> Executor:
    """The executor chosen by the settings.

    Parameters
    ----------
    settings : Settings
        ``dask_scheduler`` (None for the local pool) and ``executor_workers`` (0: one per CPU).

    Returns
    -------
    concurrent.futures.Executor
        A thread pool, or a :class:`DaskExecutor`.
    """
    threads = settings.executor_workers or os.cpu_count() or 1
    if settings.dask_scheduler:
        return DaskExecutor(settings.dask_scheduler, threads)
    return ThreadPoolExecutor(max_workers=threads, thread_name_prefix="microbearing-chunk")


def chunk_bounds(count: int, chunk_points: int = DEFAULT_CHUNK_POINTS) -> list[tuple[int, int]]:
    """``(start, stop)`` of consecutive chunks covering ``count`` points.

    Parameters
    ----------
    count : int
        Number of points [1], >= 0.
    chunk_points : int, default 65536
        Most points per chunk [1], >= 1.

    Returns
    -------
    list of tuple of int
        Half-open index ranges, in order.
    """
    if count < 0:
        raise ValueError(f"count must be >= 0, got {count}")
    if chunk_points < 1:
        raise ValueError(f"chunk_points must be >= 1, got {chunk_points}")
    return [(start, min(start + chunk_points, count)) for start in range(0, count, chunk_points)]


def map_chunks(executor: Executor | None, fn: Callable[..., Any], arguments: Iterable[Sequence[Any]],
               progress: Callable[[float], None] | None = None) -> list[Any]:
    """``[fn(*args) for args in arguments]``, run on ``executor``, results in order.

    Parameters
    ----------
    executor : concurrent.futures.Executor or None
        Where to run; None runs inline, one call after the other.
    fn : callable
        The work of one chunk. For a dask cluster it must be importable by the workers.
    arguments : iterable of sequence
        Positional arguments of each call.
    progress : callable, optional
        Called with the share of calls done [1] after each; when it raises (a cancelled job),
        the calls not yet started are cancelled and the exception propagates.

    Returns
    -------
    list
        The results, in the order of ``arguments``.

    Raises
    ------
    Exception
        The first exception raised by ``fn`` (in the order of ``arguments``), or by ``progress``.
    """
    calls = [tuple(args) for args in arguments]
    if executor is None:
        results = []
        for done, args in enumerate(calls, start=1):
            results.append(fn(*args))
            if progress is not None:
                progress(done / len(calls))
        return results
    futures = [executor.submit(fn, *args) for args in calls]
    try:
        results = []
        for done, future in enumerate(futures, start=1):
            results.append(future.result())
            if progress is not None:
                progress(done / len(futures))
        return results
    finally:
        for future in futures:
            future.cancel()  # no-op for finished calls; frees the pool after an error


def _evaluate_chunk(model: Model, points: dict[str, Any], outputs: list[str], pointer: str,
                    first_index: int) -> dict[str, np.ndarray]:
    """The outputs of a model on one chunk of points (the task :func:`evaluate_in_chunks` maps)."""
    return model.evaluate(points, outputs, pointer=pointer, first_index=first_index).values


def evaluate_in_chunks(executor: Executor | None, inputs: dict[str, Any], count: int,
                       outputs: list[str] | None, model: Model, pointer: str = "",
                       progress: Callable[[float], None] | None = None,
                       chunk_points: int = DEFAULT_CHUNK_POINTS) -> dict[str, np.ndarray]:
    """:meth:`service.models.Model.evaluate` over ``count`` points, chunk by chunk on ``executor``.

    Parameters
    ----------
    executor : concurrent.futures.Executor or None
        Where the chunks run (None: inline).
    inputs : dict
        Inputs of the model: 1-D arrays of ``count`` values, or scalars shared by every point.
    count : int
        Number of points [1].
    outputs : list of str or None
        Outputs to compute (all of the model's when None).
    model : Model
        The model (:func:`service.models.physics_in` for the physics in one convention).
    pointer : str, default ""
        JSON pointer of the inputs in the request body, for error messages.
    progress : callable, optional
        Called with the share of chunks done [1]; may raise to stop.
    chunk_points : int, default 65536
        Most points per chunk [1].

    Returns
    -------
    dict of numpy.ndarray
        Each output as an array of ``count`` values.

    Raises
    ------
    ProblemError
        422 for inputs the model rejects or non-finite outputs (naming the point's index).
    """
    columns = {name: value for name, value in inputs.items() if np.ndim(value) == 1}
    shared = {name: value for name, value in inputs.items() if np.ndim(value) != 1}
    wrong = {name: len(value) for name, value in columns.items() if len(value) != count}
    if wrong:
        raise ValueError(f"inputs {sorted(wrong)} must have count={count} values, not {wrong}")
    for name, values in columns.items():
        # Whole columns first, so that an error names the point's index in the request, not in a chunk.
        try:
            # A calibrated model also takes the condition columns its terms do not read (its domain does).
            getattr(model, "column_checks", model.inputs)[name].check(values)
        except InputError as exc:
            raise validation_problem([{"pointer": f"{pointer}/{name}", "detail": str(exc)}]) from None
    bounds = chunk_bounds(count, chunk_points)
    names = [str(name) for name in outputs] if outputs else list(model.outputs)
    arguments = [(model, {**shared, **{name: values[start:stop] for name, values in columns.items()}},
                  names, pointer, start) for start, stop in bounds]
    chunks = map_chunks(executor, _evaluate_chunk, arguments, progress)
    if not chunks:
        return {name: np.empty(0) for name in names}
    return {name: np.concatenate([np.broadcast_to(np.asarray(chunk[name], dtype=float), (stop - start,))
                                  for chunk, (start, stop) in zip(chunks, bounds, strict=True)])
            for name in names}
