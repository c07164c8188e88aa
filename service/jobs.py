"""Persistent background jobs: long work answers ``202 Accepted`` and runs in a thread pool.

A route submits a function taking a :class:`JobContext`; the function reports progress and
checks for cancellation, and returns a JSON-ready dict (NumPy arrays are turned into lists)::

    def run(ctx: JobContext) -> dict:
        for i, chunk in enumerate(chunks):
            ctx.check_cancelled()              # raises Cancelled after DELETE /v1/jobs/{id}
            ...
            ctx.progress((i + 1) / len(chunks))
        return {"columns": {...}}

    job = jobs.submit("sweep", request.model_dump(mode="json"), run)
    return accepted(job)                        # 202 + Location: /v1/jobs/{id}

Domain functions take ``progress: Callable[[float], None]``: pass ``ctx.progress``, which also
checks for cancellation, so a domain loop that reports progress is cancellable without knowing
about the service.

Jobs live in SQLite (:mod:`service.store`): status queued, running, succeeded, failed or
cancelled; progress 0..1; the result as JSON; a failure as a problem object. Each job records
the pid and instance of the server that owns it. On startup, queued or running jobs whose owner
is gone are marked failed with :data:`INTERRUPTED_DETAIL`, so several uvicorn workers can share
one data folder without failing each other's live jobs. Liveness is checked by pid and, where
``/proc`` tells it (Linux), by the process's start time, which the instance id carries: a dead
server's pid taken by an unrelated process does not keep its jobs "running" (elsewhere it does,
until a later startup finds that pid gone). A function raising ``ValueError`` fails
its job with a 422 problem, :class:`~service.problems.ProblemError` with its own problem, any
other exception with a 500 problem.

Bounds: a server process holds at most ``max_active`` queued and running jobs, and at most
``max_active_per_key`` of one API key; :meth:`JobManager.submit` refuses more with a 503 (server
full) or 429 (this key) problem carrying ``Retry-After``. A queued job holds only its request and
the closure that will build its work: routes build large designs inside ``fn``, when the job
starts, so a full queue costs kilobytes, not gigabytes. A result larger than ``max_result_bytes``
(its JSON) fails the job with a 413 problem.

Storage faults: when the store cannot take a write (disk full, read-only; see
:class:`~service.store.StorageError`), the job fails with a problem naming the cause, logged at
ERROR. If even that failure cannot be written, the job's final state is kept in memory (its
status reads ``failed`` at once) and written by the housekeeping thread once the disk takes writes
again; a restart marks such jobs failed as interrupted. The same thread deletes finished jobs and
their results ``retention_s`` after they finished.
"""

from __future__ import annotations

import contextvars
import logging
import os
import threading
import time
import uuid
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

from .problems import INTERNAL_TYPE, VALIDATION_TYPE, ProblemError
from .store import REQUESTER, StorageError, Store, json_bytes, to_json, utc_now

__all__ = ["ACTIVE", "FINISHED", "INTERRUPTED_DETAIL", "POLL_AFTER_S", "RETRY_AFTER_S", "Cancelled",
           "JobContext", "JobManager"]

logger = logging.getLogger("microbearing.service.jobs")

ACTIVE = ("queued", "running")
FINISHED = ("succeeded", "failed", "cancelled")
INTERRUPTED_DETAIL = "interrupted: the server stopped while the job ran"

#: Job managers alive in this process; a job owned by this pid but another instance is orphaned.
_LIVE_INSTANCES: set[str] = set()

#: Seconds between progress writes and between database checks for a cancellation request.
_PROGRESS_INTERVAL_S = 0.1
_CANCEL_POLL_INTERVAL_S = 0.25

#: ``Retry-After`` of a refused job request [s]: about the time a queued job waits for a worker.
RETRY_AFTER_S = 5
#: ``Retry-After`` of a 202 answer [s]: when to poll the job first.
POLL_AFTER_S = 1
#: Longest pause of the housekeeping thread [s] (retention purge, writing final states kept in memory).
_HOUSEKEEPING_INTERVAL_S = 300.0
_STORAGE_RETRY_INTERVAL_S = 2.0


class Cancelled(Exception):  # noqa: N818 - a state, not an error; the job ends "cancelled"
    """Raised by :meth:`JobContext.check_cancelled` once the job's cancellation is requested."""


def _pid_alive(pid: int) -> bool:
    if os.name != "posix":
        return True  # without a safe liveness probe, never fail another process's job
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _process_start(pid: int) -> str | None:
    """Start time of process ``pid`` in clock ticks since boot (Linux), None where unknown."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    # Field 22 of proc(5); the command name (field 2) may hold spaces and parentheses.
    fields = stat.rpartition(")")[2].split()
    return fields[19] if len(fields) > 19 else None


def _owner_alive(pid: int, instance: str) -> bool:
    if pid == os.getpid():
        return instance in _LIVE_INSTANCES
    if not _pid_alive(pid):
        return False
    # Instances are "<uuid>.<start time of the owning process>": another start time is another process.
    started = instance.partition(".")[2]
    return not started or _process_start(pid) in (None, started)


class JobContext:
    """What a running job function sees: progress reporting and cancellation.

    Parameters
    ----------
    job_id : str
        Identifier of the job.
    store : Store
        Database the job lives in.
    cancel_event : threading.Event
        Set when this process cancels the job.
    """

    def __init__(self, job_id: str, store: Store, cancel_event: threading.Event):
        self.job_id = job_id
        self._store = store
        self._cancel_event = cancel_event
        self._last_write = 0.0
        self._last_poll = 0.0

    def check_cancelled(self) -> None:
        """Raise :class:`Cancelled` when cancellation was requested (by any server process)."""
        if self._cancel_event.is_set():
            raise Cancelled(self.job_id)
        now = time.monotonic()
        if now - self._last_poll >= _CANCEL_POLL_INTERVAL_S:
            self._last_poll = now
            row = self._store.get_job(self.job_id)
            if row is None or row["cancel_requested"]:
                self._cancel_event.set()
                raise Cancelled(self.job_id)

    def progress(self, fraction: float) -> None:
        """Record progress and check for cancellation.

        Parameters
        ----------
        fraction : float
            Share of the work done [1], clipped to [0, 1].
        """
        self.check_cancelled()
        now = time.monotonic()
        if now - self._last_write >= _PROGRESS_INTERVAL_S:
            self._last_write = now
            self._store.update_job(self.job_id, only_if_status=("running",),
                                   progress=min(max(float(fraction), 0.0), 1.0))


class JobManager:
    """Submits, runs, cancels and recovers jobs of one data folder.

    Parameters
    ----------
    store : Store
        The database.
    workers : int
        Threads running jobs in this process [1].
    max_active : int, optional
        Most queued and running jobs of this process [1]; unbounded when None.
    max_active_per_key : int, optional
        Most queued and running jobs of one API key in this process [1]; unbounded when None.
    max_result_bytes : int, optional
        Largest result JSON [bytes]; unbounded when None.
    retention_s : float, optional
        Finished jobs are deleted this long after they finished [s]; kept forever when None.
    """

    def __init__(self, store: Store, workers: int, max_active: int | None = None,
                 max_active_per_key: int | None = None, max_result_bytes: int | None = None,
                 retention_s: float | None = None):
        self.store = store
        self.instance = f"{uuid.uuid4().hex}.{_process_start(os.getpid()) or ''}"
        self.max_active = max_active
        self.max_active_per_key = max_active_per_key
        self.max_result_bytes = max_result_bytes
        self.retention_s = retention_s
        self._executor = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="microbearing-job")
        self._cancel_events: dict[str, threading.Event] = {}
        #: Owner key of every queued or running job of this process (None without keys).
        self._active: dict[str, str | None] = {}
        #: Final states that the store could not take: written by the housekeeping thread.
        self._unwritten: dict[str, dict[str, Any]] = {}
        self._lock = threading.Lock()
        self._stopping = threading.Event()
        _LIVE_INSTANCES.add(self.instance)
        self.recover()
        self.purge_expired()
        self._housekeeper = threading.Thread(target=self._housekeeping, name="microbearing-jobs-housekeeping",
                                             daemon=True)
        self._housekeeper.start()

    def recover(self) -> list[str]:
        """Mark failed the active jobs whose owning server is gone; returns their ids."""
        failed = []
        for row in self.store.jobs_with_status(*ACTIVE):
            if not _owner_alive(row["owner_pid"], row["owner_instance"]):
                problem = ProblemError(500, INTERRUPTED_DETAIL, title="Job interrupted", type_=INTERNAL_TYPE)
                if self.store.update_job(row["id"], only_if_status=ACTIVE, status="failed",
                                         error_json=to_json(problem.to_dict()), finished_at=utc_now()):
                    failed.append(row["id"])
        if failed:
            logger.warning("marked %d interrupted job(s) failed: %s", len(failed), ", ".join(failed))
        return failed

    def purge_expired(self) -> int:
        """Delete the finished jobs (and results) older than the retention; returns how many."""
        if self.retention_s is None:
            return 0
        cutoff = datetime.now(UTC) - timedelta(seconds=self.retention_s)
        before = cutoff.isoformat(timespec="milliseconds").replace("+00:00", "Z")
        try:
            deleted = self.store.delete_jobs_finished_before(FINISHED, before)
        except StorageError as exc:
            logger.error("could not delete expired jobs: %s", exc.detail)
            return 0
        if deleted:
            logger.info("deleted %d finished job(s) older than %g s", deleted, self.retention_s)
        return deleted

    def _housekeeping(self) -> None:
        interval = min(_HOUSEKEEPING_INTERVAL_S, max(self.retention_s or _HOUSEKEEPING_INTERVAL_S, 0.2) / 4)
        last_purge = time.monotonic()
        while not self._stopping.wait(min(interval, _STORAGE_RETRY_INTERVAL_S)):
            self._write_unwritten()
            if time.monotonic() - last_purge >= interval:
                last_purge = time.monotonic()
                self.purge_expired()

    def _write_unwritten(self) -> None:
        with self._lock:
            pending = list(self._unwritten.items())
        for job_id, changes in pending:
            try:
                self.store.update_job(job_id, only_if_status=ACTIVE, **changes)
            except StorageError:
                return  # still failing; the next round tries again
            with self._lock:
                self._unwritten.pop(job_id, None)
            logger.info("job %s: its final state %s is stored now", job_id, changes["status"],
                        extra={"job_id": job_id})

    def _admit(self, job_id: str) -> None:
        """Reserve a place for a new job of the current requester, or raise a 503 / 429 problem."""
        owner = REQUESTER.get().key_id
        retry = {"Retry-After": str(RETRY_AFTER_S)}
        with self._lock:
            if self.max_active is not None and len(self._active) >= self.max_active:
                logger.warning("refused a job: %d jobs queued or running (MICROBEARING_MAX_ACTIVE_JOBS)",
                               len(self._active))
                raise ProblemError(503, f"The server holds {len(self._active)} queued or running jobs, "
                                        f"its limit (MICROBEARING_MAX_ACTIVE_JOBS={self.max_active}); "
                                        "retry later.", title="Server busy", headers=retry)
            if owner is not None and self.max_active_per_key is not None:
                mine = sum(1 for key in self._active.values() if key == owner)
                if mine >= self.max_active_per_key:
                    raise ProblemError(429, f"This API key has {mine} queued or running jobs, its limit "
                                            "(MICROBEARING_MAX_ACTIVE_JOBS_PER_KEY="
                                            f"{self.max_active_per_key}); wait for one to finish or cancel "
                                            "one.",
                                       title="Too many jobs", headers=retry)
            self._active[job_id] = owner

    def _release(self, job_id: str) -> None:
        with self._lock:
            self._active.pop(job_id, None)
            self._cancel_events.pop(job_id, None)

    def admit_request(self, kind: str) -> Callable[[], None]:
        """Hold a place of this admission control for work done in a request, not a job (a heavy batch).

        The place counts toward ``max_active`` and ``max_active_per_key`` as a job does, so heavy
        requests and jobs share one bound and a key's heavy requests count toward its limit.

        Returns
        -------
        callable
            Frees the place; call it once, when the work (and its streamed answer) is done.

        Raises
        ------
        ProblemError
            503 or 429 with ``Retry-After``, as :meth:`submit`.
        """
        token = f"{kind}-{uuid.uuid4().hex}"
        self._admit(token)
        return lambda: self._release(token)

    def active_count(self) -> int:
        """Queued and running jobs of this process [1]."""
        with self._lock:
            return len(self._active)

    def submit(self, kind: str, request: dict[str, Any], fn: Callable[[JobContext], dict[str, Any]]
               ) -> dict[str, Any]:
        """Queue ``fn`` as a job and return its row.

        Parameters
        ----------
        kind : str
            What the job does, e.g. ``"sweep"``.
        request : dict
            The JSON-ready request that created it (kept for the record).
        fn : callable
            ``fn(ctx) -> dict``, the work; its JSON-ready result is stored. Build large inputs
            (designs) inside it: a queued job should hold no more than its request.

        Returns
        -------
        dict
            The job row (see :meth:`get`).

        Raises
        ------
        ProblemError
            503 when this process holds ``max_active`` jobs, 429 when the requester's key holds
            ``max_active_per_key``, both with ``Retry-After``; a storage problem when the job
            cannot be recorded.
        """
        job_id = uuid.uuid4().hex
        self._admit(job_id)
        try:
            self.store.insert_job(id=job_id, kind=kind, status="queued", progress=0.0,
                                  request_json=to_json(request), owner_pid=os.getpid(),
                                  owner_instance=self.instance, created_at=utc_now())
        except BaseException:
            self._release(job_id)
            raise
        event = threading.Event()
        with self._lock:
            self._cancel_events[job_id] = event
        # Logged before the job's thread can log "started". That thread runs in a copy of the
        # submitting context: its log lines carry the id of the request that created it.
        logger.info("job %s (%s) queued", job_id, kind, extra={"job_id": job_id, "kind": kind})
        self._executor.submit(contextvars.copy_context().run, self._run, job_id, fn, event)
        return self.get(job_id)

    def get(self, job_id: str, with_result: bool = False) -> dict[str, Any] | None:
        """The job row, or None for an unknown id (``request_json`` and ``result_json`` ``with_result``).

        A final state the store could not take yet is shown as it will be written.
        """
        row = self.store.get_job(job_id, with_result=with_result)
        if row is not None:
            with self._lock:
                row.update(self._unwritten.get(job_id, {}))
        return row

    def delete(self, job_id: str) -> bool:
        """Delete a finished job and its result; returns whether it was deleted."""
        return self.store.delete_job(job_id, FINISHED)

    def cancel(self, job_id: str) -> dict[str, Any] | None:
        """Request cancellation; a queued job is cancelled at once, a running one at its next check.

        A running job's work that returns without another check still ends the job cancelled.

        Returns
        -------
        dict or None
            The job row after the request, or None for an unknown id.
        """
        if self.store.update_job(job_id, only_if_status=("queued",), status="cancelled",
                                 cancel_requested=1, finished_at=utc_now()):
            self._release(job_id)
            return self.get(job_id)
        self.store.update_job(job_id, only_if_status=("running",), cancel_requested=1)
        with self._lock:
            event = self._cancel_events.get(job_id)
        if event is not None:
            event.set()
        return self.get(job_id)

    def shutdown(self) -> None:
        """Stop: cancel queued work, interrupt running jobs and mark both failed as interrupted."""
        self._stopping.set()
        with self._lock:
            events = list(self._cancel_events.values())
        for event in events:
            event.set()
        self._executor.shutdown(wait=True, cancel_futures=True)
        self._housekeeper.join()
        _LIVE_INSTANCES.discard(self.instance)
        problem = ProblemError(500, INTERRUPTED_DETAIL, title="Job interrupted", type_=INTERNAL_TYPE)
        for row in self.store.jobs_with_status(*ACTIVE):
            if row["owner_instance"] == self.instance:
                try:
                    self.store.update_job(row["id"], only_if_status=ACTIVE, status="failed",
                                          error_json=to_json(problem.to_dict()), finished_at=utc_now())
                except StorageError as exc:  # the next start marks it failed as interrupted
                    logger.error("job %s: cannot record its interruption: %s", row["id"], exc.detail)

    def _finish(self, job_id: str, status: str, unless_cancel_requested: bool = False,
                **changes: Any) -> bool:
        finished_at = utc_now()
        try:
            finished = self.store.update_job(job_id, only_if_status=("running",), status=status,
                                             finished_at=finished_at, **changes,
                                             unless_cancel_requested=unless_cancel_requested)
        except StorageError as exc:
            if status != "failed" or "result_json" in changes:
                # Most often the result itself did not fit: fail the job with the reason (a small write).
                logger.error("job %s: its final state (%s) could not be stored: %s", job_id, status,
                             exc.detail, extra={"job_id": job_id})
                return self._finish(job_id, "failed", error_json=to_json(exc.to_dict()))
            # Not even the failure can be written: keep it in memory, the housekeeping thread retries.
            logger.error("job %s: cannot store its failure either (%s); kept in memory until the store "
                         "takes writes", job_id, exc.detail, extra={"job_id": job_id})
            with self._lock:
                self._unwritten[job_id] = {"status": status, "finished_at": finished_at, **changes}
            finished = True
        if finished:
            logger.info("job %s %s", job_id, status, extra={"job_id": job_id, "status": status})
        return finished

    def _run(self, job_id: str, fn: Callable[[JobContext], dict[str, Any]], event: threading.Event) -> None:
        try:
            self._run_job(job_id, fn, event)
        finally:
            self._release(job_id)

    def _run_job(self, job_id: str, fn: Callable[[JobContext], dict[str, Any]],
                 event: threading.Event) -> None:
        try:
            started = not event.is_set() and self.store.update_job(
                job_id, only_if_status=("queued",), status="running", started_at=utc_now())
        except StorageError as exc:
            logger.error("job %s could not start: %s", job_id, exc.detail, extra={"job_id": job_id})
            with self._lock:
                self._unwritten[job_id] = {"status": "failed", "finished_at": utc_now(),
                                           "error_json": to_json(exc.to_dict())}
            return
        if not started:
            return
        ctx = JobContext(job_id, self.store, event)
        logger.info("job %s started", job_id, extra={"job_id": job_id})
        try:
            ctx.check_cancelled()
            result = fn(ctx)
        except Cancelled:
            if self.store.get_job(job_id)["cancel_requested"]:
                self._finish(job_id, "cancelled")
            else:  # only shutdown sets the event without a request; shutdown marks the job failed
                self._finish(job_id, "failed", error_json=to_json(ProblemError(
                    500, INTERRUPTED_DETAIL, title="Job interrupted", type_=INTERNAL_TYPE).to_dict()))
        except StorageError as fault:
            logger.error("job %s failed: %s", job_id, fault.detail, extra={"job_id": job_id})
            self._finish(job_id, "failed", error_json=to_json(fault.to_dict()))
        except ProblemError as problem:
            self._finish(job_id, "failed", error_json=to_json(problem.to_dict()))
        except ValueError as exc:
            problem = ProblemError(422, str(exc), title="Invalid job input", type_=VALIDATION_TYPE)
            self._finish(job_id, "failed", error_json=to_json(problem.to_dict()))
        except Exception as exc:
            logger.exception("job %s failed", job_id)
            problem = ProblemError(500, f"The job failed: {type(exc).__name__}: {exc}", title="Job failed",
                                   type_=INTERNAL_TYPE)
            self._finish(job_id, "failed", error_json=to_json(problem.to_dict()))
        else:
            try:
                encoded = json_bytes(result)
            except (TypeError, ValueError) as exc:
                problem = ProblemError(500, f"The job's result is not finite JSON: {exc}", title="Job failed",
                                       type_=INTERNAL_TYPE)
                self._finish(job_id, "failed", error_json=to_json(problem.to_dict()))
                return
            del result
            if self.max_result_bytes is not None and len(encoded) > self.max_result_bytes:
                problem = ProblemError(413, f"The result has {len(encoded)} bytes of JSON, more than the "
                                            f"limit of {self.max_result_bytes} "
                                            "(MICROBEARING_MAX_RESULT_BYTES); ask for fewer points or "
                                            "outputs.",
                                       title="Result too large")
                self._finish(job_id, "failed", error_json=to_json(problem.to_dict()))
                return
            self._succeed(job_id, encoded.decode())

    def _succeed(self, job_id: str, result_json: str) -> None:
        # A cancellation requested while the work was finishing wins: DELETE answered
        # cancel_requested true, so the job ends cancelled and its result is discarded.
        if not self._finish(job_id, "succeeded", unless_cancel_requested=True, progress=1.0,
                            result_json=result_json):
            self._finish(job_id, "cancelled")
