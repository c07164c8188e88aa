"""Memory bounded by design: streamed batch answers, and turns for requests with large bodies.

The streamed JSON is byte for byte what the whole answer was (random chunkings, scalars, aliases);
a batch of more than one chunk is answered streamed with the physics' numbers; a request with a
large body waits for its turn (503 naming the setting when none comes), holds a place of the job
admission control (whose 429 or 503 it answers) and frees both when its answer is sent. The peak
memory of eight concurrent 2e6-point batches is measured by ``bench/batch_memory.py``.
"""

from __future__ import annotations

import asyncio
import json

import httpx
import numpy as np
import pytest
from fastapi.testclient import TestClient

from microbearing import physics
from microbearing.service.app import create_app
from microbearing.service.executor import DEFAULT_CHUNK_POINTS
from microbearing.service.limits import HEAVY_BODY_BYTES, HeavyRequestMiddleware
from microbearing.service.problems import ProblemError
from microbearing.service.settings import Settings
from microbearing.service.tables import json_bytes, json_column_pieces


@pytest.mark.parametrize("seed", range(6))
def test_streamed_columns_are_the_bytes_of_the_whole_answer(seed):
    rng = np.random.default_rng(seed)
    count = int(rng.integers(1, 400))
    pieces = min(count - 1, int(rng.integers(0, 6)))
    cuts = np.sort(rng.choice(np.arange(1, count), size=pieces, replace=False))
    bounds = list(zip([0, *cuts.tolist()], [*cuts.tolist(), count], strict=True))
    whole = {"a": rng.normal(size=count) * 10.0 ** rng.integers(-300, 300, size=count),
             "b": np.full(count, 0.25), "c": rng.uniform(size=count)}
    chunks = []
    for start, stop in bounds:
        chunk = {"a": whole["a"][start:stop], "c": whole["c"][start:stop].copy()}
        chunk["b"] = 0.25  # a scalar shared by the chunk's points
        chunks.append(chunk)
    columns = [("a", "a"), ("b", "b"), ("c", "c"), ("c_alias", "c")]
    streamed = b"".join(json_column_pieces(columns, bounds, chunks))
    assert streamed == json_bytes({"a": whole["a"], "b": whole["b"], "c": whole["c"], "c_alias": whole["c"]})
    assert all(not chunk for chunk in chunks)  # every output dropped once written


def test_a_non_finite_number_is_refused():
    with pytest.raises(ValueError, match="a"):
        b"".join(json_column_pieces([("a", "a")], [(0, 2)], [{"a": np.array([1.0, np.inf])}]))


def test_a_large_batch_is_streamed_with_the_physics_numbers(tmp_path):
    count = 3 * DEFAULT_CHUNK_POINTS + 17
    load = np.linspace(1e-3, 0.05, count)
    with TestClient(create_app(Settings(data_dir=tmp_path))) as client:
        answer = client.post("/v1/friction/batch", json={"points": {"balls": 5, "load_N": load.tolist(),
                                                                    "speed_m_s": 0.03},
                                                         "outputs": ["mu", "pivoting_moment_Nm"]})
        small = client.post("/v1/friction/batch", json={"points": {"balls": 5, "load_N": [0.01, 0.02],
                                                                   "speed_m_s": 0.03}, "outputs": ["mu"]})
    assert answer.status_code == 200, answer.text
    assert "content-length" not in answer.headers  # streamed (chunked on the wire)
    document = answer.json()
    expected = physics.evaluate(balls=5, load_N=load, speed_m_s=0.03)
    np.testing.assert_array_equal(document["mu"], expected.mu)
    np.testing.assert_array_equal(document["pivoting_moment_Nm"], expected.pivoting_moment_Nm)
    assert document["pivoting_moment_newton_metre"] == document["pivoting_moment_Nm"]
    assert list(document) == ["mu", "pivoting_moment_Nm", "pivoting_moment_newton_metre"]
    assert small.headers["content-length"] == str(len(small.content))


def heavy_app(max_requests: int, wait_s: float, admit=None):
    release = asyncio.Event()
    seen = []

    async def slow(scope, receive, send):
        message = await receive()
        seen.append(len(message.get("body", b"")))
        if scope["path"] == "/slow":
            await release.wait()
        await send({"type": "http.response.start", "status": 200, "headers": []})
        await send({"type": "http.response.body", "body": b"ok"})

    return HeavyRequestMiddleware(slow, max_requests=max_requests, wait_s=wait_s, admit=admit), release, seen


def test_a_large_body_waits_for_its_turn_and_holds_an_admission_place():
    places = []

    def admit(scope):
        places.append(scope["path"])
        return lambda: places.remove(scope["path"])

    async def scenario():
        app, release, seen = heavy_app(1, 0.3, admit)
        big = b"x" * (HEAVY_BODY_BYTES + 1)
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://t") as client:
            first = asyncio.create_task(client.post("/slow", content=big))
            while not places:
                await asyncio.sleep(0.01)
            refused = await client.post("/other", content=big)  # no turn within 0.3 s
            small = await client.post("/other", content=b"y" * 1000)  # not heavy: passes
            assert places == ["/slow"]
            release.set()
            done = await first
            after = await client.post("/other", content=big)  # the turn and place are free again
        return refused, small, done, after, seen

    refused, small, done, after, seen = asyncio.run(scenario())
    assert refused.status_code == 503 and refused.headers["retry-after"] == "5"
    assert refused.headers["content-type"] == "application/problem+json"
    assert "MICROBEARING_MAX_HEAVY_REQUESTS" in refused.json()["detail"]
    assert small.status_code == 200 and done.status_code == 200 and after.status_code == 200
    assert places == []
    assert HEAVY_BODY_BYTES + 1 in seen and 1000 in seen


def test_the_admission_control_refuses_a_heavy_request_as_it_refuses_a_job():
    def full(scope):
        raise ProblemError(429, "This API key has 16 queued or running jobs "
                                "(MICROBEARING_MAX_ACTIVE_JOBS_PER_KEY)", headers={"Retry-After": "5"})

    async def scenario():
        app, _, seen = heavy_app(2, 0.3, full)
        async with httpx.AsyncClient(transport=httpx.ASGITransport(app=app), base_url="http://t") as client:
            refused = await client.post("/other", content=b"x" * (HEAVY_BODY_BYTES + 1))
            again = await client.post("/other", content=b"x" * (HEAVY_BODY_BYTES + 1))
        return refused, again, app, seen

    refused, again, app, seen = asyncio.run(scenario())
    assert refused.status_code == 429 == again.status_code  # the turn was given back after each
    assert json.loads(refused.content)["status"] == 429 and refused.headers["retry-after"] == "5"
    assert seen == []  # the body was never read
    assert app.turns.acquire(blocking=False) and app.turns.acquire(blocking=False)


def test_heavy_batches_count_toward_the_servers_job_limit(tmp_path):
    settings = Settings(data_dir=tmp_path, max_active_jobs=1)
    load = np.linspace(1e-3, 0.05, 60_000).tolist()
    body = json.dumps({"points": {"balls": 4, "load_N": load, "speed_m_s": 0.02}, "outputs": ["mu"]})
    assert len(body) > HEAVY_BODY_BYTES
    with TestClient(create_app(settings)) as client:
        jobs = client.app.state.runtime.jobs
        hold = jobs.admit_request("test")  # the one place taken
        json_type = {"Content-Type": "application/json"}
        refused = client.post("/v1/friction/batch", content=body, headers=json_type)
        hold()
        accepted = client.post("/v1/friction/batch", content=body, headers=json_type)
        assert jobs.active_count() == 0  # the batch's place was freed with its answer
    assert refused.status_code == 503 and "MICROBEARING_MAX_ACTIVE_JOBS" in refused.json()["detail"]
    assert accepted.status_code == 200
    np.testing.assert_array_equal(accepted.json()["mu"],
                                  physics.evaluate(balls=4, load_N=np.array(load), speed_m_s=0.02).mu)
