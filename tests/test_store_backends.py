"""The store's contract on both backends (SQLite and a real PostgreSQL server), under contention.

Each ``database.store()`` is another connection to one database, as another server process (or,
with PostgreSQL, another host) has: admission limits, claims, cancels and models must hold across
them while many threads hit them at once. Then what only PostgreSQL has: the choice by setting,
the missing driver, and a server that stops and comes back (503, then served again).
"""

from __future__ import annotations

import json
import os
import sys
import threading
import time
from collections import Counter

import numpy as np
import pytest

from microbearing.service.store import REQUESTER, Requester, StorageError, utc_now


def _row(job_id: str) -> dict:
    return {"id": job_id, "kind": "square", "status": "queued", "progress": 0.0, "request_json": "{}",
            "owner_pid": os.getpid(), "owner_instance": "test", "created_at": utc_now()}


def _at_once(count: int, target) -> list:
    """Run ``target(i)`` in ``count`` threads released together; their results in order."""
    results: list = [None] * count
    barrier = threading.Barrier(count)

    def run(i: int) -> None:
        barrier.wait()
        results[i] = target(i)

    threads = [threading.Thread(target=run, args=(i,)) for i in range(count)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(60)
    return results


def test_admission_limits_hold_across_stores_under_contention(database):
    stores = [database.store() for _ in range(2)]

    def admit(i: int):
        key = "alpha" if i % 2 else "beta"
        token = REQUESTER.set(Requester(key, sees_all=False))
        try:
            return stores[i % 2].admit_job(_row(f"job-{i}"), inputs_json="{}", max_active=7,
                                           max_active_per_key=4)
        finally:
            REQUESTER.reset(token)

    outcomes = _at_once(24, admit)
    admitted = [i for i, refused in enumerate(outcomes) if refused is None]
    # 12 threads per key, 4 places per key, 7 in all: exactly 7 admitted, at most 4 of either key.
    assert len(admitted) == 7, outcomes
    per_key = Counter("alpha" if i % 2 else "beta" for i in admitted)
    assert max(per_key.values()) == 4 and sum(per_key.values()) == 7
    assert {refused[0] for refused in outcomes if refused is not None} <= {"server", "key"}
    assert stores[0].count_active_jobs() == stores[1].count_active_jobs() == 7
    assert stores[1].count_active_jobs("alpha") == per_key["alpha"]


def test_each_job_is_claimed_once_among_many_claimers(database):
    stores = [database.store() for _ in range(3)]
    job_ids = [f"job-{i:02d}" for i in range(30)]
    for job_id in job_ids:
        stores[0].admit_job(_row(job_id), inputs_json='{"n": 1}')

    def claim_all(i: int) -> list[str]:
        store, taken = stores[i % 3], []
        while (row := store.claim_job(f"c-{i}", i, ("square",), time.time() + 60, f"t-{i}")) is not None:
            taken.append(row["id"])
            assert row["inputs_json"] == '{"n": 1}' and row["attempts"] == 1
        return taken

    claims = _at_once(9, claim_all)
    everything = [job_id for taken in claims for job_id in taken]
    assert sorted(everything) == job_ids  # each job once, none lost
    rows = {job_id: stores[2].get_job(job_id) for job_id in job_ids}
    assert {row["status"] for row in rows.values()} == {"running"}
    for i, taken in enumerate(claims):
        assert all(rows[job_id]["lease_token"] == f"t-{i}" for job_id in taken)


def test_leases_cancels_and_deletes_across_stores(database):
    first, second = database.store(), database.store()
    first.admit_job(_row("running"), inputs_json="{}")
    first.admit_job(_row("queued"), inputs_json="{}")
    assert first.claim_job("first", 1, ("square",), time.time() + 60, "lease-1")["id"] == "running"
    # A cancel through the other store: a queued job ends at once, a running one is flagged for its
    # owner, who learns it at its next heartbeat.
    assert second.update_job("queued", only_if_status=("queued",), status="cancelled", cancel_requested=1,
                             finished_at=utc_now())
    assert first.count_active_jobs() == 1
    assert first.renew_leases(["lease-1"], time.time() + 60) == {"lease-1": False}
    assert second.update_job("running", only_if_status=("running",), cancel_requested=1)
    assert first.renew_leases(["lease-1"], time.time() + 60) == {"lease-1": True}
    # A lapsed lease taken over: the old claim renews nothing and writes nothing.
    assert second.update_job("running", only_if_token="lease-1", status="queued", lease_token=None,
                             cancel_requested=0)
    assert second.claim_job("second", 2, ("square",), time.time() + 60, "lease-2")["attempts"] == 2
    assert first.renew_leases(["lease-1"], time.time() + 60) == {}
    assert not first.update_job("running", only_if_token="lease-1", progress=0.5)
    assert second.update_job("running", only_if_token="lease-2", status="succeeded", finished_at=utc_now(),
                             result_json='{"square": 4}')
    assert first.get_job("running", with_result=True)["result_json"] == '{"square": 4}'
    # Deleted once: the second delete finds nothing, and the result and inputs go with the job.
    deletes = _at_once(4, lambda i: (first, second)[i % 2].delete_job("running", ("succeeded",)))
    assert deletes.count(True) == 1
    assert second.get_job("running") is None
    assert first.delete_jobs_finished_before(("cancelled",), "9999") == 1
    assert first.jobs_with_status("queued", "running", "cancelled", "succeeded") == []


def test_models_round_trip_across_stores_without_pickle(database):
    first, second = database.store(), database.store()
    rng = np.random.default_rng(7)
    arrays = {"weights": rng.normal(size=(300, 40)), "counts": np.arange(12, dtype=np.int32),
              "names": np.array(["load_N", "speed_m_s"]), "flags": np.array([True, False])}
    token = REQUESTER.set(Requester("alpha", sees_all=False))
    try:
        model_id = first.save_model("surrogate", {"score": 0.99, "inputs": ["load_N"]}, arrays, name="m")
    finally:
        REQUESTER.reset(token)
    stored = second.load_model(model_id)
    assert (stored.kind, stored.name) == ("surrogate", "m")
    assert stored.metadata == {"score": 0.99, "inputs": ["load_N"]}
    for name, array in arrays.items():
        assert stored.arrays[name].dtype == array.dtype
        np.testing.assert_array_equal(stored.arrays[name], array)
    token = REQUESTER.set(Requester("beta", sees_all=False))
    try:  # another key sees nothing of it, and cannot delete it
        assert second.load_model(model_id) is None and second.list_models() == []
        assert not second.delete_model(model_id)
    finally:
        REQUESTER.reset(token)
    assert [m["id"] for m in second.list_models("surrogate")] == [model_id]
    assert first.has_model(model_id, "surrogate") and not first.has_model(model_id, "calibration")
    assert second.delete_model(model_id) and first.load_model(model_id) is None
    with pytest.raises(ValueError, match="object"):
        first.save_model("bad", {}, {"things": np.array([{"a": 1}], dtype=object)})


# PostgreSQL only ---------------------------------------------------------------------------------

def test_the_setting_chooses_postgresql_and_sqlite_stays_the_default(postgres_url, tmp_path):
    from pydantic import ValidationError

    from microbearing.service.deps import open_database
    from microbearing.service.settings import Settings
    from microbearing.service.store import SqliteStore
    from microbearing.service.store_postgres import PostgresStore

    default = open_database(Settings(data_dir=tmp_path))
    chosen = open_database(Settings(data_dir=tmp_path, database_url=postgres_url, database_pool_size=2))
    try:
        assert isinstance(default, SqliteStore) and isinstance(chosen, PostgresStore)
        assert chosen.check_writable() is None
    finally:
        default.close()
        chosen.close()
    with pytest.raises(ValidationError, match="must be a PostgreSQL URL") as refused:
        Settings(database_url="mysql://microbearing:hunter2secret@localhost/microbearing")
    assert "hunter2secret" not in str(refused.value)  # the error does not echo the value


def test_a_missing_driver_is_named_with_the_extra(monkeypatch, tmp_path):
    from microbearing.service.deps import DataFolderError, open_database
    from microbearing.service.settings import Settings

    monkeypatch.setitem(sys.modules, "microbearing.service.store_postgres", None)  # as if not installed
    with pytest.raises(DataFolderError, match=r"pip install 'microbearing\[postgres\]'"):
        open_database(Settings(data_dir=tmp_path, database_url="postgresql://u@127.0.0.1:1/x"))


def test_an_unreachable_server_at_start_is_named_without_the_password(postgres_server, tmp_path):
    from live_server import free_port

    from microbearing.service.deps import DataFolderError, open_database
    from microbearing.service.settings import Settings

    url = f"postgresql://microbearing:hunter2secret@127.0.0.1:{free_port()}/nothing"
    started = time.monotonic()
    with pytest.raises(DataFolderError) as refused:
        open_database(Settings(data_dir=tmp_path, database_url=url, database_timeout_s=1.0))
    assert time.monotonic() - started < 10
    message = str(refused.value)
    assert "hunter2secret" not in message and "postgresql://microbearing:***@127.0.0.1" in message
    assert "MICROBEARING_DATABASE_URL" in message


def test_a_server_outage_is_a_503_storage_problem_and_service_resumes_after(postgres_server):
    from postgres_server import PostgresServer

    from microbearing.service.store_postgres import PostgresStore

    server = PostgresServer()  # its own, since this one is stopped
    store = None
    try:
        store = PostgresStore(server.new_database(), pool_size=2, timeout_s=5.0)
        store.admit_job(_row("before"), inputs_json="{}")
        server.halt()
        for attempt in (lambda: store.get_job("before"), lambda: store.admit_job(_row("during"))):
            started = time.monotonic()
            with pytest.raises(StorageError) as fault:
                attempt()
            assert fault.value.status == 503 and fault.value.headers["Retry-After"]
            assert time.monotonic() - started < 5.0 + 3.0  # the pool's timeout, not forever
            assert store.path in fault.value.detail  # names the database (its URL has no password)
        started = time.monotonic()
        reason = store.check_writable()  # what /readyz answers: within 2 s, whatever the pool's timeout
        assert reason is not None and "database" in reason and time.monotonic() - started < 2.0 + 2.0
        server.start()
        # The pool checks a connection before lending it: the first request after the outage is served.
        assert store.get_job("before")["status"] == "queued"
        assert store.check_writable() is None
    finally:
        if store is not None:
            store.close()
        server.stop()


def test_a_full_disk_on_the_server_maps_to_507():
    psycopg = pytest.importorskip("psycopg", reason="psycopg is not installed (pip install -e '.[postgres]')")

    from microbearing.service.store_postgres import classify

    full = classify(psycopg.errors.DiskFull("could not extend file: No space left on device"), "postgresql://h/d")
    assert full.status == 507 and "disk is full" in full.cause
    read_only = classify(psycopg.errors.ReadOnlySqlTransaction("read-only"), "postgresql://h/d")
    assert read_only.status == 503 and "read-only" in read_only.cause
    assert classify(psycopg.errors.UniqueViolation("duplicate key"), "postgresql://h/d") is None  # a bug: 500


def test_the_servers_own_reason_is_named_at_start(postgres_server, tmp_path):
    from microbearing.service.deps import DataFolderError, open_database
    from microbearing.service.settings import Settings

    url = f"{postgres_server.base_url}/no_such_database"
    with pytest.raises(DataFolderError, match='database "no_such_database" does not exist'):
        open_database(Settings(data_dir=tmp_path, database_url=url, database_timeout_s=2.0))


def test_the_model_commands_use_the_servers_postgresql_database(postgres_url, tmp_path, monkeypatch, capsys):
    from microbearing.service.cli import main

    monkeypatch.setenv("MICROBEARING_DATABASE_URL", postgres_url)
    monkeypatch.setenv("MICROBEARING_DATA_DIR", str(tmp_path / "unused"))
    request = tmp_path / "request.json"
    request.write_text(json.dumps({"space": {"load_N": [0.002, 0.03], "speed_m_s": [0.01, 0.15]},
                                   "fixed": {"balls": 4}, "budget": 12, "adaptive": False,
                                   "validation_points": 0}))
    assert main(["surrogate", "train", str(request)]) == 0
    out, err = capsys.readouterr()
    trained = json.loads(out)
    assert f"stored {trained['model_id']} in {postgres_url}" in err
    assert main(["surrogate", "list"]) == 0
    assert capsys.readouterr().out.splitlines()[0] == f"1 surrogate(s) in {postgres_url}"
    assert main(["surrogate", "predict", "f" * 32, "load_N=0.01", "speed_m_s=0.05"]) == 2
    assert f"looked in the PostgreSQL database {postgres_url}" in capsys.readouterr().err
    assert not (tmp_path / "unused").exists()  # no SQLite database made on the side


def test_an_older_schema_is_migrated_and_a_complete_one_needs_no_owner(postgres_server, postgres_url):
    import psycopg

    from microbearing.service.store import _SCHEMA
    from microbearing.service.store_postgres import PostgresStore, _postgres_ddl

    with psycopg.connect(postgres_url, autocommit=True) as conn:  # the first release's tables
        for statement in filter(str.strip, _SCHEMA.split(";")):
            conn.execute(_postgres_ddl(statement))
        conn.execute("INSERT INTO jobs (id, kind, status, request_json, owner_pid, owner_instance, "
                     "created_at) VALUES ('old', 'sweep', 'succeeded', '{}', 1, 'gone', '2020-01-01T00:00Z')")
    store = PostgresStore(postgres_url)  # adds the columns added since
    try:
        row = store.get_job("old")
        assert (row["status"], row["attempts"], row["lease_token"]) == ("succeeded", 0, None)
        assert row["owner_key"] is None  # visible to every key, as in SQLite
    finally:
        store.close()
    # A role that may read and write the rows but not change the tables can run the service now.
    role = f"app_{os.getpid()}"
    with psycopg.connect(postgres_url, autocommit=True) as conn:
        conn.execute(f"CREATE ROLE {role} LOGIN")
        conn.execute(f"GRANT SELECT, INSERT, UPDATE, DELETE ON ALL TABLES IN SCHEMA public TO {role}")
    as_app = postgres_url.replace("postgresql://microbearing@", f"postgresql://{role}@")
    store = PostgresStore(as_app)
    try:
        store.admit_job(_row("new"), inputs_json="{}", max_active=5)
        assert store.count_active_jobs() == 1 and store.check_writable() is None
    finally:
        store.close()
