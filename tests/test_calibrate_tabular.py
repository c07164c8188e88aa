"""Measured data as labs save them (issue 28, items 1-2): spreadsheet dialects and units in the header.

The same measurements are written as a plain CSV in SI and as the files spreadsheets export (a
European Excel export with semicolons, decimal commas, a BOM, CRLF, an empty last column and a blank
last line; tab- and semicolon-separated files; units in the header); every one must read as the same
data, converted by hand here, and say how it was read.
"""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient
from jobs_helper import job_result

from microbearing import physics
from microbearing.calibrate import DataError, parse_csv, read_csv, read_rows
from microbearing.calibrate.tabular import read_column

PROBLEM = "application/problem+json"
N = 40


def lab_rows(seed: int = 7) -> list[dict]:
    """Measurements in lab units: load in mN, speed in mm/s, humidity in %, with their SI values."""
    rng = np.random.default_rng(seed)
    load_mN = rng.choice([4.4, 8.8, 13.2], N)
    speed_mm_s = rng.choice([10.0, 50.0, 90.0, 140.0], N)
    humidity_pct = rng.choice([30.0, 45.0, 60.0, 75.0], N)
    mu = physics.evaluate(balls=4, load_N=load_mN / 1000, speed_m_s=speed_mm_s / 1000, mu_pivot=0.7).mu
    mu = np.round(mu * np.exp(rng.normal(0.0, 0.02, N)), 6)
    return [{"load_mN": float(a), "speed_mm_s": float(b), "humidity_pct": float(c), "mu": float(m)}
            for a, b, c, m in zip(load_mN, speed_mm_s, humidity_pct, mu, strict=True)]


def plain_csv(rows) -> str:
    """The same rows in SI, converted by hand: mN / 1000, mm/s / 1000, % / 100."""
    lines = ["balls,load_N,speed_m_s,relative_humidity,mu_measured"]
    lines += [f"4,{r['load_mN'] / 1000!r},{r['speed_mm_s'] / 1000!r},{r['humidity_pct'] / 100!r},{r['mu']!r}"
              for r in rows]
    return "\n".join(lines) + "\n"


def european_excel(rows) -> bytes:
    """What Excel saves as 'CSV (semicolon)' in a German locale: BOM, CRLF, decimal comma, a trailing
    separator on every line and a blank line at the end."""
    def cell(v):
        return repr(v).replace(".", ",")
    lines = ["balls;load [mN];speed [mm/s];relative humidity [%];mu_measured;"]
    lines += [f"4;{cell(r['load_mN'])};{cell(r['speed_mm_s'])};{cell(r['humidity_pct'])};{cell(r['mu'])};"
              for r in rows]
    return ("\ufeff" + "\r\n".join(lines) + "\r\n\r\n").encode()


def same_data(a, b) -> None:
    assert sorted(a.physics_columns) == sorted(b.physics_columns)
    assert sorted(a.conditions) == sorted(b.conditions)
    for name in a.physics_columns:
        np.testing.assert_allclose(a.physics_columns[name], b.physics_columns[name], rtol=1e-15, err_msg=name)
    for name in a.conditions:
        np.testing.assert_allclose(a.conditions[name], b.conditions[name], rtol=1e-15, err_msg=name)
    np.testing.assert_array_equal(a.mu_measured, b.mu_measured)


def test_a_european_excel_export_reads_as_the_plain_csv():
    rows = lab_rows()
    reference = parse_csv(plain_csv(rows))
    dataset, intake = read_csv(european_excel(rows))
    same_data(dataset, reference)
    assert (intake.separator, intake.decimal) == ("semicolon", "comma")
    assert intake.detected == ["separator", "decimal"]
    assert (intake.encoding, intake.line_endings) == ("UTF-8 with BOM", "CRLF")
    assert intake.ignored == ["1 blank line at the end", "1 empty column at the end"]
    assert intake.to_dict()["conversions"] == [
        "load [mN] read as load_N / 1000", "speed [mm/s] read as speed_m_s / 1000",
        "relative humidity [%] read as relative_humidity / 100"]


@pytest.mark.parametrize(("separator", "decimal"), [("\t", "."), ("\t", ","), (";", "."), (",", ".")])
def test_tab_and_semicolon_files_with_either_decimal_read_alike(separator, decimal):
    rows = lab_rows(3)
    header = separator.join(["balls", "load_mN", "speed_mm_s", "relative humidity [%]", "mu_measured"])
    body = [separator.join(["4", *(repr(r[k]).replace(".", decimal) for k in ("load_mN", "speed_mm_s",
                                                                               "humidity_pct", "mu"))])
            for r in rows]
    dataset, intake = read_csv(header + "\n" + "\n".join(body) + "\n")
    same_data(dataset, parse_csv(plain_csv(rows)))
    names = {"\t": "tab", ";": "semicolon", ",": "comma"}
    assert (intake.separator, intake.decimal) == (names[separator], "comma" if decimal == "," else "point")


def test_a_stated_dialect_is_used_and_reported_as_stated():
    rows = lab_rows(4)
    dataset, intake = read_csv(european_excel(rows), separator="semicolon", decimal="comma")
    same_data(dataset, parse_csv(plain_csv(rows)))
    assert intake.detected == []
    # stated wrongly: one error that names the separator, not one per cell
    with pytest.raises(DataError) as wrong:
        read_csv(european_excel(rows), separator="comma")
    assert len(wrong.value.errors) == 1
    assert "separated by semicolon" in wrong.value.errors[0]["message"]


@pytest.mark.parametrize(("sent", "name", "value", "si"), [
    ("speed [mm/s]", "speed_m_s", 50.0, 0.05),
    ("speed (mm/s)", "speed_m_s", 50.0, 0.05),
    ("speed_mm_s", "speed_m_s", 50.0, 0.05),
    ("speed [m/s]", "speed_m_s", 0.05, 0.05),
    ("Speed [mm/s]", "speed_m_s", 120.0, 0.12),
    ("load [mN]", "load_N", 8.8, 0.0088),
    ("load_mN", "load_N", 8.8, 0.0088),
    ("load [g]", "load_N", 0.9, 0.9e-3 * 9.80665),  # the paper's 0.9 g slider
    ("ball_diameter [um]", "ball_diameter_m", 285.0, 285e-6),
    ("ball_diameter_um", "ball_diameter_m", 285.0, 285e-6),
    ("viscosity [mPa s]", "viscosity_Pa_s", 1.0, 1e-3),
    ("adhesion_energy [mJ/m2]", "adhesion_energy_J_m2", 180.0, 0.18),
    ("groove_angle [rad]", "groove_angle_deg", np.deg2rad(54.7), 54.7),
    ("relative humidity [%]", "relative_humidity", 45.0, 0.45),
    ("temperature [degC]", "temperature_K", 25.0, 298.15),
    ("temperature (°C)", "temperature_K", 25.0, 298.15),
    ("pressure [kPa]", "pressure_Pa", 101.325, 101325.0),
    ("mu_measured [%]", "mu_measured", 1.2, 0.012),
])
def test_units_in_the_header_are_converted_to_si(sent, name, value, si):
    column = read_column(sent)
    assert column.name == name
    assert column.convert(value) == pytest.approx(si, rel=1e-12)
    assert column.reading.startswith(f"{sent} read as {name}") or si == value


def test_names_without_a_unit_and_condition_suffixes_stay_as_sent():
    for sent in ("load_N", "balls", "balls_touching", "temperature_C", "relative_humidity_pct", "cycle",
                 "load_cycle", "mu_measured_std"):
        column = read_column(sent)
        assert (column.name, column.reading) == (sent, "")


@pytest.mark.parametrize(("sent", "words"), [
    ("speed [furlong]", ["speed [furlong]", "furlong is not convertible", "m/s"]),  # a length is no speed
    ("load [mm]", ["N", "load [mN]"]),
    ("speed [blarg]", ["not known", "speed [mm/s]"]),     # an unknown unit: the accepted names follow
    ("speed_m_s [mm/s]", ["speed [mm/s]"]),               # the name says m/s, the brackets mm/s
    ("current [A]", ["SI unit"]),
])
def test_a_bad_unit_is_one_error_naming_the_column_as_sent(sent, words):
    with pytest.raises(DataError) as bad:
        read_csv(f"balls,load_N,{sent},mu_measured\n4,0.01,1,0.01\n".replace(f",{sent},", f",\"{sent}\","))
    assert len(bad.value.errors) == 1
    error = bad.value.errors[0]
    assert error["column"] == sent
    for word in words:
        assert word in DataError.describe(error), error


def test_a_required_input_under_another_name_is_named_as_sent():
    with pytest.raises(DataError) as bad:
        read_csv("balls,load_N,speed_rpm,mu_measured\n4,0.01,100,0.01\n")
    assert [(e["column"], "speed_m_s" in e["message"]) for e in bad.value.errors] == [("speed_rpm", True)]


def test_a_missing_required_input_names_the_columns_read_as_conditions():
    with pytest.raises(DataError) as bad:
        read_csv("balls,load_N,sped_mm_s,mu_measured\n4,0.01,1,0.01\n")
    assert len(bad.value.errors) == 1
    message = bad.value.errors[0]["message"]
    assert "speed_m_s" in message and "'sped_mm_s'" in message and "speed [mm/s]" in message


def test_two_columns_read_as_one_name_are_refused():
    with pytest.raises(DataError) as bad:
        read_csv("balls,load_N,speed_m_s,speed [mm/s],mu_measured\n4,0.01,0.1,100,0.01\n")
    assert "speed_m_s" in bad.value.errors[0]["message"]


def test_mixed_decimal_marks_and_a_decimal_comma_in_a_comma_file_are_one_error():
    with pytest.raises(DataError) as mixed:
        read_csv("balls;load_N;speed_m_s;mu_measured\n4;0,01;0.1;0,01\n4;0,01;0.2;0,01\n")
    assert len(mixed.value.errors) == 1 and "decimal" in mixed.value.errors[0]["message"]
    with pytest.raises(DataError) as commas:
        read_csv("balls,load_N,speed_m_s,mu_measured\n4,0,01,0,1,0,01\n4,0,01,0,2,0,01\n", separator="comma")
    assert len(commas.value.errors) == 1 and "decimal comma" in commas.value.errors[0]["message"]


def test_blank_lines_inside_the_data_are_still_reported():
    with pytest.raises(DataError) as blank:
        read_csv("balls;load_N;speed_m_s;mu_measured\n4;0.01;0.1;0.01\n;;;\n4;0.01;0.2;0.01\n\n\n")
    assert [(e["row"], e["message"][:8]) for e in blank.value.errors] == [(2, "is blank")]


def test_json_rows_take_units_in_their_keys():
    rows = lab_rows(5)
    json_rows = [{"balls": 4, "load [mN]": r["load_mN"], "speed_mm_s": r["speed_mm_s"],
                  "relative humidity [%]": r["humidity_pct"], "mu_measured": r["mu"]} for r in rows]
    dataset, intake = read_rows(json_rows)
    same_data(dataset, parse_csv(plain_csv(rows)))
    assert intake.format == "json" and len(intake.to_dict()["conversions"]) == 3


# --- through the API ---------------------------------------------------------------------------


def finished(client: TestClient, response) -> dict:
    return job_result(client, response, timeout_s=300, interval_s=0.1)


# The API's calibration of a spreadsheet export against the plain file (two fits, ~25 s each) is
# tests/test_intake_spreadsheets.py's, on an export with every spreadsheet habit at once: Excel's sep=
# line, Windows-1252 with a degree sign, decimal commas, CRLF, uploaded as a browser's form.


def test_api_takes_a_stated_dialect_and_json_rows_with_units(client):
    rows = lab_rows(12)
    stated = client.post("/v1/calibrations/csv", params={"separator": "semicolon", "decimal": "comma"},
                         content=european_excel(rows), headers={"content-type": "text/csv"})
    assert finished(client, stated)["intake"]["detected"] == []
    bad = client.post("/v1/calibrations/csv", params={"separator": "pipe"}, content=european_excel(rows),
                      headers={"content-type": "text/csv"})
    assert bad.status_code == 422 and bad.headers["content-type"] == PROBLEM
    assert [e.get("parameter") for e in bad.json()["errors"]] == ["separator"]
    json_rows = [{"balls": 4, "load [g]": r["load_mN"] / 9.80665, "speed [mm/s]": r["speed_mm_s"],
                  "mu_measured": r["mu"]} for r in rows]
    result = finished(client, client.post("/v1/calibrations", json={"data": json_rows, "folds": 2}))
    assert result["intake"]["format"] == "json"
    assert result["intake"]["conversions"][0].startswith("load [g] read as load_N = mass x standard gravity")


@pytest.mark.parametrize(("content", "column", "words"), [
    ("balls,load_N,speed [furlong],mu_measured\n4,0.01,1,0.01\n", None, ["speed [furlong]", "m/s"]),
    ("balls,load_N,speed [xyz],mu_measured\n4,0.01,1,0.01\n", None, ["speed [xyz]", "speed [mm/s]"]),
    ("balls;load_N;speed_m_s;mu_measured\n" + "4;0.01;0.1;0.01\n" * 84, "comma", ["separated by semicolon"]),
])
def test_api_bad_files_are_one_problem_that_says_what_is_wrong(client, content, column, words):
    params = {"separator": column} if column else {}
    response = client.post("/v1/calibrations/csv", params=params, content=content,
                           headers={"content-type": "text/csv"})
    assert response.status_code == 422 and response.headers["content-type"] == PROBLEM, response.text
    problem = response.json()
    assert len(problem["errors"]) == 1, problem
    assert problem["errors"][0]["pointer"] == "/body"
    for word in words:
        assert word in problem["errors"][0]["detail"], problem
