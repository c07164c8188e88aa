"""The UM-Bridge protocol as UQ tools meet it: a live server with API keys, driven by the real
``umbridge`` client (PyPI), every kind of model compared with the REST API, derivatives checked
against exact ones and finite differences; errors in the protocol's form (in process)."""

from __future__ import annotations

import re
from pathlib import Path

import httpx
import numpy as np
import pytest
import requests
import umbridge
from fastapi.testclient import TestClient
from jobs_helper import finished_job

from bench.api import start_server
from microbearing import physics
from microbearing.service.app import create_app
from microbearing.service.settings import Settings

REPO = Path(__file__).resolve().parent.parent
KEY = "uq-test-key"
SURROGATE_SPACE = {"load_N": [0.002, 0.03], "speed_m_s": [0.01, 0.15]}


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """Base URL of ``microbearing serve`` with an API key, on a free loopback port."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("MICROBEARING_API_KEYS", KEY)
        process, url = start_server(str(tmp_path_factory.mktemp("umbridge-data")))
    try:
        yield url
    finally:
        process.terminate()
        process.wait(timeout=20)


@pytest.fixture(scope="module")
def rest(server):
    with httpx.Client(base_url=server, headers={"Authorization": f"Bearer {KEY}"}, timeout=120) as client:
        yield client


@pytest.fixture(scope="module")
def url(server) -> str:
    """What a UQ user gives the client: the key as the password of the URL."""
    return server.replace("http://", f"http://umbridge:{KEY}@") + "/umbridge"


def _job_result(rest: httpx.Client, response: httpx.Response) -> dict:
    assert response.status_code == 202, response.text
    job = finished_job(rest, response.headers["location"], timeout_s=120, interval_s=0.1)
    return rest.get(job["result_url"]).json()


@pytest.fixture(scope="module")
def stored(rest) -> dict[str, str]:
    """A calibrated model reading relative humidity and a surrogate, by kind."""
    rng = np.random.default_rng(3)
    n = 40
    load = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n))
    speed = rng.uniform(0.01, 0.15, n)
    humidity = rng.uniform(0.2, 0.8, n)
    mu = physics.evaluate(balls=4, load_N=load, speed_m_s=speed, mu_pivot=0.7).mu
    mu = (mu + 8e-5 / (load * np.log(1 / humidity))) * np.exp(rng.normal(0.0, 0.02, n))
    rows = [{"load_N": float(a), "speed_m_s": float(b), "relative_humidity": float(c),
             "mu_measured": float(d)} for a, b, c, d in zip(load, speed, humidity, mu, strict=True)]
    calibration = _job_result(rest, rest.post("/v1/calibrations", json={
        "data": rows, "fit_parameters": ["mu_pivot"], "fixed": {"balls": 4}, "folds": 3}))
    assert calibration["missing_effect"]["drivers"] == ["relative_humidity"]
    surrogate = _job_result(rest, rest.post("/v1/surrogates", json={
        "space": SURROGATE_SPACE, "fixed": {"balls": 4}, "budget": 20}))
    return {"calibrated": calibration["model_id"], "surrogate": surrogate["model_id"]}


def test_the_client_lists_every_model_with_a_key_from_its_url(server, url, stored):
    names = umbridge.supported_models(url)
    assert names[0] == "physics" and set(stored.values()) <= set(names)
    for name in names:
        model = umbridge.HTTPModel(url, name)
        assert model.supports_evaluate() and model.supports_gradient() and model.supports_apply_jacobian()
        assert not model.supports_apply_hessian()
    # Without the key, or with a wrong one, Info lists the physics alone (no stored model; issue 28: the
    # stock client reads Info before anything else) and the evaluating paths refuse in the protocol's form.
    for auth in (None, ("umbridge", "wrong")):
        listed = requests.get(f"{server}/umbridge/Info", auth=auth, timeout=10)
        assert listed.status_code == 200 and listed.json()["models"] == ["physics"]
        refused = requests.post(f"{server}/umbridge/Evaluate", auth=auth, timeout=10,
                                json={"name": "physics", "input": [[4, 0.01, 0.05]]})
        assert refused.status_code == 401
        assert refused.json()["error"]["type"] == "Unauthorized"
    # The key as the user name alone works too; Basic credentials are for the protocol only.
    assert requests.get(f"{server}/umbridge/Info", auth=(KEY, ""), timeout=10).status_code == 200
    assert requests.get(f"{server}/v1/version", auth=("umbridge", KEY), timeout=10).status_code == 401


def test_physics_through_the_client_equals_the_rest_api(url, rest):
    model = umbridge.HTTPModel(url, "physics")
    point = {"balls": 4, "load_N": 0.008826, "speed_m_s": 0.05}
    expected = rest.post("/v1/friction", json=point).json()
    assert model.get_input_sizes() == [3] and model.get_output_sizes() == [1]
    assert model([[4.0, 0.008826, 0.05]]) == [[expected["mu"]]]

    config = {"inputs": ["load_N", "groove_angle_deg"], "outputs": list(physics.OUTPUTS),
              "fixed": {"balls": 4, "speed_m_s": 0.05, "mu_pivot": 1.0}, "convention": "derjaguin"}
    expected = rest.post("/v1/friction", json={"balls": 4, "load_N": 0.008826, "groove_angle_deg": 50.0,
                                               "speed_m_s": 0.05, "mu_pivot": 1.0,
                                               "convention": "derjaguin"}).json()
    assert model.get_output_sizes(config) == [len(physics.OUTPUTS)]
    assert model([[0.008826, 50.0]], config) == [[expected[name] for name in physics.OUTPUTS]]

    # Many points in one request, as /v1/friction/batch computes them.
    rng = np.random.default_rng(0)
    loads, speeds = rng.uniform(1e-3, 5e-2, 200).tolist(), rng.uniform(0.0, 0.2, 200).tolist()
    config = {"inputs": ["load_N", "speed_m_s"], "fixed": {"balls": 8, "balls_touching": True},
              "outputs": ["mu", "max_contact_pressure_Pa"], "points": 200}
    assert model.get_input_sizes(config) == [2] * 200
    output = model([list(pair) for pair in zip(loads, speeds, strict=True)], config)
    batch = rest.post("/v1/friction/batch", json={
        "points": {"balls": 8, "balls_touching": True, "load_N": loads, "speed_m_s": speeds},
        "outputs": ["mu", "max_contact_pressure_Pa"]}).json()
    assert [row[0] for row in output] == batch["mu"]
    assert [row[1] for row in output] == batch["max_contact_pressure_Pa"]


def test_a_calibrated_model_through_the_client_equals_the_rest_api(url, rest, stored):
    reference = stored["calibrated"]
    model = umbridge.HTTPModel(url, reference)
    # balls was fixed by the calibration: the inputs left are load, speed and the humidity it reads.
    assert model.get_input_sizes() == [3]
    config = {"outputs": ["mu", "mu_effect", "mu_pivoting", "outside_domain"], "points": 2}
    points = [[0.0088, 0.05, 0.6], [0.02, 0.1, 0.3]]
    output = model(points, config)
    for (load, speed, humidity), row in zip(points, output, strict=True):
        expected = rest.post("/v1/friction", json={
            "balls": 4, "load_N": load, "speed_m_s": speed, "model": reference,
            "conditions": {"relative_humidity": humidity}}).json()
        assert row[:3] == pytest.approx([expected["mu"], expected["mu_effect"], expected["mu_pivoting"]],
                                        rel=1e-13)
        assert row[3] == 0.0
        assert row[1] > 0  # the humidity effect adds friction


def test_a_surrogate_through_the_client_answers_its_interval_and_domain(url, rest, stored):
    reference = stored["surrogate"]
    model = umbridge.HTTPModel(url, reference)
    assert model.get_input_sizes() == [2]  # its dimensions, in the order of physics.PARAMETERS
    config = {"outputs": ["mu", "mu_lower", "mu_upper", "outside_domain"], "points": 3}
    points = [[0.01, 0.05], [0.025, 0.12], [0.2, 0.05]]  # the last load is outside the trained space
    output = np.array(model(points, config))
    predicted = rest.post(f"/v1/surrogates/{reference.split(':')[1]}/predict", json={
        "points": {"load_N": [p[0] for p in points], "speed_m_s": [p[1] for p in points]}}).json()
    for column, name in enumerate(["mu", "mu_lower", "mu_upper"]):
        assert output[:, column] == pytest.approx(predicted[name], rel=1e-13)
    assert output[:, 3].tolist() == [float(flag) for flag in predicted["outside_space"]] == [0.0, 0.0, 1.0]
    assert np.all(output[:, 1] < output[:, 0]) and np.all(output[:, 0] < output[:, 2])
    # an input that is no dimension, fixed at another value than trained (balls 4) or varied: refused, as
    # REST's predict refuses it (the answer would be the trained value's); the trained value itself passes
    for config, x, said in (({"fixed": {"balls": 8}}, [0.01, 0.05], "config.fixed.balls: " + reference),
                            ({"inputs": ["load_N", "speed_m_s", "balls"]}, [0.01, 0.05, 8],
                             "config.inputs: balls is not a dimension")):
        answer = rest.post("/umbridge/Evaluate", json={"name": reference, "input": [x], "config": config})
        assert answer.status_code == 400 and answer.json()["error"]["type"] == "InvalidInput"
        assert answer.json()["error"]["message"].startswith(said), answer.json()
    same = model([[0.01, 0.05]], {"fixed": {"balls": 4}})
    assert same[0][0] == pytest.approx(output[0, 0], rel=1e-13)


def _central_difference(model, x: list[float], j: int, config: dict, relative_step: float = 1e-5) -> float:
    step = relative_step * abs(x[j])
    up, down = list(x), list(x)
    up[j] += step
    down[j] -= step
    [[high], [low]] = model([up, down], {**config, "outputs": ["mu"], "points": 2})
    return (high - low) / (2 * step)


def test_physics_derivatives_equal_exact_ones_and_finite_differences(url):
    model = umbridge.HTTPModel(url, "physics")
    config = {"inputs": ["load_N", "groove_angle_deg", "speed_m_s", "mu_pivot", "adhesion_energy_J_m2"],
              "fixed": {"balls": 4}, "outputs": ["mu", "mu_pivoting", "mu_rolling"]}
    x = [0.008826, 54.7, 0.05, 0.8, 0.1]
    [[_, mu_pivoting, mu_rolling]] = model([x], config)
    gradient = model.gradient(0, 0, [x], [1.0, 0.0, 0.0], config)
    # Exact: mu is affine in mu_pivot through the pivoting moment alone (eq 16), and speed enters
    # only through the rolling force, proportional to V^0.66 (eq 9).
    assert gradient[3] == pytest.approx(mu_pivoting / 0.8, rel=1e-8)
    assert gradient[2] == pytest.approx(0.66 * mu_rolling / 0.05, rel=1e-8)
    for j in range(len(x)):
        assert gradient[j] == pytest.approx(_central_difference(model, x, j, config), rel=1e-6), j
    # ApplyJacobian is the same Jacobian applied to a direction.
    jacobian = np.array([model.gradient(0, 0, [x], row.tolist(), config) for row in np.eye(3)])
    direction = [2e-3, -1.5, 0.01, 0.3, -0.05]
    applied = model.apply_jacobian(0, 0, [x], direction, config)
    assert applied == pytest.approx(jacobian @ direction, rel=1e-12)
    # Points are independent: the cross-point Jacobian is zero.
    two = {**config, "points": 2}
    assert model.gradient(1, 0, [x, x], [1.0, 1.0, 1.0], two) == [0.0] * len(x)


def test_stored_model_derivatives_equal_finite_differences(url, stored):
    calibrated = umbridge.HTTPModel(url, stored["calibrated"])
    x = [0.0088, 0.05, 0.6]
    gradient = calibrated.gradient(0, 0, [x], [1.0], {})
    for j in range(len(x)):
        assert gradient[j] == pytest.approx(_central_difference(calibrated, x, j, {}), rel=1e-6), j
    assert gradient[2] > 0  # more humidity, more meniscus friction

    surrogate = umbridge.HTTPModel(url, stored["surrogate"])
    config = {"outputs": ["mu", "mu_upper"]}
    x = [0.01, 0.08]
    jacobian = np.array([surrogate.gradient(0, 0, [x], row.tolist(), config) for row in np.eye(2)])
    for j in range(len(x)):
        difference = _central_difference(surrogate, x, j, config, 1e-4)
        assert jacobian[0, j] == pytest.approx(difference, rel=1e-4), j


@pytest.fixture(scope="module")
def local(tmp_path_factory):
    settings = Settings(data_dir=tmp_path_factory.mktemp("umbridge-local"), max_batch_points=100)
    with TestClient(create_app(settings)) as client:
        yield client


POINT = {"name": "physics", "input": [[4, 0.01, 0.05]]}
GRADIENT = {"name": "physics", "outWrt": 0, "inWrt": 0, "sens": [1.0], "input": [[0.01, 0.05]],
            "config": {"inputs": ["load_N", "speed_m_s"], "fixed": {"balls": 4}}}
APPLY = {**{k: v for k, v in GRADIENT.items() if k != "sens"}, "vec": [1.0, 0.0]}
# (route, body: a dict sent as JSON or raw bytes, status, error type, pattern of the message)
ERRORS = [
    ("Evaluate", {"name": "wrong_model_name"}, 400, "ModelNotFound", "'wrong_model_name'"),
    ("ModelInfo", {"name": "surrogate:" + "0" * 32}, 400, "ModelNotFound", "0000"),
    ("ApplyHessian", {"name": "physics"}, 400, "UnsupportedFeature", "ApplyHessian"),
    ("Evaluate", {**POINT, "input": [[4, -1.0, 0.05]]}, 400, "InvalidInput",
     r"^input\[0\]\[1\] \(load_N\): load_N must be"),
    ("Evaluate", {**POINT, "input": [[4, 0.01, 0.05], [4.5, 0.01, 0.05]], "config": {"points": 2}}, 400,
     "InvalidInput", r"^input\[1\]\[0\] \(balls\): balls must be a whole number"),
    ("Evaluate", {**POINT, "input": [[4, 0.01]]}, 400, "InvalidInput", r"^input\[0\]: 2 values; expected 3"),
    ("Evaluate", {**POINT, "input": [[4, 0.01, 0.05]] * 2}, 400, "InvalidInput",
     r"^input: 2 vectors for config.points = 1"),
    ("Evaluate", {**POINT, "config": {"fixed": {"mu_pivot": 11.0}}}, 400, "InvalidInput",
     r"^config.fixed.mu_pivot: mu_pivot must be in \[0, 10\]"),
    ("Evaluate", {**POINT, "config": {"inputs": ["balls", "load_N", "speed_m_s"], "fixed": {"balls": 4}}},
     400, "InvalidInput", r"^config.inputs: 'balls' given twice"),
    ("Evaluate", {**POINT, "config": {"inputs": ["load_N", "speed"]}}, 400, "InvalidInput",
     r"^config.inputs: 'speed' is not an input of physics"),
    ("Evaluate", {**POINT, "config": {"inputs": ["load_N", "speed_m_s"]}}, 400, "InvalidInput",
     r"^config.fixed: physics needs balls"),
    ("Evaluate", {**POINT, "config": {"outputs": ["mu", "mu_lower"]}}, 400, "InvalidInput",
     r"^config.outputs: each once, from mu, .*, outside_domain; got \['mu', 'mu_lower'\]"),
    ("Evaluate", {**POINT, "config": {"points": 101}}, 413, "InvalidInput",
     r"^config.points: 101 points per request; the limit is 100"),
    ("Evaluate", {**POINT, "config": {"colour": 1}}, 400, "InvalidInput",
     r"^config.colour: Extra inputs are not permitted"),
    ("Evaluate", {**POINT, "input": [[4, "0.01", 0.05]]}, 400, "InvalidInput",
     r"^input\[0\]\[1\]: Input should be a valid number"),
    ("Evaluate", b'{"name": "physics", "name": "physics"}', 400, "InvalidInput", "twice"),
    ("Evaluate", b"[" * 70 + b"]" * 70, 400, "InvalidInput", "deep"),
    ("Evaluate", {**POINT, "input": [[4, 0.01, 0.05]] * 101}, 413, "InvalidInput", "more than 100"),
    ("Nope", POINT, 404, "UnsupportedFeature", "/umbridge/Nope"),
    # Derivatives: at a bound (mu grows like V^0.66 from V = 0), of a flag (counts are held: issue 28).
    ("Gradient", {**GRADIENT, "input": [[0.01, 0.0]]}, 400, "InvalidInput",
     r"^input\[0\]\[1\] \(speed_m_s\): the derivative with respect to speed_m_s at speed_m_s = 0 "),
    ("Gradient", {**GRADIENT, "sens": [1.0, 1.0], "config": {**GRADIENT["config"],
                                                             "outputs": ["mu", "outside_domain"]}},
     400, "InvalidInput", r"^config.outputs: outside_domain is a flag"),
    ("Gradient", {**GRADIENT, "inWrt": 1}, 400, "InvalidInput", r"^inWrt: 1 is not the index of a vector"),
    ("ApplyJacobian", {**APPLY, "vec": [1.0]}, 400, "InvalidInput", r"^vec: 1 values; expected 2"),
    ("ApplyJacobian", {**APPLY, "sens": [1.0]}, 400, "InvalidInput", r"^sens: Extra inputs are not "),
]


@pytest.mark.parametrize(("route", "body", "status", "kind", "pattern"), ERRORS)
def test_errors_take_the_protocol_form_and_name_the_field(local, route, body, status, kind, pattern):
    sent = {"content": body} if isinstance(body, bytes) else {"json": body}
    response = local.post(f"/umbridge/{route}", **sent)
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == "application/json"
    assert response.json().keys() == {"error"} and response.json()["error"].keys() == {"type", "message"}
    assert response.json()["error"]["type"] == kind
    assert re.search(pattern, response.json()["error"]["message"]), response.json()


def test_info_and_model_info_hold_the_protocol_fields_only(local):
    assert local.get("/umbridge/Info").json() == {"protocolVersion": 1.0, "models": ["physics"]}
    assert local.post("/umbridge/ModelInfo", json={"name": "physics"}).json() == {"support": {
        "Evaluate": True, "Gradient": True, "ApplyJacobian": True, "ApplyHessian": False}}


def test_the_readme_examples_run_and_print_what_they_say(url, capsys):
    """The ```python blocks of the manual's UM-Bridge page, against the live server with its key."""
    from docs_pages import code_blocks, page

    blocks = code_blocks(page("reference/umbridge.md"), "python")
    assert len(blocks) == 2
    for block in blocks:
        namespace: dict = {}
        exec(block.replace("http://127.0.0.1:8000/umbridge", url), namespace)
        printed = capsys.readouterr().out.splitlines()
        assert printed == [line[2:] for line in block.splitlines() if line.startswith("# ")]
    # The Monte Carlo spread and the first-order one from the gradient agree: the model is smooth there.
    assert namespace["first_order"] == pytest.approx(namespace["mu"].std(), rel=0.05)


def test_derivatives_at_the_bounds_of_a_range_step_inside_it(local):
    """mu is affine in mu_pivot, allowed in [0, 10]: its slope at both bounds is mu_pivoting at mu_pivot 1."""
    config = {"inputs": ["mu_pivot", "groove_angle_deg"],
              "fixed": {"balls": 4, "load_N": 0.01, "speed_m_s": 0.05}}
    slope = local.post("/umbridge/Evaluate", json={
        "name": "physics", "input": [[1.0, 54.7]], "config": {**config, "outputs": ["mu_pivoting"]}}).json()
    for bound in (0.0, 10.0):
        answer = local.post("/umbridge/Gradient", json={
            "name": "physics", "input": [[bound, 54.7]], "outWrt": 0, "inWrt": 0, "sens": [1.0],
            "config": config})
        assert answer.status_code == 200, answer.text
        # One-sided differences of order 8: well inside the promised 1e-6.
        assert answer.json()["output"][0] == pytest.approx(slope["output"][0][0], rel=1e-7)


def test_errors_keep_the_protocol_form_behind_a_proxy_prefix(tmp_path):
    # Served under a root path (uvicorn --root-path /api behind a proxy), the app's own paths start
    # after the prefix; the 404 of an unknown route still reaches a UM-Bridge client in its form.
    settings = Settings(data_dir=tmp_path)
    with TestClient(create_app(settings), root_path="/api") as client:
        assert client.get("/api/umbridge/Info").json()["models"] == ["physics"]
        response = client.post("/api/umbridge/Nope", json=POINT)
    assert response.status_code == 404
    assert response.json()["error"]["type"] == "UnsupportedFeature"


def test_a_large_body_with_a_long_list_is_refused_in_the_protocol_form_naming_model_then_field(tmp_path):
    # A long list of numbers has no place in a UM-Bridge request: over 4 MiB it is read as an array, never
    # as Python floats, and refused; the model is still named first, and a missing name said as before.
    long = b"[" + b", ".join([b"0.012345678901234567"] * 300_000) + b"]"
    assert len(long) > 4 * 2**20
    with TestClient(create_app(Settings(data_dir=tmp_path))) as client:
        for head, kind, pattern in [
            (b'{"name": "physics", "input": [[4, 0.01, 0.05]], ', "InvalidInput",
             r"^extra: Extra inputs are not permitted"),
            (b'{"name": "wrong_model_name", "input": [[4, 0.01, 0.05]], ', "ModelNotFound",
             "'wrong_model_name'"),
            (b'{"input": [[4, 0.01, 0.05]], ', "InvalidInput", r"^name: required"),
        ]:
            response = client.post("/umbridge/Evaluate", content=head + b'"extra": ' + long + b"}")
            assert response.status_code == 400, response.text[:300]
            error = response.json()["error"]
            assert error["type"] == kind and re.search(pattern, error["message"]), error
        # a long vector where a point's inputs belong: refused by the input sizes, as a short one is
        response = client.post("/umbridge/Evaluate", content=b'{"name": "physics", "input": [' + long + b"]}")
        assert response.status_code == 400 and response.json()["error"]["type"] == "InvalidInput"
        message = response.json()["error"]["message"]
        assert re.search(r"^input\[0\]: 300000 values; expected one per input", message), message


def test_evaluate_warns_of_a_unit_slip_in_the_words_of_the_friction_route(local):
    # 50 m/s is no micro bearing's speed (50 mm/s sent as m/s?): answered as asked, with /v1/friction's
    # warning beside the output, which the protocol's clients pass over.
    slipped = local.post("/umbridge/Evaluate", json={**POINT, "input": [[4, 0.01, 50.0]]}).json()
    friction = local.post("/v1/friction", json={"balls": 4, "load_N": 0.01, "speed_m_s": 50.0}).json()
    assert slipped["warnings"] == friction["input_warnings"] and "speed_m_s runs 50 to 50 m/s" in \
        slipped["warnings"][0]
    assert slipped["output"] == [[friction["mu"]]]
    assert local.post("/umbridge/Evaluate", json=POINT).json().keys() == {"output"}  # no slip: no warnings


@pytest.mark.parametrize("name", ["temp_K_C", "RH_pct [1]", "time_h_min", "temp_F [degC]"])
def test_a_condition_name_stating_two_units_is_refused_in_the_friction_route_s_words(local, name):
    # the same words at both doors: UM-Bridge said pydantic's "Value error, " before them
    friction = local.post("/v1/friction", json={"balls": 4, "load_N": 0.01, "speed_m_s": 0.05,
                                                "conditions": {name: 1}})
    assert friction.status_code == 422, friction.text
    (error,) = friction.json()["errors"]
    assert error["pointer"] == f"/conditions/{name}" and "states two units" in error["detail"], error
    bridged = local.post("/umbridge/Evaluate", json={**POINT, "config": {
        "inputs": ["balls", "load_N", "speed_m_s"], "fixed": {name: 1}}})
    assert bridged.status_code == 400, bridged.text
    assert bridged.json()["error"] == {"type": "InvalidInput", "message": f"config.fixed: {error['detail']}"}
