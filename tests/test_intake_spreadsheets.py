"""Files as spreadsheets write them (issue 34, item 2).

Excel's ``sep=;`` first line, a file saved in Windows-1252 (German Excel's default, with the degree
sign of ``temperature [°C]``), a browser's or ``curl -F`` multipart upload, problems placed at the
lines and column letters the spreadsheet shows, text columns said as what they became and left out on
request, and what a calibration fits when ``fit_parameters`` is not given. The files are generated
here from one set of measurements; the conversions they must undergo are done by hand.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import string

import numpy as np
import pytest
from fastapi.testclient import TestClient
from jobs_helper import job_result

from microbearing import physics
from microbearing.calibrate import DataError, parse_csv, read_csv, read_rows
from microbearing.calibrate.tabular import TableError, column_letter
from microbearing.service.app import create_app
from microbearing.service.settings import Settings

PROBLEM = "application/problem+json"
N = 40
OPERATORS = ("Ann", "Bo", "Cem")


def lab_rows(seed: int = 7) -> list[dict]:
    """Measurements in lab units (load in mN, speed in mm/s, temperature in degC) and their operator."""
    rng = np.random.default_rng(seed)
    load_mN = rng.choice([4.4, 8.8, 13.2], N)
    speed_mm_s = rng.choice([10.0, 50.0, 90.0, 140.0], N)
    temperature_C = rng.choice([20.5, 23.0, 25.5, 28.0], N)
    mu = physics.evaluate(balls=4, load_N=load_mN / 1000, speed_m_s=speed_mm_s / 1000, mu_pivot=0.7).mu
    mu = np.round(mu * np.exp(rng.normal(0.0, 0.02, N)), 6)
    return [{"load_mN": float(a), "speed_mm_s": float(b), "temperature_C": float(t), "mu": float(m),
             "operator": OPERATORS[i % 3]}
            for i, (a, b, t, m) in enumerate(zip(load_mN, speed_mm_s, temperature_C, mu, strict=True))]


def clean_csv(rows, operator: bool = False) -> str:
    """The rows in SI, converted by hand: mN / 1000, mm/s / 1000, degC + 273.15."""
    lines = ["balls,load_N,speed_m_s,temperature_K,mu_measured" + (",operator" if operator else "")]
    lines += [f"4,{r['load_mN'] / 1000!r},{r['speed_mm_s'] / 1000!r},{r['temperature_C'] + 273.15!r},"
              f"{r['mu']!r}" + (f",{r['operator']}" if operator else "") for r in rows]
    return "\n".join(lines) + "\n"


def excel_export(rows, separator: str = ";", encoding: str = "cp1252", operator: bool = False) -> bytes:
    """What German Excel saves as 'CSV' after a ``sep=`` line was typed in: Windows-1252, CRLF, decimal
    comma (with semicolons or tabs), the degree sign in the header."""
    decimal = "," if separator != "," else "."

    def cell(v):
        return repr(v).replace(".", decimal)
    header = ["balls", "load [mN]", "speed [mm/s]", "temperature [°C]", "mu_measured"]
    lines = [f"sep={separator}", separator.join(header + (["operator"] if operator else []))]
    lines += [separator.join(["4", cell(r["load_mN"]), cell(r["speed_mm_s"]), cell(r["temperature_C"]),
                              cell(r["mu"])] + ([r["operator"]] if operator else [])) for r in rows]
    return ("\r\n".join(lines) + "\r\n").encode(encoding)


def same_data(a, b) -> None:
    assert sorted(a.physics_columns) == sorted(b.physics_columns)
    assert sorted(a.conditions) == sorted(b.conditions)
    assert sorted(a.factors) == sorted(b.factors)
    for name in a.physics_columns:
        np.testing.assert_allclose(a.physics_columns[name], b.physics_columns[name], rtol=1e-15, err_msg=name)
    for name in a.conditions:
        np.testing.assert_allclose(a.conditions[name], b.conditions[name], rtol=1e-13, err_msg=name)
    for name in a.factors:
        np.testing.assert_array_equal(a.factors[name], b.factors[name])
    np.testing.assert_array_equal(a.mu_measured, b.mu_measured)


# --- the sep= line ---------------------------------------------------------------------------------


@pytest.mark.parametrize(("separator", "name"), [(";", "semicolon"), (",", "comma"), ("\t", "tab")])
def test_excels_sep_line_states_the_separator_and_is_not_a_column(separator, name):
    rows = lab_rows(3)
    dataset, intake = read_csv(excel_export(rows, separator))
    same_data(dataset, parse_csv(clean_csv(rows)))
    assert intake.separator == name and "separator" not in intake.detected
    assert intake.header_line == 2 and "sep=" not in " ".join(intake.to_dict()["columns"])
    assert any(note.startswith("line 1 'sep=") for note in intake.notes)
    assert "(sep= line)" in intake.summary()
    # the same separator stated agrees; another one is one problem naming both, at the parameter
    assert read_csv(excel_export(rows, separator), separator=name)[1].separator == name
    other = "comma" if name != "comma" else "semicolon"
    with pytest.raises(DataError) as wrong:
        read_csv(excel_export(rows, separator), separator=other)
    assert len(wrong.value.errors) == 1 and wrong.value.errors[0]["parameter"] == "separator"
    message = wrong.value.errors[0]["message"]
    assert f"separator={other}" in message and name in message


def test_a_sep_line_with_a_separator_not_read_is_refused():
    with pytest.raises(DataError) as pipe:
        read_csv("sep=|\nballs|load_N|speed_m_s|mu_measured\n4|0.01|0.1|0.01\n")
    assert "'sep=|'" in pipe.value.errors[0]["message"] and "semicolon" in pipe.value.errors[0]["message"]


# --- encodings -------------------------------------------------------------------------------------


def test_a_windows_1252_file_is_read_and_said_so_and_utf8_with_bom_still_works():
    rows = lab_rows(4)
    raw = excel_export(rows)
    assert b"\xb0C" in raw  # the degree sign as Windows-1252 writes it: one byte, not UTF-8
    with pytest.raises(UnicodeDecodeError):
        raw.decode("utf-8")
    reference = parse_csv(clean_csv(rows))
    dataset, intake = read_csv(raw)
    same_data(dataset, reference)
    assert intake.encoding == "Windows-1252"
    assert any("read as Windows-1252" in note and "'°'" in note for note in intake.notes)
    assert "temperature [°C]" in intake.to_dict()["columns"]
    bom = "\ufeff".encode() + raw.decode("cp1252").encode("utf-8")
    dataset, intake = read_csv(bom)
    same_data(dataset, reference)
    assert intake.encoding == "UTF-8 with BOM" and not any("Windows" in n for n in intake.notes)
    dataset, intake = read_csv(raw.decode("cp1252").encode("utf-16"))  # Excel's "Unicode text"
    same_data(dataset, reference)
    assert intake.encoding == "UTF-16 with BOM"


@pytest.mark.parametrize(("data", "words"), [
    (b"PK\x03\x04\x14\x00\x06\x00", "Excel workbook (.xlsx)"),
    (b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1", "Excel 97-2003 workbook"),
    (b"balls,load_N\n4,0.01\n4,\x000.1\n", "line 3 holds a NUL byte"),
    (b"balls,load_N\n4,0.01\x81\n", "byte 0x81 on line 2"),  # undefined in Windows-1252
])
def test_a_file_that_is_not_text_says_what_it_is(data, words):
    with pytest.raises(DataError) as bad:
        read_csv(data)
    assert len(bad.value.errors) == 1
    assert bad.value.errors[0]["message"].startswith("CSV is not UTF-8: ") and words in str(bad.value)


# --- positions as the spreadsheet shows them -------------------------------------------------------


def test_column_letters_are_the_spreadsheets():
    # brute force: A..Z, then AA..ZZ, then AAA.., as a spreadsheet numbers its columns
    letters = list(string.ascii_uppercase)
    expected = letters + ["".join(p) for p in itertools.product(letters, repeat=2)] + ["AAA"]
    assert [column_letter(i) for i in range(len(expected))] == expected


def test_problems_name_the_file_line_and_the_column_letter():
    rows = lab_rows(5)
    text = excel_export(rows).decode("cp1252").splitlines()
    # data row 7 is line 9 (sep= line 1, header line 2); its speed is column C
    cells = text[8].split(";")
    cells[2] = "-50"
    text[8] = ";".join(cells)
    text.insert(12, ";;;;")  # a blank row: line 13
    with pytest.raises(TableError) as bad:
        read_csv("\r\n".join(text) + "\r\n")
    speed = next(e for e in bad.value.errors if e["column"] == "speed_m_s")
    assert (speed["row"], speed["line"], speed["letter"], speed["sent"]) == (7, 9, "C", "speed [mm/s]")
    assert TableError.describe(speed).startswith("line 9, column C (speed [mm/s]): speed_m_s must be")
    blank = next(e for e in bad.value.errors if e["column"] is None)
    assert TableError.describe(blank).startswith("line 13: is blank")
    assert "line 9, column C (speed [mm/s])" in str(bad.value)  # a terminal reads the same
    # a bad unit in the header: its letter, without a line
    with pytest.raises(DataError) as unit:
        read_csv("balls;load_N;speed [furlong];mu_measured\n4;0.01;1;0.01\n")
    assert TableError.describe(unit.value.errors[0]).startswith("column C (speed [furlong]): ")


def test_a_quoted_cell_over_two_lines_keeps_the_lines_counted():
    text = 'balls,load_N,speed_m_s,mu_measured,note\n4,0.01,0.1,0.01,"two\nlines"\n4,0.01,-1,0.01,x\n'
    with pytest.raises(TableError) as bad:
        read_csv(text)
    assert [(e["row"], e["line"], e["letter"]) for e in bad.value.errors] == [(2, 4, "C")]


# --- text columns and ignore -----------------------------------------------------------------------


def test_text_columns_say_what_they_became_and_one_can_be_ignored():
    rows = lab_rows(6)
    raw = excel_export(rows, operator=True)
    dataset, intake = read_csv(raw)
    assert sorted(set(dataset.factors["operator"])) == sorted(OPERATORS)
    assert intake.text_columns == {"operator": "random-effect groups (3 levels)"}
    assert "operator: random-effect groups (3 levels)" in intake.summary()
    ignored, intake = read_csv(raw, ignore=["operator"])
    assert ignored.factors == {} and intake.text_columns == {}
    assert intake.ignored == ["column F (operator), as ignore asks"]
    same_data(ignored, parse_csv(clean_csv(rows)))
    # by the name a column is read as, too; a name that is no column is one problem naming the columns
    assert "temperature_K" not in read_csv(raw, ignore=["temperature_K"])[0].conditions
    with pytest.raises(DataError) as unknown:
        read_csv(raw, ignore=["operater"])
    assert unknown.value.errors[0]["parameter"] == "ignore" and "'operator'" in str(unknown.value)


def test_a_date_column_is_said_as_what_it_became():
    rows = lab_rows(8)
    lines = clean_csv(rows).splitlines()
    dates = [f"2026-11-{1 + i // 10:02d}" for i in range(N)]
    text = "\n".join([lines[0] + ",date"] + [f"{line},{d}" for line, d in zip(lines[1:], dates, strict=True)])
    dataset, intake = read_csv(text + "\n")
    became = intake.text_columns["date"]
    # whatever the data set makes of dates (groups, or hours since the first), the intake says the same
    if "date" in dataset.factors:
        assert became == f"random-effect groups ({len(set(dates))} levels)"
    else:
        assert became == f"hours since {dataset.clock['date']}: the condition date [h]"
        hours = [24.0 * (int(d[-2:]) - 1) for d in dates]  # from 2026-11-01, by hand
        np.testing.assert_allclose(dataset.conditions["date"], hours)


def test_json_rows_take_ignore_and_say_their_text_columns():
    rows = lab_rows(9)
    json_rows = [{"balls": 4, "load [mN]": r["load_mN"], "speed [mm/s]": r["speed_mm_s"],
                  "mu_measured": r["mu"], "operator": r["operator"], "comment": "ok"} for r in rows]
    dataset, intake = read_rows(json_rows, ignore=["comment"])
    assert intake.text_columns == {"operator": "random-effect groups (3 levels)"}
    assert intake.ignored == ["column comment, as ignore asks"] and "comment" not in dataset.factors


# --- through the API -------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    settings = Settings(data_dir=tmp_path_factory.mktemp("spreadsheets"), max_body_bytes=200_000,
                        max_field_bytes=4096)
    with TestClient(create_app(settings)) as test_client:
        yield test_client


def finished(client: TestClient, response) -> dict:
    return job_result(client, response, timeout_s=300, interval_s=0.1)


def test_an_excel_export_uploaded_as_a_form_calibrates_like_the_clean_file(client):
    rows = lab_rows(11)
    params = {"fit_parameters": "mu_pivot", "folds": 2}
    raw = excel_export(rows)
    # the browser's and curl -F's upload: multipart/form-data, the file in the field file
    excel = finished(client, client.post("/v1/calibrations/csv", params=params,
                                         files={"file": ("lab.csv", raw, "text/csv")}))
    clean = finished(client, client.post("/v1/calibrations/csv", params=params, content=clean_csv(rows),
                                         headers={"content-type": "text/csv"}))
    for name in ("value", "std"):
        assert excel["fitted_parameters"]["mu_pivot"][name] == pytest.approx(
            clean["fitted_parameters"]["mu_pivot"][name], rel=1e-9)
    assert excel["error_after"] == pytest.approx(clean["error_after"], rel=1e-9)
    assert excel["fitted_parameters"]["mu_pivot"]["value"] == pytest.approx(0.7, rel=0.05)
    intake = excel["intake"]
    assert (intake["separator"], intake["decimal"], intake["encoding"], intake["header_line"]) == (
        "semicolon", "comma", "Windows-1252", 2)
    assert any("read as Windows-1252" in note for note in intake["notes"])
    assert "uploaded as multipart/form-data, field file ('lab.csv')" in intake["notes"]
    assert intake["fitting"].startswith("fits mu_pivot [1]")
    assert "speed [mm/s] read as speed_m_s / 1000" in intake["conversions"]
    assert intake["columns"]["temperature [°C]"] == "temperature_K"
    assert clean["intake"]["conversions"] == [] and clean["intake"]["separator"] == "comma"
    # the calibration is stored with the report: GET answers the same intake
    assert client.get(f"/v1/calibrations/{excel['id']}").json()["intake"] == intake
    # the raw body and the form read alike
    reading = client.post("/v1/calibrations/csv/intake", content=raw, headers={"content-type": "text/csv"})
    form = client.post("/v1/calibrations/csv/intake", files={"file": ("lab.csv", raw, "text/csv")})
    assert reading.status_code == form.status_code == 200, (reading.text, form.text)
    assert {**form.json()["intake"], "notes": form.json()["intake"]["notes"][:-1]} == reading.json()["intake"]


def test_the_intake_says_what_is_fitted_and_lists_text_columns(client):
    raw = excel_export(lab_rows(12), operator=True)
    reading = client.post("/v1/calibrations/csv/intake", files={"file": ("lab.csv", raw)}).json()
    assert "operator" in reading["columns"] and reading["factors"] == ["operator"]
    assert reading["intake"]["text_columns"] == {"operator": "random-effect groups (3 levels)"}
    fitting = reading["intake"]["fitting"]
    assert fitting.startswith("fit_parameters is empty, so no declared parameter is fitted")
    assert "mu_pivot 0.5 [1]" in fitting  # the default it keeps (physics.PARAMETERS)
    named = client.post("/v1/calibrations/csv/intake", params={"fit_parameters": "mu_ball"},
                        files={"file": ("lab.csv", raw)}).json()
    assert named["intake"]["fitting"].startswith("fits mu_ball [1]")
    left_out = client.post("/v1/calibrations/csv/intake", params={"ignore": "operator"},
                           files={"file": ("lab.csv", raw)}).json()
    assert "operator" not in left_out["columns"] and left_out["intake"]["text_columns"] == {}
    given = client.post("/v1/calibrations/csv/intake", params={"fit_parameters": "mu_pivot"},
                        content="balls,load_N,speed_m_s,mu_pivot,mu_measured\n4,0.01,0.1,0.5,0.01\n",
                        headers={"content-type": "text/csv"})
    assert given.status_code == 422 and given.json()["errors"][0]["parameter"] == "fit_parameters"


def test_api_problems_name_lines_letters_and_parameters(client):
    raw = excel_export(lab_rows(13))
    wrong = client.post("/v1/calibrations/csv/intake", params={"separator": "comma"}, content=raw,
                        headers={"content-type": "text/csv"})
    assert wrong.status_code == 422 and wrong.headers["content-type"] == PROBLEM
    [error] = wrong.json()["errors"]
    assert error["parameter"] == "separator" and "separator=comma" in error["detail"] and \
        "semicolon" in error["detail"]
    lines = raw.split(b"\r\n")
    cells = lines[8].split(b";")  # data row 7: line 9 of the file
    cells[1] = b"-4,4"  # load [mN], column B
    lines[8] = b";".join(cells)
    bad = client.post("/v1/calibrations/csv/intake", files={"file": ("lab.csv", b"\r\n".join(lines))})
    assert bad.status_code == 422
    assert [e["detail"][:30] for e in bad.json()["errors"]] == ["line 9, column B (load [mN]): "]
    unknown = client.post("/v1/calibrations", json={"data": [{"balls": 4, "load_N": 0.01, "speed_m_s": 0.1,
                                                              "mu_measured": 0.01}], "ignore": ["note"]})
    assert unknown.status_code == 422 and unknown.json()["errors"][0]["pointer"] == "/ignore"


def test_a_multipart_upload_without_its_file_field_is_a_problem_naming_the_fields(client):
    response = client.post("/v1/calibrations/csv/intake", files={"upload": ("lab.csv", b"a,b\n1,2\n")},
                           data={"separator": "semicolon"})
    assert response.status_code == 422 and response.headers["content-type"] == PROBLEM
    pointers = {e["pointer"]: e["detail"] for e in response.json()["errors"]}
    assert set(pointers) == {"/upload", "/separator", "/file"}
    assert "?separator=" in pointers["/separator"] and "curl -F file=@lab.csv" in pointers["/file"]


def asgi_post(app, path: str, content_type: bytes, pieces) -> tuple[int, dict, int]:
    """POST ``pieces`` to ``app`` as a client streams a chunked body: (status, answer, bytes sent).

    The ASGI app is called directly, so the count is the bytes it had asked for when it answered
    (the TestClient reads a body whole before the app sees it).
    """
    source = iter(pieces)
    sent = {"bytes": 0}
    answer = {"status": 0, "body": b""}

    async def receive():
        piece = next(source, None)
        if piece is None:
            return {"type": "http.request", "body": b"", "more_body": False}
        sent["bytes"] += len(piece)
        return {"type": "http.request", "body": piece, "more_body": True}

    async def send(message):
        if message["type"] == "http.response.start":
            answer["status"] = message["status"]
        elif message["type"] == "http.response.body":
            answer["body"] += message.get("body", b"")

    scope = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": "POST",
             "scheme": "http", "path": path, "raw_path": path.encode(), "query_string": b"", "root_path": "",
             "headers": [(b"host", b"testserver"), (b"content-type", content_type),
                         (b"transfer-encoding", b"chunked")],
             "client": ("127.0.0.1", 50000), "server": ("testserver", 80)}
    asyncio.run(app(scope, receive, send))
    return answer["status"], json.loads(answer["body"]), sent["bytes"]


def multipart_pieces(boundary: bytes, line: bytes, count: int):
    """A CSV file of ``count`` copies of ``line`` as a browser's form sends it, piece by piece."""
    yield (b"--" + boundary + b'\r\nContent-Disposition: form-data; name="file"; filename="big.csv"'
           b"\r\nContent-Type: text/csv\r\n\r\nballs,load_N,speed_m_s,mu_measured\r\n")
    for _ in range(count):
        yield line
    yield b"\r\n--" + boundary + b"--\r\n"


def test_a_multipart_upload_past_the_limits_is_refused_while_it_streams(tmp_path):
    app = create_app(Settings(data_dir=tmp_path, max_body_bytes=200_000, max_field_bytes=4096))
    content_type = b"multipart/form-data; boundary=limit-test"
    # 5 MB of rows against a 200 kB body limit: 413 once about 200 kB came, the rest never asked for
    status, answer, sent = asgi_post(app, "/v1/calibrations/csv", content_type,
                                     multipart_pieces(b"limit-test", b"4,0.01,0.1,0.01\r\n" * 1000, 300))
    assert status == 413 and "200000 bytes" in answer["detail"], answer
    assert sent < 200_000 + 17_000 + 200, sent  # the limit, and at most the piece that passed it
    # lines past MICROBEARING_MAX_FIELD_BYTES (4 kB) in 2 MB: 413 naming the line of the multipart body,
    # from the first block looked at (256 KiB)
    app = create_app(Settings(data_dir=tmp_path, max_body_bytes=2_000_000, max_field_bytes=4096))
    status, answer, sent = asgi_post(app, "/v1/calibrations/csv", content_type,
                                     multipart_pieces(b"limit-test", b"4," + b"1" * 8000 + b"\r\n", 240))
    assert status == 413, answer
    assert "Line 6 of the multipart body is longer than 4096 bytes" in answer["detail"], answer
    assert sent < 2**18 + 8003, sent
