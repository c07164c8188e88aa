"""Scale-out: chunked evaluation over a thread pool and over a dask LocalCluster gives the same numbers."""

from __future__ import annotations

import json
import pickle
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from fastapi.testclient import TestClient

import physics
from service.app import create_app
from service.executor import DaskExecutor, chunk_bounds, evaluate_in_chunks, map_chunks
from service.problems import ProblemError
from service.settings import Settings
from service.sweeps import CHUNK_POINTS

pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def dask_local():
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
            result = evaluate_in_chunks(executor, inputs, count, ["mu", "contact_load_N"], "olaru2005",
                                        chunk_points=997)
            assert set(result) == {"mu", "contact_load_N"}
            np.testing.assert_array_equal(result["mu"], expected.mu)
            np.testing.assert_array_equal(result["contact_load_N"], expected.contact_load_N)


def test_a_bad_point_is_named_by_its_index_in_the_whole_batch(dask_local):
    count = 3_000
    inputs = {"balls": 4, "load_N": np.full(count, 0.01), "speed_m_s": 0.1}
    inputs["load_N"][2_345] = 5e-324  # a denormal load, below the table's minimum
    with pytest.raises(ProblemError) as caught:
        evaluate_in_chunks(dask_local, inputs, count, None, "olaru2005", pointer="/points", chunk_points=500)
    assert caught.value.status == 422
    assert caught.value.errors[0]["pointer"] == "/points/load_N"
    assert "index 2345" in caught.value.errors[0]["detail"]  # in the whole batch, not in its chunk


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
