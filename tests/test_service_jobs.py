"""Persistent jobs and stored models: lifecycle, cancellation, failures, restarts, dead owners."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from jobs_helper import wait_until

from microbearing.service.jobs import INTERRUPTED_DETAIL, NOT_STORED_DETAIL, JobContext, JobManager
from microbearing.service.store import SqliteStore, Store, json_bytes, to_json, utc_now


@pytest.fixture
def store(database):
    """The store of a new database, once per backend (SQLite, PostgreSQL: tests/conftest.py)."""
    return database.store()


@pytest.fixture
def manager(store):
    jobs = JobManager(store, workers=2)
    yield jobs
    jobs.shutdown()


def wait(manager: JobManager, job_id: str, timeout_s: float = 20.0) -> dict:
    wait_until(lambda: manager.get(job_id), job_id, timeout_s=timeout_s, interval_s=0.02)
    return manager.get(job_id, with_result=True)


def test_job_result_and_progress_are_stored(manager):
    seen = []
    release = threading.Event()

    def work(ctx: JobContext) -> dict:
        release.wait(10)  # hold the job until its queued/running state is checked
        for i in range(5):
            ctx.progress((i + 1) / 5)
            seen.append(i)
        return {"total": sum(seen), "values": np.arange(3.0)}

    job = manager.submit("sum", {"n": 5}, work)
    assert job["status"] in ("queued", "running") and job["owner_pid"] == os.getpid()
    release.set()
    row = wait(manager, job["id"])
    assert row["status"] == "succeeded" and row["progress"] == 1.0
    assert json.loads(row["result_json"]) == {"total": 10, "values": [0.0, 1.0, 2.0]}
    assert json.loads(row["request_json"]) == {"n": 5}
    assert row["started_at"] <= row["finished_at"]


@pytest.mark.parametrize(("error", "status", "text"), [
    (ValueError("load_N must be > 0 [N]"), 422, "load_N must be > 0"),
    (RuntimeError("boom"), 500, "RuntimeError: boom"),
])
def test_failures_are_stored_as_problems(manager, error, status, text):
    def work(ctx: JobContext) -> dict:
        raise error

    row = wait(manager, manager.submit("failing", {}, work)["id"])
    problem = json.loads(row["error_json"])
    assert row["status"] == "failed" and row["result_json"] is None
    assert problem["status"] == status and text in problem["detail"]


def test_a_result_json_cannot_hold_fails_the_job(manager):
    row = wait(manager, manager.submit("nan", {}, lambda ctx: {"x": float("nan")})["id"])
    assert row["status"] == "failed" and "not finite JSON" in json.loads(row["error_json"])["detail"]


def test_a_model_the_store_cannot_keep_fails_the_job_as_the_server_s_fault(manager, store):
    # a work storing metadata JSON cannot hold (the two-label factor's open spread did) is a 500 of the
    # server, logged, never the request's 422
    def work(ctx: JobContext) -> dict:
        return {"id": store.save_model("calibration", {"spread_high": float("inf")}, {})}

    row = wait(manager, manager.submit("unstorable", {}, work)["id"])
    problem = json.loads(row["error_json"])
    assert row["status"] == "failed" and problem["status"] == 500, problem
    assert "could not be stored" in problem["detail"] and "not strict JSON" in problem["detail"], problem
    assert store.list_models("calibration") == []


def test_cancelling_a_running_job(manager):
    started = threading.Event()

    def work(ctx: JobContext) -> dict:
        started.set()
        while True:
            ctx.progress(0.5)
            time.sleep(0.01)

    job = manager.submit("forever", {}, work)
    assert started.wait(10)
    assert manager.cancel(job["id"])["cancel_requested"] == 1
    row = wait(manager, job["id"])
    assert row["status"] == "cancelled" and row["result_json"] is None


def test_a_cancel_arriving_as_the_work_returns_still_cancels(manager):
    # the work never checks again after the request: without a final check it would succeed
    started, cancelled = threading.Event(), threading.Event()

    def work(ctx: JobContext) -> dict:
        started.set()
        cancelled.wait(10)
        return {"done": True}

    job = manager.submit("late", {}, work)
    assert started.wait(10)
    assert manager.get(job["id"])["status"] == "running"
    assert manager.cancel(job["id"])["cancel_requested"] == 1
    cancelled.set()
    row = wait(manager, job["id"])
    assert row["status"] == "cancelled" and row["result_json"] is None and row["progress"] < 1.0


def test_cancel_requested_by_another_server_process_is_seen(store, manager):
    started = threading.Event()

    def work(ctx: JobContext) -> dict:
        started.set()
        while True:
            ctx.check_cancelled()
            time.sleep(0.01)

    job = manager.submit("forever", {}, work)
    assert started.wait(10)
    other = JobManager(store, workers=1)  # a second worker process sharing the database
    try:
        other.cancel(job["id"])
        assert wait(manager, job["id"])["status"] == "cancelled"
    finally:
        other.shutdown()


def test_cancelling_a_queued_job_is_immediate(store):
    single = JobManager(store, workers=1)
    release = threading.Event()
    try:
        blocker = single.submit("block", {}, lambda ctx: {"released": release.wait(10)})
        queued = single.submit("never", {}, lambda ctx: {"ran": True})
        assert single.cancel(queued["id"])["status"] == "cancelled"
        release.set()
        assert wait(single, blocker["id"])["status"] == "succeeded"
        assert wait(single, queued["id"])["status"] == "cancelled"
    finally:
        release.set()
        single.shutdown()


def _insert_active(store: Store, job_id: str, pid: int, instance: str, status: str = "running") -> None:
    store.insert_job(id=job_id, kind="sweep", status=status, progress=0.3, request_json="{}",
                     owner_pid=pid, owner_instance=instance, created_at=utc_now())


def _dead_pid() -> int:
    process = subprocess.Popen([sys.executable, "-c", "pass"])
    process.wait()
    return process.pid


def test_startup_fails_jobs_of_dead_processes_only(store):
    _insert_active(store, "dead", _dead_pid(), "gone")
    _insert_active(store, "dead-queued", _dead_pid(), "gone", status="queued")
    _insert_active(store, "same-pid-old-instance", os.getpid(), "a previous app in this process")
    _insert_active(store, "live-process", os.getppid(), "another worker")
    manager = JobManager(store, workers=1)  # what a server does at startup
    try:
        for job_id in ("dead", "dead-queued", "same-pid-old-instance"):
            row = store.get_job(job_id)
            assert row["status"] == "failed", job_id
            # Their inputs were not stored (no kind and inputs): they cannot run again.
            expected = NOT_STORED_DETAIL if job_id == "dead-queued" else INTERRUPTED_DETAIL
            assert json.loads(row["error_json"])["detail"] == expected
        assert store.get_job("live-process")["status"] == "running"
    finally:
        manager.shutdown()


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="process start times come from Linux /proc")
def test_a_reused_pid_does_not_keep_a_dead_servers_jobs_running(store):
    # The parent process is alive, but an instance id recording another start time belongs to a
    # process that used to have its pid.
    parent = os.getppid()
    started = Path(f"/proc/{parent}/stat").read_text().rpartition(")")[2].split()[19]
    _insert_active(store, "reused-pid", parent, f"{'0' * 32}.{int(started) + 1}")
    _insert_active(store, "same-process", parent, f"{'1' * 32}.{started}")
    manager = JobManager(store, workers=1)
    try:
        assert store.get_job("reused-pid")["status"] == "failed"
        assert store.get_job("same-process")["status"] == "running"
        own_start = Path("/proc/self/stat").read_text().rpartition(")")[2].split()[19]
        assert manager.instance.split(".")[1] == own_start
    finally:
        manager.shutdown()


def test_a_job_of_another_host_is_judged_by_its_lease_not_by_a_local_pid(store):
    # On a shared PostgreSQL database a pid means nothing on another host: a job owned there with a
    # pid that is dead here stays running while its lease holds, and ends once it lapses (failed
    # here: its work was not stored).
    from microbearing.service.jobs import _HOST

    other_host = "0" * 16 if _HOST != "0" * 16 else "1" * 16
    _insert_active(store, "elsewhere", _dead_pid(), f"{'2' * 32}.12345.{other_host}")
    store.update_job("elsewhere", lease_token="t", lease_expires=time.time() + 3600)
    _insert_active(store, "here", _dead_pid(), f"{'3' * 32}.12345.{_HOST}")
    manager = JobManager(store, workers=1)
    try:
        assert store.get_job("elsewhere")["status"] == "running"
        assert store.get_job("here")["status"] == "failed"  # this host's pid check still works
        store.update_job("elsewhere", lease_expires=time.time() - 1)
        assert manager.recover() == ["elsewhere"]
        row = store.get_job("elsewhere")
        assert row["status"] == "failed" and json.loads(row["error_json"])["detail"] == INTERRUPTED_DETAIL
    finally:
        manager.shutdown()


def test_shutdown_marks_running_jobs_interrupted(store):
    manager = JobManager(store, workers=1)
    started = threading.Event()

    def work(ctx: JobContext) -> dict:
        started.set()
        while True:
            ctx.progress(0.1)
            time.sleep(0.01)

    job = manager.submit("forever", {}, work)
    assert started.wait(10)
    manager.shutdown()
    row = store.get_job(job["id"])
    assert row["status"] == "failed" and json.loads(row["error_json"])["detail"] == INTERRUPTED_DETAIL


def test_models_round_trip_without_pickle(store, database):
    weights = np.arange(6.0).reshape(2, 3)
    model_id = store.save_model("surrogate", {"inputs": ["load_N"], "r2": 0.99},
                                {"weights": weights, "names": np.array(["a", "b"])}, name="demo")
    reopened = database.store()  # another connection, as after a restart or in another process
    try:
        stored = reopened.load_model(model_id)
        assert stored.kind == "surrogate" and stored.name == "demo"
        assert stored.metadata == {"inputs": ["load_N"], "r2": 0.99}
        np.testing.assert_array_equal(stored.arrays["weights"], weights)
        assert stored.arrays["names"].tolist() == ["a", "b"]
        assert [m["id"] for m in reopened.list_models("surrogate")] == [model_id]
        assert reopened.list_models("calibration") == []
        assert reopened.delete_model(model_id) and reopened.load_model(model_id) is None
    finally:
        reopened.close()
    with pytest.raises(ValueError, match="object"):
        store.save_model("bad", {}, {"things": np.array([{"a": 1}], dtype=object)})
    with pytest.raises(ValueError):
        to_json({"x": float("inf")})


def test_fast_json_is_exact_and_strict():
    values = np.random.default_rng(0).lognormal(-5, 8, 10_000)
    document = {"mu": values, "note": "NaN and Infinity are fine inside strings", "count": np.int64(3)}
    decoded = json.loads(json_bytes(document))
    assert decoded["mu"] == values.tolist() and decoded["count"] == 3 and decoded["note"] == document["note"]
    for bad in ({"x": float("nan")}, {"x": np.array([1.0, -np.inf])}):
        with pytest.raises(ValueError):
            json_bytes(bad)
    with pytest.raises(TypeError):
        json_bytes({"x": object()})


def test_the_sqlite_database_uses_wal(tmp_path):
    store = Store(tmp_path)
    try:
        assert store.connection().execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    finally:
        store.close()


def test_a_status_read_does_not_load_the_result(store, manager):
    # a 1M-point sweep's result is tens of megabytes; polling the status must not read it
    row = wait(manager, manager.submit("big", {"n": 1}, lambda ctx: {"values": np.zeros(1000)})["id"])
    status = manager.get(row["id"])
    assert "result_json" not in status and "request_json" not in status
    assert status["status"] == "succeeded" and status["progress"] == 1.0 and status["cancel_requested"] == 0
    assert {k: v for k, v in row.items() if k not in ("result_json", "request_json")} == status
    assert json.loads(row["result_json"]) == {"values": [0.0] * 1000}
    assert all("result_json" not in r for r in store.jobs_with_status("succeeded"))


def test_a_result_stored_in_the_jobs_row_by_an_older_version_is_still_served(store):
    store.insert_job(id="old", kind="sweep", status="succeeded", progress=1.0, request_json="{}",
                     result_json='{"columns": {"mu": [0.1]}}', owner_pid=1, owner_instance="gone",
                     created_at=utc_now())
    assert json.loads(store.get_job("old", with_result=True)["result_json"]) == {"columns": {"mu": [0.1]}}
    assert "result_json" not in store.get_job("old")


# admission, retention, result size, storage faults -------------------------------------------

def blocked_manager(store: Store, **limits) -> tuple[JobManager, threading.Event]:
    """A manager of one worker whose jobs wait for the returned event."""
    release = threading.Event()
    return JobManager(store, workers=1, **limits), release


def test_a_full_server_refuses_jobs_with_503_and_a_key_past_its_share_with_429(store):
    from microbearing.service.problems import ProblemError
    from microbearing.service.store import REQUESTER, Requester

    jobs, release = blocked_manager(store, max_active=3, max_active_per_key=2)
    try:
        def hold(ctx: JobContext) -> dict:
            release.wait(20)
            return {}

        def submit_as(key_id: str, count: int) -> tuple[list[str], ProblemError | None]:
            """Submit ``count`` jobs as a key; the ids accepted and the first refusal."""
            token = REQUESTER.set(Requester(key_id, sees_all=False))
            ids = []
            try:
                for _ in range(count):
                    ids.append(jobs.submit("hold", {}, hold)["id"])
            except ProblemError as refusal:
                return ids, refusal
            finally:
                REQUESTER.reset(token)
            return ids, None

        first, refused = submit_as("alpha", 3)
        assert len(first) == 2 and refused.status == 429 and int(refused.headers["Retry-After"]) > 0
        assert "MICROBEARING_MAX_ACTIVE_JOBS_PER_KEY=2" in refused.detail
        other, full = submit_as("beta", 2)  # another key still has room, until the server is full
        assert len(other) == 1 and full.status == 503 and int(full.headers["Retry-After"]) > 0
        assert "MICROBEARING_MAX_ACTIVE_JOBS=3" in full.detail
        assert jobs.active_count() == 3
        # Cancelling a queued job frees its place at once; finished jobs free theirs. The one worker
        # takes jobs in order and the first holds it, so the second is queued whenever we look.
        assert jobs.cancel(first[1])["status"] == "cancelled"
        assert jobs.active_count() == 2
        release.set()
        for job_id in first:
            wait(jobs, job_id)
        deadline = time.monotonic() + 20
        while jobs.active_count():
            assert time.monotonic() < deadline
            time.sleep(0.02)
        assert store.jobs_with_status("queued", "running") == []
    finally:
        release.set()
        jobs.shutdown()


def test_a_result_past_the_size_limit_fails_the_job_with_413(store):
    jobs = JobManager(store, workers=1, max_result_bytes=10_000)
    try:
        small = jobs.submit("small", {}, lambda ctx: {"values": [0.5] * 100})
        large = jobs.submit("large", {}, lambda ctx: {"values": [0.5] * 10_000})  # 40 kB of JSON
        assert wait(jobs, small["id"])["status"] == "succeeded"
        row = wait(jobs, large["id"])
        problem = json.loads(row["error_json"])
        assert row["status"] == "failed" and row["result_json"] is None
        assert problem["status"] == 413 and "MICROBEARING_MAX_RESULT_BYTES" in problem["detail"]
        assert str(len(json_bytes({"values": [0.5] * 10_000}))) in problem["detail"]
    finally:
        jobs.shutdown()


def insert_finished(store: Store, job_id: str, finished_at: str, status: str = "succeeded") -> None:
    store.insert_job(id=job_id, kind="sweep", status=status, progress=1.0, request_json="{}",
                     owner_pid=os.getpid(), owner_instance="old", created_at=finished_at,
                     finished_at=finished_at)
    store.update_job(job_id, result_json='{"columns": {}}')


def test_finished_jobs_expire_after_the_retention_and_active_ones_never(store):
    insert_finished(store, "old", "2020-01-01T00:00:00.000Z")
    insert_finished(store, "old-failed", "2020-01-01T00:00:00.000Z", status="failed")
    insert_finished(store, "recent", utc_now())
    store.insert_job(id="stuck", kind="sweep", status="running", progress=0.5, request_json="{}",
                     owner_pid=os.getpid(), owner_instance="x", created_at="2020-01-01T00:00:00.000Z")
    jobs = JobManager(store, workers=1, retention_s=3600.0)  # purges at start
    try:
        assert store.get_job("old") is None and store.get_job("old-failed") is None
        assert store.get_job("recent", with_result=True)["result_json"] == '{"columns": {}}'
        with store.transaction() as conn:
            count = conn.execute("SELECT COUNT(*) AS n FROM job_results WHERE id LIKE 'old%'").fetchone()["n"]
        assert count == 0  # results go with their jobs
        assert store.get_job("stuck")["status"] == "failed"  # recovered as interrupted, kept: just finished
    finally:
        jobs.shutdown()
    short = JobManager(store, workers=1, retention_s=0.3)  # the housekeeping thread purges while it runs
    try:
        job = short.submit("quick", {}, lambda ctx: {"ok": True})
        assert wait(short, job["id"])["status"] == "succeeded"
        deadline = time.monotonic() + 30
        while short.get(job["id"]) is not None:
            assert time.monotonic() < deadline, "the finished job did not expire"
            time.sleep(0.05)
    finally:
        short.shutdown()


def test_deleting_a_job_needs_it_finished(manager, store):
    release = threading.Event()
    job = manager.submit("hold", {}, lambda ctx: release.wait(20) and {})
    assert not manager.delete(job["id"])  # active: cancel it instead
    release.set()
    wait(manager, job["id"])
    assert manager.delete(job["id"]) and manager.get(job["id"]) is None


class LimitedStore(SqliteStore):
    """A store whose database cannot grow past ``max_pages`` pages: SQLite's own "disk full"."""

    max_pages = 0

    def connection(self):
        conn = getattr(self._local, "conn", None)
        fresh = super().connection()
        if conn is None and self.max_pages:
            fresh.execute(f"PRAGMA max_page_count = {self.max_pages}")
        return fresh


def test_a_full_database_fails_the_job_with_the_reason_at_error(tmp_path, caplog):
    store = LimitedStore(tmp_path)
    store.max_pages = store.connection().execute("PRAGMA page_count").fetchone()[0] + 8
    jobs = JobManager(store, workers=1)
    try:
        with caplog.at_level("ERROR", logger="microbearing.service.jobs"):
            job = jobs.submit("big", {}, lambda ctx: {"values": np.arange(100_000.0)})  # ~1 MB > 8 pages
            row = wait(jobs, job["id"])
        problem = json.loads(row["error_json"])
        assert row["status"] == "failed" and row["result_json"] is None
        assert problem["status"] == 507 and "the disk is full" in problem["detail"]
        assert str(store.path) in problem["detail"]
        assert any(job["id"] in record.getMessage() and "disk is full" in record.getMessage()
                   for record in caplog.records if record.levelname == "ERROR")
        small = jobs.submit("small", {}, lambda ctx: {"ok": 1})  # the store still takes small writes
        assert wait(jobs, small["id"])["status"] == "succeeded"
        # A model too large for the disk, saved by a job (a surrogate or a calibration): the same.
        rng = np.random.default_rng(0)
        weights = {"w": rng.random(100_000)}  # 0.8 MB, incompressible
        model = jobs.submit("model", {}, lambda ctx: {"id": store.save_model("m", {}, weights)})
        problem = json.loads(wait(jobs, model["id"])["error_json"])
        assert problem["status"] == 507 and "the disk is full" in problem["detail"]
        assert store.list_models("m") == []
    finally:
        jobs.shutdown()
        store.close()


def test_a_store_refusing_every_write_still_ends_the_job(store, monkeypatch, caplog):
    from microbearing.service.store import StorageError

    jobs = JobManager(store, workers=1)
    release = threading.Event()
    original = store.update_job
    try:
        job = jobs.submit("hold", {}, lambda ctx: release.wait(20) and {"ok": 1})
        deadline = time.monotonic() + 20
        while jobs.get(job["id"])["status"] != "running":
            assert time.monotonic() < deadline
            time.sleep(0.01)

        def read_only(*args, **kwargs):
            raise StorageError("the database is read-only", store.path)

        monkeypatch.setattr(store, "update_job", read_only)
        with caplog.at_level("ERROR", logger="microbearing.service.jobs"):
            release.set()
            deadline = time.monotonic() + 20
            while (row := jobs.get(job["id"]))["status"] == "running":
                assert time.monotonic() < deadline, "the job stayed running"
                time.sleep(0.01)
        assert row["status"] == "failed" and "read-only" in json.loads(row["error_json"])["detail"]
        assert store.get_job(job["id"])["status"] == "running"  # not stored yet: shown from memory
        assert any(record.levelname == "ERROR" for record in caplog.records)
        monkeypatch.setattr(store, "update_job", original)  # the disk takes writes again
        deadline = time.monotonic() + 30
        while store.get_job(job["id"])["status"] != "failed":
            assert time.monotonic() < deadline, "the final state was never written"
            time.sleep(0.05)
    finally:
        release.set()
        jobs.shutdown()



def test_a_job_ending_between_heartbeats_is_not_said_to_have_lost_its_lease(store, monkeypatch, caplog):
    """Between a job's final write and the end of its run the row is no longer running under its token:
    a heartbeat in that window renews nothing for it, which is the job's own end, not a takeover (a
    loaded bench logged "this process lost its lease" for jobs that had just succeeded)."""
    renewed_after_end: list[list[str]] = []
    ended = threading.Event()
    real_update, real_renew = store.update_job, store.renew_leases

    def update_then_linger(job_id, **changes):
        done = real_update(job_id, **changes)
        if changes.get("status") == "succeeded":
            ended.set()
            time.sleep(2.5)  # the run ends 2.5 s after its final write: heartbeats (each 1 s) fall between
        return done

    def renew(tokens, lease_expires):
        if ended.is_set():
            renewed_after_end.append(list(tokens))
        return real_renew(tokens, lease_expires)

    monkeypatch.setattr(store, "update_job", update_then_linger)
    monkeypatch.setattr(store, "renew_leases", renew)
    jobs = JobManager(store, workers=1, lease_s=3.0)
    try:
        with caplog.at_level("WARNING", logger="microbearing.service.jobs"):
            job = jobs.submit("quick", {}, lambda ctx: {"ok": 1})
            assert ended.wait(20)
            deadline = time.monotonic() + 20
            while jobs.get(job["id"])["status"] == "running" or not renewed_after_end:
                assert time.monotonic() < deadline
                time.sleep(0.05)
            time.sleep(2.6)  # the run's end
        assert any(len(tokens) == 1 for tokens in renewed_after_end)  # a heartbeat asked for the ended job
        assert jobs.get(job["id"])["status"] == "succeeded"
        assert not [r for r in caplog.records if "lost its lease" in r.getMessage()]
    finally:
        jobs.shutdown()

def test_an_adaptive_fit_reports_progress_in_proportion_to_its_fitting_work():
    from microbearing.surrogate import SamplingPlan, Space, fit_adaptive

    space = Space({"load_N": (0.001, 0.05), "speed_m_s": (0.001, 0.2)}, fixed={"balls": 6})
    fractions = []
    fit = fit_adaptive(space, budget=22, target_relative_error=1e-12,
                       plan=SamplingPlan(initial_size=10, batch_size=5, n_candidates=256),
                       progress=fractions.append)
    sizes = [h["n_train"] for h in fit.history]
    assert sizes == [10, 15, 20, 22]
    # A fit on n points costs about n^3: by hand, 10^3 / (10^3 + 15^3 + 20^3 + 22^3) after the first.
    total = 10**3 + 15**3 + 20**3 + 22**3
    expected = [10**3 / total, (10**3 + 15**3) / total, (10**3 + 15**3 + 20**3) / total, 1.0]
    assert fractions == pytest.approx(expected, rel=1e-12)


def test_the_store_rebuilds_a_model_once_for_its_owner_and_forgets_it_when_deleted(database):
    from microbearing.service.store import REQUESTER, Requester

    store = database.store(rebuilt_models=2)
    builds = []

    def rebuild(stored):
        builds.append(stored.id)
        return {"weights": stored.arrays["w"].tolist()}

    def as_key(key_id, call):
        token = REQUESTER.set(Requester(key_id, sees_all=False))
        try:
            return call()
        finally:
            REQUESTER.reset(token)

    try:
        ids = [as_key("alpha", lambda i=i: store.save_model("toy", {}, {"w": np.array([i])}))
               for i in range(3)]
        first = as_key("alpha", lambda: store.rebuilt(ids[0], "toy", rebuild))
        assert first == {"weights": [0]}
        assert as_key("alpha", lambda: store.rebuilt(ids[0], "toy", rebuild)) is first  # kept, not rebuilt
        assert builds == [ids[0]]
        # Kept or not, another key does not see alpha's model, nor does anyone see it under another kind.
        assert as_key("beta", lambda: store.rebuilt(ids[0], "toy", rebuild)) is None
        assert store.rebuilt(ids[0], "other", rebuild) is None
        # Two are kept: rebuilding the second and third pushes the first out.
        for model_id in ids[1:]:
            store.rebuilt(model_id, "toy", rebuild)
        store.rebuilt(ids[0], "toy", rebuild)
        assert builds == [ids[0], ids[1], ids[2], ids[0]]
        # Deleted through any store on the folder (another process's, say), it is gone from this one too.
        other = database.store()
        assert other.delete_model(ids[0])
        assert store.rebuilt(ids[0], "toy", rebuild) is None
    finally:
        store.close()
