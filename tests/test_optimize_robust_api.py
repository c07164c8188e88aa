"""POST /v1/optimizations over an operating envelope: the designer's request on a calibrated model, the
physics' proof, payloads given in fixed.load_N, and the refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fastapi.testclient import TestClient
from jobs_helper import finished_job

from microbearing import physics
from microbearing.calibrate.model_view import CalibratedPhysicsModel
from microbearing.optimize import Constraints, DesignBounds, DesignProblem
from microbearing.optimize.robust import Envelope, optimize_robust
from microbearing.service.deps import get_runtime
from microbearing.service.models import resolve

PHYSICS = {"bounds": {"balls": [3, 12], "groove_angle_deg": [40, 60], "load_N": [0.001, 0.05]},
           "speed_m_s": [0.01, 0.1], "tolerances": {"groove_angle_deg": 0.5},
           "constraints": {"max_contact_pressure_Pa": 6e8}}


def humidity_rows(seed: int = 7, n: int = 80) -> list[dict[str, float]]:
    """Synthetic measurements of bearings of 4-8 balls and 45-60 deg grooves: the physics with mu_pivot 0.6
    plus capillary menisci growing with humidity (a meniscus force of 2e-5 N per ball at ln(1/h) = 1),
    2 % log-normal scatter."""
    rng = np.random.default_rng(seed)
    rows = []
    for _ in range(n):
        balls, angle = rng.choice([4, 6, 8]), rng.choice([45.0, 54.7, 60.0])
        load = rng.choice([0.0044, 0.0088, 0.0132])
        speed, humidity = rng.uniform(0.01, 0.15), rng.uniform(0.25, 0.75)
        mu = float(physics.evaluate(balls=balls, groove_angle_deg=angle, load_N=load, speed_m_s=speed,
                                    mu_pivot=0.6).mu)
        mu += balls * 2e-5 / (load * np.log(1 / humidity))
        rows.append({"balls": float(balls), "groove_angle_deg": float(angle), "load_N": float(load),
                     "speed_m_s": round(speed, 3), "relative_humidity": round(humidity, 2),
                     "mu_measured": mu * np.exp(rng.normal(0, 0.02))})
    return rows


def finished(client: TestClient, response) -> dict:
    assert response.status_code == 202, response.text
    location = response.headers["location"]
    job = finished_job(client, location, timeout_s=300, interval_s=0.05)
    return client.get(job["result_url"]).json()


@pytest.fixture(scope="module")
def calibrated(client) -> str:
    result = finished(client, client.post("/v1/calibrations", json={"data": humidity_rows(),
                                                                     "fit_parameters": ["mu_pivot"]}))
    return result["model_id"].removeprefix("calibrated:")


def test_physics_over_an_envelope_answers_at_once_with_its_proof(client):
    response = client.post("/v1/optimizations", json=PHYSICS)
    assert response.status_code == 200, response.text
    body = response.json()
    library = optimize_robust(DesignProblem(DesignBounds((3, 12), (40, 60), (0.001, 0.05)), 0.05,
                                            constraints=Constraints(max_contact_pressure_Pa=6e8)),
                              Envelope((0.01, 0.1), tolerances={"groove_angle_deg": 0.5}))
    assert body["design"] == pytest.approx(library.result.design, rel=1e-9)
    design, worst = body["design"], body["worst_case"]
    exact = physics.evaluate(balls=design["balls"], groove_angle_deg=design["groove_angle_deg"] + 0.5,
                             load_N=design["load_N"], speed_m_s=0.1)
    assert worst["mu"] == pytest.approx(float(exact.mu), rel=1e-12) == body["mu"]
    assert worst["speed_m_s"] == 0.1
    assert worst["groove_angle_deg"] == pytest.approx(design["groove_angle_deg"] + 0.5)
    assert float(exact.max_contact_pressure_Pa) <= 6e8 * (1 + 1e-9)
    proof = body["proof"]
    assert proof["proven"] and proof["method"] == "robust-gp-vertex" and proof["relative_gap"] <= 1e-6
    assert proof["lower_bound"] <= worst["mu"]
    assert body["objective"] == "mu" and body["envelope"]["tolerances"] == {"groove_angle_deg": 0.5}
    assert set(body["price_of_robustness"]) == {"nominal", "robust", "ratio"}


def test_the_designers_request_on_a_calibrated_model(client, calibrated):
    # "the design whose friction stays lowest, at 95 % confidence, over 10-100 mm/s and 30-70 % RH with the
    # groove angle +- 0.5 deg"
    request = {"model": f"calibrated:{calibrated}", "objective": "mu_upper",
               "bounds": {"balls": [4, 8], "groove_angle_deg": [45.5, 59.5], "load_N": [0.0044, 0.0132]},
               "speed_m_s": [0.01, 0.1], "conditions": {"relative_humidity": [0.3, 0.7]},
               "tolerances": {"groove_angle_deg": 0.5}}
    body = finished(client, client.post("/v1/optimizations", json=request))
    worst, design = body["worst_case"], body["design"]
    model = resolve(get_runtime(client.app).store, f"calibrated:{calibrated}")
    assert isinstance(model, CalibratedPhysicsModel)
    # The reported worst case is the model's own mu_upper there, and no point of a grid over the envelope
    # at the design is worse.
    at = model.predict({"balls": design["balls"], "load_N": design["load_N"],
                        "groove_angle_deg": worst["groove_angle_deg"], "speed_m_s": worst["speed_m_s"],
                        **worst["conditions"]})
    assert worst["mu_upper"] == pytest.approx(float(np.squeeze(at.mu_upper)), rel=1e-9) == body["mu"]
    speeds, humidity, offsets = np.meshgrid(np.linspace(0.01, 0.1, 7), np.linspace(0.3, 0.7, 7),
                                            np.linspace(-0.5, 0.5, 5), indexing="ij")
    grid = model.predict({"balls": design["balls"], "load_N": design["load_N"], "speed_m_s": speeds,
                          "groove_angle_deg": design["groove_angle_deg"] + offsets,
                          "relative_humidity": humidity})
    assert grid.mu_upper.max() <= worst["mu_upper"] * (1 + 1e-9)
    # friction grows with humidity (the menisci): the worst case is at 70 % RH
    assert worst["conditions"]["relative_humidity"] == pytest.approx(0.7)
    # The model's interval widens off its data cloud (issue 24): the worst case at the design is certified
    # by branch and bound with the widening bounded over each box, the best achievable worst case bounded
    # below over design boxes; both ends certified and within the target, so it is proven.
    proof = body["proof"]
    assert proof["proven"] is True and proof["method"] == "outer-approximation-certified"
    assert proof["upper_bound_certified"] and proof["relative_gap"] <= 1e-6
    assert "cloud" in proof["statement"]
    assert grid.mu_upper.max() <= proof["upper_bound"] <= worst["mu_upper"] * (1 + 2e-5)
    assert proof["lower_bound"] <= worst["mu_upper"]
    assert body["mu_lower"] < body["mu_upper"] == pytest.approx(worst["mu_upper"], rel=1e-9)
    assert body["price_of_robustness"]["robust"]["worst_case"] == worst["mu_upper"]


def test_a_payload_is_given_in_fixed(client):
    body = client.post("/v1/optimizations", json={"bounds": {"balls": [3, 8], "groove_angle_deg": [40, 60]},
                                                  "fixed": {"load_N": 0.0196}, "speed_m_s": 0.05}).json()
    assert body["design"]["load_N"] == 0.0196
    for z in range(3, 9):  # the physics at that load: no count and angle of a fine grid does better
        mu = physics.evaluate(balls=z, groove_angle_deg=np.linspace(40, 60, 201), load_N=0.0196,
                              speed_m_s=0.05).mu
        assert body["mu"] <= mu.min() * (1 + 1e-9)


@pytest.mark.parametrize(("change", "pointer"), [
    ({"conditions": {"relative_humidity": [0.3, 0.7]}}, "/conditions"),
    ({"objective": "mu_upper"}, "/objective"),
    ({"bounds": {"balls": [3, 4], "groove_angle_deg": [40, 89.8], "load_N": [0.001, 0.05]}},
     "/tolerances/groove_angle_deg"),
    ({"fixed": {"load_N": 0.0196}}, "/fixed/load_N"),
    ({"bounds": {"balls": [3, 4], "groove_angle_deg": [40, 60]}}, "/bounds/load_N"),
    ({"pareto": {"objective": "load_N"}}, "/pareto"),
    ({"tolerances": {"groove_angle_deg": 11}}, "/tolerances/groove_angle_deg"),
])
def test_refusals_name_the_field(client, change, pointer):
    response = client.post("/v1/optimizations", json={**PHYSICS, **change})
    assert response.status_code == 422, response.text
    assert response.headers["content-type"].startswith("application/problem+json")
    assert pointer in [e["pointer"] for e in response.json()["errors"]], response.json()


def test_calibrated_conditions_are_named_when_missing_or_unknown(client, calibrated):
    request = {**PHYSICS, "model": f"calibrated:{calibrated}"}
    missing = client.post("/v1/optimizations", json=request)
    assert missing.status_code == 422 and "relative_humidity" in missing.json()["detail"]
    conditions = {"relative_humidity": [0.3, 0.7], "temperature_C": [20, 60]}
    unknown = client.post("/v1/optimizations", json={**request, "conditions": conditions})
    assert unknown.status_code == 422
    assert any(e["pointer"].startswith("/conditions/temperature_C") for e in unknown.json()["errors"])


def test_the_command_line_answers_the_designers_request(capsys, tmp_path, monkeypatch):
    # A calibrated model stored in the data folder the command reads (MICROBEARING_DATA_DIR).
    from microbearing.calibrate import CalibratedModel
    from microbearing.calibrate.candidates import EffectTerm
    from microbearing.service.cli import main
    from microbearing.service.schemas.optimizations import OptimizationResult
    from microbearing.service.store import Store

    model = CalibratedModel(fitted={"mu_pivot": 0.6},
                            terms=[(EffectTerm("humidity_meniscus", ("relative_humidity",)), [2e-5])],
                            covariance=np.diag([1e-4, 1e-12]), noise_std_log=0.02,
                            domain={"load_N": [0.001, 0.05], "relative_humidity": [0.2, 0.8]},
                            conditions=["relative_humidity"])
    store = Store(tmp_path / "data")
    model_id = store.save_model("calibration", {"model": model.to_json()}, {})
    store.close()
    monkeypatch.setenv("MICROBEARING_DATA_DIR", str(tmp_path / "data"))
    request = tmp_path / "designer.json"
    request.write_text(json.dumps({
        "model": f"calibrated:{model_id}", "objective": "mu_upper",
        "bounds": {"balls": [3, 6], "groove_angle_deg": [40, 60], "load_N": [0.004, 0.0132]},
        "speed_m_s": [0.01, 0.1], "conditions": {"relative_humidity": [0.3, 0.7]},
        "tolerances": {"groove_angle_deg": 0.5}, "starts": 1}))
    assert main(["optimize", str(request), "-o", str(tmp_path / "best.json")]) == 0
    document = json.loads((tmp_path / "best.json").read_text())
    OptimizationResult.model_validate(document)
    envelope = Envelope((0.01, 0.1), {"relative_humidity": (0.3, 0.7)}, {"groove_angle_deg": 0.5})
    library = optimize_robust(DesignProblem(DesignBounds((3, 6), (40, 60), (0.004, 0.0132)), 0.05), envelope,
                              CalibratedPhysicsModel("calibrated:x", model), objective="mu_upper", starts=1)
    assert document["worst_case"]["mu_upper"] == pytest.approx(library.worst_case["mu_upper"], rel=1e-9)
    assert document["design"] == pytest.approx(library.result.design, rel=1e-9)
    # The proof, through the command line as from the library: both ends certified, the gap within target.
    proof = document["proof"]
    assert proof["proven"] and proof["upper_bound_certified"] and proof["lower_bound_boxes"] > 0
    assert proof["relative_gap"] <= 1e-6
    assert proof["lower_bound"] == pytest.approx(library.proof["lower_bound"], rel=1e-9)


def test_the_manual_example_gives_the_figures_it_shows():
    from docs_pages import page

    section = page("how-to/designers.md")
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    namespace: dict = {}
    exec(compile(code, "docs/pages/how-to/designers.md", "exec"), namespace)  # the manual's own example
    robust = namespace["robust"]
    assert robust.result.design["balls"] == 4
    assert robust.result.design["groove_angle_deg"] == pytest.approx(45.5)
    assert robust.result.design["load_N"] == pytest.approx(0.013054, rel=1e-4)
    assert robust.worst_case["mu_upper"] == pytest.approx(0.026288, rel=1e-4)
    assert robust.worst_case["conditions"] == {"relative_humidity": 0.7}
    # Both ends certified: the lower bound over the designs (branch and bound over design boxes) and the worst
    # case at the design (branch and bound over the envelope, the data cloud's widening bounded per box).
    assert robust.proof["lower_bound"] == pytest.approx(0.02628768, rel=1e-6)
    assert robust.proof["relative_gap"] < 1e-6 and robust.proof["proven"]
    assert robust.proof["upper_bound_certified"] is True
    assert robust.proof["method"] == "outer-approximation-certified" and "cloud" in robust.proof["statement"]
    assert robust.proof["worst_case_relative_gap"] <= 1e-5
    worst = robust.worst_case["mu_upper"]
    assert worst <= robust.proof["upper_bound"] <= worst * (1 + 1e-5)
    nominal = robust.price_of_robustness["nominal"]
    assert nominal["worst_case"] == pytest.approx(0.026120, rel=1e-4)
    # the nominal design's worst case is certified too, to the nominal bracket (1e-4)
    assert nominal["worst_case_certified"] and robust.price_of_robustness["robust"]["worst_case_certified"]
    assert nominal["worst_case"] <= nominal["worst_case_upper_bound"] <= nominal["worst_case"] * (1 + 1e-4)
    assert not nominal["limits_hold_over_envelope"]
    assert 1 - robust.result.design["load_N"] / nominal["design"]["load_N"] == pytest.approx(0.009, abs=5e-4)
    proven = namespace["optimize_robust"](namespace["problem"], namespace["envelope"], namespace["model"])
    assert proven.proof["proven"] and proven.worst_case["mu"] == pytest.approx(0.025198, rel=1e-4)
    assert proven.proof["relative_gap"] < 1e-6


def test_a_surrogates_envelope_design_is_verified_by_the_physics_it_stands_for(client):
    space = {"balls": [4, 8], "groove_angle_deg": [40, 61], "load_N": [0.002, 0.05]}
    training = {"space": space, "fixed": {"speed_m_s": 0.05}, "budget": 40, "adaptive": False}
    surrogate = finished(client, client.post("/v1/surrogates", json=training))
    request = {"bounds": {"balls": [4, 8], "groove_angle_deg": [40, 60], "load_N": [0.002, 0.05]},
               "speed_m_s": 0.05, "tolerances": {"groove_angle_deg": 0.5}, "model": surrogate["model_id"],
               "starts": 1}
    result = finished(client, client.post("/v1/optimizations", json=request))
    design, verification = result["design"], result["verification"]
    exact = physics.evaluate(balls=design["balls"], groove_angle_deg=design["groove_angle_deg"] + 0.5,
                             load_N=design["load_N"], speed_m_s=0.05)
    # the physics' worst case is at the angle made high (it grows with the angle): found by the search
    assert verification["mu_source"] == pytest.approx(float(exact.mu), rel=1e-12) == result["mu_source"]
    assert verification["source_model"] == "physics" == result["source_model"]
    assert verification["mu_model"] == pytest.approx(result["worst_case"]["mu"], rel=1e-9)
    assert abs(verification["relative_difference"]) < 0.05 and verification["satisfied"]
    assert result["proof"]["proven"] is False


def test_a_surrogates_speed_range_alone_is_an_envelope_with_the_physics_worst_case_proven(client):
    space = {"balls": [4, 8], "groove_angle_deg": [40, 61], "load_N": [0.002, 0.05],
             "speed_m_s": [0.005, 0.12]}
    surrogate = finished(client, client.post("/v1/surrogates", json={"space": space, "budget": 40,
                                                                      "adaptive": False}))
    request = {"bounds": {"balls": [4, 8], "groove_angle_deg": [40, 60], "load_N": [0.002, 0.05]},
               "speed_m_s": [0.01, 0.1], "model": surrogate["model_id"], "starts": 1}
    result = finished(client, client.post("/v1/optimizations", json=request))
    # no longer the 9 speeds of the local method: the envelope's treatment, said to be unproven on a surrogate
    assert result["envelope"]["speed_m_s"] == [0.01, 0.1] and result["proof"]["proven"] is False
    design, verification = result["design"], result["verification"]
    # the physics grows with speed: its worst case over the range is exactly its value at 0.1 m/s, and a
    # brute-force scan of the range finds nothing above it
    exact = physics.evaluate(balls=design["balls"], groove_angle_deg=design["groove_angle_deg"],
                             load_N=design["load_N"], speed_m_s=0.1)
    assert verification["mu_source_certified"] is True
    assert verification["mu_source"] == pytest.approx(float(exact.mu), rel=1e-12)
    assert verification["speed_m_s_source"] == 0.1
    scan = physics.evaluate(balls=design["balls"], groove_angle_deg=design["groove_angle_deg"],
                            load_N=design["load_N"], speed_m_s=np.linspace(0.01, 0.1, 91))
    assert scan.mu.max() <= verification["mu_source"] * (1 + 1e-12)


@pytest.fixture(scope="module")
def with_specimens(client) -> str:
    rows = [row | {"specimen": f"S{i % 3 + 1}"} for i, row in enumerate(humidity_rows(seed=8))]
    body = {"data": rows, "fit_parameters": ["mu_pivot"], "folds": 3}
    result = finished(client, client.post("/v1/calibrations", json=body))
    assert [g["factor"] for g in result["groups"]] == ["specimen"]
    return result["model_id"]


@pytest.mark.parametrize("specimen", ["S2", 2, ["S1", "S2"]])
def test_a_factor_over_an_envelope_is_refused_in_one_sentence_whatever_its_value(client, with_specimens,
                                                                                  specimen):
    # Issue 32: over an envelope a label was refused as a design at one point only, but the number 2 as
    # "specimen is not a condition of calibrated:...; its conditions are relative_humidity" and a list of
    # labels with pydantic's "Input should be a valid number" at each.
    request = {**PHYSICS, "model": with_specimens,
               "conditions": {"relative_humidity": [0.3, 0.6], "specimen": specimen}}
    response = client.post("/v1/optimizations", json=request)
    assert response.status_code == 422, response.text
    (error,) = response.json()["errors"]
    assert error["pointer"] == "/conditions/specimen"
    assert "group label" in error["detail"] and "not a condition" not in error["detail"], error
    assert "Input should be" not in error["detail"], error
