"""Issue 32's leftovers: a robust design's proof speaks the request's keys and units at the API and the CLI,
and a calibration uploaded with headers in other units keeps its certificates."""

from __future__ import annotations

import json

import pytest
from jobs_helper import job_result, wait_job
from labs_helper import lab_header_rows

from microbearing.optimize.robust import Envelope
from microbearing.physics.columns import read_name
from microbearing.service.cli import main
from microbearing.service.optimizations import prepare
from microbearing.service.schemas.optimizations import OptimizationRequest
from microbearing.service.store import Store


@pytest.fixture(scope="module")
def model(client) -> str:
    response = client.post("/v1/calibrations", json={"data": lab_header_rows(),
                                                     "fit_parameters": ["mu_pivot"], "folds": 3})
    return job_result(client, response, timeout_s=300, interval_s=0.1)["model_id"]


def _fahrenheit(kelvin: float) -> float:
    return (kelvin - 273.15) * 9 / 5 + 32


BASE = {"bounds": {"balls": [4, 6], "groove_angle_deg": [50, 55], "load_N": [0.008, 0.012]},
        "time_limit_s": 20}
CONDITIONS = {"relative humidity [%]": [30, 60], "temp_F": {"low": 70, "high": 100}}


def _optimized(client, request: dict) -> dict:
    job = wait_job(client, client.post("/v1/optimizations", json=request), timeout_s=300)
    assert job["status"] == "succeeded", job
    return client.get(job["result_url"]).json()


def test_a_proof_names_the_worst_vertex_in_the_keys_and_units_sent(client, model):
    # before: "... one vertex: the angle made high (+0 deg), speed 0.05 m/s, relative_humidity at 0.6, temp_K
    # at 294.261" where the request said RH [%] [30, 60], temp_F [70, 100] and speed [mm/s] [20, 50]
    result = _optimized(client, {**BASE, "model": model, "speed [mm/s]": [20, 50], "conditions": CONDITIONS})
    proof, worst = result["proof"], result["worst_case"]
    assert proof["method"] == "robust-gp-vertex" and proof["proven"], proof
    rh, kelvin, speed = (worst["conditions"]["relative_humidity"], worst["conditions"]["temp_K"],
                         worst["speed_m_s"])
    # by hand: % = 100 x the fraction, degF = (K - 273.15) x 9/5 + 32, mm/s = 1000 x m/s
    assert (round(100 * rh, 9), round(_fahrenheit(kelvin), 9), round(1000 * speed, 9)) == (60, 70, 50), worst
    words = (f"speed [mm/s] at 50 (speed_m_s {speed:g}), relative humidity [%] at 60 (relative_humidity "
             f"{rh:g}), temp_F at 70 (temp_K {kelvin:g})")
    assert words in proof["statement"], proof["statement"]
    assert words in result["certificate"]
    assert "temp_K at" not in proof["statement"] and "relative_humidity at" not in proof["statement"]
    # sent in the model's own keys and units, the words stay the column's
    plain = _optimized(client, {**BASE, "model": model, "speed_m_s": 0.05,
                                "conditions": {"relative_humidity": [0.3, 0.6], "temp_K": [295, 310]}})
    assert "speed 0.05 m/s, relative_humidity at 0.6, temp_K at 295." in plain["proof"]["statement"]


def test_a_proof_of_mu_upper_is_certified_on_an_upload_with_headers_in_other_units(client, model):
    # before: "its headers has no bound over a box here": outer-approximation-local, gap 1.13e-3, not proven
    result = _optimized(client, {**BASE, "model": model, "speed_m_s": 0.05, "objective": "mu_upper",
                                 "conditions": CONDITIONS})
    proof = result["proof"]
    assert "headers" not in proof["statement"], proof["statement"]
    assert proof["method"] == "outer-approximation-certified" and proof["upper_bound_certified"], proof
    assert proof["relative_gap"] <= proof["gap_target"] and proof["proven"], proof


def test_the_physics_proof_names_the_speed_as_sent_and_the_cli_says_the_same(client, tmp_path):
    request = {**BASE, "speed [mm/s]": [10, 50], "tolerances": {"groove_angle_deg": 0.5}}
    answer = client.post("/v1/optimizations", json=request)
    assert answer.status_code in (200, 202), answer.text
    result = answer.json() if answer.status_code == 200 else _optimized(client, request)
    assert "the highest speed, speed [mm/s] at 50 (speed_m_s 0.05);" in result["proof"]["statement"], result
    path = tmp_path / "robust.json"
    path.write_text(json.dumps(request))
    out = tmp_path / "design.json"
    assert main(["optimize", str(path), "-o", str(out)]) == 0
    assert json.loads(out.read_text())["proof"]["statement"] == result["proof"]["statement"]


def test_an_envelope_says_a_value_as_its_reading_does():
    readings = {"temperature_K": read_name("T [degF]"), "speed_m_s": read_name("speed [cm/s]")}
    ranges = {"temperature_K": (294.261111111, 310.0), "relative_humidity": (0.3, 0.6)}
    envelope = Envelope((0.01, 0.05), ranges, readings=readings)
    assert envelope.said("temperature_K", 294.261111111) == "T [degF] at 70 (temperature_K 294.261)"
    assert envelope.said("speed_m_s", 0.05) == "speed [cm/s] at 5 (speed_m_s 0.05)"
    assert envelope.said("relative_humidity", 0.6) == "relative_humidity at 0.6"
    # the words are no part of what the envelope is
    assert envelope == Envelope((0.01, 0.05), ranges)


def test_an_envelope_s_speed_and_tolerance_are_shown_in_the_keys_and_units_sent(client, tmp_path):
    # before: as_sent covered the conditions only: a speed sent as speed [mm/s] [10, 50] and a tolerance
    # sent as groove angle [rad] 0.01 were shown back only as speed_m_s [0.01, 0.05] and 0.5729577951 deg
    request = {**BASE, "speed [mm/s]": [10, 50], "tolerances": {"groove angle [rad]": 0.01}}
    answer = client.post("/v1/optimizations", json=request)
    assert answer.status_code in (200, 202), answer.text
    result = answer.json() if answer.status_code == 200 else _optimized(client, request)
    envelope, worst = result["envelope"], result["worst_case"]
    assert envelope["speed_m_s"] == pytest.approx([0.01, 0.05])
    assert envelope["as_sent"] == {"speed [mm/s]": [10, 50]}, envelope
    # by hand: mm/s = 1000 x m/s; rad = deg x pi / 180
    assert worst["as_sent"] == {"speed [mm/s]": pytest.approx(1000 * worst["speed_m_s"]),
                                "groove_angle_deg": worst["groove_angle_deg"]}, worst
    assert envelope["tolerances"]["groove_angle_deg"] == pytest.approx(0.01 * 180 / 3.141592653589793)
    assert envelope["tolerances_as_sent"] == {"groove angle [rad]": 0.01}, envelope
    path = tmp_path / "robust.json"
    path.write_text(json.dumps(request))
    out = tmp_path / "design.json"
    assert main(["optimize", str(path), "-o", str(out)]) == 0
    cli = json.loads(out.read_text())
    assert cli["envelope"]["as_sent"] == envelope["as_sent"]
    assert cli["worst_case"]["as_sent"] == worst["as_sent"]
    assert cli["envelope"]["tolerances_as_sent"] == envelope["tolerances_as_sent"]
    # sent in the model's own keys, the same keys come back
    plain = {**BASE, "speed_m_s": [0.01, 0.05], "tolerances": {"groove_angle_deg": 0.5}}
    answer = client.post("/v1/optimizations", json=plain)
    result = answer.json() if answer.status_code == 200 else _optimized(client, plain)
    assert result["envelope"]["as_sent"] == {"speed_m_s": [0.01, 0.05]}, result["envelope"]
    assert result["envelope"]["tolerances_as_sent"] == {"groove_angle_deg": 0.5}, result["envelope"]


def test_a_design_in_a_proof_is_said_in_the_bounds_keys_and_units():
    # before: "A design lower at the points ... was found (5 balls, 51.0000000 deg, 0.01 N: ...)" whatever
    # the keys of the bounds: now under them, in their units, the column's value in brackets
    body = OptimizationRequest.model_validate(
        {"bounds": {"balls": [4, 6], "groove angle [rad]": [0.87, 0.96], "load [gf]": [0.8, 1.2]},
         "speed [mm/s]": [10, 50], "tolerances": {"groove_angle_deg": 0.5}})
    envelope = prepare(None, body).envelope
    design = {"balls": 5, "groove_angle_deg": 51.0, "load_N": 0.00980665}
    # by hand: 51 deg = 51 x pi / 180 rad = 0.8901179185; 0.00980665 N = 1 gf
    assert envelope.said_design(design) == ("5 balls, groove angle [rad] at 0.8901179 (groove_angle_deg "
                                            "51.0000000), load [gf] at 1 (load_N 0.00980665)")
    assert envelope.said("speed_m_s", 0.05) == "speed [mm/s] at 50 (speed_m_s 0.05)"
    # sent in the model's own keys, the words stay the column's
    plain = OptimizationRequest.model_validate({**BASE, "speed_m_s": [0.01, 0.05]})
    assert prepare(None, plain).envelope.said_design(design) == "5 balls, 51.0000000 deg, 0.00980665 N"


def test_a_calibration_stored_before_its_headers_were_kept_has_them_back_from_its_intake(client, model,
                                                                                        data_dir):
    # A calibration stored before the model kept the upload's headers (metadata "headers" absent): before,
    # a bare "temperature": 80 was judged against the column's own unit ("the calibration's column temp_K is
    # in K"), not the upload's temp_F; its report's intake ({"temp_F": "temp_K", ...}) still says how the
    # upload was read, and the model has its headers back.
    store = Store(data_dir)
    stored = store.load_model(model.split(":")[1])
    metadata = json.loads(json.dumps(stored.metadata))
    assert metadata["model"].pop("headers")["temp_K"] == "temp_F"
    assert metadata["report"]["intake"]["columns"]["temp_F"] == "temp_K"
    old = "calibrated:" + store.save_model(stored.kind, metadata, dict(stored.arrays), name="old")
    point = {"balls": 4, "load_N": 0.01, "speed_m_s": 0.05}
    bare = {"relative humidity [%]": 50, "temperature": 80}
    answer = client.post("/v1/friction", json={**point, "model": old, "conditions": bare})
    assert answer.status_code == 422, answer.text
    detail = " ".join(e["detail"] for e in answer.json()["errors"])
    assert all(w in detail for w in ("states no unit", "degF", "temp_F")), detail
    # the key the upload sent still reads, to the digit of the model stored with its headers
    mu = [client.post("/v1/friction", json={**point, "model": m, "conditions": {
        "relative humidity [%]": 50, "temp_F": 80}}).json()["mu"] for m in (old, model)]
    assert mu[0] == mu[1], mu
    assert main(["evaluate", "--data-dir", str(data_dir), "--model", old, "balls=4", "load_N=0.01",
                 "speed_m_s=0.05", "relative humidity [%]=50", "temperature=80", "-o",
                 str(data_dir / "old.json")]) != 0


def _answer(client, request: dict) -> dict:
    answer = client.post("/v1/optimizations", json=request)
    assert answer.status_code in (200, 202), answer.text
    return answer.json() if answer.status_code == 200 else _optimized(client, request)


def test_a_found_design_and_its_worst_angle_are_shown_in_the_bounds_keys_and_units(client, tmp_path):
    # before: the design was only in N and deg ({"balls": 4, "groove_angle_deg": 49.847, "load_N": 0.01177})
    # and the worst case's angle only in deg, whatever the keys of the bounds (rad, gf)
    bounds = {"balls": [4, 6], "groove angle [rad]": [0.87, 0.96], "load [gf]": [0.8, 1.2]}
    request = {"bounds": bounds, "speed [mm/s]": [10, 50], "tolerances": {"groove angle [rad]": 0.01},
               "time_limit_s": 20}
    result = _answer(client, request)
    gram_force, radian = 0.00980665, 3.141592653589793 / 180  # by hand: 1 gf in N, 1 deg in rad
    design, sent, worst = result["design"], result["design_as_sent"], result["worst_case"]
    # beside the design, which stays a point /v1/friction takes as it is (SI fields kept)
    assert set(design) == {"balls", "groove_angle_deg", "load_N"}, design
    assert client.post("/v1/friction", json={**design, "speed_m_s": 0.05}).status_code == 200
    assert sent == {"balls": design["balls"],
                    "groove angle [rad]": pytest.approx(design["groove_angle_deg"] * radian),
                    "load [gf]": pytest.approx(design["load_N"] / gram_force)}, sent
    # the design sits on the bounds' ends: shown as typed, not their round trip (0.8699999999)
    assert sent["groove angle [rad]"] == 0.87 and sent["load [gf]"] == 1.2, sent
    assert isinstance(sent["balls"], int)
    # the angle made at the worst case: nominal + the tolerance, 0.87 + 0.01 rad
    assert worst["as_sent"]["groove angle [rad]"] == pytest.approx(worst["groove_angle_deg"] * radian)
    assert worst["as_sent"]["groove angle [rad]"] == 0.88, worst
    for part in ("nominal", "robust"):
        assert result["price_of_robustness"][part]["design_as_sent"] == sent
    path, out = tmp_path / "robust.json", tmp_path / "design.json"
    path.write_text(json.dumps(request))
    assert main(["optimize", str(path), "-o", str(out)]) == 0
    cli = json.loads(out.read_text())
    assert cli["design_as_sent"] == sent and cli["worst_case"]["as_sent"] == worst["as_sent"]
    # a design at one point, its load fixed in mN: under those keys too, at the API and the CLI
    one = {"bounds": {"balls": [4, 6], "groove angle [rad]": [0.87, 0.96]}, "fixed": {"load [mN]": 10},
           "speed_m_s": 0.05}
    result = _answer(client, one)
    assert result["design_as_sent"] == {"balls": result["design"]["balls"],
                                        "groove angle [rad]": pytest.approx(
                                            result["design"]["groove_angle_deg"] * radian),
                                        "load [mN]": 10}, result
    path.write_text(json.dumps(one))
    assert main(["optimize", str(path), "-o", str(out)]) == 0
    assert json.loads(out.read_text())["design_as_sent"] == result["design_as_sent"]
    # sent in the model's own keys, the same keys come back
    plain = _answer(client, {**BASE, "speed_m_s": 0.05})
    assert plain["design_as_sent"] == plain["design"], plain


def test_a_proof_states_a_tolerance_in_the_unit_it_was_sent_in(client, model, tmp_path):
    # before: "the angle made high (nominal + 0.572958 deg)" and "the angle box moved by 0.572958 deg" where
    # the request sent groove angle [rad] 0.01; the calibrated vertex's "(+0.286479 deg)" likewise
    request = {**BASE, "speed [mm/s]": [10, 50], "tolerances": {"groove angle [rad]": 0.01}}
    result = _answer(client, request)
    # by hand: 0.01 rad x 180 / pi = 0.5729577951 deg
    assert result["proof"]["method"] == "robust-gp-vertex", result["proof"]
    statement = result["proof"]["statement"]
    assert "the angle made high (nominal + 0.01 rad (0.572958 deg))" in statement, statement
    assert "the angle box moved by 0.01 rad (0.572958 deg) at that speed" in statement, statement
    assert "+ 0.572958 deg" not in statement and "by 0.572958 deg" not in statement
    path, out = tmp_path / "robust.json", tmp_path / "design.json"
    path.write_text(json.dumps(request))
    assert main(["optimize", str(path), "-o", str(out)]) == 0
    assert json.loads(out.read_text())["proof"]["statement"] == statement
    # a calibrated model's vertex, 0.005 rad = 0.2864788976 deg
    calibrated = _optimized(client, {**BASE, "model": model, "speed_m_s": 0.05, "conditions": CONDITIONS,
                                     "tolerances": {"groove angle [rad]": 0.005}})
    assert calibrated["proof"]["method"] == "robust-gp-vertex", calibrated["proof"]
    assert "the angle made high (+0.005 rad (0.286479 deg))," in calibrated["proof"]["statement"], calibrated
    # sent in deg, the words stay in deg
    plain = _answer(client, {**BASE, "speed_m_s": [0.01, 0.05], "tolerances": {"groove_angle_deg": 0.5}})
    assert "the angle made high (nominal + 0.5 deg)" in plain["proof"]["statement"], plain["proof"]


def test_an_old_calibration_s_stored_data_have_the_upload_s_headers_back_for_its_plots(client, model,
                                                                                       data_dir):
    # A calibration stored before the upload's headers were kept lacks them in its model and in its data's
    # arrays (header.<column>); the model had them back from the report's intake, its data did not: the
    # plots and refits of next-experiments drew temp_K [K] and relative_humidity as a fraction, not the
    # upload's temp_F [degF] and relative humidity [%].
    from microbearing.calibrate.plots import DrawnColumn
    from microbearing.service.calibrations import stored_dataset
    from microbearing.service.models import stored_calibrated

    store = Store(data_dir)
    stored = store.load_model(model.split(":")[1])
    metadata = json.loads(json.dumps(stored.metadata))
    metadata["model"].pop("headers")
    arrays = {key: value for key, value in stored.arrays.items() if not key.startswith("data.header.")}
    assert set(stored.arrays) - set(arrays) == {"data.header.relative_humidity", "data.header.temp_K"}
    old = store.load_model(store.save_model(stored.kind, metadata, arrays, name="old data"))
    datasets = []
    for kept in (stored, old):
        calibrated = stored_calibrated(kept.metadata)
        datasets.append(stored_dataset(kept.arrays, calibrated.fixed, calibrated.headers))
    assert datasets[1].headers == datasets[0].headers == {"relative_humidity": "relative humidity [%]",
                                                          "temp_K": "temp_F"}, datasets[1].headers
    drawn = [DrawnColumn.of(datasets[1], name) for name in ("temp_K", "relative_humidity")]
    assert [column.label for column in drawn] == ["temp_F [degF]", "relative humidity [%]"]
    # by hand: degF = (K - 273.15) x 9/5 + 32, % = 100 x the fraction; the upload's values come back
    kelvin, fraction = datasets[1].conditions["temp_K"], datasets[1].conditions["relative_humidity"]
    assert drawn[0].shown(kelvin) == pytest.approx((kelvin - 273.15) * 9 / 5 + 32, rel=1e-12)
    assert drawn[1].shown(fraction) == pytest.approx(100 * fraction, rel=1e-12)
    fahrenheit = [row["temp_F"] for row in lab_header_rows()]
    assert sorted(drawn[0].shown(kelvin)) == pytest.approx(sorted(fahrenheit), rel=1e-9)
    # the data stored with their headers read as before
    fixed = stored_calibrated(stored.metadata).fixed
    assert stored_dataset(stored.arrays, fixed).headers == datasets[0].headers
