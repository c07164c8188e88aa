"""A humidity whose name carries a bare % (``RH%``, ``humidity_%``, ``%RH``: what lab exports write) is in
percent, as ``RH [%]`` is, at the upload and at prediction (issue 32's seams, third sweep).

Before: ``RH%`` was a column of fractions named ``RH%``, so the upload refused its 45 as "values look like
percent ... name the column RH%_pct", and the key ``RH%`` was unknown at prediction."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient
from jobs_helper import finished_job

from bench.calibrated_batch import measurements
from microbearing.calibrate.tabular import read_csv
from microbearing.physics.columns import match_column, read_name
from microbearing.physics.slips import read_slip
from microbearing.service.app import create_app
from microbearing.service.settings import Settings

POINT = {"balls": 4, "load_N": 0.01, "speed_m_s": 0.05}


@pytest.mark.parametrize("sent", ["RH%", "RH_%", "rh %", "Humidity %", "humidity_%", "%RH", "% RH"])
def test_a_bare_percent_sign_beside_a_humidity_is_its_unit(sent):
    reading = read_name(sent)
    assert reading.convert(45.0) == pytest.approx(0.45, rel=1e-12)
    assert match_column(sent, ["relative_humidity"]).convert(45.0) == pytest.approx(0.45, rel=1e-12)
    assert read_slip(reading, [45.0]) is None
    # judged in percent: 120 % is no humidity, 0.5 % is a dry room, not a fraction of 50 %
    assert "lies in [0, 100]" in read_slip(reading, [120.0])
    assert read_slip(reading, [0.5]) is None
    dataset, _ = read_csv(f"balls,load_N,speed_m_s,{sent},mu_measured\n4,0.01,0.05,45,0.01\n")
    assert [float(v[0]) for v in dataset.conditions.values()] == [pytest.approx(0.45, rel=1e-12)]


@pytest.mark.parametrize("sent", ["strain%", "load%"])
def test_a_percent_sign_beside_another_quantity_is_not_read_as_a_humidity(sent):
    assert read_name(sent).name == sent and read_name(sent).convert(45.0) == 45.0


def test_an_upload_with_rh_percent_calibrates_and_predicts_under_that_key(tmp_path):
    rows = [{("RH%" if k == "relative_humidity" else k): (100.0 * v if k == "relative_humidity" else v)
             for k, v in row.items()} for row in measurements(3)]
    with TestClient(create_app(Settings(data_dir=tmp_path))) as client:
        job = finished_job(client, client.post("/v1/calibrations", json={
            "data": rows, "fit_parameters": ["mu_pivot"], "folds": 3}), timeout_s=600)
        result = client.get(job["result_url"]).json()
        assert [e["name"] for e in result["effects"]] == ["humidity_meniscus"], result["decision"]
        model = result["model_id"]
        column = result["model"]["conditions"][0]
        # the model's column holds the fraction (45 % is 0.45): the same answer by its own name
        by_name = client.post("/v1/friction", json={**POINT, "model": model, "conditions": {column: 0.45}})
        by_sign = client.post("/v1/friction", json={**POINT, "model": model, "conditions": {"RH%": 45}})
        assert by_name.status_code == by_sign.status_code == 200, by_sign.text
        for name in ("mu", "mu_lower", "mu_upper"):
            assert by_sign.json()[name] == pytest.approx(by_name.json()[name], rel=1e-12)
        refused = client.post("/v1/friction", json={**POINT, "model": model, "conditions": {"RH%": 4500}})
        assert refused.status_code == 422 and refused.headers["content-type"] == "application/problem+json"
        assert [e["pointer"] for e in refused.json()["errors"]] == ["/conditions/RH%"], refused.text
