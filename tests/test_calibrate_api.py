"""/v1/calibrations (JSON rows and CSV upload), its plots, the calibrated-model loader and the CLI."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest
from fastapi.testclient import TestClient
from jobs_helper import finished_job

from microbearing import physics
from microbearing.service.calibrations import load_mu_model
from microbearing.service.cli import main
from microbearing.service.deps import get_runtime
from microbearing.service.problems import ProblemError

PROBLEM = "application/problem+json"
N_ROWS = 120
FIT = ["mu_pivot", "adhesion_energy_J_m2"]


def measurements(seed: int, humidity_effect: bool) -> list[dict]:
    """Physics with mu_pivot 0.7, 2 % noise and, optionally, menisci growing with humidity."""
    rng = np.random.default_rng(seed)
    c = {"balls": rng.choice([4, 8, 12], N_ROWS).astype(float),
         "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), N_ROWS)),
         "speed_m_s": rng.uniform(0.0, 0.15, N_ROWS),
         "relative_humidity": rng.uniform(0.2, 0.8, N_ROWS),
         "temperature_C": rng.uniform(20.0, 40.0, N_ROWS)}
    mu = physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"], mu_pivot=0.7).mu
    if humidity_effect:
        mu = mu + c["balls"] * 2e-5 / (c["load_N"] * np.log(1 / c["relative_humidity"]))
    mu = mu * np.exp(rng.normal(0.0, 0.02, N_ROWS))
    return [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(N_ROWS)]


def as_csv(rows: list[dict]) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
    return buffer.getvalue()


def finished_result(client: TestClient, response) -> dict:
    assert response.status_code == 202, response.text
    location = response.headers["location"]
    job = finished_job(client, location, timeout_s=120, interval_s=0.1)
    result = client.get(job["result_url"]).json()
    assert result.pop("kind") == job["kind"]  # the job's kind tags its result
    return result


@pytest.fixture(scope="module")
def humidity_result(client):
    body = {"data": measurements(1, True), "fit_parameters": FIT, "folds": 3}
    return finished_result(client, client.post("/v1/calibrations", json=body))


def assert_problem(response, status: int) -> dict:
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == PROBLEM
    return response.json()


def test_json_calibration_names_the_effect_and_is_stored(client, humidity_result):
    result = humidity_result
    assert result["n_points"] == N_ROWS
    assert result["missing_effect"]["drivers"] == ["relative_humidity"]
    assert [e["label"] for e in result["effects"]] == [result["missing_effect"]["label"]]
    assert result["outliers"]["count"] == 0 and result["noise"] is None
    assert result["error_after"]["relative_rmse"] <= result["error_before"]["relative_rmse"] / 3
    # The nested after-error and the same-fold one of the chosen effect are both reported, with the
    # choice of every fold (3 folds here).
    assert result["error_after_selection"]["relative_rmse"] <= result["error_before"]["relative_rmse"] / 3
    assert result["effect_stability"]["folds"] == len(result["effect_stability"]["choices"]) == 3
    assert all(c["drivers"][:1] == ["relative_humidity"] for c in result["effect_stability"]["choices"])
    assert set(result["fitted_parameters"]) == set(FIT)
    assert result["model_id"] == f"calibrated:{result['id']}"
    assert client.get(f"/v1/calibrations/{result['id']}").json() == result
    for url in result["plots"].values():
        png = client.get(url)
        assert png.status_code == 200 and png.headers["content-type"] == "image/png"
        assert png.content.startswith(b"\x89PNG")
    assert_problem(client.get(f"/v1/calibrations/{result['id']}/plots/nope.png"), 404)
    assert_problem(client.get("/v1/calibrations/0123"), 404)


def test_calibrated_model_loads_by_id_and_predicts_like_the_report(client, humidity_result):
    store = get_runtime(client.app).store
    mu_model = load_mu_model(store, humidity_result["model_id"])
    points = {"balls": np.array([4.0, 8.0]), "load_N": np.array([0.01, 0.02]),
              "speed_m_s": np.array([0.05, 0.1]), "relative_humidity": np.array([0.3, 0.7])}
    fitted = {k: v["value"] for k, v in humidity_result["fitted_parameters"].items()}
    force = humidity_result["missing_effect"]["parameters"]["meniscus_force_N"]
    by_hand = physics.evaluate(**{k: v for k, v in points.items() if k != "relative_humidity"}, **fitted).mu
    by_hand = by_hand + points["balls"] * force / (points["load_N"] * np.log(1 / points["relative_humidity"]))
    np.testing.assert_allclose(mu_model(points), by_hand, rtol=1e-12)
    plain = load_mu_model(store, "physics")
    assert plain({"balls": 4, "load_N": 0.01, "speed_m_s": 0.1}) == physics.evaluate(
        balls=4, load_N=0.01, speed_m_s=0.1).mu
    with pytest.raises(ProblemError) as malformed:
        load_mu_model(store, "calibrated:xyz")
    assert malformed.value.status == 422
    with pytest.raises(ProblemError) as unknown:
        load_mu_model(store, "calibrated:" + "0" * 32)
    assert unknown.value.status == 404


def test_csv_upload_with_fixed_values_and_noise_alone(client):
    rows = measurements(2, False)
    for row in rows:
        row.pop("balls")
    params = [("fit_parameters", "mu_pivot"), ("fixed", "balls=8"), ("folds", "3")]
    rows_fixed = measurements(2, False)
    # The rows were drawn with several ball counts; recompute mu for 8 balls so that the fixed value is true.
    rng = np.random.default_rng(5)
    for row, original in zip(rows, rows_fixed, strict=True):
        mu = physics.evaluate(balls=8, load_N=row["load_N"], speed_m_s=row["speed_m_s"], mu_pivot=0.7).mu
        row["mu_measured"] = float(mu * np.exp(rng.normal(0.0, 0.02)))
        assert row["load_N"] == original["load_N"]
    response = client.post("/v1/calibrations/csv", params=params, content=as_csv(rows),
                           headers={"content-type": "text/csv"})
    result = finished_result(client, response)
    assert result["missing_effect"] is None, result["decision"]
    assert result["fitted_parameters"]["mu_pivot"]["value"] == pytest.approx(0.7, rel=0.05)
    assert result["model"]["fixed"] == {"balls": 8.0}
    assert sorted(result["plots"]) == ["measured_vs_predicted", "residuals"]


def test_bad_rows_are_422_with_a_pointer_per_cell(client):
    rows = measurements(3, False)[:20]
    rows[1]["load_N"] = -1.0
    rows[4]["mu_measured"] = 0.0
    del rows[7]["speed_m_s"]
    problem = assert_problem(client.post("/v1/calibrations", json={"data": rows}), 422)
    pointers = {e["pointer"] for e in problem["errors"]}
    assert pointers == {"/data/1/load_N", "/data/4/mu_measured", "/data/7/speed_m_s"}
    csv_rows = measurements(3, False)[:20]
    csv_rows[0]["speed_m_s"] = -0.1
    text = as_csv(csv_rows)
    csv_problem = assert_problem(client.post("/v1/calibrations/csv", content=text,
                                             headers={"content-type": "text/csv"}), 422)
    # placed as the spreadsheet shows it: the header is line 1, speed_m_s column C
    assert [e["detail"][:40] for e in csv_problem["errors"]] == ["line 2, column C (speed_m_s): speed_m_s "]
    assert [e["pointer"] for e in csv_problem["errors"]] == ["/body"]


@pytest.mark.parametrize(("content", "params", "expected"), [
    (b"\xff\xfeload_N\n", [], {"pointer": "/body", "detail": "CSV is not UTF-8: "}),
    (b"", [], {"pointer": "/body", "detail": "CSV is empty; expected a header row"}),
    (b"balls,load_N,speed_m_s,mu_measured\n4,0.01,0.1,0.01\n,,,\n4,-1,0.1,0.01\n", [],
     {"pointer": "/body", "detail": "line 3: is blank"}),
    (b"balls,load_N,speed_m_s,mu_measured\n4,0.01,0.1,0.01\n,,,\n4,-1,0.1,0.01\n", [],
     {"pointer": "/body", "detail": "line 4, column B (load_N): load_N must be"}),
    (b"load_N,speed_m_s\n0.01,0.1\n", [("fixed", "balls=4")],
     {"pointer": "/body", "detail": "column mu_measured: required column is missing"}),
    (b"balls,load_N,speed_m_s,mu_measured\n4,0.01,0.1,0.01\n", [("fixed", "balls=4")],
     {"parameter": "fixed", "detail": "balls: fixed value given for a data column too"}),
])
def test_csv_problems_point_at_the_body_and_name_row_and_column(client, content, params, expected):
    problem = assert_problem(client.post("/v1/calibrations/csv", params=params, content=content,
                                         headers={"content-type": "text/csv"}), 422)
    assert any(set(e) == set(expected) and all(e[k].startswith(v) for k, v in expected.items())
               for e in problem["errors"]), problem
    assert "None" not in problem["detail"], problem


@pytest.mark.parametrize(("body", "pointer"), [
    ({"fixed": {"mu_pivot": -1}}, "/fixed/mu_pivot"),
    ({"fixed": {"balls": 4}}, "/fixed/balls"),
    ({"fit_parameters": ["balls"]}, "/fit_parameters/0"),
    ({"fit_parameters": ["mu_pivot"], "fixed": {"mu_pivot": 0.5}}, "/fit_parameters"),
    ({"folds": 11}, "/folds"),
    ({"data_rows": 5}, "/data"),
])
def test_bad_requests_name_the_field(client, body, pointer):
    rows = measurements(4, False)[:20]
    request = {"data": rows[:body.pop("data_rows", 20)], **body}
    problem = assert_problem(client.post("/v1/calibrations", json=request), 422)
    assert pointer in [e.get("pointer") for e in problem["errors"]], problem


def test_cli_prints_the_report_and_writes_plots_and_json(tmp_path, capsys):
    data = tmp_path / "data.csv"
    data.write_text(as_csv(measurements(1, True)))
    code = main(["calibrate", str(data), "--fit", ",".join(FIT), "--folds", "3", "--no-store",
                 "--plots", str(tmp_path / "plots"), "--json", str(tmp_path / "report.json")])
    out = capsys.readouterr().out
    assert code == 0
    assert "missing effect: humidity_meniscus" in out and "driven by relative_humidity" in out
    plots = sorted(p.name for p in (tmp_path / "plots").iterdir())
    assert plots == ["effect_1.png", "measured_vs_predicted.png", "residuals.png"]
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["model"]["terms"][0]["name"] == "humidity_meniscus"
    data.write_text("balls,load_N,speed_m_s,mu_measured\n4,-1,0.1,0.01\n")
    assert main(["calibrate", str(data)]) == 2
    assert "row 1, column load_N" in capsys.readouterr().err


def test_friction_answers_with_a_calibrated_model(client, humidity_result):
    point = {"balls": 8, "load_N": 0.015, "speed_m_s": 0.08}
    body = {**point, "model": humidity_result["model_id"], "conditions": {"relative_humidity": 0.6}}
    answer = client.post("/v1/friction", json=body)
    assert answer.status_code == 200, answer.text
    answer = answer.json()
    fitted = {k: v["value"] for k, v in humidity_result["fitted_parameters"].items()}
    declared = physics.evaluate(**point, **fitted)
    force = humidity_result["missing_effect"]["parameters"]["meniscus_force_N"]
    effect = 8 * force / (0.015 * np.log(1 / 0.6))
    assert answer["mu_pivoting"] == pytest.approx(float(declared.mu_pivoting), rel=1e-12)
    assert answer["mu_effect"] == pytest.approx(effect, rel=1e-9)
    assert answer["mu"] == pytest.approx(float(declared.mu) + effect, rel=1e-12)
    assert answer["model"] == humidity_result["model_id"]
    # A 95 % interval around mu, inside the data's ranges.
    assert answer["mu_lower"] < answer["mu"] < answer["mu_upper"] < 1.2 * answer["mu"]
    assert answer["in_domain"] is True and answer["domain_warnings"] == []
    # Far outside the data: answered, but flagged, naming the column and its range.
    wet = client.post("/v1/friction", json={**body, "conditions": {"relative_humidity": 0.97}}).json()
    assert wet["in_domain"] is False
    warning = wet["domain_warnings"][0]
    assert warning.startswith("relative_humidity = 0.97") and "range [0.2" in warning
    heavy = client.post("/v1/friction", json={**body, "load_N": 0.5}).json()
    assert heavy["in_domain"] is False and heavy["domain_warnings"][0].startswith("load_N = 0.5 [N]")
    assert heavy["mu_upper"] / heavy["mu_lower"] > answer["mu_upper"] / answer["mu_lower"]
    # An unknown condition key, or a missing one the effect needs, is a 422 naming it.
    unknown = assert_problem(client.post("/v1/friction", json={**body, "conditions": {
        "relative_humidity": 0.6, "humidity_typo": 0.5}}), 422)
    assert unknown["errors"][0]["pointer"] == "/conditions/humidity_typo"
    without_conditions = {**point, "model": humidity_result["model_id"]}
    missing = assert_problem(client.post("/v1/friction", json=without_conditions), 422)
    assert "relative_humidity" in missing["detail"]
    assert_problem(client.post("/v1/friction", json={**point, "model": "calibrated:" + "0" * 32}), 404)
    assert_problem(client.post("/v1/friction", json={**point, "conditions": {"relative_humidity": 0.6}}), 422)
    plain = client.post("/v1/friction", json=point).json()
    assert "model" not in plain and plain["mu"] == float(physics.evaluate(**point).mu)


def test_a_surrogate_learns_the_calibrated_model(client, humidity_result):
    model_id = humidity_result["model_id"]
    space = {"balls": [4, 12], "load_N": [0.003, 0.03], "speed_m_s": [0.01, 0.15]}
    body = {"space": space, "budget": 60, "target_relative_error": 1e-3, "model": model_id,
            "conditions": {"relative_humidity": 0.6}}
    trained = finished_result(client, client.post("/v1/surrogates", json=body))
    assert trained["model"] == model_id and trained["conditions"] == {"relative_humidity": 0.6}
    assert client.get(f"/v1/surrogates/{trained['id']}").json() == trained
    # each input whose range in the space leaves the calibration data is said, with the data's range
    domain = humidity_result["model"]["domain"]
    wider = {name for name, (low, high) in {**space, "relative_humidity": (0.6, 0.6)}.items()
             if name in domain and (low < domain[name][0] or high > domain[name][1])}
    said = {w.split(" ")[0] for w in trained["warnings"] if f"reaches outside the data of {model_id}" in w}
    assert wider and said == wider, (trained["warnings"], domain)
    stated = trained["metrics"]
    assert stated["n_test"] > 1000 and stated["median_relative_error"] < 0.01
    # 32 points of the space (not the test design), drawn as the held-out design is (log-uniform load
    # and speed, the space's scales): the calibrated model's own /v1/friction answers.
    rng = np.random.default_rng(7)
    points = {"balls": rng.integers(4, 13, 32).tolist(),
              "load_N": np.exp(rng.uniform(np.log(0.003), np.log(0.03), 32)).tolist(),
              "speed_m_s": np.exp(rng.uniform(np.log(0.01), np.log(0.15), 32)).tolist()}
    predicted = client.post(f"/v1/surrogates/{trained['id']}/predict", json={"points": points})
    assert predicted.status_code == 200, predicted.text
    assert set(trained["warnings"]) <= set(predicted.json()["warnings"])  # said with every prediction
    mu = np.array(predicted.json()["mu"])
    truth = np.array([client.post("/v1/friction", json={
        "balls": points["balls"][i], "load_N": points["load_N"][i], "speed_m_s": points["speed_m_s"][i],
        "model": model_id, "conditions": {"relative_humidity": 0.6}}).json()["mu"] for i in range(32)])
    error = np.abs(mu / truth - 1)
    assert np.median(error) <= 2 * stated["median_relative_error"]
    assert np.max(error) <= 3 * stated["p95_relative_error"]
    # The plain physics (defaults, no humidity effect) is far from what the surrogate learned.
    plain = physics.evaluate(**{k: np.array(v) for k, v in points.items()}).mu
    assert np.median(np.abs(mu / plain - 1)) > 50 * stated["median_relative_error"]
    # Errors: unknown calibration, missing condition, conditions for the physics, another convention.
    unknown = {**body, "model": "calibrated:" + "0" * 32}
    assert_problem(client.post("/v1/surrogates", json=unknown), 404)
    missing = assert_problem(client.post("/v1/surrogates", json={**body, "conditions": None}), 422)
    assert missing["errors"][0]["pointer"] == "/conditions"
    assert "relative_humidity" in missing["errors"][0]["detail"]
    for_physics = assert_problem(client.post("/v1/surrogates", json={**body, "model": "physics"}), 422)
    assert for_physics["errors"][0]["pointer"] == "/conditions"
    other = next(c for c in physics.CONVENTIONS if c != humidity_result["model"]["convention"])
    convention = assert_problem(client.post("/v1/surrogates", json={**body, "convention": other}), 422)
    assert convention["errors"][0]["pointer"] == "/convention"
    saturated = {**body, "conditions": {"relative_humidity": 1.0}}  # log(1/RH) = 0: mu infinite
    dry = assert_problem(client.post("/v1/surrogates", json=saturated), 422)
    # at the condition as sent, the law's domain in words
    assert dry["errors"][0]["pointer"] == "/conditions/relative_humidity", dry
    assert "value 1 lies outside" in dry["errors"][0]["detail"], dry


def test_a_surrogate_of_a_calibration_with_fixed_values_inherits_them(client):
    rows = [{k: v for k, v in row.items() if k != "balls"} for row in measurements(6, False)]
    body = {"data": rows, "fixed": {"balls": 8}, "fit_parameters": ["mu_pivot"], "folds": 3}
    calibration = finished_result(client, client.post("/v1/calibrations", json=body))
    space = {"load_N": [0.003, 0.03], "speed_m_s": [0.01, 0.15]}
    request = {"space": space, "budget": 20, "model": calibration["model_id"]}
    trained = finished_result(client, client.post("/v1/surrogates", json=request))
    assert trained["fixed"] == {"balls": 8.0}
    point = {"load_N": 0.01, "speed_m_s": 0.1}
    mu = client.post(f"/v1/surrogates/{trained['id']}/predict", json={"points": point}).json()["mu"][0]
    friction = client.post("/v1/friction", json={**point, "balls": 8, "model": calibration["model_id"]})
    assert mu == pytest.approx(friction.json()["mu"], rel=0.01)
    # Without the calibrated model there is no ball count: the physics needs one.
    problem = assert_problem(client.post("/v1/surrogates", json={**request, "model": "physics"}), 422)
    assert problem["errors"][0]["pointer"] == "/space"


def test_a_calibration_stored_before_intervals_still_loads_and_answers(client):
    # The report and model as version 1 stored them: one effect, no covariance, no domain, old plot names.
    errors = {"rmse": 0.001, "relative_rmse": 0.02, "max_abs_error": 0.004}
    model = {"format_version": 1, "convention": "olaru2005", "fixed": {}, "fitted": {"mu_pivot": 0.7},
             "effect": {"name": "constant_drag", "drivers": ["load_N"], "parameters": {"drag_force_N": 1e-4},
                        "constants": {}}}
    report = {"n_points": 120, "fit_parameters": ["mu_pivot"], "error_default": errors,
              "fitted_declared": {"mu_pivot": {"value": 0.6, "std": 0.01}},
              "fitted_parameters": {"mu_pivot": {"value": 0.7, "std": 0.01}}, "error_before": errors,
              "error_after": errors, "missing_effect": None, "discrepancy_gp": {
                  "errors": errors, "features": [], "length_scales": {}, "noise_std_log": None,
                  "max_train_rows": 300}, "candidates": [], "decision": "nothing added", "folds": 3,
              "model": model, "plots": ["residual"]}
    store = get_runtime(client.app).store
    old_id = store.save_model("calibration", {"report": report, "model": model},
                              {"residual": np.frombuffer(b"\x89PNG old", dtype=np.uint8)})
    shown = client.get(f"/v1/calibrations/{old_id}")
    assert shown.status_code == 200 and shown.json()["plots"] == {
        "residual": f"/v1/calibrations/{old_id}/plots/residual.png"}
    assert client.get(f"/v1/calibrations/{old_id}/plots/residual.png").content == b"\x89PNG old"
    answer = client.post("/v1/friction", json={"balls": 4, "load_N": 0.01, "speed_m_s": 0.1,
                                                "model": f"calibrated:{old_id}"})
    assert answer.status_code == 200, answer.text
    answer = answer.json()
    expected = float(physics.evaluate(balls=4, load_N=0.01, speed_m_s=0.1, mu_pivot=0.7).mu) + 1e-4 / 0.01
    assert answer["mu"] == pytest.approx(expected, rel=1e-12)
    assert answer["mu_lower"] is None and answer["in_domain"] is None and answer["domain_warnings"] == []
