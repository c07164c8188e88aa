"""The REST API in process: friction, batch, sweeps, jobs, meta and problem+json errors."""

from __future__ import annotations

import csv
import io
import json
import math
from importlib.metadata import version

import numpy as np
import pytest
from fastapi import APIRouter, Depends, Request
from fastapi.responses import Response
from fastapi.routing import APIRoute
from fastapi.testclient import TestClient
from jobs_helper import wait_job

from microbearing import physics
from microbearing.service.app import PlainRoute, create_app, plain_routes
from microbearing.service.schemas.base import FOLDING_SAFE_NAMES
from microbearing.service.settings import Settings

PROBLEM = "application/problem+json"
JSON_HEADERS = {"content-type": "application/json"}
POINT = {"balls": 4, "load_N": 0.01, "speed_m_s": 0.1}


def make_client(tmp_path, **overrides) -> TestClient:
    return TestClient(create_app(Settings(data_dir=tmp_path, **overrides)))


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    settings = {"max_batch_points": 2_000_000, "sweep_sync_max_points": 1_000, "max_sweep_points": 100_000}
    with make_client(tmp_path_factory.mktemp("api"), **settings) as test_client:
        yield test_client


def assert_problem(response, status: int, pointer: str | None = None) -> dict:
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == PROBLEM
    problem = response.json()
    assert problem["status"] == status
    assert {"type", "title", "detail"} <= set(problem)
    if pointer is not None:
        assert pointer in [e.get("pointer") for e in problem["errors"]], problem
    return problem


# /v1/friction --------------------------------------------------------------------------------

def test_friction_returns_the_physics_outputs_with_defaults(client):
    response = client.post("/v1/friction", json=POINT)
    assert response.status_code == 200
    body = response.json()
    expected = physics.evaluate(**POINT)
    assert body["convention"] == physics.DEFAULT_CONVENTION
    assert set(body) == {"convention", *physics.OUTPUTS, *FOLDING_SAFE_NAMES.values()}
    for name in physics.OUTPUTS:
        assert body[name] == float(getattr(expected, name)), name  # JSON keeps floats exactly
    for name, alias in FOLDING_SAFE_NAMES.items():
        assert body[alias] == body[name], alias
    # Independent hand calculations of two outputs (eq 7 and eq 1) with the table defaults.
    theta = math.radians(54.7)
    assert body["contact_load_N"] == pytest.approx(0.01 / (2 * 4 * math.cos(theta)), rel=1e-12)
    assert body["adhesion_force_N"] == pytest.approx(3 * math.pi * 0.18 * 285e-6 / 2, rel=1e-12)
    parts = ("mu_pivoting", "mu_hysteresis", "mu_rolling", "mu_ball_ball")
    assert sum(body[p] for p in parts) == pytest.approx(body["mu"], rel=1e-12)


def test_friction_passes_optional_inputs_and_convention(client):
    point = {**POINT, "balls_touching": True, "mu_ball": 1.0, "convention": "derjaguin"}
    body = client.post("/v1/friction", json=point).json()
    expected = physics.evaluate(convention="derjaguin", balls=4, load_N=0.01, speed_m_s=0.1,
                                balls_touching=True, mu_ball=1.0)
    assert body["convention"] == "derjaguin"
    assert body["mu_ball_ball"] == float(expected.mu_ball_ball) > 0


@pytest.mark.parametrize(("change", "pointer"), [
    ({"load_N": "0.01"}, "/load_N"),              # a string for a number
    ({"load_N": True}, "/load_N"),                # a boolean for a number
    ({"balls": 4.5}, "/balls"),                   # a fraction for an integer
    ({"balls_touching": 1}, "/balls_touching"),   # a number for a boolean
    ({"load_N": 0}, "/load_N"),                   # exclusive minimum
    ({"groove_angle_deg": 90}, "/groove_angle_deg"),
    ({"ball_poisson_ratio": 0.5}, "/ball_poisson_ratio"),
    ({"speed_m_s": -1e-9}, "/speed_m_s"),
    ({"colour": "red"}, "/colour"),               # unknown field
    ({"convention": "other"}, "/convention"),
])
def test_friction_rejects_bad_fields_naming_them(client, change, pointer):
    problem = assert_problem(client.post("/v1/friction", json={**POINT, **change}), 422, pointer)
    if pointer in ("/load_N", "/groove_angle_deg"):
        spec = physics.PARAMETERS[pointer[1:]]
        assert spec.range_text() in problem["detail"] and f"[{spec.unit}]" in problem["detail"]


def test_friction_rejects_missing_required_fields(client):
    problem = assert_problem(client.post("/v1/friction", json={"balls": 4}), 422)
    assert {"/load_N", "/speed_m_s"} <= {e["pointer"] for e in problem["errors"]}


@pytest.mark.parametrize("token", ["NaN", "Infinity", "-Infinity"])
def test_friction_rejects_non_finite_numbers(client, token):
    body = '{"balls": 4, "load_N": TOKEN, "speed_m_s": 0.1}'.replace("TOKEN", token)
    response = client.post("/v1/friction", content=body, headers=JSON_HEADERS)
    assert_problem(response, 422, "/load_N")


def test_extreme_inputs_are_422_not_500(client):
    # outside the physics' bounds, where outputs would overflow: refused naming the field
    response = client.post("/v1/friction", json={**POINT, "ball_diameter_m": 1e-300})
    assert_problem(response, 422, "/ball_diameter_m")
    response = client.post("/v1/friction", json={**POINT, "load_N": 5e-324})
    assert_problem(response, 422, "/load_N")


def test_malformed_json_is_400(client):
    response = client.post("/v1/friction", content=b'{"balls": 4,', headers=JSON_HEADERS)
    assert_problem(response, 400)
    response = client.post("/v1/friction/batch", content=b"[1,", headers=JSON_HEADERS)
    assert_problem(response, 400)


def test_a_missing_body_is_said_and_a_body_not_sent_as_json_is_415(client):
    problem = assert_problem(client.post("/v1/optimizations", content=b"", headers=JSON_HEADERS), 422)
    assert problem["detail"] == ("The request is invalid: the request has no body: send a JSON object with "
                                 "Content-Type: application/json")
    # the routes FastAPI reads and those that read their own bodies answer alike
    design = {"bounds": {"balls": [4, 8], "groove_angle_deg": [35, 70], "load_N": [0.001, 0.05]},
              "speed_m_s": 0.05}
    for path, body in (("/v1/optimizations", json.dumps(design).encode()),
                       ("/v1/friction", b'{"balls": 4, "load_N": 0.01, "speed_m_s": 0.1}')):
        response = client.post(path, content=body, headers={"content-type": "Text/Plain"})
        problem = assert_problem(response, 415)
        assert problem["detail"] == "The body must be application/json, not 'text/plain'.", problem
        assert response.headers["accept"] == "application/json"
        assert client.post(path, content=body, headers=JSON_HEADERS).status_code == 200


def test_unknown_path_is_404_and_wrong_method_405_with_allow(client):
    assert_problem(client.get("/v1/nothing"), 404)
    response = client.get("/v1/friction")
    assert_problem(response, 405)
    assert response.headers["allow"] == "POST"
    response = client.post("/v1/jobs/abc")
    assert_problem(response, 405)
    assert set(response.headers["allow"].split(", ")) == {"GET", "HEAD", "DELETE"}
    response = client.head("/v1/friction")  # no GET there: no HEAD either
    assert response.status_code == 405 and response.headers["allow"] == "POST" and response.content == b""


def test_the_plain_route_answers_what_fastapis_route_answers(tmp_path, caplog):
    """/v1/friction is served by Starlette's plain route ahead of FastAPI's: the same answers and logs."""
    served = create_app(Settings(data_dir=tmp_path / "plain"))
    assert [route.path for route in served.router.routes if isinstance(route, PlainRoute)] == ["/v1/friction"]
    reference = create_app(Settings(data_dir=tmp_path / "fastapi"))
    routes = reference.router.routes
    routes[:] = [route for route in routes if not isinstance(route, PlainRoute)]
    assert not any(isinstance(route, PlainRoute) for route in reference.router.routes)
    requests = [("POST", {"json": POINT}),
                ("POST", {"json": {**POINT, "groove_angle_deg": 60.0, "convention": "derjaguin"}}),
                ("POST", {"json": {**POINT, "balls": "4"}}),  # wrong type
                ("POST", {"json": {**POINT, "load_N": -1.0, "unknown_N": 1.0}}),
                ("POST", {"json": {**POINT, "model": "calibrated:" + "0" * 32}}),  # no such calibration
                ("POST", {"json": {**POINT, "conditions": {"humidity": 0.5}}}),
                ("POST", {"content": b'{"balls": 4,', "headers": JSON_HEADERS}),
                ("POST", {"content": b"balls=4", "headers": {"content-type": "text/plain"}}),
                ("POST", {"json": POINT, "headers": {"accept": "text/csv"}}),
                ("GET", {}), ("HEAD", {}), ("DELETE", {})]
    answers, logged = {}, {}
    for name, app in (("plain", served), ("fastapi", reference)):
        with TestClient(app) as test_client, caplog.at_level("INFO", logger="microbearing.access"):
            caplog.clear()
            answers[name] = [test_client.request(method, "/v1/friction", **kwargs)
                             for method, kwargs in requests]
            logged[name] = [(r.method, r.route, r.status) for r in caplog.records
                            if r.name == "microbearing.access"]
    statuses = [response.status_code for response in answers["plain"]]
    assert statuses == [200, 200, 422, 422, 404, 422, 400, 415, 406, 405, 405, 405]
    for plain, fastapi in zip(answers["plain"], answers["fastapi"], strict=True):
        assert plain.status_code == fastapi.status_code
        assert plain.content == fastapi.content
        assert {k: v for k, v in plain.headers.items() if k != "x-request-id"} == \
            {k: v for k, v in fastapi.headers.items() if k != "x-request-id"}
    # Logs and metrics carry the same labels: the route template where it matched.
    assert logged["plain"] == logged["fastapi"]
    assert [route for _, route, _ in logged["plain"]][:2] == ["/v1/friction", "/v1/friction"]


def test_only_routes_that_need_nothing_of_fastapi_are_served_plain():
    class OwnHandling(APIRoute):
        pass

    router, custom = APIRouter(prefix="/t"), APIRouter(prefix="/c", route_class=OwnHandling)

    @router.post("/plain")
    async def plain(request: Request) -> Response:
        return Response(b"{}")

    @router.post("/dependency")
    async def dependency(request: Request, settings: str = Depends(lambda: "x")) -> Response:
        return Response(b"{}")

    @router.get("/item/{item_id}")
    async def path_parameter(request: Request, item_id: str) -> Response:
        return Response(b"{}")

    @router.get("/model")
    async def returns_a_model(request: Request) -> dict:
        return {}

    @custom.post("/own")
    async def own_handling(request: Request) -> Response:
        return Response(b"{}")

    routes = plain_routes([router, custom])
    assert [(route.path, route.methods, route.name) for route in routes] == [("/t/plain", {"POST"}, "plain")]


def test_head_answers_wherever_get_does_with_the_same_headers_and_no_body(client):
    request = {"design": "grid", "outputs": ["mu"], "fixed": {"balls": 4, "load_N": 0.01},
               "axes": {"speed_m_s": {"start": 0.0, "stop": 0.1, "num": 1_001}}}  # over the sync limit: a job
    job_id = client.post("/v1/sweeps", json=request).json()["id"]
    wait_job(client, f"/v1/jobs/{job_id}", timeout_s=60)
    spec = client.app.openapi()
    paths = [path.replace("{job_id}", job_id) for path, item in spec["paths"].items() if "get" in item
             and "{" not in path.replace("{job_id}", "")] + ["/healthz", "/v1/jobs/no-such-job"]
    assert {"/healthz", "/v1/version", f"/v1/jobs/{job_id}", f"/v1/jobs/{job_id}/result"} <= set(paths)
    for path in paths:
        got, head = client.get(path), client.head(path)
        assert head.status_code == got.status_code, path
        assert head.content == b"", path
        assert head.headers["content-type"] == got.headers["content-type"], path
        if path != "/metrics":  # the scrape counts itself: its length grows between the two
            assert head.headers["content-length"] == got.headers["content-length"], path


def test_bodies_over_the_limit_are_413_declared_or_streamed(tmp_path):
    with make_client(tmp_path, max_body_bytes=2_000) as small:
        big = {"points": {**POINT, "load_N": [0.01] * 1_000}}
        assert_problem(small.post("/v1/friction/batch", json=big), 413)

        def chunks():  # no Content-Length: the body is counted as it streams
            yield json.dumps(big).encode()

        response = small.post("/v1/friction/batch", content=chunks(), headers=JSON_HEADERS)
        assert_problem(response, 413)
        assert small.post("/v1/friction", json=POINT).status_code == 200


# /v1/friction/batch --------------------------------------------------------------------------

def test_batch_broadcasts_scalars_and_matches_the_physics(client):
    loads = [0.005, 0.01, 0.02]
    speeds = [0.0, 0.05, 0.15]
    request = {"points": {"balls": 18, "load_N": loads, "speed_m_s": speeds, "balls_touching": True}}
    body = client.post("/v1/friction/batch", json=request).json()
    expected = physics.evaluate(balls=18, load_N=np.array(loads), speed_m_s=np.array(speeds),
                                balls_touching=True)
    assert set(body) == {*physics.OUTPUTS, *FOLDING_SAFE_NAMES.values()}
    for name in physics.OUTPUTS:
        assert body[name] == getattr(expected, name).tolist(), name
    assert body["pivoting_moment_newton_metre"] == body["pivoting_moment_Nm"]
    assert body["mu_rolling"][0] == 0.0  # no rolling force at rest


def test_batch_returns_only_the_chosen_outputs(client):
    request = {"points": {**POINT, "speed_m_s": [0.0, 0.1]}, "outputs": ["mu", "contact_radius_m"]}
    body = client.post("/v1/friction/batch", json=request).json()
    assert set(body) == {"mu", "contact_radius_m"}
    assert len(body["mu"]) == 2 and body["mu"][1] > body["mu"][0]  # mu grows with speed
    # a name given twice is one column (the JSON had the key twice)
    twice = client.post("/v1/friction/batch", json={**request, "outputs": ["mu", "contact_radius_m", "mu"]})
    assert twice.text.count('"mu"') == 1 and twice.json() == body


def test_batch_of_scalars_is_one_point(client):
    body = client.post("/v1/friction/batch", json={"points": POINT, "outputs": ["mu"]}).json()
    assert body == {"mu": [float(physics.evaluate(**POINT).mu)]}


def test_batch_lists_of_different_lengths_name_the_field(client):
    request = {"points": {"balls": [4, 6], "load_N": [0.01, 0.02], "speed_m_s": [0.1, 0.1, 0.1]}}
    problem = assert_problem(client.post("/v1/friction/batch", json=request), 422, "/points/speed_m_s")
    assert "3 values" in problem["detail"]


def test_batch_points_to_the_bad_element(client):
    request = {"points": {**POINT, "load_N": [0.01, 0.02, -3.0]}}
    assert_problem(client.post("/v1/friction/batch", json=request), 422, "/points/load_N/2")
    request = {"points": {**POINT, "load_N": [0.01, "x"]}}
    assert_problem(client.post("/v1/friction/batch", json=request), 422, "/points/load_N/1")
    assert_problem(client.post("/v1/friction/batch", json={"points": {**POINT, "load_N": []}}), 422,
                   "/points/load_N")
    assert_problem(client.post("/v1/friction/batch", json={"points": POINT, "outputs": ["mu", "nope"]}),
                   422, "/outputs/1")


def test_batch_over_the_point_limit_is_413(tmp_path):
    with make_client(tmp_path, max_batch_points=10) as small:
        request = {"points": {**POINT, "speed_m_s": [0.1] * 11}}
        assert "limit is 10" in assert_problem(small.post("/v1/friction/batch", json=request), 413)["detail"]
        request = {"points": {**POINT, "speed_m_s": [0.1] * 10}, "outputs": ["mu"]}
        assert len(small.post("/v1/friction/batch", json=request).json()["mu"]) == 10


def test_batch_of_a_million_points(client):
    speeds = np.linspace(0.0, 0.15, 1_000_000)
    request = {"points": {**POINT, "speed_m_s": speeds.tolist()}, "outputs": ["mu"]}
    mu = np.array(client.post("/v1/friction/batch", json=request).json()["mu"])
    assert mu.shape == (1_000_000,)
    picks = np.array([0, 1, 499_999, 999_999])
    np.testing.assert_array_equal(mu[picks], physics.evaluate(**{**POINT, "speed_m_s": speeds[picks]}).mu)
    assert np.all(np.diff(mu) >= 0)  # mu never decreases with speed


# /v1/sweeps ----------------------------------------------------------------------------------

def test_grid_sweep_is_the_full_factorial(client):
    request = {"design": "grid", "outputs": ["mu"], "fixed": {"load_N": 0.01},
               "axes": {"speed_m_s": {"start": 0.0, "stop": 0.15, "num": 4},
                        "balls": {"start": 4, "stop": 18, "num": 3}}}
    body = client.post("/v1/sweeps", json=request).json()
    assert body["count"] == 12 and body["varied"] == ["balls", "speed_m_s"]  # parameter-table order
    columns = body["columns"]
    pairs = set(zip(columns["speed_m_s"], columns["balls"], strict=True))
    # grid values read as typed (0.05, not 0.15 / 3 = 0.049999999999999996), ball counts as integers
    assert pairs == {(s, b) for s in (0.0, 0.05, 0.1, 0.15) for b in (4, 11, 18)}
    assert all(type(b) is int for b in columns["balls"])
    expected = physics.evaluate(load_N=0.01, speed_m_s=np.array(columns["speed_m_s"]),
                                balls=np.array(columns["balls"])).mu
    assert columns["mu"] == expected.tolist()


def test_grid_log_spacing_and_whole_numbers(client):
    request = {"design": "grid", "outputs": ["mu"], "fixed": {"speed_m_s": 0.1},
               "axes": {"load_N": {"start": 1e-4, "stop": 1e-2, "num": 3, "spacing": "log"},
                        "balls": {"start": 1, "stop": 3, "num": 7}}}
    columns = client.post("/v1/sweeps", json=request).json()["columns"]
    assert sorted(set(columns["load_N"])) == pytest.approx([1e-4, 1e-3, 1e-2], rel=1e-12)
    assert sorted(set(columns["balls"])) == [1, 2, 3]  # 7 values rounded to 3 whole numbers
    assert len(columns["mu"]) == 9


def test_sweep_as_csv(client):
    request = {"design": "grid", "outputs": ["mu", "contact_load_N"], "fixed": {"balls": 4, "load_N": 0.01},
               "axes": {"speed_m_s": {"start": 0.0, "stop": 0.1, "num": 3}}}
    response = client.post("/v1/sweeps", json=request, headers={"accept": "text/csv"})
    assert response.status_code == 200 and response.headers["content-type"].startswith("text/csv")
    rows = list(csv.reader(io.StringIO(response.text)))
    # the fixed inputs after the varied ones (issue 28: a table carries its inputs)
    assert rows[0] == ["speed_m_s", "balls", "load_N", "mu", "contact_load_N"]
    assert {(r[1], r[2]) for r in rows[1:]} == {("4", "0.01")}
    json_columns = client.post("/v1/sweeps", json=request).json()["columns"]
    assert [float(r[3]) for r in rows[1:]] == json_columns["mu"]
    assert [r[0] for r in rows[1:]] == ["0.0", "0.05", "0.1"]  # not 0.1 * 1/2 = 0.05000000000000001


def test_sweep_csv_prints_ball_counts_as_integers(client):
    request = {"design": "sobol", "points": 4, "seed": 3, "outputs": ["mu"], "fixed": {"load_N": 0.01},
               "ranges": {"balls": {"low": 3, "high": 30}, "speed_m_s": {"low": 0.0, "high": 0.1}}}
    rows = list(csv.reader(io.StringIO(client.post("/v1/sweeps", json=request,
                                                   headers={"accept": "text/csv"}).text)))
    assert rows[0][0] == "balls" and all(r[0].isdigit() for r in rows[1:]), rows


@pytest.mark.parametrize(("accept", "csv_expected"), [
    ("text/csv;q=0", None), ("text/csv;q=0.3, application/json", False), ("*/*", False),
    ("application/json;q=0.1, text/csv", True), ("TEXT/CSV; q=0.5", True), ("text/*", True),
    ("text/*, application/json;q=0", True)])
def test_sweep_format_follows_accept_qualities(client, accept, csv_expected):
    request = {"design": "grid", "outputs": ["mu"], "fixed": {"balls": 4, "load_N": 0.01},
               "axes": {"speed_m_s": {"start": 0.0, "stop": 0.1, "num": 2}}}
    response = client.post("/v1/sweeps", json=request, headers={"accept": accept})
    if csv_expected is None:  # neither CSV nor JSON acceptable
        assert_problem(response, 406)
        return
    assert response.status_code == 200
    media_type = response.headers["content-type"]
    assert media_type.startswith("text/csv" if csv_expected else "application/json"), (accept, media_type)


@pytest.mark.parametrize("design", ["sobol", "latin_hypercube"])
def test_design_of_experiments_stays_in_range_and_repeats_with_a_seed(client, design):
    request = {"design": design, "points": 64, "seed": 7, "outputs": ["mu"], "fixed": {"speed_m_s": 0.1},
               "ranges": {"load_N": {"low": 1e-3, "high": 1e-2}, "balls": {"low": 3, "high": 20}}}
    body = client.post("/v1/sweeps", json=request).json()
    loads, balls = np.array(body["columns"]["load_N"]), np.array(body["columns"]["balls"])
    assert body["count"] == 64 and np.all((loads >= 1e-3) & (loads <= 1e-2))
    assert np.all(balls == np.round(balls)) and balls.min() >= 3 and balls.max() <= 20
    assert body == client.post("/v1/sweeps", json=request).json()
    other = client.post("/v1/sweeps", json={**request, "seed": 8}).json()
    assert other["columns"]["load_N"] != body["columns"]["load_N"]


def test_latin_hypercube_puts_one_point_in_each_stratum(client):
    n = 50
    request = {"design": "latin_hypercube", "points": n, "seed": 1, "outputs": ["mu"],
               "fixed": {"balls": 4}, "ranges": {"load_N": {"low": 0.0, "high": 1.0},
                                                 "speed_m_s": {"low": 0.0, "high": 0.5}}}
    response = client.post("/v1/sweeps", json=request)
    assert_problem(response, 422, "/ranges/load_N/low")  # load_N must be > 0
    request["ranges"]["load_N"] = {"low": 1.0, "high": 2.0}
    columns = client.post("/v1/sweeps", json=request).json()["columns"]
    for name, low, high in (("load_N", 1.0, 2.0), ("speed_m_s", 0.0, 0.5)):
        strata = np.floor((np.array(columns[name]) - low) / (high - low) * n)
        assert sorted(strata.tolist()) == list(range(n)), name


@pytest.mark.parametrize(("request_body", "pointer"), [
    ({"design": "grid", "axes": {"speed_m_s": {"start": 0, "stop": 1, "num": 2}}, "fixed": {"balls": 4}},
     "/fixed/load_N"),
    ({"design": "grid", "axes": {"speed_m_s": {"start": 0, "stop": 1, "num": 2}},
      "fixed": {"balls": 4, "load_N": 1, "speed_m_s": 1}}, "/fixed/speed_m_s"),
    ({"design": "grid", "axes": {}, "fixed": {"balls": 4, "load_N": 1, "speed_m_s": 1}}, "/axes"),
    ({"design": "grid", "axes": {"load_N": {"start": 1, "stop": 2, "num": 1000},
                                 "speed_m_s": {"start": 0, "stop": 1, "num": 1000}}, "fixed": {"balls": 4}},
     "/axes"),
    ({"design": "grid", "axes": {"load_N": {"start": -1, "stop": 2, "num": 3}},
      "fixed": {"balls": 4, "speed_m_s": 1}}, "/axes/load_N/start"),
    ({"design": "grid", "axes": {"speed_m_s": {"start": 0, "stop": 2, "num": 3, "spacing": "log"}},
      "fixed": {"balls": 4, "load_N": 1}}, "/axes/speed_m_s/spacing"),
    ({"design": "sobol", "points": 8, "ranges": {"load_N": {"low": 2, "high": 1}},
      "fixed": {"balls": 4, "speed_m_s": 1}}, "/ranges/load_N/high"),
    # a range sent as the pair [low, high] is pointed at by index: the pair has no /high
    ({"design": "sobol", "points": 8, "ranges": {"load_N": [2, 1]},
      "fixed": {"balls": 4, "speed_m_s": 1}}, "/ranges/load_N/1"),
    ({"design": "sobol", "points": 8, "ranges": {"load_N": [-1, 1]},
      "fixed": {"balls": 4, "speed_m_s": 1}}, "/ranges/load_N/0"),
    ({"design": "latin_hypercube", "points": 8, "ranges": {"load [mN]": [20, 10]},
      "fixed": {"balls": 4, "speed_m_s": 1}}, "/ranges/load [mN]/1"),
    ({"design": "sobol", "points": 8, "ranges": {"balls_touching": {"low": 0, "high": 1}},
      "fixed": {"balls": 4, "load_N": 1, "speed_m_s": 1}}, "/ranges/balls_touching"),
    ({"design": "annealing", "points": 8}, "/design"),
    ({"points": 8}, "/design"),
])
def test_bad_sweeps_name_the_field(client, request_body, pointer):
    assert_problem(client.post("/v1/sweeps", json=request_body), 422, pointer)


def test_an_input_a_field_does_not_vary_is_said_so_not_called_extra(client):
    request = {"design": "grid", "fixed": {"load_N": 0.01, "balls": 4},
               "axes": {"balls_touching": {"values": [1, 0]}, "speed_m_s": {"values": [0.05]}}}
    problem = assert_problem(client.post("/v1/sweeps", json=request), 422, "/axes/balls_touching")
    assert problem["errors"][0]["detail"] == ("balls_touching is a physics input, but not one this field "
                                              "takes; give it in fixed instead")


# jobs ----------------------------------------------------------------------------------------

def test_large_sweep_runs_as_a_job_with_json_and_csv_results(client):
    request = {"design": "grid", "outputs": ["mu"], "fixed": {"balls": 4},
               "axes": {"load_N": {"start": 1e-3, "stop": 1e-2, "num": 50},
                        "speed_m_s": {"start": 0.0, "stop": 0.15, "num": 40}}}
    response = client.post("/v1/sweeps", json=request)
    assert response.status_code == 202
    location = response.headers["location"]
    assert location == f"/v1/jobs/{response.json()['id']}"
    assert int(response.headers["retry-after"]) >= 1
    job = wait_job(client, location, timeout_s=60)
    assert job["status"] == "succeeded" and job["progress"] == 1.0 and job["error"] is None
    result = client.get(job["result_url"]).json()
    assert result["count"] == 2_000
    columns = result["columns"]
    expected = physics.evaluate(balls=4, load_N=np.array(columns["load_N"]),
                                speed_m_s=np.array(columns["speed_m_s"])).mu
    assert columns["mu"] == expected.tolist()
    rows = list(csv.reader(io.StringIO(client.get(job["result_url"], headers={"accept": "text/csv"}).text)))
    assert rows[0] == ["load_N", "speed_m_s", "balls", "mu"] and len(rows) == 2_001  # with the fixed balls
    assert {r[2] for r in rows[1:]} == {"4"}
    deleted = client.delete(location)  # a finished job is deleted with its result
    assert deleted.status_code == 204 and deleted.content == b""
    assert_problem(client.get(location), 404)
    assert_problem(client.get(job["result_url"]), 404)
    assert_problem(client.delete(location), 404)


def test_cancelling_a_sweep_job_over_http(tmp_path):
    request = {"design": "grid", "fixed": {"balls": 4},  # every output at 2 million points: seconds
               "axes": {"load_N": {"start": 1e-3, "stop": 1e-2, "num": 2_000},
                        "speed_m_s": {"start": 0.0, "stop": 0.15, "num": 1_000}}}
    with make_client(tmp_path, sweep_sync_max_points=0, max_result_bytes=2**31) as test_client:
        location = test_client.post("/v1/sweeps", json=request).headers["location"]
        # cancel a job under way
        job = wait_job(test_client, location, timeout_s=60, interval_s=0.005,
                       until=lambda job: job["progress"] != 0 or job["status"] not in ("queued", "running"))
        assert job["status"] == "running" and 0 < job["progress"] < 1, job
        early = test_client.get(f"{location}/result")  # not yet: 409, and when to ask again
        assert_problem(early, 409)
        assert int(early.headers["retry-after"]) >= 1
        response = test_client.delete(location)
        assert response.status_code == 200, response.text
        assert response.json()["cancel_requested"] is True and response.json()["status"] == "running"
        job = wait_job(test_client, location, timeout_s=60)
        assert job["status"] == "cancelled" and job["result_url"] is None and job["progress"] < 1
        never = test_client.get(f"{location}/result")  # never: 409 without Retry-After
        assert_problem(never, 409)
        assert "retry-after" not in never.headers


def test_unknown_jobs_are_404(client):
    assert_problem(client.get("/v1/jobs/0123"), 404)
    assert_problem(client.delete("/v1/jobs/0123"), 404)
    assert_problem(client.get("/v1/jobs/0123/result"), 404)


def test_a_finished_job_survives_a_restart(tmp_path):
    settings = {"sweep_sync_max_points": 0}
    request = {"design": "grid", "outputs": ["mu"], "fixed": {"balls": 4, "load_N": 0.01},
               "axes": {"speed_m_s": {"start": 0.0, "stop": 0.1, "num": 5}}}
    with make_client(tmp_path, **settings) as first:
        location = first.post("/v1/sweeps", json=request).headers["location"]
        job = wait_job(first, location, timeout_s=60)
        result = first.get(job["result_url"]).json()
    with make_client(tmp_path, **settings) as second:  # a new app on the same data folder
        assert second.get(location).json() == job
        assert second.get(job["result_url"]).json() == result


# meta ----------------------------------------------------------------------------------------

def test_health_version_and_materials(client):
    assert client.get("/healthz").json() == {"status": "ok"}
    body = client.get("/v1/version").json()
    assert body["version"] == version("microbearing")
    assert body["physics_convention"] == physics.DEFAULT_CONVENTION
    assert set(body["conventions"]) == set(physics.CONVENTIONS)
    materials = client.get("/v1/materials").json()["materials"]
    assert {m["name"]: m["youngs_modulus_Pa"] for m in materials} == {
        name: m.youngs_modulus_Pa for name, m in physics.MATERIALS.items()}


@pytest.mark.parametrize(("path", "body", "pointer", "with_range"), [
    # a field under a parameter's name that is not its value: no range of the parameter
    ("/v1/sweeps", {"design": "grid", "axes": {"load_N": {"start": 1e-3, "stop": 0.1, "num": 0}},
                    "fixed": {"balls": 6, "speed_m_s": 0.1}}, "/axes/load_N/num", None),
    # the schema's own bound (100,000 balls), not the physics one (a million): no contradiction
    ("/v1/optimizations", {"bounds": {"balls": [4, 1_000_000], "groove_angle_deg": [35, 70],
                                      "load_N": [0.001, 0.05]}, "speed_m_s": 0.05}, "/bounds/balls/1", None),
    # the parameter's value against its own range: the range and unit help
    ("/v1/friction", {"balls": 4, "load_N": -1, "speed_m_s": 0.05}, "/load_N", "load_N must be in [1e-09"),
    ("/v1/friction/batch", {"points": {"balls": 4, "load_N": [0.01, -1], "speed_m_s": 0.05}},
     "/points/load_N/1", "[N]"),
])
def test_a_parameter_range_is_appended_only_to_errors_about_that_parameter(client, path, body, pointer,
                                                                           with_range):
    errors = assert_problem(client.post(path, json=body), 422)["errors"]
    assert [e["pointer"] for e in errors] == [pointer]
    detail = errors[0]["detail"]
    if with_range is None:
        assert " must be " not in detail and "[" not in detail, detail
    else:
        assert with_range in detail, detail


def test_the_manuals_error_example_is_the_servers_answer(client):
    # docs/pages/reference/rest-api.md's "Errors" shows the problem of a negative load, word for word
    from docs_pages import code_blocks, page, section

    [shown] = code_blocks(section(page("reference/rest-api.md"), "## Errors"), "json")
    response = client.post("/v1/friction", json={"balls": 4, "load_N": -0.01, "speed_m_s": 0.1})
    assert response.status_code == 422 and response.json() == json.loads(shown)

