"""Claiming, leases and the per-kind rule for interrupted runs, with several job managers on one folder.

Each manager stands for a server process (its own store connection, its own instance); the
database is all they share. Kinds registered here rebuild their work from the stored inputs.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections import Counter

import pytest
from jobs_helper import wait_until

from microbearing.service.jobs import JOB_KINDS, MAX_ATTEMPTS, JobContext, JobManager, register_kind
from microbearing.service.store import Store, utc_now

RAN: list[tuple[str, str]] = []  # (job id, how its work was obtained)
_ran_lock = threading.Lock()


def _record(ctx: JobContext, how: str, inputs: dict) -> dict:
    time.sleep(inputs.get("sleep_s", 0.0))
    with _ran_lock:
        RAN.append((ctx.job_id, how))
    return {"square": inputs["n"] ** 2, "how": how}


@pytest.fixture(autouse=True)
def kinds():
    register_kind("square",
                  lambda inputs, services: lambda ctx: _record(ctx, f"rebuilt by {services}", inputs))
    register_kind("fragile", lambda inputs, services: lambda ctx: {"ok": True}, requeue=False,
                  rule="it is not idempotent")
    RAN.clear()
    yield
    JOB_KINDS.pop("square", None)
    JOB_KINDS.pop("fragile", None)


def wait(manager: JobManager, job_id: str, statuses=("succeeded", "failed", "cancelled"),
         timeout_s: float = 30.0) -> dict:
    return wait_until(lambda: manager.get(job_id, with_result=True), job_id, statuses, timeout_s, 0.02)


def _dead_pid() -> int:
    process = subprocess.Popen([sys.executable, "-c", "pass"])
    process.wait()
    return process.pid


def test_each_stored_job_runs_exactly_once_among_four_processes(database):
    stores = [database.store() for _ in range(4)]
    managers = [JobManager(store, workers=1 if i == 0 else 2, services=f"manager {i}")
                for i, store in enumerate(stores)]
    try:
        ids = {}
        for n in range(40):
            inputs = {"n": n, "sleep_s": 0.05}
            work = lambda ctx, inputs=inputs: _record(ctx, "closure", inputs)  # noqa: E731
            job = managers[0].submit("square", {"n": n}, work, inputs=inputs)
            ids[job["id"]] = n
        for job_id, n in ids.items():
            row = wait(managers[0], job_id)
            assert row["status"] == "succeeded" and json.loads(row["result_json"])["square"] == n ** 2
            assert row["attempts"] == 1
        runs = Counter(job_id for job_id, _ in RAN)
        assert set(runs) == set(ids) and set(runs.values()) == {1}  # every job, once
        assert len({how for _, how in RAN}) >= 2  # the submitter's one worker did not run them all
    finally:
        for manager in managers:
            manager.shutdown()
        for store in stores:
            store.close()


def test_a_lapsed_lease_is_taken_over_and_the_old_run_writes_nothing(database):
    first_store, second_store = database.store(), database.store()
    first = JobManager(first_store, workers=1, services="first", lease_s=60.0)
    release, inside = threading.Event(), threading.Event()
    second = None
    try:
        def held(ctx: JobContext) -> dict:
            inside.set()
            release.wait(30)
            return {"square": -1, "how": "the stalled first run"}

        job = first.submit("square", {"n": 3}, held, inputs={"n": 3})
        # Wait for the work itself, not only the claim: a run that has not passed its first
        # cancellation check yet would see the takeover, stop, and free the first process's worker,
        # which may then claim the re-queued job itself (correct, but not the case tested here).
        assert inside.wait(30)
        # The first process stops renewing (as if stalled): its lease lapses.
        with first_store.transaction() as conn:
            conn.execute("UPDATE jobs SET lease_expires = 0 WHERE id = ?", (job["id"],))
        second = JobManager(second_store, workers=1, services="second", lease_s=60.0)  # recovers at start
        row = wait(second, job["id"])
        assert row["status"] == "succeeded" and row["attempts"] == 2
        assert row["owner_instance"] == second.instance
        assert json.loads(row["result_json"]) == {"square": 9, "how": "rebuilt by second"}
        release.set()  # the stalled run ends now: its claim is gone, so it changes nothing
        time.sleep(0.5)
        result = second.get(job["id"], with_result=True)["result_json"]
        assert json.loads(result)["how"] == "rebuilt by second"
    finally:
        release.set()
        first.shutdown()
        if second is not None:
            second.shutdown()
        first_store.close()
        second_store.close()


def _insert_running(store: Store, job_id: str, kind: str, attempts: int, inputs: dict | None,
                    cancel_requested: int = 0) -> None:
    store.admit_job({"id": job_id, "kind": kind, "status": "queued", "progress": 0.0,
                     "request_json": "{}", "owner_pid": _dead_pid(), "owner_instance": "gone",
                     "created_at": utc_now()}, inputs_json=None if inputs is None else json.dumps(inputs))
    store.update_job(job_id, status="running", started_at=utc_now(), attempts=attempts,
                     lease_token=f"token-{job_id}", lease_expires=time.time() + 3600,
                     cancel_requested=cancel_requested)


def test_an_interrupted_run_follows_the_rule_of_its_kind(database):
    store = database.store()
    _insert_running(store, "first-run", "square", 1, {"n": 4})
    _insert_running(store, "second-run", "square", MAX_ATTEMPTS, {"n": 5})
    _insert_running(store, "not-idempotent", "fragile", 1, {})
    _insert_running(store, "cancel-asked", "square", 1, {"n": 6}, cancel_requested=1)
    _insert_running(store, "no-inputs", "square", 1, None)
    manager = JobManager(store, workers=1, services="restarted")  # the owner is dead: found at start
    try:
        row = wait(manager, "first-run")
        assert row["status"] == "succeeded" and row["attempts"] == 2
        assert json.loads(row["result_json"]) == {"square": 16, "how": "rebuilt by restarted"}
        details = {job_id: json.loads(manager.get(job_id)["error_json"] or "null")
                   for job_id in ("second-run", "not-idempotent", "no-inputs")}
        assert "not re-queued again" in details["second-run"]["detail"]
        assert "its server process is gone" in details["second-run"]["detail"]
        assert "a fragile job is not re-run: it is not idempotent" in details["not-idempotent"]["detail"]
        assert details["no-inputs"]["detail"].startswith("interrupted")
        assert manager.get("cancel-asked")["status"] == "cancelled"
        assert {job_id for job_id, _ in RAN} == {"first-run"}
    finally:
        manager.shutdown()
        store.close()


def test_shutdown_re_queues_a_running_stored_job_without_counting_the_run(database):
    store = database.store()
    manager = JobManager(store, workers=1, services="first")
    started = threading.Event()

    def forever(ctx: JobContext) -> dict:
        started.set()
        while True:
            ctx.progress(0.5)
            time.sleep(0.01)

    job = manager.submit("square", {"n": 7}, forever, inputs={"n": 7})
    queued = manager.submit("square", {"n": 8}, forever, inputs={"n": 8})
    closure_only = manager.submit("square", {"n": 9}, forever)  # no inputs: cannot outlive the process
    assert started.wait(10)
    manager.shutdown(grace_s=0.2)
    assert (store.get_job(job["id"])["status"], store.get_job(job["id"])["attempts"]) == ("queued", 0)
    assert (store.get_job(queued["id"])["status"], store.get_job(queued["id"])["attempts"]) == ("queued", 0)
    assert store.get_job(closure_only["id"])["status"] == "failed"
    restarted = JobManager(store, workers=2, services="second")
    try:
        for job_id, n in ((job["id"], 7), (queued["id"], 8)):
            row = wait(restarted, job_id)
            assert row["status"] == "succeeded" and row["attempts"] == 1
            assert json.loads(row["result_json"]) == {"square": n * n, "how": "rebuilt by second"}
    finally:
        restarted.shutdown()
        store.close()


def test_a_shutdown_waits_for_a_job_that_ends_within_the_grace_period(database):
    store = database.store()
    manager = JobManager(store, workers=1, services="first", shutdown_grace_s=10.0)
    job = manager.submit("square", {"n": 2}, lambda ctx: _record(ctx, "closure", {"n": 2, "sleep_s": 0.5}),
                         inputs={"n": 2})
    wait(manager, job["id"], ("running",))
    started = time.monotonic()
    manager.shutdown()
    assert time.monotonic() - started < 10.0
    row = store.get_job(job["id"])
    assert row["status"] == "succeeded" and row["attempts"] == 1
    store.close()


@pytest.mark.skipif(not os.path.exists("/proc/self/stat"), reason="process states come from Linux /proc")
def test_a_killed_process_not_yet_reaped_counts_as_gone():
    from microbearing.service.jobs import _owner_alive

    process = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        assert _owner_alive(process.pid, "another server")
        os.kill(process.pid, signal.SIGKILL)
        deadline = time.monotonic() + 10
        while _owner_alive(process.pid, "another server"):  # a zombie until waited for: still gone
            assert time.monotonic() < deadline
            time.sleep(0.01)
        assert process.poll() is not None  # reaped only now
    finally:
        process.kill()
        process.wait()


def test_shutdown_re_queues_before_the_work_reaches_its_next_check(database):
    store = database.store()
    manager = JobManager(store, workers=1, services="first")
    started, release = threading.Event(), threading.Event()

    def deaf(ctx: JobContext) -> dict:  # a long step that checks nothing (a model fit)
        started.set()
        release.wait(30)
        ctx.progress(0.5)
        return {"square": -1, "how": "too late"}

    job = manager.submit("square", {"n": 3}, deaf, inputs={"n": 3})
    assert started.wait(10)
    stopping = threading.Thread(target=manager.shutdown, kwargs={"grace_s": 0.0})
    stopping.start()
    try:
        deadline = time.monotonic() + 10
        while store.get_job(job["id"])["status"] != "queued":  # a kill now would lose nothing
            assert time.monotonic() < deadline
            time.sleep(0.01)
        assert stopping.is_alive()  # still waiting for the work
    finally:
        release.set()
        stopping.join(30)
    row = store.get_job(job["id"], with_result=True)
    # Its late end wrote nothing.
    assert (row["status"], row["attempts"], row["result_json"]) == ("queued", 0, None)
    store.close()


def test_a_run_that_lost_its_claim_writes_no_progress_and_stops(database):
    from microbearing.service.jobs import Cancelled

    store = database.store()
    try:
        store.admit_job({"id": "j", "kind": "square", "status": "queued", "progress": 0.0,
                         "request_json": "{}", "owner_pid": os.getpid(), "owner_instance": "me",
                         "created_at": utc_now()},
                        inputs_json='{"n": 1}')
        first = store.claim_job("me", os.getpid(), ("square",), time.time() + 60, "first-claim")
        assert first["id"] == "j" and first["lease_token"] == "first-claim"
        store.update_job("j", status="queued")  # its lease lapsed and it was queued again ...
        assert store.claim_job("other", 1, ("square",), time.time() + 60, "second-claim")["id"] == "j"
        old = JobContext("j", store, threading.Event(), "first-claim")  # ... and claimed by another
        old._last_poll = -1e9
        with pytest.raises(Cancelled):
            old.progress(0.9)
        assert not store.update_job("j", only_if_token="first-claim", progress=0.9)
        row = store.get_job("j")
        assert (row["progress"], row["lease_token"], row["attempts"]) == (0.0, "second-claim", 2)
    finally:
        store.close()
