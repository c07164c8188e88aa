"""Every size bounded before work starts: calibration columns (413) and a sweep's result size at submit.

The sweep bound is checked against real results: it exceeds the result's JSON length by exactly
what the values not known before the computation (outputs, and a sampled design's inputs) fall
short of the longest form of a double, counted here value by value from the result itself.
"""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from fastapi.testclient import TestClient
from jobs_helper import finished_job
from pydantic import TypeAdapter

from microbearing.service.app import create_app
from microbearing.service.schemas.sweeps import SweepRequest
from microbearing.service.settings import Settings
from microbearing.service.store import json_bytes
from microbearing.service.sweeps import (
    MAX_NUMBER_BYTES,
    design_columns,
    design_size,
    result_bytes_bound,
    run_sweep,
)

PROBLEM = "application/problem+json"
LIMIT = 200_000


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    settings = Settings(data_dir=tmp_path_factory.mktemp("bounds"), max_calibration_rows=5,
                        max_calibration_columns=6, max_result_bytes=LIMIT, sweep_sync_max_points=0)
    with TestClient(create_app(settings)) as test_client:
        yield test_client


def csv_body(columns: int, rows: int = 3) -> bytes:
    names = ["balls", "load_N", "speed_m_s", "mu_measured"] + [f"extra_{i}" for i in range(columns - 4)]
    row = ["4", "0.01", "-0.1", "0.02"] + ["1.0"] * (columns - 4)  # a bad speed: 422 once read
    return ("\n".join([",".join(names), *[",".join(row)] * rows]) + "\n").encode()


@pytest.mark.parametrize("columns, status", [(6, 422), (7, 413), (20_000, 413)])
def test_calibration_columns_past_the_limit_get_413_before_parsing(client, columns, status):
    csv = client.post("/v1/calibrations/csv", content=csv_body(columns), headers={"content-type": "text/csv"})
    row = dict(zip(csv_body(columns).decode().splitlines()[0].split(","),
                   [4.0, 0.01, -0.1, 0.02] + [1.0] * (columns - 4), strict=True))
    rows = client.post("/v1/calibrations", json={"data": [row, row]})
    for response in (csv, rows):
        assert response.status_code == status, response.text[:300]
        assert response.headers["content-type"] == PROBLEM
        if status == 413:
            detail = response.json()["detail"]
            if response is rows and columns > 6 + 256:  # refused as it streams, at the object's 263rd key
                assert "more than 262 members; the limit is 262 (it follows " \
                       "MICROBEARING_MAX_CALIBRATION_COLUMNS" in detail, detail
            else:
                assert f"has {columns} columns; the limit is 6 (MICROBEARING_MAX_CALIBRATION_COLUMNS)" \
                    in detail


@pytest.mark.parametrize("separator, query", [(";", ""), ("\t", ""), (";", "?separator=semicolon")])
def test_a_semicolon_or_tab_header_past_the_limit_gets_413_before_parsing(client, separator, query):
    # Excel's European CSV: the header is split on the separator the parser will use (detected or stated).
    body = csv_body(7).decode().replace(",", separator).encode()
    response = client.post(f"/v1/calibrations/csv{query}", content=body, headers={"content-type": "text/csv"})
    assert response.status_code == 413, response.text[:300]
    assert "has 7 columns; the limit is 6 (MICROBEARING_MAX_CALIBRATION_COLUMNS)" in response.json()["detail"]
    # Within the limit, the same file is read (and its bad speed named): the count does not over-refuse.
    body = csv_body(6).decode().replace(",", separator).encode()
    response = client.post(f"/v1/calibrations/csv{query}", content=body, headers={"content-type": "text/csv"})
    assert response.status_code == 422 and "speed" in response.text, response.text[:300]


def test_the_default_column_limit_refuses_the_20000_column_csv(tmp_path):
    with TestClient(create_app(Settings(data_dir=tmp_path))) as test_client:
        response = test_client.post("/v1/calibrations/csv", content=csv_body(20_000, rows=30),
                                    headers={"content-type": "text/csv"})
    assert response.status_code == 413 and "limit is 64" in response.json()["detail"]


def test_no_double_takes_more_json_than_the_bound():
    rng = np.random.default_rng(7)
    bits = rng.integers(0, 2**64, size=20_000, dtype=np.uint64)
    values = [v for v in (struct.unpack("<d", struct.pack("<Q", int(b)))[0] for b in bits) if np.isfinite(v)]
    extremes = [-2.2250738585072014e-308, -1.7976931348623157e308, 5e-324, -1.2345678901234567e-100]
    lengths = [len(json_bytes(v)) for v in values + extremes]
    assert max(lengths) == MAX_NUMBER_BYTES  # reached, never passed


SWEEPS = [
    {"design": "grid", "axes": {"load_N": {"start": 1e-3, "stop": 0.05, "num": 37},
                                "balls": {"start": 2, "stop": 12, "num": 11}},
     "fixed": {"speed_m_s": 0.05}, "outputs": ["mu", "friction_force_N"]},
    {"design": "grid", "axes": {"speed_m_s": {"start": 1e-4, "stop": 0.2, "num": 50, "spacing": "log"}},
     "fixed": {"balls": 4, "load_N": 0.01}},  # every output
    {"design": "sobol", "points": 256, "ranges": {"load_N": {"low": 1e-3, "high": 0.05},
                                                  "speed_m_s": {"low": 0.0, "high": 0.2}},
     "fixed": {"balls": 5}, "outputs": ["mu"]},
    {"design": "latin_hypercube", "points": 300, "ranges": {"groove_angle_deg": {"low": 30.0, "high": 80.0}},
     "fixed": {"balls": 5, "load_N": 0.01, "speed_m_s": 0.1}, "outputs": ["mu", "mu_rolling"]},
]


@pytest.mark.parametrize("sweep", SWEEPS, ids=lambda s: s["design"])
def test_the_bound_is_exact_but_for_the_digits_of_the_unknown_values(sweep):
    body = TypeAdapter(SweepRequest).validate_json(json.dumps(sweep))
    count = design_size(body, 10**7)
    bound = result_bytes_bound(body, count)
    result = run_sweep(body, design_columns(body, 10**7))
    actual = len(json_bytes(result))
    unknown = result["columns"].keys() - (set(result["varied"]) if sweep["design"] == "grid" else set())
    shortfall = sum(MAX_NUMBER_BYTES - len(json_bytes(value))
                    for name in unknown for value in np.asarray(result["columns"][name]).tolist())
    assert bound - actual == shortfall
    assert actual <= bound


def sobol_sweep(points: int) -> dict:
    return {"design": "sobol", "points": points, "ranges": {"load_N": {"low": 1e-3, "high": 0.05}},
            "fixed": {"balls": 4, "speed_m_s": 0.05}, "outputs": ["mu"]}


def test_a_sweep_is_refused_at_submit_exactly_past_the_bound_and_never_fails_for_its_size(client):
    adapter = TypeAdapter(SweepRequest)

    def bound(points: int) -> int:
        return result_bytes_bound(adapter.validate_json(json.dumps(sobol_sweep(points))), points)

    largest = max(p for p in range(3000, 5000) if bound(p) <= LIMIT)  # found by brute force
    refused = client.post("/v1/sweeps", json=sobol_sweep(largest + 1))
    assert refused.status_code == 413 and refused.headers["content-type"] == PROBLEM
    assert f"up to {bound(largest + 1)} bytes" in refused.json()["detail"]
    accepted = client.post("/v1/sweeps", json=sobol_sweep(largest))
    assert accepted.status_code == 202, accepted.text
    job_url = accepted.headers["location"]
    finished_job(client, job_url)
    assert len(client.get(f"{job_url}/result").content) <= LIMIT + len('"kind":"sweep",')
