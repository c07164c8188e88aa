"""POST /v1/optimizations: certified optima at once, jobs, infeasibility, Pareto plots, other models."""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient
from jobs_helper import finished_job

from microbearing import physics
from microbearing.calibrate import CalibratedModel
from microbearing.calibrate.candidates import EffectTerm
from microbearing.optimize import Constraints, DesignBounds, DesignProblem, optimize_design
from microbearing.service.deps import get_runtime
from microbearing.service.optimizations import INFEASIBLE_TYPE

PROBLEM = "application/problem+json"
ISSUE_EXAMPLE = {"bounds": {"balls": [4, 24], "groove_angle_deg": [35, 70], "load_N": [0.001, 0.05]},
                 "fixed": {"speed_m_s": 0.05, "mu_pivot": 1.0},
                 "constraints": {"max_contact_pressure_Pa": 1e9}}


def finished(client: TestClient, response) -> dict:
    assert response.status_code == 202, response.text
    location = response.headers["location"]
    job = finished_job(client, location, timeout_s=120, interval_s=0.05)
    result = client.get(job["result_url"])
    assert result.status_code == 200
    return {"job": job, **result.json()}


def test_issue_example_answers_at_once_with_a_checked_optimum(client):
    response = client.post("/v1/optimizations", json=ISSUE_EXAMPLE)
    assert response.status_code == 200, response.text
    body = response.json()
    design = body["design"]
    assert 4 <= design["balls"] <= 24 and 35 <= design["groove_angle_deg"] <= 70
    exact = physics.evaluate(balls=design["balls"], groove_angle_deg=design["groove_angle_deg"],
                             load_N=design["load_N"], speed_m_s=0.05, mu_pivot=1.0)
    assert body["mu"] == pytest.approx(float(exact.mu), rel=1e-12)
    assert body["mu_physics"] == body["mu"]  # the physics is its own exact model
    assert float(exact.max_contact_pressure_Pa) <= 1e9
    library = optimize_design(DesignProblem(DesignBounds((4, 24), (35, 70), (0.001, 0.05)), speed_m_s=0.05,
                                            fixed={"mu_pivot": 1.0},
                                            constraints=Constraints(max_contact_pressure_Pa=1e9)))
    assert body["mu"] == pytest.approx(library.mu, rel=1e-8)
    assert body["model"] == "physics" and body["method"] == "dgp-enumeration"
    assert {c["name"] for c in body["constraints"]} >= {"max_contact_pressure_Pa", "load_N_max"}
    assert all(c["satisfied"] for c in body["constraints"])
    assert [r["balls"] for r in body["per_ball_count"]] == list(range(4, 25))
    assert body["ties"] and "global" in body["certificate"].lower()


def test_speed_range_at_top_level_designs_for_its_upper_end(client):
    request = {**ISSUE_EXAMPLE, "fixed": {"mu_pivot": 1.0}, "speed_m_s": [0.01, 0.08]}
    body = client.post("/v1/optimizations", json=request).json()
    assert body["speed_m_s"] == 0.08 and "worst case" in body["certificate"]


def test_infeasible_limits_answer_422_naming_them(client):
    # the pressure of 10 balls at 40 deg under 0.01 N is the least any design carrying 0.01 N can have
    pressure = float(physics.evaluate(balls=10, groove_angle_deg=40.0, load_N=0.01, speed_m_s=0.05)
                     .max_contact_pressure_Pa)
    request = {"bounds": {"balls": [4, 10], "groove_angle_deg": [40, 60], "load_N": [0.001, 0.05]},
               "speed_m_s": 0.05,
               "constraints": {"max_contact_pressure_Pa": 0.999 * pressure, "min_load_capacity_N": 0.01}}
    response = client.post("/v1/optimizations", json=request)
    assert response.status_code == 422 and response.headers["content-type"].startswith(PROBLEM)
    problem = response.json()
    assert problem["type"] == "urn:microbearing:problem:infeasible-design"
    pointers = {e["pointer"] for e in problem["errors"]}
    assert {"/constraints/max_contact_pressure_Pa", "/constraints/min_load_capacity_N"} <= pointers
    assert "/constraints/max_friction_force_N" not in pointers


@pytest.mark.parametrize("change, pointer", [
    ({"fixed": {}}, "/speed_m_s"),
    ({"speed_m_s": 0.1}, "/speed_m_s"),
    ({"fixed": {}, "speed_m_s": [0.2, 0.1]}, "/speed_m_s"),
    ({"bounds": {"balls": [9, 4], "groove_angle_deg": [35, 70], "load_N": [0.001, 0.05]}}, "/bounds/balls"),
    ({"fixed": {"speed_m_s": 0.05, "load_N": 0.01}}, "/fixed/load_N"),
    ({"model": "newton"}, "/model"),
    ({"constraints": {"max_contact_pressure_Pa": -1.0}}, "/constraints/max_contact_pressure_Pa"),
    ({"model": "calibrated:" + "0" * 32, "pareto": {"objective": "load_N"}}, "/pareto"),
    ({"conditions": {"relative_humidity": 0.5}}, "/conditions"),
    ({"conditions": {"relative_humidity": "wet"}}, "/conditions/relative_humidity"),
])
def test_invalid_requests_name_the_field(client, change, pointer):
    response = client.post("/v1/optimizations", json={**ISSUE_EXAMPLE, **change})
    assert response.status_code == 422 and response.headers["content-type"].startswith(PROBLEM)
    assert pointer in {e.get("pointer") for e in response.json()["errors"]}, response.json()


@pytest.mark.parametrize("model", ["calibrated:" + "a" * 32, "surrogate:" + "b" * 32])
def test_unknown_models_are_404(client, model):
    response = client.post("/v1/optimizations", json={**ISSUE_EXAMPLE, "model": model})
    assert response.status_code == 404 and response.headers["content-type"].startswith(PROBLEM)


def test_pareto_front_runs_as_a_job_with_a_png(client):
    bounds = {"balls": [4, 8], "groove_angle_deg": [35, 70], "load_N": [0.001, 0.05]}
    pareto = {"objective": "max_contact_pressure_Pa", "points": 4}
    request = {**ISSUE_EXAMPLE, "bounds": bounds, "pareto": pareto}
    result = finished(client, client.post("/v1/optimizations", json=request))
    front = result["pareto"]
    assert front["objective"] == "max_contact_pressure_Pa" and len(front["points"]) >= 2
    assert all(p["value"] <= 1e9 for p in front["points"])
    assert front["plot_url"] == f"/v1/optimizations/{result['job']['id']}/pareto.png"
    png = client.get(front["plot_url"])
    assert png.status_code == 200 and png.headers["content-type"] == "image/png"
    assert png.content.startswith(b"\x89PNG")
    assert client.get("/v1/optimizations/nosuchjob/pareto.png").status_code == 404


def test_wide_ball_count_range_runs_as_a_job(client):
    bounds = {"balls": [3, 60], "groove_angle_deg": [35, 70], "load_N": [0.001, 0.05]}
    request = {**ISSUE_EXAMPLE, "bounds": bounds}
    result = finished(client, client.post("/v1/optimizations", json=request))
    assert len(result["per_ball_count"]) == 58 and all(c["satisfied"] for c in result["constraints"])
    png = client.get(f"/v1/optimizations/{result['job']['id']}/pareto.png")
    assert png.status_code == 404  # no front was asked for
    # the result is no table: JSON wherever the Accept header admits it, even below CSV; 406 where it does not
    path = f"/v1/jobs/{result['job']['id']}/result"
    preferring_csv = client.get(path, headers={"accept": "application/json;q=0.1, text/csv"})
    assert preferring_csv.status_code == 200 and preferring_csv.headers["content-type"] == "application/json"
    assert preferring_csv.json()["per_ball_count"] == result["per_ball_count"]
    assert client.get(path, headers={"accept": "text/csv"}).status_code == 406


def test_calibrated_model_is_optimized_locally_with_its_fitted_values(client):
    store = get_runtime(client.app).store
    model = CalibratedModel(fitted={"mu_pivot": 0.8})
    model_id = store.save_model("calibration", {"model": model.to_json()}, {})
    request = {"bounds": {"balls": [4, 8], "groove_angle_deg": [40, 60], "load_N": [0.001, 0.05]},
               "speed_m_s": 0.05, "model": f"calibrated:{model_id}"}
    result = finished(client, client.post("/v1/optimizations", json=request))
    assert result["method"] == "sequential-convex-approximation"
    assert "not a global proof" in result["certificate"]
    # the calibrated model is the physics with mu_pivot 0.8: its certified optimum is the reference
    reference = optimize_design(DesignProblem(DesignBounds((4, 8), (40, 60), (0.001, 0.05)), speed_m_s=0.05,
                                              fixed={"mu_pivot": 0.8}))
    assert result["mu"] == pytest.approx(reference.mu, rel=1e-4)
    assert result["mu"] >= reference.mu * (1 - 1e-7)


def test_surrogate_model_is_optimized_locally_and_verified(client):
    space = {"balls": [4, 8], "groove_angle_deg": [40, 60], "load_N": [0.002, 0.05]}
    training = {"space": space, "fixed": {"speed_m_s": 0.05}, "budget": 40, "adaptive": False}
    surrogate = finished(client, client.post("/v1/surrogates", json=training))
    request = {"bounds": {"balls": [4, 8], "groove_angle_deg": [40, 60], "load_N": [0.002, 0.05]},
               "speed_m_s": 0.05, "model": surrogate["model_id"], "starts": 2}
    result = finished(client, client.post("/v1/optimizations", json=request))
    assert result["method"] == "sequential-convex-approximation" and result["model"] == surrogate["model_id"]
    design = result["design"]
    # the reported mu is the surrogate's own prediction at the design, asked for independently
    predicted = client.post(f"/v1/surrogates/{surrogate['id']}/predict", json={"points": {
        "balls": design["balls"], "groove_angle_deg": design["groove_angle_deg"], "load_N": design["load_N"],
        "speed_m_s": 0.05}}).json()
    assert result["mu"] == pytest.approx(predicted["mu"][0], rel=1e-9)
    exact = physics.evaluate(speed_m_s=0.05, **design).mu
    assert result["mu_physics"] == pytest.approx(float(exact), rel=1e-12)
    # a 40-point surrogate is not the physics: its optimum is close to, never below, the certified one
    certified = optimize_design(DesignProblem(DesignBounds((4, 8), (40, 60), (0.002, 0.05)), speed_m_s=0.05))
    assert certified.mu * (1 - 1e-9) <= result["mu_physics"] <= certified.mu * 1.1
    # verified by the source (the physics): both values of mu, and the limits judged by the physics
    assert result["source_model"] == "physics" and result["mu_source"] == result["mu_physics"]
    report = result["verification"]
    assert report["mu_model"] == result["mu"] and report["mu_source"] == result["mu_source"]
    assert report["relative_difference"] == pytest.approx(result["mu"] / result["mu_source"] - 1, rel=1e-12)
    assert report["satisfied"] and all(c["satisfied"] and c["decided_by"] == "physics"
                                       for c in result["constraints"])
    # inside its trained space: its interval at the design, no warning
    assert result["in_domain"] is True and result["domain_warnings"] == []
    assert result["mu_lower"] < result["mu"] < result["mu_upper"]
    # bounds beyond the space: mu rises with the angle, so the design lies below the trained 40 deg and
    # is said to be an extrapolation, input by input
    wider = finished(client, client.post("/v1/optimizations", json={
        **request, "bounds": {**request["bounds"], "groove_angle_deg": [30, 60]}}))
    assert wider["design"]["groove_angle_deg"] < 40 and wider["in_domain"] is False
    assert [w.split(" = ")[0] for w in wider["domain_warnings"]] == ["groove_angle_deg"]
    # a value it was trained at, asked otherwise, is one it cannot answer at: refused, not dropped
    refused = client.post("/v1/optimizations", json={**request, "fixed": {"mu_pivot": 5.0}})
    assert refused.status_code == 422
    assert [e["pointer"] for e in refused.json()["errors"]] == ["/fixed/mu_pivot"]
    assert "trained at mu_pivot = 0.5" in refused.json()["errors"][0]["detail"]
    faster = client.post("/v1/optimizations", json={**request, "speed_m_s": [0.05, 0.1]})  # trained at 0.05
    assert faster.status_code == 422 and [e["pointer"] for e in faster.json()["errors"]] == ["/speed_m_s"]
    # an infeasible problem answers as on the physics: 422 at once, naming the same limit
    infeasible = {**request, "constraints": {"max_contact_pressure_Pa": 1e6}}
    on_physics = client.post("/v1/optimizations", json={**infeasible, "model": "physics"})
    on_surrogate = client.post("/v1/optimizations", json=infeasible)
    assert on_physics.status_code == on_surrogate.status_code == 422
    assert on_surrogate.json()["type"] == on_physics.json()["type"] == INFEASIBLE_TYPE
    assert on_surrogate.json()["errors"] == on_physics.json()["errors"]


def test_a_surrogate_design_is_judged_by_the_physics_on_a_binding_friction_limit(client):
    space = {"balls": [4, 8], "groove_angle_deg": [40, 60], "load_N": [0.002, 0.05]}
    training = {"space": space, "fixed": {"speed_m_s": 0.05, "mu_pivot": 0.8}, "budget": 12,
                "adaptive": False}
    surrogate = finished(client, client.post("/v1/surrogates", json=training))
    request = {"bounds": space, "speed_m_s": 0.05, "model": surrogate["model_id"], "starts": 1,
               "constraints": {"max_friction_force_N": 1e-4}}
    result = finished(client, client.post("/v1/optimizations", json=request))
    design = result["design"]
    # the physics at the surrogate's training values (mu_pivot 0.8, inherited by the problem)
    exact = float(physics.evaluate(speed_m_s=0.05, mu_pivot=0.8, **design).mu)
    friction = next(c for c in result["constraints"] if c["name"] == "max_friction_force_N")
    assert friction["decided_by"] == "physics"
    assert friction["value"] == pytest.approx(exact * design["load_N"], rel=1e-12)
    assert friction["value_model"] == pytest.approx(result["mu"] * design["load_N"], rel=1e-12)
    # satisfied is the physics' verdict, never the surrogate's
    assert friction["satisfied"] == (friction["value"] <= 1e-4) == result["verification"]["satisfied"]


def test_calibrated_model_with_an_effect_reads_its_conditions(client):
    store = get_runtime(client.app).store
    # Fitted on loads up to 0.01 N only, with a covariance and a scatter: the answer gives an interval and
    # says whether the optimum lies in the data.
    model = CalibratedModel(fitted={"mu_pivot": 0.6},
                            terms=[(EffectTerm("humidity_meniscus", ("relative_humidity",)), [2e-5])],
                            covariance=np.diag([1e-4, 1e-12]), noise_std_log=0.02,
                            domain={"load_N": [0.001, 0.01], "relative_humidity": [0.2, 0.8]},
                            conditions=["relative_humidity"])
    model_id = store.save_model("calibration", {"model": model.to_json()}, {})
    request = {"bounds": {"balls": [4, 8], "groove_angle_deg": [40, 60], "load_N": [0.001, 0.05]},
               "speed_m_s": 0.05, "model": f"calibrated:{model_id}"}
    missing = client.post("/v1/optimizations", json=request)
    assert missing.status_code == 422 and "relative_humidity" in missing.json()["detail"]
    result = finished(client, client.post("/v1/optimizations",
                                          json={**request, "conditions": {"relative_humidity": 0.5}}))
    # no point of a 5 x 60 x 200 grid of the calibrated model itself is better than the design
    z, theta, load = np.arange(4, 9)[:, None, None], np.linspace(40, 60, 60)[None, :, None], \
        np.geomspace(0.001, 0.05, 200)[None, None, :]
    grid = model({"balls": z, "groove_angle_deg": theta, "load_N": load, "speed_m_s": 0.05,
                  "relative_humidity": np.full(np.broadcast_shapes(z.shape, theta.shape, load.shape), 0.5)})
    assert result["mu"] <= grid.min() * (1 + 1e-9)
    design = result["design"]
    check = model({**design, "speed_m_s": 0.05, "relative_humidity": 0.5})
    assert result["mu"] == pytest.approx(float(np.squeeze(check)), rel=1e-12)
    assert result["mu_lower"] < result["mu"] < result["mu_upper"]
    # mu falls with load here: the optimum lies beyond the loads of the data, and the result says so.
    assert design["load_N"] > 0.01 and result["in_domain"] is False
    assert any(w.startswith("load_N = ") and "range [0.001, 0.01]" in w for w in result["domain_warnings"])


def test_speed_range_of_a_calibrated_model_falling_with_speed_is_designed_for_its_worst_speed(client):
    # a generic effect exp(-2 (V - 0.1) / 0.05) on speed: mu falls with speed, the worst case is 0.01 m/s
    store = get_runtime(client.app).store
    model = CalibratedModel(fitted={"mu_pivot": 0.8}, terms=[
        (EffectTerm("generic_linear", ("speed_m_s",), {"centre": 0.1, "scale": 0.05}), [-2.0])])
    model_id = store.save_model("calibration", {"model": model.to_json()}, {})
    request = {"bounds": {"balls": [4, 8], "groove_angle_deg": [40, 60], "load_N": [0.001, 0.05]},
               "speed_m_s": [0.01, 0.2], "model": f"calibrated:{model_id}", "starts": 1}
    result = finished(client, client.post("/v1/optimizations", json=request))
    assert result["speed_m_s"] == pytest.approx(0.01, abs=1e-15)
    at = {v: float(np.squeeze(model({**result["design"], "speed_m_s": v}))) for v in (0.01, 0.2)}
    assert result["mu"] == pytest.approx(at[0.01], rel=1e-12) and at[0.01] > 100 * at[0.2]
    # Judged over the whole range by branch and bound (mu rises with speed in the physics and falls in the
    # term: no single worst vertex is known in advance), with a certified lower bound at the worst speed.
    assert result["worst_case"]["speed_m_s"] == pytest.approx(0.01, abs=1e-15)
    proof = result["proof"]
    assert proof["method"] == "outer-approximation-certified" and proof["proven"], proof["statement"]
    assert proof["lower_bound"] <= result["mu"] <= proof["upper_bound"] <= result["mu"] * (1 + 1e-6)
