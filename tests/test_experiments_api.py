"""/v1/calibrations/{id}/next-experiments and /v1/experiments: jobs, results, plot and problems."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fastapi.testclient import TestClient
from jobs_helper import finished_job
from labs_helper import kelvin_rows

from microbearing.service.cli import main

PROBLEM = "application/problem+json"
SPACE = {"balls": {"low": 4, "high": 8}, "load_N": {"low": 3e-3, "high": 3e-2, "spacing": "log"},
         "speed_m_s": {"low": 0.0, "high": 0.15},
         "relative_humidity": {"values": [0.2, 0.35, 0.5, 0.65, 0.8, 0.9]}}


def finished(client: TestClient, response) -> dict:
    assert response.status_code == 202, response.text
    job = response.json()
    location = response.headers["location"]
    job = finished_job(client, location, timeout_s=120, interval_s=0.1)
    result = client.get(job["result_url"]).json()
    assert result.pop("kind") == "experiments"
    return result


def problem(response, status: int) -> dict:
    assert response.status_code == status, response.text
    assert response.headers["content-type"] == PROBLEM
    return response.json()


@pytest.fixture(scope="module")
def calibration_id(client):
    body = {"data": kelvin_rows(), "fit_parameters": ["mu_pivot", "adhesion_energy_J_m2"]}
    return _calibrate(client, body)


def _calibrate(client, body) -> str:
    response = client.post("/v1/calibrations", json=body)
    assert response.status_code == 202, response.text
    location = response.headers["location"]
    job = finished_job(client, location, timeout_s=180, interval_s=0.2)
    return client.get(job["result_url"]).json()["id"]


def test_discriminate_proposes_runs_where_the_humidity_laws_part(client, calibration_id):
    response = client.post(f"/v1/calibrations/{calibration_id}/next-experiments",
                           json={"runs": 12, "goal": "discriminate", "space": SPACE})
    result = finished(client, response)
    assert result["model"] == f"calibrated:{calibration_id}" and result["goal"] == "discriminate"
    assert len(result["runs"]) == 12
    for run in result["runs"]:
        assert isinstance(run["balls"], int) and 4 <= run["balls"] <= 8
        assert run["conditions"]["relative_humidity"] in SPACE["relative_humidity"]["values"]
        assert run["mu_lower"] < run["mu"] < run["mu_upper"]
    assert 0.8 < result["efficiency_lower_bound"] <= 1.0
    assert any("(linear)" in rival["label"] for rival in result["rivals"])
    assert all(rival["expected_chi2_separation"] > 0 for rival in result["rivals"])
    assert result["plot"]["axes"][0] == "relative_humidity", result["plot"]
    assert len(result["plot"]["data"]["relative_humidity"]) == 150  # the data taken
    png = client.get(result["plot_url"])
    assert png.status_code == 200 and png.headers["content-type"] == "image/png"
    assert png.content[:8] == b"\x89PNG\r\n\x1a\n"


def test_predict_narrows_the_interval_over_the_envelope(client, calibration_id):
    envelope = {"balls": [6], "load_N": {"low": 0.005, "high": 0.02}, "speed_m_s": [0.05],
                "relative_humidity": {"low": 0.7, "high": 0.85}}
    result = finished(client, client.post(f"/v1/calibrations/{calibration_id}/next-experiments",
                                          json={"runs": 10, "goal": "predict", "space": SPACE,
                                                "envelope": envelope}))
    figures = result["envelope"]
    assert figures["mean_half_width_after"]["mean"] < figures["mean_half_width_now"]["mean"]
    assert figures["half_width_after"]["mean"] <= figures["half_width_now"]["mean"]
    assert any(not run["in_domain"] for run in result["runs"])  # 70-85 % RH lies beyond the data


def test_planned_runs_may_name_columns_with_their_units(client, calibration_id):
    # the planned runs read as the space reads its columns: the same plan from the upload's spellings
    si = [{"balls": 4, "load_N": 0.01, "speed_m_s": 0.05, "relative_humidity": 0.8},
          {"balls": 8, "load_N": 0.02, "speed_m_s": 0.1, "relative_humidity": 0.9}]
    lab = [{"balls": 4, "load [mN]": 10, "speed [mm/s]": 50, "relative humidity [%]": 80},
           {"balls": 8, "load_mN": 20, "speed_mm_s": 100, "RH_pct": 90}]
    url = f"/v1/calibrations/{calibration_id}/next-experiments"
    plans = [finished(client, client.post(url, json={"runs": 4, "goal": "parameters", "space": SPACE,
                                                       "planned": planned}))["runs"] for planned in (si, lab)]
    assert plans[0] == plans[1]
    # a slip in a planned run is refused at its key as sent, as in the space
    slipped = [{**si[0], "relative_humidity": 80}]
    answer = problem(client.post(url, json={"runs": 4, "goal": "parameters", "space": SPACE,
                                            "planned": slipped}), 422)
    assert [e["pointer"] for e in answer["errors"]] == ["/planned/0/relative_humidity"], answer
    assert "look like percent" in answer["errors"][0]["detail"], answer
    # a physics input out of its range is named by its key and value as sent, not as the model reads it
    negative = [{**lab[0], "load [mN]": -10}]
    answer = problem(client.post(url, json={"runs": 4, "goal": "parameters", "space": SPACE,
                                            "planned": negative}), 422)
    assert [e["pointer"] for e in answer["errors"]] == ["/planned/0/load [mN]"], answer
    assert "sent as load [mN]: -10, read as load_N: -0.01" in answer["errors"][0]["detail"], answer


@pytest.mark.parametrize(("field", "replaced", "body", "pointer", "sent"), [
    # a JSON pointer spells / as ~1 (RFC 6901)
    ("space", "speed_m_s", {"speed [mm/s]": {"low": -5, "high": 150}}, "/space/speed [mm~1s]",
     "sent as speed [mm/s]: {low: -5, high: 150}"),
    ("fixed", None, {"groove angle [rad]": -1}, "/fixed/groove angle [rad]",
     "sent as groove angle [rad]: -1"),
    ("envelope", "load_N", {"load [mN]": [-1, 20]}, "/envelope/load [mN]", "sent as load [mN]: [-1, 20]"),
])
def test_a_physics_input_is_refused_by_its_key_as_sent_at_every_field(client, calibration_id, field, replaced,
                                                                        body, pointer, sent):
    # hand: -5 mm/s is -0.005 m/s, below speed_m_s's 0; -1 rad below 0 deg; -1 mN below load_N's 0
    request = {"runs": 4, "goal": "predict", "space": dict(SPACE), "envelope": dict(SPACE), "fixed": {}}
    request[field] = {**{k: v for k, v in request[field].items() if k != replaced}, **body}
    answer = problem(client.post(f"/v1/calibrations/{calibration_id}/next-experiments", json=request), 422)
    errors = {e["pointer"]: e["detail"] for e in answer["errors"]}
    assert pointer in errors, answer
    assert sent in errors[pointer], answer


def test_refusals_of_next_runs_name_the_field_and_key_as_sent(client, calibration_id):
    url = f"/v1/calibrations/{calibration_id}/next-experiments"
    run = {"balls": 4, "load_N": 0.01, "speed_m_s": 0.05, "relative_humidity": 0.5}
    # a planned run's key no column is (a typo) is refused as the same key in fixed is; it was ignored
    errors = problem(client.post(url, json={"runs": 4, "goal": "parameters", "space": SPACE,
                                            "planned": [{**run, "cycle_count": 5}]}), 422)["errors"]
    assert [e["pointer"] for e in errors] == ["/planned/0/cycle_count"], errors
    assert "not a physics input nor a condition column" in errors[0]["detail"]
    # low above high in the envelope is the envelope's, named by its key and values as sent
    envelope = {"balls": [6], "load [mN]": [20, 5], "speed_m_s": [0.05], "relative_humidity": [0.7, 0.8]}
    errors = problem(client.post(url, json={"runs": 4, "goal": "predict", "space": SPACE,
                                            "envelope": envelope}), 422)["errors"]
    assert [e["pointer"] for e in errors] == ["/envelope/load [mN]"], errors
    assert "low must not exceed high" in errors[0]["detail"], errors
    assert "sent as load [mN]: [20, 5]" in errors[0]["detail"], errors
    # text in fixed: a number is asked for in words, not pydantic's two type errors
    errors = problem(client.post(url, json={"runs": 4, "goal": "parameters", "space": SPACE,
                                            "fixed": {"groove_angle_deg": "sixty"}}), 422)["errors"]
    assert [e["pointer"] for e in errors] == ["/fixed/groove_angle_deg"], errors
    assert "must be a number, not 'sixty'" in errors[0]["detail"], errors


def test_a_first_design_reads_the_upload_s_spellings_as_the_next_runs_do(client):
    # the same design from SI keys and from the lab's units: 150 mm/s is 0.15 m/s, 54.7 deg as sent
    si = {"balls": {"values": [4, 8]}, "load_N": {"low": 1e-3, "high": 3e-2, "spacing": "log"},
          "speed_m_s": {"low": 0.0, "high": 0.15}}
    lab = {"balls": {"values": [4, 8]}, "load [mN]": {"low": 1, "high": 30, "spacing": "log"},
           "speed [mm/s]": {"low": 0, "high": 150}}
    runs = []
    for space in (si, lab):
        body = {"runs": 6, "space": space, "fit_parameters": ["mu_pivot"], "noise_std_log": 0.03}
        result = finished(client, client.post("/v1/experiments", json=body))
        runs.append([(run["balls"], run["load_N"], run["speed_m_s"]) for run in result["runs"]])
    assert runs[0] == runs[1]
    assert max(speed for _, _, speed in runs[1]) <= 0.15 + 1e-12
    assert min(load for _, load, _ in runs[1]) >= 1e-3 - 1e-15
    body = {"runs": 6, "space": lab, "fit_parameters": ["mu_pivot"],
            "planned": [{"balls": 4, "load [mN]": 5, "speed [mm/s]": -1}]}
    answer = problem(client.post("/v1/experiments", json=body), 422)
    assert [e["pointer"] for e in answer["errors"]] == ["/planned/0/speed [mm~1s]"], answer


def test_first_design_on_the_physics(client):
    space = {"balls": {"values": [4, 8, 12]}, "load_N": {"low": 1e-3, "high": 3e-2, "spacing": "log"},
             "speed_m_s": {"low": 0.0, "high": 0.15}}
    body = {"runs": 8, "space": space,
            "fit_parameters": ["mu_pivot", "adhesion_energy_J_m2"], "noise_std_log": 0.03,
            "fixed": {"groove_angle_deg": 54.7}}
    result = finished(client, client.post("/v1/experiments", json=body))
    assert result["model"] == "physics" and result["calibration_id"] is None
    assert len(result["runs"]) == 8
    assert all(run["inputs"]["groove_angle_deg"] == 54.7 for run in result["runs"])
    assert [p["name"] for p in result["parameters"]] == ["mu_pivot", "adhesion_energy_J_m2"]
    assert all(p["std_now"] is None and p["std_after"] > 0 for p in result["parameters"])
    assert result["efficiency_lower_bound"] > 0.8


@pytest.mark.parametrize(("body", "pointer"), [
    ({"runs": 5, "space": {**SPACE, "temperature_C": [20, 30]}}, "/space/temperature_C"),
    ({"runs": 5, "space": {**SPACE, "load_N": {"low": -1.0, "high": 1.0}}}, "/space/load_N"),
    ({"runs": 5, "goal": "predict", "space": SPACE}, "/envelope"),
    ({"runs": 0, "space": SPACE}, "/runs"),
    ({"runs": 501, "space": SPACE}, "/runs"),
    ({"runs": 5, "space": {k: v for k, v in SPACE.items() if k != "relative_humidity"}}, "/space"),
    ({"runs": 5, "space": SPACE, "fixed": {"mu_pivot": -1.0}}, "/fixed/mu_pivot"),
    ({"runs": 5, "space": SPACE, "planned": [{"balls": 4}]}, "/planned/0"),
    # a flag for a condition: refused, never read as 1 past its unit (cycles [kcycles]: true was 1 cycle)
    ({"runs": 5, "space": {k: v for k, v in SPACE.items() if k != "relative_humidity"},
      "fixed": {"relative humidity [%]": True}}, "/fixed/relative humidity [%]"),
])
def test_bad_requests_are_problems_naming_the_field(client, calibration_id, body, pointer):
    answer = problem(client.post(f"/v1/calibrations/{calibration_id}/next-experiments", json=body), 422)
    assert pointer in [e["pointer"] for e in answer["errors"]], answer


def test_unknown_calibration_and_plot_are_404(client):
    unknown = f"/v1/calibrations/{'0' * 32}/next-experiments"
    problem(client.post(unknown, json={"runs": 5, "space": SPACE}), 404)
    problem(client.get("/v1/experiments/nope/plot.png"), 404)
    answer = problem(client.post("/v1/experiments", json={"runs": 5, "space": SPACE, "goal": "discriminate",
                                                          "fit_parameters": ["mu_pivot"]}), 422)
    assert answer["errors"][0]["pointer"] == "/goal"


def test_cli_first_design_and_next_runs_of_a_stored_calibration(client, calibration_id, data_dir, tmp_path,
                                                                 monkeypatch):
    first = tmp_path / "first.json"
    first.write_text(json.dumps({"runs": 6, "fit_parameters": ["mu_pivot"],
                                 "space": {"balls": {"values": [4, 8]}, "load_N": {"low": 1e-3, "high": 3e-2},
                                           "speed_m_s": [0.05]}}))
    assert main(["experiments", str(first), "-o", str(tmp_path / "first-runs.json")]) == 0
    document = json.loads((tmp_path / "first-runs.json").read_text())
    assert len(document["runs"]) == 6 and document["plot_url"] is None
    assert all(run["in_domain"] is None for run in document["runs"])  # no calibration, no domain
    monkeypatch.setenv("MICROBEARING_DATA_DIR", str(data_dir))
    request = tmp_path / "next.json"
    request.write_text(json.dumps({"runs": 6, "goal": "discriminate", "space": SPACE}))
    code = main(["experiments", str(request), "--calibration", f"calibrated:{calibration_id}",
                 "-o", str(tmp_path / "runs.json"), "--plot", str(tmp_path / "runs.png")])
    assert code == 0
    assert len(json.loads((tmp_path / "runs.json").read_text())["runs"]) == 6
    assert (tmp_path / "runs.png").read_bytes()[:4] == b"\x89PNG"
    request.write_text(json.dumps({"runs": 6, "space": {**SPACE, "temperature_C": [20.0]}}))
    assert main(["experiments", str(request), "--calibration", calibration_id]) == 2


def test_a_planned_run_s_own_value_of_a_fixed_input_counts(client):
    # a run planned at another groove angle than the fixed one is taken as planned: its information
    # differs, so the design's criterion does (it had been the same for every angle: the column was dropped)
    space = {"balls": [4, 8], "load_N": [0.003, 0.03], "speed_m_s": [0.02, 0.15]}
    run = {"balls": 6, "speed_m_s": 0.05, "load_N": 0.01}
    criteria = []
    for planned in ([run], [{**run, "groove_angle_deg": 20}], [{**run, "groove_angle_deg": 85}]):
        body = {"runs": 2, "fit_parameters": ["mu_pivot"], "space": space, "fixed": {"groove_angle_deg": 20},
                "planned": planned}
        criteria.append(finished(client, client.post("/v1/experiments", json=body))["criterion"])
    assert criteria[0] == pytest.approx(criteria[1], rel=1e-9)  # the fixed angle, given or not
    assert criteria[2] != pytest.approx(criteria[0], rel=1e-6), criteria
    # a column some runs give and another does not, with no fixed value: refused at submit
    body = {"runs": 2, "fit_parameters": ["mu_pivot"], "space": space,
            "planned": [{**run, "groove_angle_deg": 85}, run]}
    errors = problem(client.post("/v1/experiments", json=body), 422)["errors"]
    assert errors[0]["pointer"].startswith("/planned/1"), errors


def test_the_plan_plot_draws_each_column_under_its_key_and_unit_as_sent(client):
    # a lab's space in mN and mm/s: the plot's axes read "load [mN]" and "speed [mm/s]" with the runs'
    # values in those units (1-30 mN, 0-150 mm/s), not load_N 0.001-0.03 "[as in the data]"
    import matplotlib.pyplot as plt

    from microbearing.calibrate.plan_plot import plan_figure

    lab = {"balls": {"values": [4, 8]}, "load [mN]": {"low": 1, "high": 30, "spacing": "log"},
           "speed [mm/s]": {"low": 0, "high": 150}}
    body = {"runs": 6, "space": lab, "fit_parameters": ["mu_pivot"], "noise_std_log": 0.03}
    result = finished(client, client.post("/v1/experiments", json=body))
    plot = result["plot"]
    assert plot["sent_as"]["load_N"] == "load [mN]" and plot["sent_as"]["speed_m_s"] == "speed [mm/s]"
    figure = plan_figure(result)
    try:
        ax = figure.axes[0]
        labels = {ax.get_xlabel(): 0, ax.get_ylabel(): 1}
        drawn = ax.collections[-1].get_offsets()  # the proposed runs, (x, y) per setting
        for name, key in plot["sent_as"].items():
            if key not in labels:
                continue
            sent = np.asarray(drawn)[:, labels[key]]
            si = np.asarray(plot["runs"][name], dtype=float)
            factor = 1e3 if name in ("load_N", "speed_m_s") else 1.0
            assert np.allclose(np.sort(np.unique(sent)), np.sort(np.unique(si * factor))), (key, sent, si)
        if "balls" in labels:  # ball counts get whole ticks
            axis = ax.xaxis if labels["balls"] == 0 else ax.yaxis
            ticks = [t for t in axis.get_majorticklocs() if 3.5 <= t <= 8.5]
            assert ticks and all(float(t).is_integer() for t in ticks), ticks
    finally:
        plt.close(figure)


def test_the_plan_plot_speaks_percent_and_degrees_fahrenheit_as_sent():
    # drawn from a document alone: RH 0.2-0.8 sent as "RH [%]" is drawn 20-80, 300 K sent as
    # "temperature [degF]" is drawn 80.33 degF (hand: 300 K = 26.85 degC = 80.33 degF)
    import matplotlib.pyplot as plt

    from microbearing.calibrate.plan_plot import plan_figure

    document = {"goal": "parameters", "efficiency_lower_bound": 0.9,
                "plot": {"axes": ["relative_humidity", "temperature_K"],
                         "runs": {"relative_humidity": [0.2, 0.8], "temperature_K": [300.0, 310.0]},
                         "envelope": {"relative_humidity": [0.5, 0.6], "temperature_K": [300.0, 300.0]},
                         "sent_as": {"relative_humidity": "RH [%]", "temperature_K": "temperature [degF]"}}}
    figure = plan_figure(document)
    try:
        ax = figure.axes[0]
        assert (ax.get_xlabel(), ax.get_ylabel()) == ("RH [%]", "temperature [degF]")
        offsets = np.asarray(ax.collections[-1].get_offsets())
        assert np.allclose(sorted(offsets[:, 0]), [20.0, 80.0])
        assert np.allclose(sorted(offsets[:, 1]), [80.33, 98.33], atol=1e-6)
        patch = ax.patches[0]  # the envelope, 50-60 % wide
        assert np.isclose(patch.get_x(), 50.0) and np.isclose(patch.get_width(), 10.0)
    finally:
        plt.close(figure)


def test_the_rivals_panel_names_columns_by_their_keys_as_sent():
    # discriminate's curves: a rival's label names the model's column (RH); drawn, it names the key sent
    import matplotlib.pyplot as plt

    from microbearing.calibrate.plan_plot import plan_figure

    curves = [{"label": "calibrated model", "x": [0.2, 0.8], "mu": [0.010, 0.020]},
              {"label": "mu_pivot drifts with RH (linear) in place of humidity_meniscus on RH",
               "x": [0.2, 0.8], "mu": [0.011, 0.016]}]
    document = {"goal": "discriminate", "efficiency_lower_bound": 0.9,
                "plot": {"axes": ["RH", "balls"], "runs": {"RH": [0.2, 0.8], "balls": [4.0, 8.0]},
                         "curves": curves, "others": {"load_N": 0.01}, "sent_as": {"RH": "RH [%]",
                                                                                  "load_N": "load [mN]"}}}
    figure = plan_figure(document)
    try:
        right = figure.axes[1]
        legend = [t.get_text() for t in right.get_legend().get_texts()]
        assert legend[1].startswith("mu_pivot drifts with RH [%] (linear)"), legend
        assert right.get_xlabel() == "RH [%]"
        assert np.allclose(right.get_lines()[0].get_xdata(), [20.0, 80.0])
        assert "load [mN] = 10" in right.get_title()
    finally:
        plt.close(figure)


def test_runs_beyond_the_data_are_worded_in_the_keys_and_units_of_the_space(client, calibration_id):
    # the calibration's humidity ran 0.2-0.5 (kelvin_rows); a space sent in percent reaching 80 % is
    # warned of in percent, under its key (by hand: the data's range x 100)
    body = {"runs": 6, "goal": "parameters",
            "space": {"balls": {"values": [4, 8]}, "load [mN]": {"low": 3, "high": 30, "spacing": "log"},
                      "speed_m_s": {"low": 0.0, "high": 0.15}, "relative humidity [%]": {"values": [30, 80]}}}
    result = finished(client, client.post(f"/v1/calibrations/{calibration_id}/next-experiments", json=body))
    domain = client.get(f"/v1/calibrations/{calibration_id}").json()["model"]["domain"]["relative_humidity"]
    beyond = [w for w in result["warnings"] if "outside the calibration data's range" in w]
    # the Kelvin law's parameters are learnt where humidity reaches furthest: runs at 80 %
    assert any(run["conditions"]["relative_humidity"] == 0.8 for run in result["runs"]), result["runs"]
    assert beyond and beyond[0].startswith(
        f"relative humidity [%] = 80 is outside the calibration data's range "
        f"[{100 * domain[0]:.6g}, {100 * domain[1]:.6g}]"), beyond
    assert not any(w.startswith("relative_humidity =") for w in result["warnings"]), result["warnings"]
    assert not any("load_N =" in w for w in result["warnings"]), result["warnings"]
