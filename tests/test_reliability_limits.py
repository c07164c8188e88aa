"""Limits on every input: calibration rows, echoed input in errors, content coding, Accept, result size."""

from __future__ import annotations

import json

import pytest
from fastapi.testclient import TestClient

from microbearing.service.app import create_app
from microbearing.service.settings import Settings

PROBLEM = "application/problem+json"
POINT = {"balls": 4, "load_N": 0.01, "speed_m_s": 0.1}
ROW = {"balls": 4.0, "load_N": 0.01, "speed_m_s": -0.1, "mu_measured": 0.02}  # a bad speed: 422 if read


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    settings = Settings(data_dir=tmp_path_factory.mktemp("limits"), max_calibration_rows=5,
                        max_result_bytes=1_000_000, sweep_sync_max_points=0)
    with TestClient(create_app(settings)) as test_client:
        yield test_client


def problem(response, status: int) -> dict:
    assert response.status_code == status, response.text[:500]
    assert response.headers["content-type"] == PROBLEM
    body = response.json()
    assert body["status"] == status
    return body


def csv_body(rows: int, final_newline: bool = True) -> bytes:
    lines = ["balls,load_N,speed_m_s,mu_measured", *["4,0.01,-0.1,0.02"] * rows]
    return ("\n".join(lines) + ("\n" if final_newline else "")).encode()


@pytest.mark.parametrize("rows, status", [(5, 422), (6, 413), (1000, 413)])
def test_calibration_rows_past_the_limit_get_413_in_json_and_csv(client, rows, status):
    csv = {"content-type": "text/csv"}
    answers = [client.post("/v1/calibrations", json={"data": [ROW] * rows}),
               client.post("/v1/calibrations/csv", content=csv_body(rows), headers=csv),
               client.post("/v1/calibrations/csv", content=csv_body(rows, final_newline=False), headers=csv)]
    for response in answers:
        body = problem(response, status)  # at the limit the rows are read (and the bad speed found)
        if status == 413:
            assert f"has {rows} rows; the limit is 5 (MICROBEARING_MAX_CALIBRATION_ROWS)" in body["detail"]


def test_an_echoed_long_key_gets_a_bounded_error(client):
    # 60,000 characters: under the structure check's longest key (65,536 bytes), so the schema answers
    key = "k" * 60_000
    body = ('{"balls": 4, "load_N": 0.01, "speed_m_s": 0.1, "' + key + '": 1}').encode()
    response = client.post("/v1/friction", content=body, headers={"content-type": "application/json"})
    answer = problem(response, 422)
    assert len(response.content) < 10_000
    pointer = answer["errors"][0]["pointer"]
    assert pointer.startswith("/kkkk") and pointer.endswith("more characters)")
    assert "more characters)" in answer["detail"]


def test_a_key_of_a_megabyte_is_refused_before_parsing(client):
    key = "k" * 1_000_000
    body = ('{"balls": 4, "load_N": 0.01, "speed_m_s": 0.1, "' + key + '": 1}').encode()
    response = client.post("/v1/friction", content=body, headers={"content-type": "application/json"})
    answer = problem(response, 413)
    assert len(response.content) < 10_000 and "key" in answer["detail"] and "65536 bytes" in answer["detail"]


@pytest.mark.parametrize("encoding", ["gzip", "deflate", "br", "GZIP"])
@pytest.mark.parametrize("path", ["/v1/friction", "/v1/sweeps", "/v1/calibrations/csv"])
def test_a_compressed_body_gets_415(client, path, encoding):
    response = client.post(path, content=b"\x1f\x8b\x08\x00" + bytes(64),
                           headers={"content-type": "application/json", "content-encoding": encoding})
    answer = problem(response, 415)
    assert response.headers["accept-encoding"] == "identity" and "Content-Encoding" in answer["detail"]
    identity = client.post("/v1/friction", json=POINT, headers={"content-encoding": "identity"})
    assert identity.status_code == 200


@pytest.mark.parametrize("content_type, status", [
    ("text/plain", 415), ("application/x-www-form-urlencoded", 415), ("TEXT/CSV; charset=utf-8", 415),
    ("application/json", 200), ("Application/JSON; charset=utf-8", 200), ("application/vnd.point+json", 200),
    (None, 200),  # no type: read as JSON
])
@pytest.mark.parametrize("path", ["/v1/friction", "/v1/friction/batch"])
def test_a_body_declared_as_something_else_than_json_gets_415(client, path, content_type, status):
    # The JSON body of a route that parses its own body, declared by its Content-Type header.
    body = {"points": POINT} if path.endswith("batch") else POINT
    headers = {} if content_type is None else {"content-type": content_type}
    response = client.post(path, content=json.dumps(body).encode(), headers=headers)
    if status == 415:
        media_type = content_type.split(";")[0].lower()
        assert f"not {media_type!r}" in problem(response, 415)["detail"]
    else:
        assert response.status_code == 200, response.text[:300]
        mu = response.json()["mu"]
        assert (mu if path.endswith("batch") else [mu])[0] > 0


@pytest.mark.parametrize("accept, status", [
    ("image/png", 406), ("text/csv", 406), ("application/json;q=0, text/html", 406), ("text/*", 406),
    ("application/json", 200), ("*/*", 200), ("application/*", 200), ("text/html, */*;q=0.1", 200),
    ("APPLICATION/JSON", 200),
])
def test_an_accept_the_route_cannot_satisfy_gets_406(client, accept, status):
    response = client.post("/v1/friction", json=POINT, headers={"accept": accept})
    if status == 406:
        answer = problem(response, 406)
        assert "application/json" in answer["detail"]
    else:
        assert response.status_code == 200 and response.headers["content-type"] == "application/json"


def test_routes_with_several_media_types_accept_each(client):
    sweep = {"design": "grid", "axes": {"load_N": {"start": 1e-3, "stop": 0.05, "num": 3}},
             "fixed": {"balls": 4, "speed_m_s": 0.05}, "outputs": ["mu"]}
    assert client.post("/v1/sweeps", json=sweep, headers={"accept": "text/csv"}).status_code == 202
    problem(client.post("/v1/sweeps", json=sweep, headers={"accept": "image/png"}), 406)
    plot = client.get("/v1/calibrations/0123/plots/residual.png", headers={"accept": "image/png"})
    assert plot.status_code == 404
    # a plot is no JSON: asked for JSON alone, 406 naming what it offers (it passed as a PNG)
    answer = problem(client.get("/v1/calibrations/0123/plots/residual.png",
                                headers={"accept": "application/json"}), 406)
    assert "image/png" in answer["detail"]
    assert client.get("/metrics", headers={"accept": "text/plain"}).status_code == 200  # outside the spec


def test_a_sweep_whose_result_would_pass_the_size_limit_gets_413(client):
    sweep = {"design": "sobol", "points": 100_000, "outputs": ["mu"],
             "ranges": {"load_N": {"low": 1e-3, "high": 0.05}}, "fixed": {"balls": 4, "speed_m_s": 0.05}}
    answer = problem(client.post("/v1/sweeps", json=sweep), 413)
    assert "MICROBEARING_MAX_RESULT_BYTES" in answer["detail"] and "1000000" in answer["detail"]
    sweep["points"] = 10_000  # about 400 kB: accepted
    assert client.post("/v1/sweeps", json=sweep).status_code == 202


def test_tables_past_a_limit_are_answered_word_for_word(tmp_path):
    # The four refusals of a table's size, as the README and clients read them (one helper makes them).
    settings = Settings(data_dir=tmp_path, max_calibration_rows=5, max_calibration_columns=6)
    csv = {"content-type": "text/csv"}
    wide = {**ROW, "a": 1.0, "b": 2.0, "c": 3.0}
    with TestClient(create_app(settings)) as test_client:
        answers = {
            "json rows": test_client.post("/v1/calibrations", json={"data": [ROW] * 6}),
            "json columns": test_client.post("/v1/calibrations", json={"data": [wide] * 2}),
            "csv rows": test_client.post("/v1/calibrations/csv", content=csv_body(6), headers=csv),
            "csv columns": test_client.post("/v1/calibrations/csv", headers=csv,
                                            content=b"balls,load_N,speed_m_s,mu_measured,a,b,c\n4,1,1,1,1,1,1\n"),
        }
    expected = {
        "json rows": ("Too many rows",
                      "/data has 6 rows; the limit is 5 (MICROBEARING_MAX_CALIBRATION_ROWS)."),
        "json columns": ("Too many columns",
                         "/data has 7 columns; the limit is 6 (MICROBEARING_MAX_CALIBRATION_COLUMNS)."),
        "csv rows": ("Too many rows",
                     "The CSV body has 6 rows; the limit is 5 (MICROBEARING_MAX_CALIBRATION_ROWS)."),
        "csv columns": ("Too many columns", "The CSV body's header has 7 columns; the limit is 6 "
                                            "(MICROBEARING_MAX_CALIBRATION_COLUMNS)."),
    }
    for name, response in answers.items():
        body = problem(response, 413)
        assert (body["title"], body["detail"]) == expected[name], name
        assert set(body) == {"type", "title", "status", "detail", "instance"}, body


def test_each_limit_past_which_a_request_is_refused_names_its_setting(tmp_path):
    settings = Settings(data_dir=tmp_path, max_body_bytes=20_000, max_batch_points=50, max_sweep_points=200)
    with TestClient(create_app(settings)) as small:
        padded = b'{"points": {"balls": 4, "load_N": 0.01, "speed_m_s": 0.1}' + b" " * 25_000 + b"}"
        json_type = {"content-type": "application/json"}
        declared = problem(small.post("/v1/friction/batch", content=padded, headers=json_type), 413)
        assert "(MICROBEARING_MAX_BODY_BYTES)" in declared["detail"], declared
        streamed = small.post("/v1/friction/batch", content=iter([padded[:10_000], padded[10_000:]]),
                              headers=json_type)  # no Content-Length: counted as it streams
        assert "(MICROBEARING_MAX_BODY_BYTES)" in problem(streamed, 413)["detail"]
        many = {"points": {"balls": 4, "load_N": [0.01] * 51, "speed_m_s": 0.1}}
        assert "(MICROBEARING_MAX_BATCH_POINTS)" in problem(small.post("/v1/friction/batch", json=many),
                                                             413)["detail"]
        sweep = {"design": "sobol", "points": 201, "fixed": {"balls": 4, "load_N": 0.01},
                 "ranges": {"speed_m_s": {"low": 0.0, "high": 0.1}}}
        refused = problem(small.post("/v1/sweeps", json=sweep), 422)
        assert "(MICROBEARING_MAX_SWEEP_POINTS)" in refused["detail"]


def test_a_document_larger_than_its_limit_is_refused_while_a_batch_of_that_size_passes(tmp_path):
    # A sweep, an optimization or one point is a document: past MICROBEARING_MAX_DOCUMENT_BYTES it is refused
    # as it streams, before it is parsed; the routes of data columns take up to MICROBEARING_MAX_BODY_BYTES.
    settings = Settings(data_dir=tmp_path, max_body_bytes=200_000, max_document_bytes=20_000)
    json_type = {"content-type": "application/json"}
    point = b'{"balls": 4, "load_N": 0.01, "speed_m_s": 0.1' + b" " * 30_000 + b"}"
    batch = b'{"points": {"balls": 4, "load_N": 0.01, "speed_m_s": 0.1}' + b" " * 30_000 + b"}"
    with TestClient(create_app(settings), root_path="/bearing") as small:
        for path in ("/v1/friction", "/v1/sweeps", "/v1/optimizations", "/v1/surrogates", "/v1/calibrations",
                     "/v1/experiments", "/v1/calibrations/some-id/next-experiments"):
            declared = problem(small.post(path, content=point, headers=json_type), 413)
            assert "20000 (MICROBEARING_MAX_DOCUMENT_BYTES)" in declared["detail"], (path, declared)
            streamed = small.post(path, content=iter([point[:10_000], point[10_000:]]), headers=json_type)
            assert "(MICROBEARING_MAX_DOCUMENT_BYTES)" in problem(streamed, 413)["detail"], path
        small_point = point[:100].rstrip() + b"}"
        assert small.post("/v1/friction", content=small_point, headers=json_type).status_code == 200
        answer = small.post("/v1/friction/batch", content=batch, headers=json_type)
        assert answer.status_code == 200 and len(answer.json()["mu"]) == 1
        larger = batch + b" " * 200_000
        too_large = problem(small.post("/v1/friction/batch", content=larger, headers=json_type), 413)
        assert "(MICROBEARING_MAX_BODY_BYTES)" in too_large["detail"]
        # a predict of an unknown surrogate is read (not refused for its size) and answered 404
        predict = b'{"points": {"load_N": 0.01}' + b" " * 30_000 + b"}"
        unknown = small.post("/v1/surrogates/nope/predict", content=predict, headers=json_type)
        assert unknown.status_code == 404


def test_a_job_whose_result_is_too_large_keeps_nothing_not_even_its_model(tmp_path):
    # A calibration stores its model as it ends; its result (the report) then passes the limit: the job
    # fails naming the setting and the model goes too (it had stayed listed, counting toward the limit
    # of stored models, with no job result to find it by).
    from jobs_helper import wait_job

    with TestClient(create_app(Settings(data_dir=tmp_path, max_result_bytes=5000))) as small:
        loads = [0.002, 0.004, 0.006, 0.01, 0.014, 0.02, 0.03, 0.04] * 3
        rows = [{"balls": 4, "load_N": g, "speed_m_s": 0.05, "mu_measured": 0.012 * (g / 0.01) ** -0.2}
                for g in loads]
        job = wait_job(small, small.post("/v1/calibrations", json={"data": rows, "folds": 3}))
        assert job["status"] == "failed" and job["error"]["status"] == 413, job
        assert "(MICROBEARING_MAX_RESULT_BYTES)" in job["error"]["detail"]
        assert small.get("/v1/calibrations").json()["calibrations"] == []


def test_the_guard_on_a_bodys_strings_and_containers_passes_what_the_limits_allow(tmp_path):
    # Counted against the batch-points limit alone it refused 48-50 UM-Bridge points (an array each) and
    # a 12-row calibration (its rows' keys are strings) with limits of 50 points and 30 rows.
    settings = Settings(data_dir=tmp_path, max_batch_points=50, max_calibration_rows=30,
                        max_calibration_columns=6)
    with TestClient(create_app(settings)) as small:
        points = {"name": "physics", "input": [[4, 0.01, 0.05]] * 50,
                  "config": {"inputs": ["balls", "load_N", "speed_m_s"], "points": 50}}
        answer = small.post("/umbridge/Evaluate", json=points)
        assert answer.status_code == 200 and len(answer.json()["output"]) == 50, answer.text[:300]
        rows = [{"balls": 4, "load_N": 0.01, "speed_m_s": 0.05, "mu_measured": 0.01}] * 12
        assert small.post("/v1/calibrations", json={"data": rows}).status_code != 413
        # past what any limit allows: refused while it streams, naming the settings it follows
        labels = {"points": {"balls": 4, "load_N": 0.01, "speed_m_s": 0.05},  # 1,620 strings, 50 a container
                  "extra": {f"k{i}": [{"a": "b"}] * 40 for i in range(20)}}
        answer = problem(small.post("/v1/friction/batch", json=labels), 413)
        assert "(a limit that follows MICROBEARING_MAX_BATCH_POINTS and MICROBEARING_MAX_CALIBRATION_ROWS" \
            in answer["detail"], answer


@pytest.mark.parametrize("path, content_type, body, where", [
    # the CSV routes read a body of any type as CSV: generated clients send application/octet-stream
    ("/v1/calibrations/csv", "application/octet-stream", b"balls,load_N,note\n4,0.01," + b"x" * 5000 + b"\n",
     "Line 2 of the application/octet-stream body"),
    ("/v1/calibrations/csv/intake", "text/plain", b"balls,load_N,note\n4,0.01," + b"x" * 5000 + b"\n",
     "Line 2 of the text/plain body"),
    # UM-Bridge reads its body as JSON whatever the type
    ("/umbridge/Evaluate", "text/plain", b'{"name": "physics", "input": [[4]], "x": "' + b"a" * 5000 + b'"}',
     "A string in the body"),
    ("/umbridge/Evaluate", "application/octet-stream",
     b'{"name": "physics", "input": [[1' + b"0" * 5000 + b"]]}", "A value or a run of whitespace"),
], ids=["octet-stream csv", "text/plain csv intake", "umbridge text/plain", "umbridge octet-stream number"])
def test_a_field_past_the_limit_is_refused_as_it_streams_whatever_the_declared_type(
        tmp_path, path, content_type, body, where):
    settings = Settings(data_dir=tmp_path, max_field_bytes=1024)
    with TestClient(create_app(settings)) as small:
        response = small.post(path, content=body, headers={"content-type": content_type})
    assert response.status_code == 413, response.text[:300]
    answer = response.json()
    detail = answer["detail"] if path.startswith("/v1") else answer["error"]["message"]  # UM-Bridge's form
    assert where in detail and "MICROBEARING_MAX_FIELD_BYTES" in detail, detail
