"""Resources a user manages (issue 28, item 3): list and delete calibrations, list one's jobs.

Through the API, with API keys: a key lists and deletes only what it created, the admin key all; a
deleted calibration is gone from every list, from UM-Bridge and from requests that name it.
"""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient
from jobs_helper import finished_job

from microbearing import physics
from microbearing.service.app import create_app
from microbearing.service.settings import Settings

ALPHA, BETA, ADMIN = "alpha-key-0123456789", "beta-key-9876543210", "admin-key-5555555555"
SWEEP = {"design": "grid", "axes": {"load_N": {"start": 1e-3, "stop": 0.05, "num": 5}},
         "fixed": {"balls": 4, "speed_m_s": 0.05}, "outputs": ["mu"]}
PROBLEM = "application/problem+json"


def bearer(key: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {key}"}


def rows(seed: int, n: int = 40) -> list[dict]:
    rng = np.random.default_rng(seed)
    load = rng.uniform(3e-3, 3e-2, n)
    speed = rng.uniform(0.0, 0.15, n)
    mu = physics.evaluate(balls=4, load_N=load, speed_m_s=speed, mu_pivot=0.7).mu
    mu = mu * np.exp(rng.normal(0, 0.02, n))
    return [{"balls": 4, "load [mN]": 1e3 * a, "speed_m_s": b, "mu_measured": c}
            for a, b, c in zip(load, speed, mu, strict=True)]


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    settings = Settings(data_dir=tmp_path_factory.mktemp("resources"), api_keys=f"{ALPHA},{BETA}",
                        admin_api_key=ADMIN, sweep_sync_max_points=0)
    with TestClient(create_app(settings)) as test_client:
        yield test_client


def finished(client: TestClient, response, key: str) -> dict:
    assert response.status_code == 202, response.text
    job = finished_job(client, response.headers["location"], headers=bearer(key), timeout_s=120,
                       interval_s=0.05)
    return client.get(job["result_url"], headers=bearer(key)).json()


def calibrate(client: TestClient, key: str, seed: int) -> dict:
    body = {"data": rows(seed), "fit_parameters": ["mu_pivot"], "folds": 2}
    return finished(client, client.post("/v1/calibrations", json=body, headers=bearer(key)), key)


def listed(client: TestClient, key: str) -> list[str]:
    response = client.get("/v1/calibrations", headers=bearer(key))
    assert response.status_code == 200, response.text
    return [c["id"] for c in response.json()["calibrations"]]


def umbridge_models(client: TestClient, key: str) -> list[str]:
    return client.get("/umbridge/Info", headers=bearer(key)).json()["models"]


def test_calibrations_are_listed_and_deleted_by_their_owner_or_the_admin(client):
    first = calibrate(client, ALPHA, 1)
    second = calibrate(client, ALPHA, 2)
    other = calibrate(client, BETA, 3)
    assert listed(client, ALPHA)[:2] == [second["id"], first["id"]]  # newest first
    assert other["id"] not in listed(client, ALPHA) and listed(client, BETA) == [other["id"]]
    assert set(listed(client, ADMIN)) >= {first["id"], second["id"], other["id"]}
    summary = client.get("/v1/calibrations", headers=bearer(ALPHA)).json()["calibrations"][1]
    assert summary["model_id"] == first["model_id"] and summary["n_points"] == 40
    assert summary["fit_parameters"] == ["mu_pivot"]
    assert summary["error_after"] == first["error_after"]
    assert "load_N" in summary["columns"]
    assert client.get(summary["url"], headers=bearer(ALPHA)).json()["id"] == first["id"]
    # another key cannot delete it; its owner can, and it is gone everywhere
    gone = client.delete(f"/v1/calibrations/{first['id']}", headers=bearer(BETA))
    assert gone.status_code == 404 and gone.headers["content-type"] == PROBLEM
    assert first["model_id"] in umbridge_models(client, ALPHA)
    assert client.delete(f"/v1/calibrations/{first['id']}", headers=bearer(ALPHA)).status_code == 204
    assert first["id"] not in listed(client, ALPHA) and first["id"] not in listed(client, ADMIN)
    assert first["model_id"] not in umbridge_models(client, ALPHA)
    assert client.get(f"/v1/calibrations/{first['id']}", headers=bearer(ALPHA)).status_code == 404
    friction = client.post("/v1/friction", headers=bearer(ALPHA), json={
        "balls": 4, "load_N": 0.01, "speed_m_s": 0.05, "model": first["model_id"]})
    assert friction.status_code == 404, friction.text
    assert client.delete(f"/v1/calibrations/{first['id']}", headers=bearer(ALPHA)).status_code == 404
    # the admin deletes another key's calibration
    assert client.delete(f"/v1/calibrations/{other['id']}", headers=bearer(ADMIN)).status_code == 204
    assert listed(client, BETA) == []
    assert second["id"] in listed(client, ALPHA)


def test_jobs_are_listed_per_key_filtered_and_paginated(client):
    ids = []
    for _ in range(5):
        response = client.post("/v1/sweeps", json=SWEEP, headers=bearer(ALPHA))
        finished(client, response, ALPHA)
        ids.append(response.json()["id"])
    beta = client.post("/v1/sweeps", json=SWEEP, headers=bearer(BETA))
    finished(client, beta, BETA)
    # every sweep of ALPHA, newest first, two per page, by following next_url
    seen, url, pages = [], "/v1/jobs?kind=sweep&limit=2", 0
    while url is not None:
        page = client.get(url, headers=bearer(ALPHA))
        assert page.status_code == 200, page.text
        body = page.json()
        assert len(body["jobs"]) <= 2
        seen += [job["id"] for job in body["jobs"]]
        url, pages = body["next_url"], pages + 1
    assert seen == ids[::-1] and pages == 3
    assert beta.json()["id"] not in seen
    everything = client.get("/v1/jobs", params={"limit": 100}, headers=bearer(ALPHA)).json()["jobs"]
    assert {j["kind"] for j in everything} == {"sweep", "calibration"}  # the first test's calibrations
    assert all(j["id"] != beta.json()["id"] for j in everything)
    admin = [j["id"] for j in client.get("/v1/jobs?limit=100", headers=bearer(ADMIN)).json()["jobs"]]
    assert beta.json()["id"] in admin and set(ids) <= set(admin)
    calibrations = client.get("/v1/jobs", params={"kind": "calibration"},
                              headers=bearer(ALPHA)).json()["jobs"]
    assert calibrations and all(j["kind"] == "calibration" for j in calibrations)
    assert client.get("/v1/jobs", params={"status": "queued"}, headers=bearer(ALPHA)).json()["jobs"] == []
    succeeded = client.get("/v1/jobs", params=[("status", "succeeded"), ("status", "failed"), ("limit", 100)],
                           headers=bearer(ALPHA)).json()["jobs"]
    assert {j["id"] for j in succeeded} >= set(ids)
    # a deleted job is no longer listed
    assert client.delete(f"/v1/jobs/{ids[0]}", headers=bearer(ALPHA)).status_code == 204
    left = client.get("/v1/jobs?limit=100", headers=bearer(ALPHA)).json()["jobs"]
    assert ids[0] not in [j["id"] for j in left]


@pytest.mark.parametrize(("params", "name"), [
    ({"kind": "teleport"}, "kind"), ({"status": "done"}, "status"), ({"limit": 0}, "limit"),
    ({"limit": 101}, "limit"), ({"page_token": "not a token"}, "page_token"),
])
def test_bad_list_parameters_are_problems_naming_them(client, params, name):
    response = client.get("/v1/jobs", params=params, headers=bearer(ALPHA))
    assert response.status_code == 422 and response.headers["content-type"] == PROBLEM, response.text
    assert [e.get("parameter") for e in response.json()["errors"]] == [name]
