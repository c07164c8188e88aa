"""Ownership: with API keys, a key sees only its own jobs, surrogates and calibrations; the admin key all."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient
from jobs_helper import wait_job

from microbearing.service.app import create_app
from microbearing.service.deps import get_runtime
from microbearing.service.security import key_id
from microbearing.service.settings import Settings
from microbearing.service.store import REQUESTER, Requester

ALPHA, BETA, ADMIN = "alpha-key-0123456789", "beta-key-9876543210", "admin-key-5555555555"
SWEEP = {"design": "grid", "axes": {"load_N": {"start": 1e-3, "stop": 0.05, "num": 20}},
         "fixed": {"balls": 4, "speed_m_s": 0.05}, "outputs": ["mu"]}
SURROGATE = {"space": {"load_N": [1e-3, 0.05], "balls": [4, 6], "groove_angle_deg": [40.0, 60.0]},
             "fixed": {"speed_m_s": 0.05}, "budget": 8, "adaptive": False}


def bearer(key: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {key}"}


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    settings = Settings(data_dir=tmp_path_factory.mktemp("owned"), api_keys=f"{ALPHA},{BETA}",
                        admin_api_key=ADMIN, sweep_sync_max_points=0)
    with TestClient(create_app(settings)) as test_client:
        yield test_client


def finished(client: TestClient, location: str, key: str) -> dict:
    return wait_job(client, location, headers=bearer(key), timeout_s=60, interval_s=0.02)


def assert_404(response) -> None:
    assert response.status_code == 404, response.text
    assert response.headers["content-type"] == "application/problem+json"


def test_jobs_belong_to_the_key_that_created_them(client):
    response = client.post("/v1/sweeps", json=SWEEP, headers=bearer(ALPHA))
    assert response.status_code == 202
    location = response.headers["location"]
    job = finished(client, location, ALPHA)
    assert job["status"] == "succeeded"
    for method, path in [("GET", location), ("GET", f"{location}/result"), ("DELETE", location)]:
        assert_404(client.request(method, path, headers=bearer(BETA)))
    assert client.get(f"{location}/result", headers=bearer(ADMIN)).status_code == 200
    stored = get_runtime(client.app).store.get_job(job["id"])
    assert stored["owner_key"] == key_id(ALPHA) and ALPHA not in str(stored)  # an id, never the key
    assert client.delete(location, headers=bearer(ALPHA)).status_code == 204
    assert_404(client.get(location, headers=bearer(ADMIN)))


def test_the_admin_key_can_cancel_and_delete_any_job(client):
    location = client.post("/v1/sweeps", json=SWEEP, headers=bearer(BETA)).headers["location"]
    finished(client, location, BETA)
    assert client.delete(location, headers=bearer(ADMIN)).status_code == 204
    assert_404(client.get(location, headers=bearer(BETA)))


def test_surrogates_are_listed_and_served_only_to_their_key(client):
    response = client.post("/v1/surrogates", json=SURROGATE, headers=bearer(ALPHA))
    assert response.status_code == 202, response.text
    job = finished(client, response.headers["location"], ALPHA)
    assert job["status"] == "succeeded", job
    surrogate_id = client.get(job["result_url"], headers=bearer(ALPHA)).json()["id"]
    listed = {key: [s["id"] for s in client.get("/v1/surrogates", headers=bearer(key)).json()["surrogates"]]
              for key in (ALPHA, BETA, ADMIN)}
    assert surrogate_id in listed[ALPHA] and surrogate_id in listed[ADMIN]
    assert surrogate_id not in listed[BETA]
    points = {"points": {"load_N": [0.01], "balls": [5], "groove_angle_deg": [50.0]}}
    # Alpha's use puts the fitted surrogate in the server's cache: Beta must not reach it through that.
    predicted = client.post(f"/v1/surrogates/{surrogate_id}/predict", json=points, headers=bearer(ALPHA))
    assert predicted.status_code == 200, predicted.text
    assert_404(client.get(f"/v1/surrogates/{surrogate_id}", headers=bearer(BETA)))
    assert_404(client.post(f"/v1/surrogates/{surrogate_id}/predict", json=points, headers=bearer(BETA)))
    assert_404(client.get(f"/v1/surrogates/{surrogate_id}/sensitivity", headers=bearer(BETA)))
    assert_404(client.delete(f"/v1/surrogates/{surrogate_id}", headers=bearer(BETA)))
    optimization = {"model": f"surrogate:{surrogate_id}", "speed_m_s": 0.05,
                    "bounds": {"balls": [4, 6], "groove_angle_deg": [40, 60], "load_N": [1e-3, 0.05]}}
    assert_404(client.post("/v1/optimizations", json=optimization, headers=bearer(BETA)))
    assert client.get(f"/v1/surrogates/{surrogate_id}", headers=bearer(ALPHA)).status_code == 200


def test_calibrations_are_served_only_to_their_key_and_older_rows_to_all(client):
    store = get_runtime(client.app).store
    report = {"report": {"plots": {}}, "model": {}}
    token = REQUESTER.set(Requester(key_id(ALPHA), sees_all=False))
    try:
        owned = store.save_model("calibration", report, {})
    finally:
        REQUESTER.reset(token)
    legacy = store.save_model("calibration", report, {})  # no key: as written before keys were set
    assert client.get(f"/v1/calibrations/{owned}", headers=bearer(ALPHA)).status_code == 200
    assert_404(client.get(f"/v1/calibrations/{owned}", headers=bearer(BETA)))
    assert_404(client.get(f"/v1/calibrations/{owned}/plots/residual.png", headers=bearer(BETA)))
    assert client.get(f"/v1/calibrations/{owned}", headers=bearer(ADMIN)).status_code == 200
    for key in (ALPHA, BETA):
        assert client.get(f"/v1/calibrations/{legacy}", headers=bearer(key)).status_code == 200


def test_without_keys_everything_is_shared(tmp_path):
    with TestClient(create_app(Settings(data_dir=tmp_path, sweep_sync_max_points=0))) as open_client:
        location = open_client.post("/v1/sweeps", json=SWEEP).headers["location"]
        assert finished(open_client, location, "")["status"] == "succeeded"
        assert get_runtime(open_client.app).store.get_job(location.rsplit("/", 1)[1])["owner_key"] is None


def test_the_umbridge_protocol_shows_a_key_only_its_own_models(client):
    response = client.post("/v1/surrogates", json=SURROGATE, headers=bearer(ALPHA))
    assert response.status_code == 202, response.text
    job = finished(client, response.headers["location"], ALPHA)
    assert job["status"] == "succeeded", job
    name = f"surrogate:{client.get(job['result_url'], headers=bearer(ALPHA)).json()['id']}"
    models = {key: client.get("/umbridge/Info", headers=bearer(key)).json()["models"]
              for key in (ALPHA, BETA)}
    assert name in models[ALPHA] and name not in models[BETA] and "physics" in models[BETA]
    request = {"name": name, "input": [[5, 50.0, 0.01]], "config": {}}  # balls, groove angle, load
    answered = client.post("/umbridge/Evaluate", json=request, headers=bearer(ALPHA))
    assert answered.status_code == 200, answered.text
    refused = client.post("/umbridge/Evaluate", json=request, headers=bearer(BETA))
    assert refused.json()["error"]["type"] == "ModelNotFound", refused.text
