"""Persistent background jobs: long work answers ``202 Accepted`` and runs in a thread pool.

A route submits a function taking a :class:`JobContext`; the function reports progress and
checks for cancellation, and returns a JSON-ready dict (NumPy arrays are turned into lists)::

    def run(ctx: JobContext) -> dict:
        for i, chunk in enumerate(chunks):
            ctx.check_cancelled()              # raises Cancelled after DELETE /v1/jobs/{id}
            ...
            ctx.progress((i + 1) / len(chunks))
        return {"columns": {...}}

    request = body.model_dump(mode="json")
    job = jobs.submit("sweep", request, run, inputs=request)
    return accepted(job)                        # 202 + Location: /v1/jobs/{id}

Domain functions take ``progress: Callable[[float], None]``: pass ``ctx.progress``, which also
checks for cancellation, so a domain loop that reports progress is cancellable without knowing
about the service.

Jobs live in the database (SQLite or PostgreSQL, :mod:`service.store`): status queued, running,
succeeded, failed or cancelled; progress 0..1; the result as JSON; a failure as a problem object. A
function raising ``ValueError`` fails its job with a 422 problem,
:class:`~service.problems.ProblemError` with its own problem, any other exception with a 500
problem.

Several processes, one truth. Every server process sharing a database runs a :class:`JobManager`;
the database is all they share. A job submitted with ``inputs`` of a kind declared by
:func:`register_kind` is stored whole: any process can rebuild its work, so it stays queued across
any restart and is run by whichever process claims it first (one write transaction: never two). A
claim is a lease of ``lease_s`` renewed every third of it by the claiming process (its heartbeat,
which also passes on cancellations requested through other processes). A running job whose lease
lapsed, or whose process is gone (pid, start time and zombie state, where ``/proc`` tells them, for
a process of the same host), is re-queued by another process or by the next start, once
(:data:`MAX_ATTEMPTS` runs), or failed with the reason, by its kind's rule (:class:`JobKind`);
writes of the run that lost its claim are refused (they name its ``lease_token``). Work submitted
without inputs (library use, tests) runs only in the process that holds it, and is failed as
interrupted when that process is gone.

Shutdown stops claiming, lets running jobs finish for ``shutdown_grace_s``, then interrupts the rest
at their next progress check and re-queues them without counting the run (queued jobs stay queued).

Bounds: a data folder holds at most ``max_active`` queued and running jobs, and at most
``max_active_per_key`` of one API key, counted in the transaction that inserts a job;
:meth:`JobManager.submit` refuses more with a 503 (server full) or 429 (this key) problem carrying
``Retry-After``. A queued job holds only its request and the closure that will build its work:
routes build large designs inside ``fn``, when the job starts, so a full queue costs kilobytes, not
gigabytes. A result larger than ``max_result_bytes`` (its JSON) fails the job with a 413 problem.

Storage faults: when the store cannot take a write (disk full, read-only; see
:class:`~service.store.StorageError`), the job fails with a problem naming the cause, logged at
ERROR. If even that failure cannot be written, the job's final state is kept in memory (its
status reads ``failed`` at once) and written by the housekeeping thread once the disk takes writes
again; a restart before that treats them as any interrupted run. The same thread deletes finished jobs and
their results ``retention_s`` after they finished.
"""

from __future__ import annotations

import contextvars
import hashlib
import json
import logging
import os
import socket
import threading
import time
import uuid
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

from .problems import INTERNAL_TYPE, VALIDATION_TYPE, ProblemError
from .store import (
    FINISHED_STATUSES,
    REQUESTER,
    Requester,
    StorageError,
    Store,
    UnstorableError,
    json_bytes,
    to_json,
    utc_now,
)

__all__ = ["ACTIVE", "FINISHED", "INTERRUPTED_DETAIL", "JOB_KINDS", "MAX_ATTEMPTS", "NOT_STORED_DETAIL",
           "POLL_AFTER_S", "RETRY_AFTER_S", "Cancelled", "JobContext", "JobKind", "JobManager",
           "register_kind"]

logger = logging.getLogger("microbearing.service.jobs")

ACTIVE = ("queued", "running")
FINISHED = FINISHED_STATUSES
INTERRUPTED_DETAIL = "interrupted: the server stopped while the job ran"
NOT_STORED_DETAIL = ("interrupted: the server process holding this queued job stopped, and its work was not "
                     "stored (only jobs submitted with their inputs outlive their process)")

#: Job managers alive in this process; a job owned by this pid but another instance is orphaned.
_LIVE_INSTANCES: set[str] = set()

#: Seconds between progress writes and between database checks for a cancellation request.
_PROGRESS_INTERVAL_S = 0.1
_CANCEL_POLL_INTERVAL_S = 0.25
#: Longest pause of the dispatcher [s]: jobs queued or re-queued by another process are claimed this soon.
_CLAIM_POLL_INTERVAL_S = 0.5

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
    # A killed process that its parent has not reaped yet (a zombie) still answers signal 0.
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0]
    except (OSError, IndexError):
        return True
    return state not in ("Z", "X")


def _process_start(pid: int) -> str | None:
    """Start time of process ``pid`` in clock ticks since boot (Linux), None where unknown."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    # Field 22 of proc(5); the command name (field 2) may hold spaces and parentheses.
    fields = stat.rpartition(")")[2].split()
    return fields[19] if len(fields) > 19 else None


def _host_id() -> str:
    """This host (and pid namespace): a hash of the host name and the boot id (Linux), no dots."""
    try:
        boot = Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    except OSError:
        boot = ""
    return hashlib.sha256(f"{socket.gethostname()}\n{boot}".encode()).hexdigest()[:16]


#: This host, in the job managers' instances: a pid is checked only on the host it belongs to.
_HOST = _host_id()


def _owner_alive(pid: int, instance: str) -> bool:
    # Instances are "<uuid>.<start time of the owning process>.<host>" (older ones lack the host).
    _, started, host = [*instance.split("."), "", ""][:3]
    if host and host != _HOST:
        return True  # another host's process (a shared PostgreSQL database): only its lease tells
    if pid == os.getpid():
        return instance in _LIVE_INSTANCES
    if not _pid_alive(pid):
        return False
    # Another start time is another process.
    return not started or _process_start(pid) in (None, started)


def _interrupted(detail: str) -> ProblemError:
    return ProblemError(500, detail, title="Job interrupted", type_=INTERNAL_TYPE)


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
    lease_token : str, optional
        The claim this run holds (:meth:`Store.claim_job`): a run whose claim was taken over
        stops as cancelled and writes nothing.
    """

    def __init__(self, job_id: str, store: Store, cancel_event: threading.Event,
                 lease_token: str | None = None):
        self.job_id = job_id
        self._store = store
        self._cancel_event = cancel_event
        self._token = lease_token
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
            if row is None or row["cancel_requested"] or (self._token and row["lease_token"] != self._token):
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
            self._store.update_job(self.job_id, only_if_status=("running",), only_if_token=self._token,
                                   progress=min(max(float(fraction), 0.0), 1.0))


@dataclass(frozen=True)
class JobKind:
    """How a process runs a job of one kind from its stored inputs, and what an interruption does to it.

    Attributes
    ----------
    name : str
        The job's ``kind``, e.g. ``"sweep"``.
    build : callable
        ``build(inputs, services) -> fn``: the work of a job from the JSON inputs stored at submit
        and the running app's services (its ``store``, ``settings`` and ``executor``). Called in the
        job's thread, under the key that submitted the job; raising fails the job as ``fn`` would.
    requeue : bool
        Whether a run interrupted by the loss of its process (SIGKILL, a crash, a lapsed lease) is
        queued again (once: a second interruption fails the job) or failed at once.
    rule : str
        Why, for the documentation (README, "Jobs across restarts and processes").
    """

    name: str
    build: Callable[[dict[str, Any], Any], Callable[[JobContext], dict[str, Any]]]
    requeue: bool = True
    rule: str = ""


#: Kinds whose work any process can rebuild from stored inputs; filled by :func:`register_kind` (the
#: service's own: :data:`service.job_kinds.JOB_KIND_TABLE`, registered by the app at start).
JOB_KINDS: dict[str, JobKind] = {}

#: Runs of a job: a re-queued job that is interrupted again fails (it may be what kills the server).
MAX_ATTEMPTS = 2


def register_kind(name: str, build: Callable[[dict[str, Any], Any], Callable[[JobContext], dict[str, Any]]],
                  *, requeue: bool = True, rule: str = "") -> None:
    """Declare how to run a job of ``name`` from its stored inputs (see :class:`JobKind`).

    A route submitting such a job passes ``inputs=`` to :meth:`JobManager.submit`: the job then
    survives restarts and can be run by any process sharing the data folder.
    """
    JOB_KINDS[name] = JobKind(name, build, requeue, rule)


class JobManager:
    """Submits, claims, runs, cancels and recovers the jobs of one data folder.

    Every process sharing the folder runs one manager; the database is the one truth between them.
    Admission counts the active jobs of the whole folder in the transaction that inserts a job. A
    dispatcher thread claims queued jobs (:meth:`Store.claim_job`) while a worker thread is free,
    each with a lease of ``lease_s`` renewed every ``lease_s / 3`` (the heartbeat, which also
    passes on cancellations requested through any process). The same thread finds the running
    jobs whose lease lapsed, or whose process is gone (pid and start time, for a process of this host), and
    re-queues or fails them by their kind's rule (:class:`JobKind`).

    Parameters
    ----------
    store : Store
        The database.
    workers : int
        Threads running jobs in this process [1].
    max_active : int, optional
        Most queued and running jobs of the data folder (all processes) [1]; unbounded when None.
    max_active_per_key : int, optional
        Most queued and running jobs of one API key (all processes) [1]; unbounded when None.
    max_result_bytes : int, optional
        Largest result JSON [bytes]; unbounded when None.
    retention_s : float, optional
        Finished jobs are deleted this long after they finished [s]; kept forever when None.
    services : object, optional
        What :attr:`JobKind.build` receives (the app's runtime); without it this process runs
        only the jobs it submitted.
    lease_s : float, default 15
        Lease of a claimed job [s]: another process re-queues a job whose owner has not renewed
        it for this long.
    shutdown_grace_s : float, default 0
        :meth:`shutdown` lets running jobs finish for this long [s] before interrupting them.
    """

    def __init__(self, store: Store, workers: int, max_active: int | None = None,
                 max_active_per_key: int | None = None, max_result_bytes: int | None = None,
                 retention_s: float | None = None, services: Any = None, lease_s: float = 15.0,
                 shutdown_grace_s: float = 0.0):
        self.store = store
        self.instance = f"{uuid.uuid4().hex}.{_process_start(os.getpid()) or ''}.{_HOST}"
        self.workers = int(workers)
        self.max_active = max_active
        self.max_active_per_key = max_active_per_key
        self.max_result_bytes = max_result_bytes
        self.retention_s = retention_s
        self.services = services
        self.lease_s = float(lease_s)
        self.heartbeat_s = self.lease_s / 3
        self.shutdown_grace_s = float(shutdown_grace_s)
        self._executor = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="microbearing-job")
        #: Work submitted here and not claimed yet: job id -> (fn, context of the submitting request).
        self._local: dict[str, tuple[Callable[[JobContext], dict[str, Any]], contextvars.Context]] = {}
        #: Jobs this process runs: job id -> (lease token, cancel event).
        self._running: dict[str, tuple[str, threading.Event]] = {}
        #: Final states that the store could not take: written by the housekeeping thread.
        self._unwritten: dict[str, dict[str, Any]] = {}
        #: Running jobs writing their final state: a lease no longer held is their own doing, not a takeover.
        self._ending: set[str] = set()
        self._lock = threading.Lock()
        self._requests: dict[str, str | None] = {}  # heavy requests' places (admit_request): token -> key
        self._stopping = threading.Event()
        self._interrupting = threading.Event()
        self._wake = threading.Event()
        _LIVE_INSTANCES.add(self.instance)
        self.recover()
        self.purge_expired()
        self._housekeeper = threading.Thread(target=self._housekeeping, name="microbearing-jobs-housekeeping",
                                             daemon=True)
        self._housekeeper.start()
        self._dispatcher = threading.Thread(target=self._dispatch, name="microbearing-jobs-dispatch",
                                            daemon=True)
        self._dispatcher.start()

    def _kinds(self) -> tuple[str, ...]:
        return tuple(sorted(JOB_KINDS)) if self.services is not None else ()

    def recover(self) -> list[str]:
        """Re-queue or fail the running jobs whose lease lapsed or whose process is gone; returns their ids.

        Also fails the queued jobs whose work was never stored (submitted without ``inputs``) when the
        process holding it is gone. Runs at start and at every heartbeat.
        """
        changed = []
        now = time.time()
        for row in self.store.jobs_with_status(*ACTIVE):
            mine = row["owner_instance"] == self.instance
            if row["status"] == "queued":
                if not row["replayable"] and not mine and not _owner_alive(row["owner_pid"],
                                                                           row["owner_instance"]):
                    if self.store.update_job(row["id"], only_if_status=("queued",), status="failed",
                                             error_json=to_json(_interrupted(NOT_STORED_DETAIL).to_dict()),
                                             finished_at=utc_now()):
                        changed.append(row["id"])
                continue
            with self._lock:  # ours and running, or ended with a final state not written yet
                held = mine and (row["id"] in self._running or row["id"] in self._unwritten)
            if held:
                continue
            lapsed = row["lease_expires"] is not None and row["lease_expires"] < now
            if lapsed or not _owner_alive(row["owner_pid"], row["owner_instance"]):
                why = "its lease lapsed" if lapsed else "its server process is gone"
                if self._interrupt(row, why, graceful=False):
                    changed.append(row["id"])
        return changed

    def _interrupt(self, row: dict[str, Any], why: str, graceful: bool) -> bool:
        """End a run that lost its process: cancelled, re-queued or failed; whether the row changed.

        A graceful stop (shutdown) re-queues every replayable job without counting the run; a lost
        process re-queues a job of a kind with ``requeue`` once (:data:`MAX_ATTEMPTS` runs).
        """
        condition: dict[str, Any] = {"only_if_status": ("running",), "only_if_token": row["lease_token"]}
        kind = JOB_KINDS.get(row["kind"])
        if row["replayable"] and kind is None:
            return False  # a kind this process does not know (not a server): left to one that does
        if row["cancel_requested"]:
            changes: dict[str, Any] = {"status": "cancelled", "finished_at": utc_now()}
            outcome = "cancelled"
        elif row["replayable"] and kind is not None and (graceful or (kind.requeue
                                                                       and row["attempts"] < MAX_ATTEMPTS)):
            changes = {"status": "queued", "progress": 0.0, "started_at": None, "lease_token": None,
                       "lease_expires": None}
            if graceful:
                changes["attempts"] = max(row["attempts"] - 1, 0)
            outcome = "re-queued"
        else:
            if not row["replayable"] or kind is None:
                detail = INTERRUPTED_DETAIL
            elif not kind.requeue:
                detail = f"{INTERRUPTED_DETAIL} ({why}); a {row['kind']} job is not re-run: {kind.rule}"
            else:
                detail = (f"{INTERRUPTED_DETAIL} ({why}); its {row['attempts']} runs were all interrupted, "
                          "so it is not re-queued again (it may be what stops the server)")
            changes = {"status": "failed", "finished_at": utc_now(),
                       "error_json": to_json(_interrupted(detail).to_dict())}
            outcome = "failed"
        try:
            done = self.store.update_job(row["id"], **condition, **changes)
        except StorageError as exc:  # the next heartbeat (or start) tries again
            logger.error("job %s: cannot record its interruption: %s", row["id"], exc.detail)
            return False
        if done:
            logger.warning("job %s (%s) %s: %s", row["id"], row["kind"], outcome, why,
                           extra={"job_id": row["id"], "status": changes["status"]})
            if changes["status"] == "queued":
                self._wake.set()
        return done

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

    def _held(self, owner: str | None) -> tuple[int, int]:
        """Places held in this process by heavy requests (:meth:`admit_request`): all, and ``owner``'s."""
        with self._lock:
            held = list(self._requests.values())
        return len(held), sum(1 for key in held if owner is not None and key == owner)

    def admit_request(self, kind: str) -> Callable[[], None]:
        """Hold a place of this admission control for work done in a request, not a job (a heavy batch).

        The place counts toward ``max_active`` and ``max_active_per_key`` as a job does: the jobs of
        the data folder (every process) and the heavy requests this process is serving share one
        bound, and a key's heavy requests count toward its limit. (Heavy requests of other processes
        are bounded by their own ``MICROBEARING_MAX_HEAVY_REQUESTS``.)

        Returns
        -------
        callable
            Frees the place; call it once, when the work (and its streamed answer) is done.

        Raises
        ------
        ProblemError
            503 or 429 with ``Retry-After``, as :meth:`submit`.
        """
        owner = REQUESTER.get().key_id
        token = f"{kind}-{uuid.uuid4().hex}"
        with self._lock:  # reserved first, so that two requests checking at once both count it
            self._requests[token] = owner
        try:
            held, mine = self._held(owner)
            if self.max_active is not None:
                active = self.store.count_active_jobs() + held
                if active > self.max_active:
                    self._refuse("server", active - 1)
            if owner is not None and self.max_active_per_key is not None:
                active = self.store.count_active_jobs(owner) + mine
                if active > self.max_active_per_key:
                    self._refuse("key", active - 1)
        except BaseException:
            self._release_request(token)
            raise
        return lambda: self._release_request(token)

    def _release_request(self, token: str) -> None:
        with self._lock:
            self._requests.pop(token, None)

    def active_count(self) -> int:
        """Queued and running jobs of the data folder, every process's [1]."""
        return self.store.count_active_jobs()

    def submit(self, kind: str, request: dict[str, Any], fn: Callable[[JobContext], dict[str, Any]],
               inputs: dict[str, Any] | None = None) -> dict[str, Any]:
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
        inputs : dict, optional
            JSON-ready inputs from which :attr:`JobKind.build` of ``kind`` rebuilds ``fn`` (see
            :func:`register_kind`). With them the job is stored whole: it stays queued across
            restarts and any process sharing the folder may run it. Without them only this process
            can, and a restart fails it.

        Returns
        -------
        dict
            The job row (see :meth:`get`).

        Raises
        ------
        ProblemError
            503 when the data folder holds ``max_active`` jobs, 429 when the requester's key holds
            ``max_active_per_key``, both with ``Retry-After``; a storage problem when the job
            cannot be recorded.
        """
        if self._stopping.is_set():
            raise ProblemError(503, "The server is shutting down and takes no new jobs; retry on another "
                                    "server process.", title="Server shutting down",
                               headers={"Retry-After": str(RETRY_AFTER_S)})
        job_id = uuid.uuid4().hex
        replayable = inputs is not None and kind in JOB_KINDS
        owner = REQUESTER.get().key_id
        per_key = self.max_active_per_key if owner is not None else None
        held, mine = self._held(owner)  # heavy requests served here hold places too
        with self._lock:  # before the row exists, so that the dispatcher finds the work once it does
            self._local[job_id] = (fn, contextvars.copy_context())
        try:
            refused = self.store.admit_job(
                {"id": job_id, "kind": kind, "status": "queued", "progress": 0.0,
                 "request_json": to_json(request), "owner_pid": os.getpid(), "owner_instance": self.instance,
                 "created_at": utc_now()},
                inputs_json=to_json(inputs) if replayable else None,
                max_active=None if self.max_active is None else max(self.max_active - held, 0),
                max_active_per_key=None if per_key is None else max(per_key - mine, 0))
        except BaseException:
            with self._lock:
                self._local.pop(job_id, None)
            raise
        if refused is not None:
            with self._lock:
                self._local.pop(job_id, None)
            limit, count = refused
            self._refuse(limit, count + (held if limit == "server" else mine))
        # Logged before the job's thread can log "started". That thread runs in a copy of the
        # submitting context: its log lines carry the id of the request that created it.
        logger.info("job %s (%s) queued", job_id, kind, extra={"job_id": job_id, "kind": kind})
        self._wake.set()
        return self.get(job_id)

    def _refuse(self, limit: str, count: int) -> None:
        retry = {"Retry-After": str(RETRY_AFTER_S)}
        if limit == "server":
            logger.warning("refused a job: %d jobs queued or running (MICROBEARING_MAX_ACTIVE_JOBS)", count)
            raise ProblemError(503, f"The server holds {count} queued or running jobs, its limit "
                                    f"(MICROBEARING_MAX_ACTIVE_JOBS={self.max_active}); retry later.",
                               title="Server busy", headers=retry)
        raise ProblemError(429, f"This API key has {count} queued or running jobs, its limit "
                                f"(MICROBEARING_MAX_ACTIVE_JOBS_PER_KEY={self.max_active_per_key}); wait for "
                                "one to finish or cancel one.", title="Too many jobs", headers=retry)

    def get(self, job_id: str, with_result: bool = False) -> dict[str, Any] | None:
        """The job row, or None for an unknown id (``request_json`` and ``result_json`` ``with_result``).

        A final state the store could not take yet is shown as it will be written.
        """
        row = self.store.get_job(job_id, with_result=with_result)
        if row is not None:
            with self._lock:
                row.update(self._unwritten.get(job_id, {}))
        return row

    def list(self, kinds: tuple[str, ...] = (), statuses: tuple[str, ...] = (), limit: int = 20,
             before: tuple[str, str] | None = None) -> list[dict[str, Any]]:
        """The requester's jobs, newest first (:meth:`Store.list_jobs`), shown as :meth:`get` shows them."""
        rows = self.store.list_jobs(kinds, statuses, limit, before)
        with self._lock:
            for row in rows:
                row.update(self._unwritten.get(row["id"], {}))
        return rows

    def delete(self, job_id: str) -> bool:
        """Delete a finished job and its result; returns whether it was deleted."""
        return self.store.delete_job(job_id, FINISHED)

    def cancel(self, job_id: str) -> dict[str, Any] | None:
        """Request cancellation; a queued job is cancelled at once, a running one at its next check.

        Works from any process sharing the data folder: a queued job's place is freed at once (the
        limits count the database), and the process running a job sees the request at its next
        progress report or heartbeat. A running job's work that returns without another check still
        ends the job cancelled.

        Returns
        -------
        dict or None
            The job row after the request, or None for an unknown id (or one deleted meanwhile).
        """
        if self.store.update_job(job_id, only_if_status=("queued",), status="cancelled",
                                 cancel_requested=1, finished_at=utc_now()):
            with self._lock:
                self._local.pop(job_id, None)
            return self.get(job_id)
        self.store.update_job(job_id, only_if_status=("running",), cancel_requested=1)
        with self._lock:
            running = self._running.get(job_id)
        if running is not None:
            running[1].set()
        return self.get(job_id)

    def shutdown(self, grace_s: float | None = None) -> None:
        """Stop: take no more jobs, let running ones finish for a grace period, then re-queue the rest.

        Queued jobs stay queued (for the next start, or another process). Running jobs still
        running after ``grace_s`` (default: ``shutdown_grace_s``) are interrupted and re-queued
        when their inputs are stored, without counting the run (:meth:`_interrupt`); the others
        are failed as interrupted, and so is the queued work that only this process held.

        Parameters
        ----------
        grace_s : float, optional
            Time running jobs may take to finish [s].
        """
        self._stopping.set()
        self._wake.set()
        self._dispatcher.join()
        deadline = time.monotonic() + (self.shutdown_grace_s if grace_s is None else grace_s)
        while time.monotonic() < deadline:
            with self._lock:
                if not self._running:
                    break
            time.sleep(0.02)
        self._interrupting.set()
        with self._lock:
            events = [event for _, event in self._running.values()]
        for event in events:
            event.set()
        # Re-queued now, before waiting for the work to reach its next progress check: a process
        # manager that kills the process meanwhile loses nothing, and the run's late writes are refused.
        self._requeue_own_running()
        self._executor.shutdown(wait=True, cancel_futures=True)
        self._housekeeper.join()
        _LIVE_INSTANCES.discard(self.instance)
        self._requeue_own_running()
        for row in self.store.jobs_with_status("queued"):
            if row["owner_instance"] != self.instance:
                continue
            if not row["replayable"]:
                try:
                    self.store.update_job(row["id"], only_if_status=("queued",), status="failed",
                                          error_json=to_json(_interrupted(NOT_STORED_DETAIL).to_dict()),
                                          finished_at=utc_now())
                except StorageError as exc:  # the next start marks it failed as interrupted
                    logger.error("job %s: cannot record its interruption: %s", row["id"], exc.detail)
        with self._lock:
            self._local.clear()

    def _requeue_own_running(self) -> None:
        try:
            rows = self.store.jobs_with_status("running")
        except StorageError as exc:
            logger.error("cannot read the running jobs to re-queue them: %s", exc.detail)
            return
        for row in rows:
            if row["owner_instance"] == self.instance:
                self._interrupt(row, "the server stopped", graceful=True)

    # dispatching ----------------------------------------------------------------------------

    def _dispatch(self) -> None:
        next_beat = time.monotonic() + self.heartbeat_s
        while not self._stopping.is_set():
            try:
                if time.monotonic() >= next_beat:
                    next_beat = time.monotonic() + self.heartbeat_s
                    self._heartbeat()
                    self.recover()
                while not self._stopping.is_set() and self._claim_one():
                    pass
            except StorageError as exc:  # the disk refuses writes: try again at the next round
                logger.error("job dispatch: %s", exc.detail)
            except Exception:  # never let the dispatcher die: no job would run again in this process
                logger.exception("job dispatch failed; retrying")
            self._wake.wait(max(min(next_beat - time.monotonic(), _CLAIM_POLL_INTERVAL_S), 0.0))
            self._wake.clear()

    def _heartbeat(self) -> None:
        """Renew the leases of this process's running jobs, pass on cancellations, drop claimed work."""
        with self._lock:
            running = dict(self._running)
            local = list(self._local)
        held = self.store.renew_leases([token for token, _ in running.values()], time.time() + self.lease_s)
        with self._lock:  # read after the renewal: a job that ended since the snapshot has its id here
            ending = set(self._ending)
        for job_id, (token, event) in running.items():
            if token not in held and job_id in ending:
                continue  # its final state is written (the row is no longer running), not taken over
            if token not in held:  # another process took the job after our lease lapsed: stop the work
                logger.warning("job %s: this process lost its lease; stopping its run", job_id,
                               extra={"job_id": job_id})
                event.set()
            elif held[token]:
                event.set()
        gone = [job_id for job_id, status in self.store.job_statuses(local).items() if status != "queued"]
        gone += sorted(set(local) - set(self.store.job_statuses(local)))
        with self._lock:
            for job_id in gone:
                if job_id not in self._running:
                    self._local.pop(job_id, None)

    def _claim_one(self) -> bool:
        """Claim and start one queued job if a worker is free; whether one was started."""
        with self._lock:
            if len(self._running) >= self.workers:
                return False
        token = uuid.uuid4().hex
        row = self.store.claim_job(self.instance, os.getpid(), self._kinds(), time.time() + self.lease_s,
                                   token)
        if row is None:
            return False
        event = threading.Event()
        with self._lock:
            self._running[row["id"]] = (token, event)
            local = self._local.pop(row["id"], None)
        if local is not None:
            fn, context = local
            make: Callable[[], Callable[[JobContext], dict[str, Any]]] = lambda: fn  # noqa: E731
        else:
            kind = JOB_KINDS[row["kind"]]
            inputs = json.loads(row["inputs_json"])
            context = contextvars.Context()
            context.run(REQUESTER.set, Requester(row["owner_key"], bool(row["owner_sees_all"])
                                                 or row["owner_key"] is None))
            make = lambda: kind.build(inputs, self.services)  # noqa: E731
        run = f" (run {row['attempts']})" if row["attempts"] > 1 else ""
        self._executor.submit(context.run, self._run, row["id"], token, make, event, run)
        return True

    # running --------------------------------------------------------------------------------

    def _finish(self, job_id: str, token: str, status: str, unless_cancel_requested: bool = False,
                **changes: Any) -> bool:
        with self._lock:
            self._ending.add(job_id)
        finished_at = utc_now()
        try:
            finished = self.store.update_job(job_id, only_if_status=("running",), status=status,
                                             finished_at=finished_at, **changes, only_if_token=token,
                                             unless_cancel_requested=unless_cancel_requested)
        except StorageError as exc:
            if status != "failed" or "result_json" in changes:
                # Most often the result itself did not fit: fail the job with the reason (a small write).
                logger.error("job %s: its final state (%s) could not be stored: %s", job_id, status,
                             exc.detail, extra={"job_id": job_id})
                return self._finish(job_id, token, "failed", error_json=to_json(exc.to_dict()))
            # Not even the failure can be written: keep it in memory, the housekeeping thread retries.
            logger.error("job %s: cannot store its failure either (%s); kept in memory until the store "
                         "takes writes", job_id, exc.detail, extra={"job_id": job_id})
            with self._lock:
                self._unwritten[job_id] = {"status": status, "finished_at": finished_at, **changes}
            finished = True
        if finished:
            logger.info("job %s %s", job_id, status, extra={"job_id": job_id, "status": status})
        return finished

    def _run(self, job_id: str, token: str, make: Callable[[], Callable[[JobContext], dict[str, Any]]],
             event: threading.Event, run: str = "") -> None:
        try:
            self._run_job(job_id, token, make, event, run)
        finally:
            with self._lock:
                self._running.pop(job_id, None)
                self._ending.discard(job_id)
            self._wake.set()  # a worker is free

    def _run_job(self, job_id: str, token: str, make: Callable[[], Callable[[JobContext], dict[str, Any]]],
                 event: threading.Event, run: str = "") -> None:
        ctx = JobContext(job_id, self.store, event, token)
        logger.info("job %s%s started", job_id, run, extra={"job_id": job_id})
        try:
            ctx.check_cancelled()
            result = make()(ctx)
        except Cancelled:
            row = self.store.get_job(job_id)
            if row is None or row["lease_token"] != token:
                return  # deleted, or taken by another process after our lease lapsed: not ours to write
            if row["cancel_requested"]:
                self._finish(job_id, token, "cancelled")
            elif self._interrupting.is_set():  # shutdown: re-queued (or failed) by its rule
                self._interrupt(row, "the server stopped", graceful=True)
            else:
                self._finish(job_id, token, "failed",
                             error_json=to_json(_interrupted(INTERRUPTED_DETAIL).to_dict()))
        except StorageError as fault:
            logger.error("job %s failed: %s", job_id, fault.detail, extra={"job_id": job_id})
            self._finish(job_id, token, "failed", error_json=to_json(fault.to_dict()))
        except ProblemError as problem:
            self._finish(job_id, token, "failed", error_json=to_json(problem.to_dict()))
        except UnstorableError as fault:  # the code's fault, not the request's: 500, logged
            logger.error("job %s failed: %s", job_id, fault, extra={"job_id": job_id})
            problem = ProblemError(500, f"The job's result could not be stored: {fault}", title="Job failed",
                                   type_=INTERNAL_TYPE)
            self._finish(job_id, token, "failed", error_json=to_json(problem.to_dict()))
        except ValueError as exc:
            problem = ProblemError(422, str(exc), title="Invalid job input", type_=VALIDATION_TYPE)
            self._finish(job_id, token, "failed", error_json=to_json(problem.to_dict()))
        except Exception as exc:
            logger.exception("job %s failed", job_id)
            problem = ProblemError(500, f"The job failed: {type(exc).__name__}: {exc}", title="Job failed",
                                   type_=INTERNAL_TYPE)
            self._finish(job_id, token, "failed", error_json=to_json(problem.to_dict()))
        else:
            try:
                encoded = json_bytes(result)
            except (TypeError, ValueError) as exc:
                problem = ProblemError(500, f"The job's result is not finite JSON: {exc}", title="Job failed",
                                       type_=INTERNAL_TYPE)
                self._finish(job_id, token, "failed", error_json=to_json(problem.to_dict()))
                return
            # the model the work stored (a calibration's, a surrogate's), if any: a discarded result takes it
            stored = result.get("id") if isinstance(result, dict) and result.get("model_id") else None
            del result
            if self.max_result_bytes is not None and len(encoded) > self.max_result_bytes:
                problem = ProblemError(413, f"The result has {len(encoded)} bytes of JSON, more than the "
                                            f"limit of {self.max_result_bytes} "
                                            "(MICROBEARING_MAX_RESULT_BYTES); ask for fewer points or "
                                            "outputs, or raise the limit. Nothing of the job is kept (a "
                                            "model it made is deleted).",
                                       title="Result too large")
                self._discard_model(stored)
                self._finish(job_id, token, "failed", error_json=to_json(problem.to_dict()))
                return
            self._succeed(job_id, token, encoded.decode(), stored)

    def _discard_model(self, model_id: str | None) -> None:
        """Delete the model a job stored whose result is not kept (too large, or the job cancelled)."""
        if model_id is not None:
            try:
                self.store.delete_model(model_id)
            except Exception:  # the job's end is written whatever this does; the model stays listed
                logger.exception("the model %s of a discarded result could not be deleted", model_id)

    def _succeed(self, job_id: str, token: str, result_json: str, stored: str | None = None) -> None:
        # A cancellation requested while the work was finishing wins: DELETE answered
        # cancel_requested true, so the job ends cancelled and its result (and model) is discarded.
        if not self._finish(job_id, token, "succeeded", unless_cancel_requested=True, progress=1.0,
                            result_json=result_json):
            self._discard_model(stored)
            self._finish(job_id, token, "cancelled")
