"""Scale-out: chunked evaluation over a thread pool and over a dask LocalCluster gives the same numbers."""

from __future__ import annotations

import importlib.util
import json
import pickle
import time
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from jobs_helper import finished_job

from microbearing import physics
from microbearing.calibrate import CalibratedModel
from microbearing.optimize import DesignBounds, DesignProblem, optimize_design
from microbearing.optimize.general import GROUP_COUNTS, optimize_model, physics_model
from microbearing.service.app import create_app
from microbearing.service.deps import get_runtime
from microbearing.service.executor import DaskExecutor, chunk_bounds, evaluate_in_chunks, map_chunks
from microbearing.service.models import physics_in
from microbearing.service.problems import ProblemError
from microbearing.service.settings import Settings
from microbearing.service.sweeps import CHUNK_POINTS

#: Only the tests on a dask cluster need dask.distributed (the "dask" extra); the others always run.
needs_dask = pytest.mark.skipif(importlib.util.find_spec("distributed") is None,
                                reason="dask.distributed is not installed")


@pytest.fixture(scope="module")
def dask_local():
    pytest.importorskip("distributed")
    executor = DaskExecutor("local", threads=2)
    yield executor
    executor.shutdown()


@pytest.mark.parametrize("count, size", [(0, 5), (1, 5), (10, 5), (11, 5), (65_537, 65_536), (7, 100)])
def test_chunks_cover_every_point_once_in_order(count, size):
    bounds = chunk_bounds(count, size)
    covered = [i for start, stop in bounds for i in range(start, stop)]
    assert covered == list(range(count))
    assert all(0 < stop - start <= size for start, stop in bounds)
    assert len(bounds) == -(-count // size)


def test_chunk_bounds_reject_bad_sizes():
    with pytest.raises(ValueError, match="chunk_points"):
        chunk_bounds(10, 0)
    with pytest.raises(ValueError, match="count"):
        chunk_bounds(-1, 10)


@pytest.mark.parametrize("use_pool", [False, True])
def test_map_chunks_keeps_order_and_reports_progress(use_pool):
    seen = []
    with ThreadPoolExecutor(3) as pool:
        results = map_chunks(pool if use_pool else None, pow, [(2, n) for n in range(10)], seen.append)
    assert results == [2**n for n in range(10)]
    assert seen == pytest.approx([(n + 1) / 10 for n in range(10)])


def test_map_chunks_stops_when_progress_raises():
    class StopError(Exception):
        pass

    def stop_after_two(fraction):
        if fraction >= 0.2:
            raise StopError

    with ThreadPoolExecutor(1) as pool, pytest.raises(StopError):
        map_chunks(pool, pow, [(2, n) for n in range(10)], stop_after_two)


class _FlakyScheduler(DaskExecutor):
    """A remote cluster (no dask needed) on a thread pool whose scheduler is lost after ``up`` submits:
    the next ``refusals`` submits are refused as DaskExecutor refuses them while its connection is
    reconnecting, and :meth:`fault` says so until the scheduler is back."""

    def __init__(self, up: int, refusals: int, fault_timeout_s: float = 30.0):
        super().__init__("tcp://127.0.0.1:1", threads=2, fault_timeout_s=fault_timeout_s)
        self.pool = ThreadPoolExecutor(2)
        self.up, self.refusals, self.submits, self.refused = up, refusals, 0, 0
        self.identity = (1, "scheduler-1")

    def submit(self, fn, /, *args, **kwargs):
        self.submits += 1
        if self.submits > self.up and self.refused < self.refusals:
            self.refused += 1
            raise ProblemError(503, f"The dask scheduler {self.scheduler} cannot be reached (the connection "
                                    "is connecting); retry later.")
        return self.pool.submit(fn, *args, **kwargs)

    def fault(self, connect_timeout_s: float = 2.0):
        if self.refused < self.refusals:
            self.refused += 1  # each look at the lost scheduler uses up a refusal: it comes back after them
            if self._faulty_since is None:
                self._faulty_since = time.monotonic()
            return "cannot be reached (the connection is connecting)"
        self._faulty_since = None
        return None


def test_chunks_the_scheduler_refused_while_they_were_submitted_are_submitted_again():
    cluster = _FlakyScheduler(up=3, refusals=4)
    try:
        results = map_chunks(cluster, pow, [(2, n) for n in range(10)])
    finally:
        cluster.pool.shutdown()
    assert results == [2**n for n in range(10)]
    assert cluster.submits > 10  # the refused chunks went out again


def test_a_scheduler_unreachable_at_the_first_chunk_is_the_callers_503_at_once():
    cluster = _FlakyScheduler(up=0, refusals=1)
    try:
        with pytest.raises(ProblemError) as raised:
            map_chunks(cluster, pow, [(2, n) for n in range(10)])
    finally:
        cluster.pool.shutdown()
    assert raised.value.status == 503 and cluster.submits == 1


def test_a_scheduler_that_stays_lost_mid_submission_fails_the_work_after_the_fault_timeout():
    cluster = _FlakyScheduler(up=2, refusals=10**9, fault_timeout_s=1.0)
    try:
        with pytest.raises(ProblemError) as raised:
            map_chunks(cluster, pow, [(2, n) for n in range(10)])
    finally:
        cluster.pool.shutdown()
    assert raised.value.status == 503 and "MICROBEARING_DASK_FAULT_TIMEOUT_S=1" in raised.value.detail


def test_problems_cross_process_boundaries():
    problem = ProblemError(422, "bad input", errors=[{"pointer": "/load_N", "detail": "must be > 0"}])
    copy = pickle.loads(pickle.dumps(problem))
    assert copy.to_dict("/x") == problem.to_dict("/x") and copy.status == 422


def batch_inputs(count: int) -> dict:
    rng = np.random.default_rng(7)
    return {"balls": rng.integers(1, 40, count).astype(float), "load_N": rng.uniform(1e-4, 0.1, count),
            "speed_m_s": rng.uniform(0.0, 0.2, count), "balls_touching": rng.random(count) < 0.5,
            "mu_pivot": 0.4, "groove_angle_deg": 54.7}


def test_chunked_evaluation_equals_the_physics_on_every_executor(dask_local):
    count = 10_007
    inputs = batch_inputs(count)
    expected = physics.evaluate(**inputs)
    with ThreadPoolExecutor(2) as pool:
        for executor in (None, pool, dask_local):
            result = evaluate_in_chunks(executor, inputs, count, ["mu", "contact_load_N"],
                                        physics_in("olaru2005"), chunk_points=997)
            assert set(result) == {"mu", "contact_load_N"}
            np.testing.assert_array_equal(result["mu"], expected.mu)
            np.testing.assert_array_equal(result["contact_load_N"], expected.contact_load_N)


def test_a_bad_point_is_named_by_its_index_in_the_whole_batch(dask_local):
    count = 3_000
    inputs = {"balls": 4, "load_N": np.full(count, 0.01), "speed_m_s": 0.1}
    inputs["load_N"][2_345] = 5e-324  # a denormal load, below the table's minimum
    with pytest.raises(ProblemError) as caught:
        evaluate_in_chunks(dask_local, inputs, count, None, physics_in("olaru2005"), pointer="/points",
                           chunk_points=500)
    assert caught.value.status == 422
    assert caught.value.errors[0]["pointer"] == "/points/load_N"
    assert "index 2345" in caught.value.errors[0]["detail"]  # in the whole batch, not in its chunk


@needs_dask
def test_a_sweep_on_a_dask_local_cluster_equals_the_local_run(tmp_path):
    # 300 x 300 = 90,000 points: two chunks of the service's chunk size, answered at once (200).
    assert 300 * 300 > CHUNK_POINTS
    sweep = {"design": "grid", "axes": {"load_N": {"start": 1e-3, "stop": 0.1, "num": 300, "spacing": "log"},
                                        "speed_m_s": {"start": 0.0, "stop": 0.2, "num": 300}},
             "fixed": {"balls": 6}, "outputs": ["mu", "mu_rolling"]}
    common = {"sweep_sync_max_points": 100_000, "max_sweep_points": 100_000}
    answers = {}
    for name, extra in {"local": {}, "dask": {"dask_scheduler": "local", "executor_workers": 2}}.items():
        settings = Settings(data_dir=tmp_path / name, **common, **extra)
        with TestClient(create_app(settings)) as client:
            response = client.post("/v1/sweeps", json=sweep)
            assert response.status_code == 200, response.text
            answers[name] = response.content
            if name == "dask":
                assert type(client.app.state.runtime.executor) is DaskExecutor
    assert answers["dask"] == answers["local"]  # byte for byte

    table = json.loads(answers["dask"])["columns"]
    load, speed = np.meshgrid(np.geomspace(1e-3, 0.1, 300), np.linspace(0.0, 0.2, 300), indexing="ij")
    expected = physics.evaluate(balls=6, load_N=load.ravel(), speed_m_s=speed.ravel())
    np.testing.assert_allclose(table["mu"], expected.mu, rtol=1e-12)
    np.testing.assert_allclose(table["mu_rolling"], expected.mu_rolling, rtol=1e-12)


@needs_dask
def test_a_batch_on_a_dask_local_cluster_equals_the_local_run(tmp_path):
    count = 70_000  # two chunks
    rng = np.random.default_rng(3)
    body = {"points": {"balls": 7, "load_N": rng.uniform(1e-3, 0.05, count).tolist(),
                       "speed_m_s": rng.uniform(0.0, 0.2, count).tolist()},
            "outputs": ["mu", "contact_radius_m"]}
    answers = {}
    for name, extra in {"local": {}, "dask": {"dask_scheduler": "local", "executor_workers": 2}}.items():
        with TestClient(create_app(Settings(data_dir=tmp_path / name, **extra))) as client:
            response = client.post("/v1/friction/batch", json=body)
            assert response.status_code == 200, response.text
            answers[name] = response.content
    assert answers["dask"] == answers["local"]
    expected = physics.evaluate(balls=7, load_N=np.array(body["points"]["load_N"]),
                                speed_m_s=np.array(body["points"]["speed_m_s"]))
    np.testing.assert_array_equal(json.loads(answers["dask"])["mu"], expected.mu)


WIDE = DesignProblem(DesignBounds((3, 40), (40, 60), (0.001, 0.05)), speed_m_s=0.05, fixed={"mu_pivot": 0.8})


@pytest.mark.parametrize("kind", ["pool", pytest.param("dask", marks=needs_dask)])
def test_a_multi_start_optimization_on_an_executor_equals_the_in_process_run(request, kind):
    # 38 ball counts x 2 starts: three groups of GROUP_COUNTS counts, each a task on the executor
    assert len(WIDE.ball_counts()) > 2 * GROUP_COUNTS
    seen = []
    reference = optimize_model(WIDE, physics_model(), starts=2, model_name="physics")
    with ThreadPoolExecutor(2) as pool:
        executor = pool if kind == "pool" else request.getfixturevalue("dask_local")
        result = optimize_model(WIDE, physics_model(), starts=2, model_name="physics",
                                map_calls=partial(map_chunks, executor), progress=seen.append)
    assert result.design == reference.design and result.mu == reference.mu
    assert result.per_ball_count == reference.per_ball_count
    assert result.certificate == reference.certificate
    assert seen == pytest.approx([1 / 3, 2 / 3, 1.0])  # one report per finished group
    # independent check: a local method on the physics lands on the certified global optimum
    certified = optimize_design(WIDE)
    assert certified.mu * (1 - 1e-7) <= reference.mu <= certified.mu * (1 + 1e-4)


class _CountingPool(ThreadPoolExecutor):
    """A thread pool that counts the calls submitted to it."""

    def __init__(self):
        super().__init__(2)
        self.calls = 0

    def submit(self, fn, /, *args, **kwargs):
        self.calls += 1
        return super().submit(fn, *args, **kwargs)


@pytest.mark.parametrize("scheduler", [None, pytest.param("local", marks=needs_dask)])
def test_an_optimization_job_runs_its_groups_on_the_apps_executor(tmp_path, scheduler):
    settings = Settings(data_dir=tmp_path, **({"dask_scheduler": scheduler, "executor_workers": 2}
                                              if scheduler else {}))
    with TestClient(create_app(settings)) as client:
        runtime = get_runtime(client.app)
        if scheduler is None:
            runtime.executor.shutdown()
            runtime.executor = _CountingPool()
        else:
            assert type(runtime.executor) is DaskExecutor
        model_id = runtime.store.save_model(
            "calibration", {"model": CalibratedModel(fitted={"mu_pivot": 0.8}).to_json()}, {})
        request = {"bounds": {"balls": [3, 40], "groove_angle_deg": [40, 60], "load_N": [0.001, 0.05]},
                   "speed_m_s": 0.05, "model": f"calibrated:{model_id}", "starts": 2}
        response = client.post("/v1/optimizations", json=request)
        assert response.status_code == 202, response.text
        job = finished_job(client, response.headers["location"], timeout_s=120, interval_s=0.05)
        result = client.get(job["result_url"]).json()
        if scheduler is None:
            assert runtime.executor.calls == 3  # one task per group of ball counts
    # the calibrated model is the physics with mu_pivot 0.8: the in-process run of the same method
    expected = optimize_model(WIDE, physics_model(), starts=2)
    assert result["design"] == expected.design
    assert result["mu"] == pytest.approx(expected.mu, rel=1e-12)


@needs_dask
def test_an_unreachable_scheduler_is_a_documented_503_and_the_rest_of_the_api_works(tmp_path):
    # the discard port: nothing listens there
    settings = Settings(data_dir=tmp_path, dask_scheduler="tcp://127.0.0.1:9")
    sweep = {"design": "grid", "axes": {"load_N": {"start": 1e-3, "stop": 0.1, "num": 5}},
             "fixed": {"balls": 6, "speed_m_s": 0.1}}
    batch = {"points": {"balls": 7, "load_N": [0.01, 0.02], "speed_m_s": 0.1}}
    with TestClient(create_app(settings)) as client:
        get_runtime(client.app).executor.connect_timeout_s = 1.0
        for path, body in (("/v1/sweeps", sweep), ("/v1/friction/batch", batch)):
            response = client.post(path, json=body)
            assert response.status_code == 503, response.text
            assert response.headers["content-type"] == "application/problem+json"
            assert "cannot be reached" in response.json()["detail"]
        point = {"balls": 7, "load_N": 0.01, "speed_m_s": 0.1}
        assert client.post("/v1/friction", json=point).status_code == 200
    spec = json.loads((Path(__file__).parents[1] / "openapi" / "openapi.json").read_text())
    for path in ("/v1/sweeps", "/v1/friction/batch"):
        assert "503" in spec["paths"][path]["post"]["responses"], path
