"""Deleting a calibration or a surrogate erases its data: from the API and from the store's files.

A calibration's specimens carry labels found nowhere else; before the DELETE they are in SQLite's
files (so the search below can find them), after it in none of them (the database, its write-ahead
log), and on both backends every job that made or used the model answers 410 for its result.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from jobs_helper import finished_job

from microbearing import physics
from microbearing.service.app import create_app
from microbearing.service.settings import Settings

LABELS = [f"ERASE-ME-{i}-7f3a9c" for i in range(1, 5)]


def rows() -> list[dict]:
    rng = np.random.default_rng(5)
    data = []
    for label, level in zip(LABELS, (0.95, 1.0, 1.05, 1.1), strict=True):
        load = rng.uniform(3e-3, 3e-2, 6)
        speed = rng.uniform(0.02, 0.15, 6)
        mu = physics.evaluate(balls=4, load_N=load, speed_m_s=speed).mu * level
        data += [{"balls": 4, "load_N": float(f), "speed_m_s": float(v), "specimen": label,
                  "mu_measured": float(m)} for f, v, m in zip(load, speed, mu, strict=True)]
    return data


def stored_bytes(data_dir: Path) -> bytes:
    return b"".join(path.read_bytes() for path in sorted(data_dir.rglob("*")) if path.is_file())


@pytest.fixture
def served(database):
    """An app on a new database of each backend (SQLite's files are searched; PostgreSQL's are its own)."""
    settings = Settings(data_dir=database.folder, sweep_sync_max_points=0, **database.settings())
    with TestClient(create_app(settings)) as client:
        yield client, database.folder if database.url is None else None


def test_deleting_a_calibration_erases_its_rows_from_every_job_and_the_files(served):
    client, data_dir = served
    made = finished_job(client, client.post("/v1/calibrations", json={
        "data": rows(), "fit_parameters": ["mu_pivot"], "factors": ["specimen"], "folds": 3}), timeout_s=300)
    result = client.get(made["result_url"]).json()
    calibration = result["id"]
    used = finished_job(client, client.post("/v1/optimizations", json={
        "bounds": {"balls": [3, 8], "groove_angle_deg": [40, 60], "load_N": [0.005, 0.03]},
        "speed_m_s": 0.05, "model": f"calibrated:{calibration}", "starts": 1}), timeout_s=300)
    other = finished_job(client, client.post("/v1/sweeps", json={
        "design": "sobol", "points": 16, "seed": 1, "outputs": ["mu"],
        "ranges": {"load_N": {"low": 1e-3, "high": 0.05}}, "fixed": {"balls": 4, "speed_m_s": 0.05}}))
    if data_dir is not None:
        assert all(label.encode() in stored_bytes(data_dir) for label in LABELS)  # the search finds them

    assert client.delete(f"/v1/calibrations/{calibration}").status_code == 204

    for job in (made, used):
        answer = client.get(f"/v1/jobs/{job['id']}/result")
        assert answer.status_code == 410, answer.text
        assert answer.headers["content-type"] == "application/problem+json"
        assert "erased" in answer.json()["detail"] and "deleted" in answer.json()["detail"]
        view = client.get(f"/v1/jobs/{job['id']}").json()
        assert view["status"] == "succeeded" and view["erased_at"] and view["result_url"] is None
    assert client.get(f"/v1/jobs/{other['id']}/result").status_code == 200  # a job that did not name it
    assert client.get(f"/v1/calibrations/{calibration}").status_code == 404
    if data_dir is not None:
        files = stored_bytes(data_dir)
        assert not [label for label in LABELS if label.encode() in files]


def test_deleting_a_surrogate_erases_its_training_job_result(served):
    client, _ = served
    made = finished_job(client, client.post("/v1/surrogates", json={
        "space": {"load_N": [1e-3, 0.05]}, "fixed": {"balls": 4, "speed_m_s": 0.05}, "budget": 12,
        "target_relative_error": 1e-6, "validation_points": 0}), timeout_s=300)
    surrogate = client.get(made["result_url"]).json()["id"]
    assert client.delete(f"/v1/surrogates/{surrogate}").status_code == 204
    assert client.get(f"/v1/jobs/{made['id']}/result").status_code == 410
    assert client.get(f"/v1/surrogates/{surrogate}").status_code == 404
