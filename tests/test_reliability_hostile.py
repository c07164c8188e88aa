"""Hostile input: every endpoint answers malformed, oversized or absurd requests with a 4xx problem.

The endpoints come from the app's own OpenAPI spec, so a route added later is attacked too.
After every attack the server must still answer ``/healthz``; a 5xx anywhere fails the test.
"""

from __future__ import annotations

import json
import math
import re

import pytest
from fastapi.testclient import TestClient

from microbearing import physics
from microbearing.service.app import create_app
from microbearing.service.jsonguard import MAX_DEPTH, check_json_structure
from microbearing.service.problems import ProblemError
from microbearing.service.settings import Settings

PROBLEM = "application/problem+json"
JSON = {"content-type": "application/json"}
POINT = {"balls": 4, "load_N": 0.01, "speed_m_s": 0.1}


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    # Default limits (256 MiB bodies, 2 million batch points), as a deployment has them.
    app = create_app(Settings(data_dir=tmp_path_factory.mktemp("hostile")))
    with TestClient(app, raise_server_exceptions=False) as test_client:
        yield test_client


def operations(client: TestClient) -> list[tuple[str, str, list[str]]]:
    """(method, path template, request media types) of every operation in the spec."""
    spec = client.app.openapi()
    return [(method.upper(), path, list((operation.get("requestBody") or {}).get("content", {})))
            for path, item in spec["paths"].items() for method, operation in item.items()]


def concrete(path: str, value: str = "0123abcd") -> str:
    return re.sub(r"\{[^}]+\}", value, path)


def assert_client_error(response, where: str) -> None:
    assert 400 <= response.status_code < 500, f"{where}: {response.status_code} {response.text[:300]}"
    assert response.headers["content-type"] == PROBLEM, where
    problem = response.json()
    assert problem["status"] == response.status_code and problem["title"] and problem["detail"], where


def assert_healthy(client: TestClient) -> None:
    assert client.get("/healthz").json() == {"status": "ok"}


def deep(levels: int, opener: bytes = b"[", closer: bytes = b"]") -> bytes:
    return opener * levels + b"1" + closer * levels


DEEP_OBJECT = b'{"a":' * 10_000 + b"1" + b"}" * 10_000

#: Bodies that are wrong for every JSON operation, whatever its schema.
MALFORMED = {
    "10,000 nested arrays": deep(10_000),
    "10,000 nested objects": DEEP_OBJECT,
    "nesting one past the limit": deep(MAX_DEPTH + 1),
    "null": b"null",
    "a bare number": b"1e400",
    "a huge integer literal": b"1" + b"0" * 400,
    "a 5000-digit integer": b"9" * 5000,
    "an empty body": b"",
    "truncated": b'{"balls": 4, "load_N":',
    "invalid UTF-8": b'{"balls": 4, "\xff\xfe": 1}',
    "UTF-16": json.dumps(POINT).encode("utf-16"),
    "a byte-order mark": b"\xef\xbb\xbf" + json.dumps(POINT).encode(),
    "duplicate keys": b'{"balls": 4, "balls": 5, "load_N": 0.01, "speed_m_s": 0.1}',
    "an array of 20 million items": b"[" + b"1," * 19_999_999 + b"1]",
    "30 MB of spaces": b" " * 30_000_000,
    "a 30 MB string": b'{"design": "' + b"x" * 30_000_000 + b'"}',
    "NaN": b'{"balls": 4, "load_N": NaN, "speed_m_s": 0.1}',
    "Infinity": b'{"balls": 4, "load_N": Infinity, "speed_m_s": 0.1}',
    "a list of nulls": b"[null, null, null]",
    "a string": b'"friction"',
}


@pytest.mark.parametrize("name", list(MALFORMED))
def test_malformed_bodies_get_4xx_problems_everywhere(client, name):
    body = MALFORMED[name]
    for method, path, media_types in operations(client):
        if not media_types:
            continue
        headers = {"content-type": media_types[0] if media_types[0] != "text/csv" else "application/json"}
        response = client.request(method, concrete(path), content=body, headers=headers)
        assert_client_error(response, f"{method} {path} with {name}")
    assert_healthy(client)


@pytest.mark.parametrize("second", ["text/plain", "application/json"])
def test_two_content_type_headers_are_refused_before_the_body_is_read(client, second):
    # Starlette reads the first Content-Type, a dict of the headers the last: either way round, one
    # reader would skip the structure check the other relies on. Refused outright, on every operation.
    bodies = {"100,000 nested arrays": b"[" * 100_000 + b"]" * 100_000,
              "duplicate keys": b'{"design": "grid", "design": "sobol", "points": 8}',
              "a valid point": json.dumps(POINT).encode()}
    for first in ("application/json", "text/plain"):
        headers = [("content-type", first), ("content-type", second)]
        for method, path, _ in operations(client):
            for name, body in bodies.items():
                response = client.request(method, concrete(path), content=body, headers=headers)
                where = f"{method} {path} with {name} as {first}, {second}"
                assert response.status_code == 400, f"{where}: {response.status_code} {response.text[:200]}"
                assert_client_error(response, where)
                assert "Content-Type" in response.json()["detail"], where
    assert_healthy(client)


def test_the_body_parser_answers_nesting_beyond_the_stack_with_a_400_problem():
    # service.jsonguard refuses such bodies first; the parser on its own must not fail with a 500 either
    import asyncio

    from starlette.requests import Request

    from microbearing.service.schemas.base import parse_json_body
    from microbearing.service.schemas.friction import FrictionRequest

    body = b"[" * 100_000 + b"]" * 100_000

    async def receive():
        return {"type": "http.request", "body": body, "more_body": False}

    request = Request({"type": "http", "method": "POST", "path": "/v1/friction", "query_string": b"",
                       "headers": [(b"content-type", b"application/json")]}, receive)
    with pytest.raises(ProblemError) as caught:
        asyncio.run(parse_json_body(request, FrictionRequest))
    assert caught.value.status == 400 and "too deeply" in caught.value.detail


@pytest.mark.parametrize("content_type", ["text/plain", "application/x-www-form-urlencoded",
                                          "multipart/form-data; boundary=x", "application/xml", "image/png"])
def test_wrong_content_types_are_refused(client, content_type):
    body = json.dumps({"points": POINT, **POINT}).encode()
    for method, path, media_types in operations(client):
        if media_types and "application/json" in media_types:
            response = client.request(method, concrete(path), content=body,
                                      headers={"content-type": content_type})
            assert_client_error(response, f"{method} {path} as {content_type}")
    assert_healthy(client)


ABSURD_NUMBERS = {
    "1e400": "1e400", "-1e400": "-1e400", "10**400": "1" + "0" * 400, "-10**400": "-1" + "0" * 400,
    "1e-400 (underflows to 0)": "1e-400", "5e-324 (denormal)": "5e-324", "-5e-324": "-5e-324",
    "1.7976931348623157e308": "1.7976931348623157e308", "null": "null", "true": "true", "a string": '"0.01"',
    "a list in a list": "[[0.01]]", "an object": '{"value": 0.01}', "-0.0": "-0.0",
}


def with_value(template: str, literal: str) -> bytes:
    return template.replace("@", literal).encode()


#: Each operation's body with one numeric field replaced by an absurd literal (``@``).
TEMPLATES = {
    "/v1/friction": ['{"balls": 4, "load_N": @, "speed_m_s": 0.1}',
                     '{"balls": @, "load_N": 0.01, "speed_m_s": 0.1}',
                     '{"balls": 4, "load_N": 0.01, "speed_m_s": 0.1, "groove_angle_deg": @}'],
    "/v1/friction/batch": ['{"points": {"balls": 4, "load_N": [0.01, @], "speed_m_s": 0.1}}',
                           '{"points": {"balls": [4, @], "load_N": 0.01, "speed_m_s": 0.1}}',
                           '{"points": {"balls": 4, "load_N": @, "speed_m_s": [0.1, 0.2]}}'],
    "/v1/sweeps": ['{"design": "grid", "axes": {"load_N": {"start": @, "stop": 0.1, "num": 3}}, '
                   '"fixed": {"balls": 4, "speed_m_s": 0.1}}',
                   '{"design": "grid", "axes": {"load_N": {"start": 0.001, "stop": 0.1, "num": @}}, '
                   '"fixed": {"balls": 4, "speed_m_s": 0.1}}',
                   '{"design": "sobol", "ranges": {"load_N": {"low": 0.001, "high": @}}, "points": 8, '
                   '"fixed": {"balls": 4, "speed_m_s": 0.1}}',
                   '{"design": "latin_hypercube", "ranges": {"speed_m_s": {"low": 0, "high": 0.1}}, '
                   '"points": @, "fixed": {"balls": 4, "load_N": 0.01}}'],
    "/v1/calibrations": ['{"data": [{"balls": 4, "load_N": @, "speed_m_s": 0.1, "mu_measured": 0.01}], '
                         '"fit_parameters": ["mu_pivot"]}',
                         '{"data": [{"balls": 4, "load_N": 0.01, "speed_m_s": 0.1, "mu_measured": @}], '
                         '"folds": @}'],
    "/v1/surrogates": ['{"space": {"load_N": [@, 0.05]}, "fixed": {"balls": 4, "speed_m_s": 0.05}, '
                       '"budget": 2, "adaptive": false}',
                       '{"space": {"load_N": [0.001, 0.05]}, "fixed": {"balls": 4, "speed_m_s": 0.05}, '
                       '"budget": @, "adaptive": false}'],
    "/v1/optimizations": ['{"bounds": {"balls": [4, 8], "groove_angle_deg": [35, 70], "load_N": [@, 0.05]}, '
                          '"speed_m_s": 0.05}',
                          '{"bounds": {"balls": [4, 8], "groove_angle_deg": [35, 70], '
                          '"load_N": [0.001, 0.05]}, "speed_m_s": 0.05, '
                          '"constraints": {"max_contact_pressure_Pa": @}}'],
}


def finite_outputs(document) -> bool:
    numbers = [v for value in document.values() for v in (value if isinstance(value, list) else [value])
               if isinstance(v, float)]
    return all(math.isfinite(v) for v in numbers)


@pytest.mark.parametrize("path", list(TEMPLATES))
def test_absurd_numbers_never_cause_a_server_error(client, path):
    known = {p for _, p, _ in operations(client)}
    if path not in known:
        pytest.skip(f"{path} is not served")
    for template in TEMPLATES[path]:
        for name, literal in ABSURD_NUMBERS.items():
            response = client.post(path, content=with_value(template, literal), headers=JSON)
            where = f"{path} {template} with {name}"
            if response.status_code < 300:
                # Only values inside the allowed ranges (or null for an optional limit) may pass;
                # the answer must then be finite.
                assert name in {"5e-324 (denormal)", "-0.0", "1.7976931348623157e308", "true", "null"}, where
                if response.status_code == 200 and response.headers["content-type"] == "application/json":
                    assert finite_outputs(response.json()), where
            else:
                assert_client_error(response, where)
    assert_healthy(client)


def test_a_20_million_point_batch_is_refused_before_parsing(client):
    column = b"[" + b"0.01," * 19_999_999 + b"0.01]"
    body = b'{"points": {"balls": 4, "load_N": ' + column + b', "speed_m_s": 0.1}}'
    response = client.post("/v1/friction/batch", content=body, headers=JSON)
    assert_client_error(response, "20 million points")
    assert response.status_code == 413
    assert "2000000" in response.json()["detail"]
    assert_healthy(client)


def test_a_batch_just_over_the_point_limit_is_refused(tmp_path):
    settings = Settings(data_dir=tmp_path, max_batch_points=1000)
    with TestClient(create_app(settings)) as small:
        ok = small.post("/v1/friction/batch", json={"points": {**POINT, "load_N": [0.01] * 1000}})
        assert ok.status_code == 200 and len(ok.json()["mu"]) == 1000
        response = small.post("/v1/friction/batch", json={"points": {**POINT, "load_N": [0.01] * 1001}})
        assert_client_error(response, "1001 points")
        assert response.status_code == 413


def test_a_body_over_the_configured_limit_is_refused(tmp_path):
    settings = Settings(data_dir=tmp_path, max_body_bytes=1_000_000)
    with TestClient(create_app(settings), raise_server_exceptions=False) as small:
        big = json.dumps({"points": {**POINT, "load_N": [0.01] * 400_000}}).encode()
        assert len(big) > 1_000_000
        declared = small.post("/v1/friction/batch", content=big, headers=JSON)
        assert_client_error(declared, "declared oversize body")
        assert declared.status_code == 413

        def chunks():  # no Content-Length: the limit counts the streamed bytes
            for start in range(0, len(big), 65_536):
                yield big[start:start + 65_536]

        streamed = small.post("/v1/friction/batch", content=chunks(), headers=JSON)
        assert_client_error(streamed, "streamed oversize body")
        assert streamed.status_code == 413
        assert small.get("/healthz").status_code == 200


@pytest.mark.parametrize("identifier", ["x" * 10_000, "%00", "..%2F..%2Fetc%2Fpasswd", "%FF%FE", "null",
                                        "-1", "1e400", "%F0%9F%92%A5", "' OR 1=1 --", "a%0Ab"])
def test_absurd_path_parameters_get_4xx(client, identifier):
    for method, path, _ in operations(client):
        if "{" not in path:
            continue
        response = client.request(method, concrete(path, identifier))
        assert_client_error(response, f"{method} {path} with {identifier[:20]}")
    assert_healthy(client)


def test_wrong_shapes_and_nulls_name_the_field(client):
    response = client.post("/v1/friction/batch", json={"points": {**POINT, "load_N": [[0.01], [0.02]]}})
    assert_client_error(response, "nested list")
    assert any(e["pointer"].startswith("/points/load_N") for e in response.json()["errors"])
    response = client.post("/v1/friction", json={**POINT, "load_N": None})
    assert_client_error(response, "null load")
    assert "/load_N" in [e["pointer"] for e in response.json()["errors"]]
    response = client.post("/v1/friction/batch", json={"points": {**POINT, "load_N": [0.01, 0.02],
                                                                  "speed_m_s": [0.1, 0.2, 0.3]}})
    assert_client_error(response, "lists of different lengths")


def test_unknown_methods_and_paths_are_problems(client):
    assert_client_error(client.request("PATCH", "/v1/friction", json=POINT), "PATCH")
    assert_client_error(client.request("BREW", "/v1/friction"), "unknown method")
    assert_client_error(client.get("/v1/" + "a/" * 2000), "long path")
    assert_healthy(client)


@pytest.mark.parametrize("body, max_items, status", [
    (b'{"a": 1, "b": [1, 2, {"c": "x,y,z"}]}', 4, None),
    (b'{"a": 1, "a": 2}', 100, 400),
    (b'{"a": {"k": 1}, "b": {"k": 2}}', 100, None),      # the same key in two objects is fine
    (b'{"ab": 1, "a\\u0062": 2}', 100, 400),           # the same key, escaped differently
    (b'["\\"[[[{{{", "]]]}}}"]', 3, None),              # brackets and quotes inside strings
    (b'[1, 2, 3, 4]', 3, 413),                          # one array longer than the limit
    (b'[1, 2, 3]', 3, None),
    (b'["a,b,c,d,e,f"]', 3, None),                      # commas inside a string are not elements
    (b'["a", "b", "c", "d"]', 3, 413),                  # more strings than the limit
    (b'[[], [], [], []]', 3, 413),                      # more containers than the limit
    (deep(MAX_DEPTH), 100, None),
    (deep(MAX_DEPTH + 1), 100, 400),
    (b'\xc3\x28', 3, 400),                              # not UTF-8
])
def test_the_structure_check_on_its_own(body, max_items, status):
    if status is None:
        check_json_structure(body, max_items=max_items)
        json.loads(body)  # the cases it accepts are valid JSON the parser takes too
    else:
        with pytest.raises(ProblemError) as caught:
            check_json_structure(body, max_items=max_items)
        assert caught.value.status == status


def test_every_parameter_bound_is_enforced_with_a_4xx(client):
    # Independent of the schema code: walk the physics table and step just outside each bound.
    for name, spec in physics.PARAMETERS.items():
        outside = []
        if spec.minimum is not None:
            step = max(1, abs(spec.minimum))
            outside.append(spec.minimum if spec.exclusive_minimum else spec.minimum - step)
        if spec.maximum is not None:
            step = max(1, abs(spec.maximum))
            outside.append(spec.maximum if spec.exclusive_maximum else spec.maximum + step)
        for value in outside:
            value = int(value) if spec.kind == "int" else float(value)
            response = client.post("/v1/friction", json={**POINT, name: value})
            assert_client_error(response, f"{name}={value}")
            assert f"/{name}" in [e.get("pointer") for e in response.json()["errors"]], name
    assert_healthy(client)


def test_a_million_bad_values_get_a_bounded_answer(client):
    # 200,000 wrong values: the answer lists the first 100 fields and counts the rest; answering it
    # used to compare every pointer with every other (quadratic: a minute for 10,000 values).
    body = json.dumps({"points": {**POINT, "load_N": ["x"] * 200_000}}).encode()
    response = client.post("/v1/friction/batch", content=body, headers=JSON)
    assert_client_error(response, "200,000 strings")
    problem = response.json()
    assert len(problem["errors"]) == 100
    assert [e["pointer"] for e in problem["errors"][:3]] == ["/points/load_N/0", "/points/load_N/1",
                                                             "/points/load_N/2"]
    assert "200001 errors in all" in problem["detail"] and len(response.content) < 50_000
    assert_healthy(client)


@pytest.mark.parametrize(("body", "repeated"), [
    (b'{"balls": 4, "load_N": 0.01, "speed_m_s": 0.1}', None),
    (b'{"a:b": 1, "a": "b", "b": "a", "": 2}', None),  # a colon in a key, keys written as values
    (b'{"a" : 1,"a"\n:2}', "a"),  # whitespace around the colon
    (b'{"a": 1, "\\u0061": 2}', "a"),  # the same key written with an escape
    (b'{"a": {"b": 1, "b": 2}}', "b"),  # nested: not one flat object
])
def test_duplicate_keys_of_one_flat_object_are_found_without_the_parser_too(body, repeated):
    # one flat object without escapes (a single point's body) is checked by its strings before a colon
    if repeated is None:
        check_json_structure(body, 1000)
        return
    with pytest.raises(ProblemError, match=f"The key '{repeated}' appears twice in one object"):
        check_json_structure(body, 1000)
