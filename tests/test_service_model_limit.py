"""Stored models are bounded: ``MICROBEARING_MAX_STORED_MODELS`` calibrations and surrogates together.

Past it a request that would store one more is refused with a 507 problem naming the setting (nothing
runs, nothing is lost), a job that reaches it while running fails with that problem, and deleting a model
makes room again.
"""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient
from jobs_helper import wait_job
from test_service_resources import bearer, finished, rows

from microbearing.service.app import create_app
from microbearing.service.deps import get_runtime
from microbearing.service.settings import Settings
from microbearing.service.store import ModelLimitError

KEY = "alpha-key-0123456789"
PROBLEM = "application/problem+json"
SURROGATE = {"space": {"balls": [4, 8]}, "fixed": {"load_N": 0.01, "speed_m_s": 0.05}, "budget": 4,
             "validation_points": 0}


@pytest.fixture()
def client(tmp_path):
    settings = Settings(data_dir=tmp_path, api_keys=KEY, max_stored_models=1)
    with TestClient(create_app(settings)) as test_client:
        yield test_client


def _calibration(client: TestClient, seed: int):
    return client.post("/v1/calibrations", json={"data": rows(seed), "fit_parameters": ["mu_pivot"],
                                                 "folds": 2}, headers=bearer(KEY))


def test_past_the_limit_a_new_model_is_a_507_naming_the_setting_and_a_deleted_one_makes_room(client):
    first = finished(client, _calibration(client, 1), KEY)
    surrogate_request = client.post("/v1/surrogates", json=SURROGATE, headers=bearer(KEY))
    for response in (_calibration(client, 2), surrogate_request):
        assert response.status_code == 507, response.text
        assert response.headers["content-type"] == PROBLEM
        problem = response.json()
        assert problem["title"] == "Stored-model limit reached"
        assert "MICROBEARING_MAX_STORED_MODELS = 1" in problem["detail"], problem
        assert "holds 1 stored models" in problem["detail"], problem
    # Nothing was queued by the refusals.
    jobs = client.get("/v1/jobs", headers=bearer(KEY)).json()["jobs"]
    assert [job["kind"] for job in jobs] == ["calibration"]
    assert client.delete(f"/v1/calibrations/{first['id']}", headers=bearer(KEY)).status_code == 204
    surrogate = finished(client, client.post("/v1/surrogates", json=SURROGATE, headers=bearer(KEY)), KEY)
    listed = client.get("/v1/surrogates", headers=bearer(KEY)).json()["surrogates"]
    assert [s["id"] for s in listed] == [surrogate["id"]]


def test_a_job_that_reaches_the_limit_while_running_fails_with_the_problem(client):
    response = _calibration(client, 3)  # admitted: nothing is stored yet
    assert response.status_code == 202, response.text
    store = get_runtime(client.app).store
    store.save_model("surrogate", {"note": "stored while the calibration ran"}, {})  # fills the limit
    job = wait_job(client, response.headers["location"], headers=bearer(KEY), timeout_s=120, interval_s=0.05)
    assert job["status"] == "failed", job
    assert job["error"]["status"] == 507 and "MICROBEARING_MAX_STORED_MODELS" in job["error"]["detail"], job
    with pytest.raises(ModelLimitError):
        store.save_model("surrogate", {}, {})
    assert len(store.list_models()) == 1
