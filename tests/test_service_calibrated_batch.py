"""/v1/friction/batch on a calibrated model: the /v1/friction answer column by column, intervals, domain."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fastapi.testclient import TestClient
from jobs_helper import wait_job

from bench.calibrated_batch import calibration as calibrate_through_the_api
from microbearing import physics
from microbearing.calibrate import CalibratedModel
from microbearing.service.app import create_app
from microbearing.service.deps import get_runtime
from microbearing.service.schemas.base import FOLDING_SAFE_NAMES
from microbearing.service.settings import Settings

PROBLEM = "application/problem+json"


@pytest.fixture(scope="module")
def calibration(client) -> dict:
    """A model of menisci growing with relative humidity; its data also has a temperature no term reads."""
    result = calibrate_through_the_api(client)
    assert CalibratedModel.from_json(result["model"]).required_columns == ["relative_humidity"], result
    assert "temperature_C" in result["model"]["conditions"]
    return result


def assert_problem(response, status: int, pointer: str | None = None) -> dict:
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == PROBLEM
    problem = response.json()
    if pointer is not None:
        assert pointer in [e.get("pointer") for e in problem["errors"]], problem
    return problem


# Points inside the data (0..5), then outside it: humidity above its range (6), a heavy load (7), a
# temperature below its range (8, read by no term: flagged only), both humidity and load (9).
POINTS = {"balls": [4, 8, 4, 8, 4, 8, 4, 8, 4, 4],
          "load_N": [0.006, 0.01, 0.02, 0.025, 0.012, 0.008, 0.01, 0.5, 0.01, 0.4],
          "speed_m_s": [0.02, 0.05, 0.1, 0.14, 0.08, 0.03, 0.05, 0.05, 0.05, 0.05]}
HUMIDITY = [0.25, 0.4, 0.5, 0.6, 0.7, 0.75, 0.97, 0.5, 0.5, 0.95]
TEMPERATURE = [25.0, 30.0, 35.0, 22.0, 38.0, 30.0, 30.0, 30.0, 5.0, 30.0]
OUTSIDE = [False] * 6 + [True] * 4


def test_batch_gives_the_single_point_answers_and_the_calibrated_model_s_own(client, calibration):
    model = calibration["model_id"]
    request = {"points": POINTS, "model": model,
               "conditions": {"relative_humidity": HUMIDITY, "temperature_C": TEMPERATURE}}
    response = client.post("/v1/friction/batch", json=request)
    assert response.status_code == 200, response.text
    batch = response.json()
    assert batch["model"] == model
    assert set(physics.OUTPUTS) | {"mu_effect", "mu_lower", "mu_upper"} <= set(batch)
    n = len(HUMIDITY)
    # Point by point, the /v1/friction answer.
    for i in range(n):
        point = {name: values[i] for name, values in POINTS.items()}
        single = client.post("/v1/friction", json={**point, "model": model, "conditions": {
            "relative_humidity": HUMIDITY[i], "temperature_C": TEMPERATURE[i]}}).json()
        for name in ("mu", "mu_effect", "mu_lower", "mu_upper", "mu_pivoting", "max_contact_pressure_Pa"):
            assert batch[name][i] == pytest.approx(single[name], rel=1e-12, abs=0.0), (name, i)
        assert batch["in_domain"][i] is single["in_domain"] is (not OUTSIDE[i])
    # The calibrate package's own prediction of the stored model, all points at once.
    stored = CalibratedModel.from_json(calibration["model"])
    columns = {k: np.asarray(v, dtype=float) for k, v in POINTS.items()}
    predicted = stored.predict({**columns, "relative_humidity": np.array(HUMIDITY),
                                "temperature_C": np.array(TEMPERATURE)})
    for name in ("mu", "mu_lower", "mu_upper"):
        np.testing.assert_allclose(batch[name], getattr(predicted, name), rtol=1e-12)
    mu = np.array(batch["mu"])
    assert np.all(batch["mu_lower"] < mu) and np.all(mu < batch["mu_upper"])
    # The declared physics with the fitted parameters underneath, the terms on top.
    declared = physics.evaluate(**columns, **stored.fitted)
    np.testing.assert_allclose(mu - batch["mu_effect"], declared.mu, rtol=1e-12)
    # but the friction force is the one at the model's mu, as a tribometer reads it and a limit judges it
    np.testing.assert_allclose(batch["friction_force_N"], mu * columns["load_N"], rtol=1e-12)
    assert np.all(np.abs(np.array(batch["friction_force_N"]) / declared.friction_force_N - 1) > 1e-6)
    # One warning per column outside, naming it with the data's range and counting the batch's points.
    warnings = batch["domain_warnings"]
    low, high = calibration["model"]["domain"]["relative_humidity"]
    humid = next(w for w in warnings if w.startswith("relative_humidity = "))
    assert f"[{low:.6g}, {high:.6g}]" in humid and "(2 point(s))" in humid
    heavy = next(w for w in warnings if w.startswith("load_N = "))
    assert "[N]" in heavy and "(2 point(s))" in heavy
    cold = next(w for w in warnings if w.startswith("temperature_C = 5"))
    assert "(1 point(s))" in cold
    assert len(warnings) == 3


def test_conditions_broadcast_and_outputs_bring_the_interval(client, calibration):
    model = calibration["model_id"]
    request = {"points": {"balls": 4, "load_N": [0.01, 0.02], "speed_m_s": 0.05}, "model": model,
               "conditions": {"relative_humidity": 0.5}, "outputs": ["mu"]}
    batch = client.post("/v1/friction/batch", json=request).json()
    assert set(batch) == {"mu", "mu_effect", "mu_lower", "mu_upper", "model", "in_domain", "domain_warnings"}
    assert batch["in_domain"] == [True, True] and batch["domain_warnings"] == []
    # Scalars only are one point; a list of conditions alone sets the number of points.
    scalars = {**request, "points": {"balls": 4, "load_N": 0.01, "speed_m_s": 0.05}}
    one = client.post("/v1/friction/batch", json=scalars).json()
    assert one["mu"] == batch["mu"][:1]
    humid = client.post("/v1/friction/batch", json={
        **scalars, "conditions": {"relative_humidity": [0.3, 0.5, 0.7]}}).json()
    assert len(humid["mu"]) == 3 and humid["mu"][1] == pytest.approx(one["mu"][0], rel=1e-12)
    assert humid["mu"][0] < humid["mu"][1] < humid["mu"][2]  # menisci grow with humidity
    # Without mu, no interval (it is mu's); the domain is still said.
    pressure = client.post("/v1/friction/batch", json={
        **request, "outputs": ["max_contact_pressure_Pa"]}).json()
    assert set(pressure) == {"max_contact_pressure_Pa", "model", "in_domain", "domain_warnings"}


def test_a_calibrated_batch_evaluates_the_physics_a_fixed_number_of_times(client, calibration, monkeypatch):
    """Vectorized: the calls of physics.evaluate do not grow with the number of points."""
    calls = []
    evaluate = physics.evaluate

    def counted(*args, **kwargs):
        calls.append(np.size(kwargs.get("load_N", 0)))
        return evaluate(*args, **kwargs)

    monkeypatch.setattr(physics, "evaluate", counted)
    model = calibration["model_id"]
    for count in (10, 3000):
        load_N = np.linspace(0.006, 0.03, count).tolist()
        humidity = np.linspace(0.3, 0.7, count).tolist()
        request = {"points": {"balls": 4, "load_N": load_N, "speed_m_s": 0.05}, "model": model,
                   "conditions": {"relative_humidity": humidity}}
        assert client.post("/v1/friction/batch", json=request).status_code == 200
    small, large = calls[:len(calls) // 2], calls[len(calls) // 2:]
    assert len(small) == len(large) <= 5 and set(small) == {10} and set(large) == {3000}


@pytest.mark.parametrize(("change", "pointer", "detail"), [
    ({"conditions": {"relative_humidity": 0.5, "humidity_typo": 0.5}}, "/conditions/humidity_typo",
     "unknown condition column"),
    ({"conditions": {"temperature_C": 30.0}}, "/conditions", "relative_humidity"),
    ({"conditions": None}, "/conditions", "relative_humidity"),
    ({"conditions": {"relative_humidity": 0.5, "load_N": 0.01}}, "/conditions/load_N", "physics input"),
    ({"conditions": {"relative_humidity": [0.5, 0.6, 0.7]}}, "/conditions/relative_humidity", "length"),
    ({"conditions": {"relative_humidity": [0.5, "wet"]}}, "/conditions/relative_humidity",
     "element 1 is 'wet' among numbers"),
    ({"conditions": {"relative_humidity": []}}, "/conditions/relative_humidity", "empty"),
    ({"conditions": {"relative_humidity": [0.5, 1.0]}}, "/conditions/relative_humidity",  # log(1/RH) = 0
     "outside [0, 1)"),
    ({"convention": "another"}, "/convention", "omit convention"),
    ({"model": "calibrated:xyz"}, "/model", None),
])
def test_bad_conditions_are_422_naming_the_field(client, calibration, change, pointer, detail):
    request = {"points": {"balls": 4, "load_N": [0.01, 0.02], "speed_m_s": 0.05},
               "model": calibration["model_id"], "conditions": {"relative_humidity": 0.5}, **change}
    if "convention" in change:
        used = calibration["model"]["convention"]
        request["convention"] = next(c for c in physics.CONVENTIONS if c != used)
    problem = assert_problem(client.post("/v1/friction/batch", json=request), 422, pointer)
    if detail is not None:
        assert detail in " ".join(e["detail"] for e in problem["errors"]), problem


def test_unknown_model_is_404_and_the_physics_reads_no_conditions(client):
    points = {"balls": 4, "load_N": [0.01, 0.02], "speed_m_s": 0.05}
    unknown = {"points": points, "model": "calibrated:" + "0" * 32}
    assert_problem(client.post("/v1/friction/batch", json=unknown), 404)
    assert_problem(client.post("/v1/friction/batch", json={"points": points, "conditions": {
        "relative_humidity": 0.5}}), 422, "/conditions")
    # The physics batch answers as before: its outputs only.
    plain = client.post("/v1/friction/batch", json={"points": points}).json()
    assert set(plain) == set(physics.OUTPUTS) | set(FOLDING_SAFE_NAMES.values())
    assert plain["mu"] == physics.evaluate(balls=4, load_N=np.array([0.01, 0.02]), speed_m_s=0.05).mu.tolist()


def test_the_point_limit_holds_for_condition_lists(data_dir, calibration):
    with TestClient(create_app(Settings(data_dir=data_dir, max_batch_points=12))) as small:
        request = {"points": {"balls": 4, "load_N": 0.01, "speed_m_s": 0.05},
                   "model": calibration["model_id"], "conditions": {"relative_humidity": [0.5] * 12}}
        assert len(small.post("/v1/friction/batch", json=request).json()["mu"]) == 12
        request["conditions"]["relative_humidity"] = [0.5] * 13
        assert "limit" in assert_problem(small.post("/v1/friction/batch", json=request), 413)["detail"]


def test_a_batch_of_several_chunks_answers_each_point_as_alone(client, calibration):
    """Chunks of 65,536 points: the points either side of a chunk boundary, and one warning for the batch."""
    count = 66_000
    load_N = np.linspace(0.005, 0.04, count)  # the upper end lies above the data's loads
    humidity = np.linspace(0.3, 0.7, count)
    request = {"points": {"balls": 4, "load_N": load_N.tolist(), "speed_m_s": 0.05},
               "model": calibration["model_id"], "conditions": {"relative_humidity": humidity.tolist()},
               "outputs": ["mu"]}
    batch = client.post("/v1/friction/batch", json=request).json()
    picked = [0, 65_535, 65_536, count - 1]
    alone = client.post("/v1/friction/batch", json={
        **request, "points": {"balls": 4, "load_N": load_N[picked].tolist(), "speed_m_s": 0.05},
        "conditions": {"relative_humidity": humidity[picked].tolist()}}).json()
    for name in ("mu", "mu_lower", "mu_upper"):
        np.testing.assert_allclose([batch[name][i] for i in picked], alone[name], rtol=1e-12)
    assert [batch["in_domain"][i] for i in picked] == alone["in_domain"]
    outside = count - sum(batch["in_domain"])
    low, high = calibration["model"]["domain"]["load_N"]
    # A column's range is widened by twice the mean spacing of its values at each end (a new point drawn
    # like the data lies beyond a sample's extreme with chance 1 / (rows + 1)).
    slack = 2 * (high - low) / (calibration["model"]["domain_rows"] - 1)
    beyond = (load_N < low - slack) | (load_N > high + slack)
    assert outside == np.count_nonzero(beyond) > 0
    assert np.count_nonzero((load_N < low) | (load_N > high)) > outside
    assert len(batch["domain_warnings"]) == 1 and f"({outside} point(s))" in batch["domain_warnings"][0]


def test_a_large_calibrated_batch_read_into_arrays_answers_each_point_as_alone(client, calibration):
    """Over 4 MiB a batch's long columns are read straight into arrays (service.schemas.number_lists); the
    calibrated model answers them, conditions included, as it answers the same points sent small."""
    count = 240_000
    load_N = np.random.default_rng(2).uniform(0.005, 0.03, count)
    humidity = np.random.default_rng(3).uniform(0.3, 0.7, count)
    request = {"points": {"balls": 4, "load_N": load_N.tolist(), "speed_m_s": 0.05},
               "model": calibration["model_id"], "conditions": {"relative_humidity": humidity.tolist()},
               "outputs": ["mu"]}
    body = json.dumps(request)
    assert len(body) > 4 * 2**20
    batch = client.post("/v1/friction/batch", content=body, headers={"content-type": "application/json"})
    assert batch.status_code == 200, batch.text[:300]
    picked = [0, 77_777, count - 1]
    alone = client.post("/v1/friction/batch", json={
        **request, "points": {"balls": 4, "load_N": load_N[picked].tolist(), "speed_m_s": 0.05},
        "conditions": {"relative_humidity": humidity[picked].tolist()}}).json()
    for name in ("mu", "mu_lower", "mu_upper"):
        np.testing.assert_allclose([batch.json()[name][i] for i in picked], alone[name], rtol=1e-12)


def test_a_model_stored_without_interval_or_domain_answers_mu_alone(client):
    """A calibrated model saved before intervals and domains: mu, and neither bounds nor a domain flag."""
    plain = CalibratedModel(fitted={"mu_pivot": 0.7})
    assert plain.covariance is None and plain.domain is None
    store = get_runtime(client.app).store
    stored = store.save_model("calibration", {"model": plain.to_json()}, {}, name="old")
    points = {"balls": 4, "load_N": [0.01, 0.02], "speed_m_s": 0.05}
    batch = client.post("/v1/friction/batch", json={"points": points, "model": f"calibrated:{stored}"}).json()
    assert batch["mu"] == physics.evaluate(balls=4, load_N=np.array([0.01, 0.02]), speed_m_s=0.05,
                                           mu_pivot=0.7).mu.tolist()
    assert batch["mu_effect"] == [0.0, 0.0] and batch["domain_warnings"] == []
    assert not {"mu_lower", "mu_upper", "in_domain"} & set(batch)
    single = client.post("/v1/friction", json={"balls": 4, "load_N": 0.02, "speed_m_s": 0.05,
                                               "model": f"calibrated:{stored}"}).json()
    assert single["mu"] == batch["mu"][1] and single["mu_lower"] is None and single["in_domain"] is None


def test_the_single_point_refuses_another_convention_as_the_batch_does(client, calibration):
    used = calibration["model"]["convention"]
    other = next(c for c in physics.CONVENTIONS if c != used)
    point = {"balls": 4, "load_N": 0.01, "speed_m_s": 0.05, "model": calibration["model_id"],
             "conditions": {"relative_humidity": 0.5}}
    refused = client.post("/v1/friction", json={**point, "convention": other})
    problem = assert_problem(refused, 422, "/convention")
    assert used in problem["errors"][0]["detail"]
    answer = client.post("/v1/friction", json={**point, "convention": used})
    assert answer.status_code == 200 and answer.json()["convention"] == used
    assert answer.json() == client.post("/v1/friction", json=point).json()


@pytest.mark.parametrize(("cache_size", "rebuilds"), [(16, 1), (0, 4)])
def test_a_calibrated_model_is_rebuilt_once_for_many_single_points(data_dir, calibration, monkeypatch,
                                                                    cache_size, rebuilds):
    built = []
    from_json = CalibratedModel.from_json.__func__

    def counted(cls, document):
        built.append(1)
        return from_json(cls, document)

    monkeypatch.setattr(CalibratedModel, "from_json", classmethod(counted))
    point = {"balls": 4, "load_N": 0.01, "speed_m_s": 0.05, "model": calibration["model_id"],
             "conditions": {"relative_humidity": 0.5}}
    # A fresh app on the same data folder: nothing rebuilt yet.
    with TestClient(create_app(Settings(data_dir=data_dir, model_cache_size=cache_size))) as fresh:
        answers = [fresh.post("/v1/friction", json={**point, "load_N": load}).json()
                   for load in (0.01, 0.012, 0.014, 0.01)]
    assert len(built) == rebuilds
    assert answers[0] == answers[3] and answers[0]["mu"] != answers[1]["mu"]


def test_an_interval_that_overflows_far_from_the_data_is_422_not_500(client):
    # Found by schemathesis' stateful phase following the spec's link from a calibration to
    # /v1/friction: 400,000 balls at 149 m/s widen the 95 % interval of the mu_pivot model of the
    # spec's example past floating point (mu_upper inf), which JSON cannot carry (was: 500).
    from microbearing.service.schemas.examples import CALIBRATION

    location = client.post("/v1/calibrations", json=CALIBRATION).headers["location"]
    wait_job(client, location, timeout_s=120)
    model = client.get(f"{location}/result").json()["model_id"]
    far = {"balls": 401564, "ball_poisson_ratio": 0.49117826135052206,
           "race_youngs_modulus_Pa": 5136756337280.07, "load_N": 0.5, "speed_m_s": 148.83583745516464}
    problem = assert_problem(client.post("/v1/friction", json={**far, "model": model}), 422)
    assert "mu_upper is not finite" in problem["errors"][0]["detail"]
    # named at the inputs outside the calibration data (the example's data vary balls, load and speed)
    pointers = {e["pointer"] for e in problem["errors"]}
    assert {"/balls", "/load_N", "/speed_m_s"} <= pointers <= {f"/{name}" for name in far}, pointers
    batch = client.post("/v1/friction/batch", json={"points": {**far, "balls": [401564, 4]}, "model": model})
    assert batch.status_code == 422, batch.text
    near = client.post("/v1/friction", json={"balls": 4, "load_N": 0.01, "speed_m_s": 0.05, "model": model})
    assert near.status_code == 200 and np.isfinite(near.json()["mu_upper"]), near.text
