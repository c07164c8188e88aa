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

Faults of a remote cluster (:meth:`DaskExecutor.fault`): a scheduler that cannot be reached, or
one without workers. A connection the client has given up on is replaced by a new one on the
next use (and on each ``/readyz``), so the service reconnects once the scheduler is back. While
chunks are out, :func:`map_chunks` looks at the cluster every :data:`WAIT_TICK_S`: a fault that
lasts ``MICROBEARING_DASK_FAULT_TIMEOUT_S`` fails the work with a 503 problem naming the scheduler
and the fault, and chunks the scheduler dropped when it was lost are submitted again once it is
back within that time. The wait also calls ``progress`` on every tick, so a cancelled or
shut-down job stops waiting within a tick whatever the cluster does.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import CancelledError, Executor, Future, ThreadPoolExecutor
from typing import Any

import numpy as np

from microbearing.physics.model import InputError, Model, ModelError

from .problems import ProblemError, pointer_at, validation_problem
from .settings import Settings

__all__ = ["DEFAULT_CHUNK_POINTS", "WAIT_TICK_S", "DaskExecutor", "chunk_bounds", "create_executor",
           "evaluate_chunks", "evaluate_in_chunks", "map_chunks"]

#: Points per chunk: bounds the memory of one task and sets how often progress is reported.
DEFAULT_CHUNK_POINTS = 65_536
#: While chunks are out, how often the wait calls ``progress`` and looks at the cluster [s].
WAIT_TICK_S = 0.25

logger = logging.getLogger("microbearing.service.executor")


class DaskExecutor(Executor):
    """A :class:`concurrent.futures.Executor` running on dask.distributed, connected on first use.

    Parameters
    ----------
    scheduler : str
        Address of a scheduler (``tcp://host:8786``), or ``"local"`` for an embedded
        :class:`distributed.LocalCluster` of ``threads`` threads in this process.
    threads : int
        Threads of the embedded cluster [1]; ignored for a remote scheduler.
    fault_timeout_s : float, default 30
        How long the scheduler may stay unreachable, or without workers, before the work waiting
        on it fails [s] (``MICROBEARING_DASK_FAULT_TIMEOUT_S``).
    """

    #: How long a connection to a remote scheduler is tried before the request gets a 503. [s]
    connect_timeout_s = 10.0
    #: Longest wait for closing the connection at shutdown (a lost scheduler must not hold it). [s]
    close_timeout_s = 5.0

    def __init__(self, scheduler: str, threads: int, fault_timeout_s: float = 30.0):
        self.scheduler = scheduler
        self.threads = threads
        self.fault_timeout_s = fault_timeout_s
        self._lock = threading.Lock()
        self._client: Any = None
        self._cluster: Any = None
        self._executor: Executor | None = None
        #: Monotonic time since which :meth:`fault` has seen a fault (None: healthy when last seen).
        self._faulty_since: float | None = None
        #: The connection and scheduler last seen working (client object, scheduler id): a new one
        #: tells :func:`map_chunks` that calls pending on the old one are lost.
        self.identity: tuple[int, str] | None = None
        self._last_check = -1e9

    @property
    def remote(self) -> bool:
        """Whether the cluster runs outside this process (a scheduler's address, not ``"local"``)."""
        return self.scheduler != "local"

    def _connected(self, timeout_s: float | None = None) -> Executor:
        with self._lock:
            if self._client is not None and self._client.status in ("closing", "closed", "failed"):
                # The client gave up reconnecting to a lost scheduler: a new one, as for a first use.
                logger.warning("the dask client of %s is %s: connecting again", self.scheduler,
                               self._client.status)
                self._close_quietly(self._client)
                self._client = self._executor = None
            if self._client is not None and self._client.status != "running":  # reconnecting now
                raise ProblemError(503, f"The dask scheduler {self.scheduler} cannot be reached "
                                   f"(the connection is {self._client.status}); retry later.",
                                   headers={"Retry-After": "5"})
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
                        self._client = Client(self.scheduler, timeout=timeout_s or self.connect_timeout_s)
                    self.identity = self._identify(self._client)
                except OSError as exc:
                    raise ProblemError(503, f"The dask scheduler {self.scheduler} cannot be reached: "
                                       f"{exc}", headers={"Retry-After": "5"}) from exc
                self._executor = self._client.get_executor()
            return self._executor

    @staticmethod
    def _identify(client: Any) -> tuple[int, str]:
        return id(client), str(client.scheduler_info(n_workers=1).get("id"))

    def fault(self, connect_timeout_s: float = 2.0) -> str | None:
        """What is wrong with the cluster now, or None when it takes work.

        Connects first when there is no connection (trying for at most ``connect_timeout_s`` [s]).
        The embedded cluster is never at fault.

        Returns
        -------
        str or None
            E.g. ``"cannot be reached: ..."`` or ``"has no workers"``.
        """
        if not self.remote:
            return None
        try:
            self._connected(connect_timeout_s)
            client = self._client
            info = client.scheduler_info(n_workers=-1)
            reason = self._worker_fault(client, info.get("workers", {}))
        except ProblemError as problem:
            reason = problem.detail.removeprefix(f"The dask scheduler {self.scheduler} ")
        except (OSError, RuntimeError, TimeoutError) as exc:  # the scheduler went away during the question
            reason = f"cannot be reached: {exc}"
        with self._lock:
            if reason is None:
                self.identity = (id(client), str(info.get("id")))
                self._faulty_since = None
            elif self._faulty_since is None:
                self._faulty_since = time.monotonic()
        return reason

    @property
    def silent_after_s(self) -> float:
        """How long a worker may go without a heartbeat before it counts as not answering [s].

        Half the fault timeout (5 s at least): a worker stopped without dying (SIGSTOP, a hung
        host, a lost network) then fails the work waiting on it within 1.5 fault timeouts. Dask's
        own heartbeats come every 0.5-2 s on clusters of up to 200 workers.
        """
        return max(5.0, self.fault_timeout_s / 2)

    def _worker_fault(self, client: Any, workers: Mapping[str, Mapping[str, Any]]) -> str | None:
        """Why the cluster's workers cannot take the work, or None.

        A scheduler keeps a worker that stopped answering until its ``worker-ttl`` (5 minutes by
        default): its tasks wait that long. Ages of the last heartbeats are read on the scheduler's
        clock, so the hosts' clocks need not agree. A silent worker is a fault when no worker
        answers, or when it holds tasks (they wait on it); an idle one only costs its slots.
        """
        if not workers:
            return "has no workers"
        now = client.run_on_scheduler(time.time)
        silent = {address: now - float(worker.get("last_seen", now)) for address, worker in workers.items()}
        silent = {address: age for address, age in silent.items() if age > self.silent_after_s}
        if not silent:
            return None
        longest = max(silent.values())
        if len(silent) == len(workers):
            return (f"has no worker answering ({len(silent)} silent, the last heartbeat {longest:.0f} s ago; "
                    "stopped or hung workers)")
        holding = {address: len(keys) for address, keys in client.processing(workers=list(silent)).items()
                   if keys}
        if not holding:
            return None
        address = max(holding, key=holding.get)
        return (f"has a worker that stopped answering while it holds work: {address}, silent for "
                f"{silent[address]:.0f} s with {holding[address]} task(s)")

    def check(self) -> None:
        """Raise a 503 problem when the cluster has been at fault for ``fault_timeout_s`` or more.

        Asks the cluster at most once a second (:meth:`fault`); calls in between cost nothing.
        """
        now = time.monotonic()
        if now - self._last_check < 1.0:
            return
        self._last_check = now
        reason = self.fault()
        since = self._faulty_since
        if reason is not None and since is not None and time.monotonic() - since >= self.fault_timeout_s:
            raise ProblemError(503, f"The dask scheduler {self.scheduler} {reason.rstrip('.')}, for "
                                    f"{time.monotonic() - since:.0f} s (MICROBEARING_DASK_FAULT_TIMEOUT_S="
                                    f"{self.fault_timeout_s:g}); the work waiting on it was stopped.",
                               title="Cluster unavailable", headers={"Retry-After": "30"})

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future:
        """Run ``fn(*args, **kwargs)`` on the cluster; returns a concurrent.futures Future."""
        return self._connected().submit(fn, *args, **kwargs)

    def _close_quietly(self, client: Any) -> None:
        """Close ``client`` in a thread, for ``close_timeout_s`` at most (a lost scheduler can hang it)."""
        def close() -> None:
            try:
                client.close(timeout=self.close_timeout_s)
            except Exception as exc:  # closing a broken connection: nothing more to do
                logger.info("closing the dask client of %s: %s", self.scheduler, exc)

        closer = threading.Thread(target=close, name="microbearing-dask-close", daemon=True)
        closer.start()
        closer.join(self.close_timeout_s)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Close the connection, and the embedded cluster if there is one, within ``close_timeout_s`` each."""
        with self._lock:
            client, cluster = self._client, self._cluster
            self._executor = self._client = self._cluster = None
        if client is not None:
            self._close_quietly(client)
        if cluster is not None:
            cluster.close(timeout=self.close_timeout_s)


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
        return DaskExecutor(settings.dask_scheduler, threads, settings.dask_fault_timeout_s)
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
        Called with the share of calls done [1] after each (and, on a remote dask cluster, every
        :data:`WAIT_TICK_S` while waiting); when it raises (a cancelled job), the calls not yet
        started are cancelled and the exception propagates.

    Returns
    -------
    list
        The results, in the order of ``arguments``.

    Raises
    ------
    Exception
        The first exception raised by ``fn`` (in the order of ``arguments``), or by ``progress``.
    ProblemError
        503 when the executor is a dask cluster that stays unreachable, or without workers, for
        its fault timeout (:meth:`DaskExecutor.check`).
    """
    calls = [tuple(args) for args in arguments]
    if executor is None:
        results = []
        for done, args in enumerate(calls, start=1):
            results.append(fn(*args))
            if progress is not None:
                progress(done / len(calls))
        return results
    # A remote cluster can hold the wait forever: watched on every tick. A local pool or embedded
    # cluster finishes what it was given, and progress is reported once per call.
    cluster = executor if isinstance(executor, DaskExecutor) and executor.remote else None
    futures: list[Future] = []

    def submit(args: tuple) -> Future:
        """The call's future; on a remote cluster that took an earlier call, a submit the lost scheduler
        refused is a cancelled future, submitted again with the other lost calls when it is back (a
        cluster unreachable at the first call is the caller's 503 at once)."""
        try:
            return executor.submit(fn, *args)
        except (ProblemError, OSError, RuntimeError) as exc:
            if cluster is None or not futures:
                raise
            logger.warning("a chunk could not be submitted to the dask scheduler %s (%s): it is submitted "
                           "again when the scheduler is back", cluster.scheduler, exc)
            refused: Future = Future()
            refused.cancel()
            return refused

    for args in calls:
        futures.append(submit(args))
    born = [cluster.identity if cluster else None] * len(calls)  # the connection each call went out on

    def lost(i: int) -> bool:
        """Dropped by a lost scheduler: cancelled, or left pending on a connection that is gone."""
        return futures[i].cancelled() or (not futures[i].done() and born[i] != cluster.identity)

    try:
        results = []
        for done in range(len(calls)):
            while True:
                try:
                    results.append(futures[done].result(timeout=None if cluster is None else WAIT_TICK_S))
                    break
                except TimeoutError:
                    pass
                except CancelledError:
                    if cluster is None:
                        raise
                    time.sleep(WAIT_TICK_S)
                if cluster is not None:
                    if progress is not None:
                        progress(done / len(calls))  # a cancelled or shut-down job stops waiting here
                    cluster.check()  # a fault that lasts the fault timeout ends the wait
                    if lost(done) and cluster.fault() is None:
                        # The cluster is back: what it dropped is submitted again, on the new connection.
                        again = [i for i in range(done, len(calls)) if lost(i)]
                        for i in again:
                            futures[i] = submit(calls[i])
                            born[i] = cluster.identity
                        logger.warning("%d chunk(s) lost with the dask scheduler %s were submitted again",
                                       len(again), cluster.scheduler)
            if progress is not None:
                progress((done + 1) / len(calls))
        return results
    finally:
        for future in futures:
            future.cancel()  # no-op for finished calls; frees the pool after an error


def _evaluate_chunk(model: Model, points: dict[str, Any], outputs: list[str], pointer: str,
                    first_index: int) -> dict[str, np.ndarray]:
    """The outputs of a model on one chunk of points (the task :func:`evaluate_in_chunks` maps)."""
    try:
        return model.evaluate(points, outputs, pointer=pointer, first_index=first_index).values
    except ModelError as exc:
        raise validation_problem(exc.errors) from None


def evaluate_chunks(executor: Executor | None, inputs: dict[str, Any], count: int,
                    outputs: list[str] | None, model: Model, pointer: str = "",
                    progress: Callable[[float], None] | None = None,
                    chunk_points: int = DEFAULT_CHUNK_POINTS
                    ) -> tuple[list[str], list[tuple[int, int]], list[dict[str, np.ndarray]]]:
    """:func:`evaluate_in_chunks` without joining the chunks: the output names, chunk bounds and chunks.

    A chunk's output may be a scalar (broadcast to its points). A caller that writes the outputs
    chunk by chunk (the streamed batch answer, :func:`service.tables.json_column_pieces`) needs no
    second copy of them. Parameters and errors as :func:`evaluate_in_chunks`.
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
            model.column_checks[name].check(values)
        except InputError as exc:
            raise validation_problem([{"pointer": pointer_at(pointer, name), "detail": str(exc)}]) from None
    bounds = chunk_bounds(count, chunk_points)
    names = [str(name) for name in outputs] if outputs else list(model.outputs)
    arguments = [(model, {**shared, **{name: values[start:stop] for name, values in columns.items()}},
                  names, pointer, start) for start, stop in bounds]
    return names, bounds, map_chunks(executor, _evaluate_chunk, arguments, progress)


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
    names, bounds, chunks = evaluate_chunks(executor, inputs, count, outputs, model, pointer, progress,
                                            chunk_points)
    if not chunks:
        return {name: np.empty(0) for name in names}
    return {name: np.concatenate([np.broadcast_to(np.asarray(chunk[name], dtype=float), (stop - start,))
                                  for chunk, (start, stop) in zip(chunks, bounds, strict=True)])
            for name in names}
