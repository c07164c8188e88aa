"""The lab's measurement system (issue 33, items 1-3): replicates and lack of fit, drift over a session
(order and ISO 8601 time), a clipping sensor (censored rows) and constant data.

The pieces are checked against independent numbers (an ANOVA by hand, a Tobit likelihood maximized
directly, datetime arithmetic); each item once through ``POST /v1/calibrations`` on data drawn here from
the physics (mu_pivot 0.65, 3 % scatter, one seed; bench/measurement_system.py runs several).
"""

from __future__ import annotations

from dataclasses import replace
from datetime import UTC, datetime, timedelta, timezone

import numpy as np
import pytest
from jobs_helper import finished_job
from scipy import optimize, stats

from microbearing import physics
from microbearing.calibrate import CalibratedModel, DataError, parse_csv, parse_rows
from microbearing.calibrate.candidates import EffectTerm, candidate_terms
from microbearing.calibrate.censored import censored_residual, residual_variance
from microbearing.calibrate.fit import fit
from microbearing.calibrate.measurement import (
    LackOfFit,
    drift_words,
    folds,
    inspect,
    lack_of_fit,
    unit_slips,
    with_censor_scale,
)
from microbearing.calibrate.rivals import PLACE_LR
from microbearing.calibrate.scores import count_parameters
from microbearing.physics.changepoints import step_places

PIVOT, NOISE, BALLS = 0.65, 0.03, 4


def truth(load_N, speed_m_s):
    return physics.evaluate(balls=BALLS, load_N=load_N, speed_m_s=speed_m_s, mu_pivot=PIVOT).mu


def as_rows(columns: dict, mu: np.ndarray) -> list[dict]:
    return [{k: (v[i] if isinstance(v[i], str) else float(v[i])) for k, v in columns.items()}
            | {"mu_measured": float(mu[i])} for i in range(mu.size)]


def calibrated(client, rows, folds_=3) -> dict:
    response = client.post("/v1/calibrations", json={"data": rows, "fit_parameters": ["mu_pivot"],
                                                     "fixed": {"balls": BALLS}, "folds": folds_})
    assert response.status_code == 202, response.text
    job = finished_job(client, response, timeout_s=300, interval_s=0.2)
    return client.get(job["result_url"]).json()


def coverage(report, points, true_mu, rng) -> tuple[float, float]:
    """Truth error (RMS of log predicted / true) and the 95 % coverage of fresh measurements."""
    prediction = CalibratedModel.from_json(report["model"]).predict({"balls": BALLS, **points})
    fresh = true_mu * np.exp(rng.normal(0.0, NOISE, true_mu.size))
    error = float(np.sqrt(np.mean(np.square(np.log(prediction.mu / true_mu)))))
    return error, float(np.mean((prediction.mu_lower <= fresh) & (fresh <= prediction.mu_upper)))


# --- 1. replicates -------------------------------------------------------------------------------------


def test_lack_of_fit_is_the_anova_split_by_hand():
    rng = np.random.default_rng(3)
    design = np.repeat(np.arange(6), [2, 3, 4, 2, 5, 3])
    residual = rng.normal(0.0, 0.03, design.size) + 0.02 * (design % 2)
    d = parse_rows([{"load_N": 0.01, "mu_measured": 0.01}] * design.size,
                   fixed={"balls": 4, "speed_m_s": 0.1})
    lof = lack_of_fit(replace(d, design=design), residual, n_fitted=2)
    # By hand: within-point sum of squares on n - m dof, the points' means weighted by their counts on
    # m - p dof, and the F distribution's upper tail.
    means = np.array([residual[design == k].mean() for k in range(6)])
    ss_pe = sum(np.sum((residual[design == k] - means[k]) ** 2) for k in range(6))
    ss_lof = sum(np.sum(design == k) * means[k] ** 2 for k in range(6))
    assert ss_pe + ss_lof == pytest.approx(np.sum(residual ** 2))
    f = (ss_lof / 4) / (ss_pe / (design.size - 6))
    assert (lof.points, lof.pure_error_dof, lof.lack_of_fit_dof) == (6, design.size - 6, 4)
    assert lof.pure_error == pytest.approx(np.sqrt(ss_pe / (design.size - 6)))
    assert lof.f == pytest.approx(f) and lof.p == pytest.approx(stats.f.sf(f, 4, design.size - 6))


def test_design_points_are_found_through_jitter_and_folds_keep_them_whole():
    rng = np.random.default_rng(5)
    loads = np.repeat(np.geomspace(3e-3, 3e-2, 4), 6) * (1 + 0.003 * rng.standard_normal(24))
    speeds = np.tile(np.repeat([0.02, 0.1], 3), 4)
    rows = as_rows({"load_N": loads, "speed_m_s": speeds, "run_index": np.arange(24)}, np.full(24, 0.01)
                   * np.exp(rng.normal(0, 0.03, 24)))
    dataset = parse_rows(rows, fixed={"balls": 4})
    system = inspect(dataset, 4)
    # 4 loads x 2 speeds, 3 replicates each; the run index is order, not design.
    assert system.sessions == ("run_index",) and system.grouped_folds
    assert np.unique(system.design).size == 8 and np.all(np.bincount(system.design) == 3)
    parts = folds(system.apply(dataset), 4, seed=1)
    assert sorted(np.concatenate(parts).tolist()) == list(range(24))
    assert all(len({int(system.design[i]) for i in part}) * 3 == part.size for part in parts)
    # Random loads (no two alike up to the jitter's chain) are no design: row folds as before.
    scattered = parse_rows(as_rows({"load_N": np.exp(rng.uniform(-6, -3, 60)), "speed_m_s": np.full(60, 0.1)},
                                   np.full(60, 0.01) * np.exp(rng.normal(0, 0.03, 60))), fixed={"balls": 4})
    assert inspect(scattered, 5).design is None


def test_design_points_drawn_at_random_are_found_jointly_and_one_wide_point_loses_only_itself():
    rng = np.random.default_rng(7)
    # 25 points at random loads and speeds, 3 replicates each (load read with 0.3 % jitter): some loads of
    # different points lie within 2 % of each other, so a column alone cannot tell its levels.
    loads = np.exp(rng.uniform(np.log(2e-3), np.log(4e-2), 25))
    speeds = rng.uniform(0.02, 0.2, 25)
    truth_point = np.repeat(np.arange(25), 3)
    load = loads[truth_point] * (1 + 0.003 * rng.standard_normal(75))
    log_gaps = np.diff(np.sort(np.log(loads)))
    assert log_gaps.min() < 0.02  # the case the joint rule is for
    order = rng.permutation(75)
    rows = as_rows({"load_N": load[order], "speed_m_s": speeds[truth_point][order]}, np.full(75, 0.01))
    design = inspect(parse_rows(rows, fixed={"balls": 4}), 5).design
    assert design is not None
    # the same partition as the truth's (labels aside): a bijection between found and true points
    pairs = set(zip(design.tolist(), truth_point[order].tolist(), strict=True))
    assert len(pairs) == 25 == np.unique(design).size
    # One point read 10 % apart in load: not a point within the jitter, its rows counted singly; the others
    # stay points.
    load[truth_point == 4] *= np.array([1.0, 1.05, 1.10])
    rows = as_rows({"load_N": load, "speed_m_s": speeds[truth_point]}, np.full(75, 0.01))
    counts = np.bincount(inspect(parse_rows(rows, fixed={"balls": 4}), 5).design)
    assert sorted(counts.tolist()) == [1, 1, 1] + [3] * 24


def test_replicates_through_the_api(client):
    rng = np.random.default_rng(11)
    loads, speeds = np.meshgrid(np.geomspace(3e-3, 3e-2, 3), np.linspace(0.02, 0.14, 4))
    load = np.repeat(loads.ravel(), 4) * (1 + 0.002 * rng.standard_normal(48))
    speed = np.repeat(speeds.ravel(), 4)
    mu = truth(load, speed) * np.exp(rng.normal(0.0, NOISE, 48))
    report = calibrated(client, as_rows({"load_N": load, "speed_m_s": speed}, mu))
    replicates = report["measurement_system"]["replicates"]
    assert replicates["points"] == 12 and replicates["rows"] == 48
    assert 0.02 < replicates["pure_error_relative"] < 0.04  # truth 3 %
    assert replicates["p"] > 0.01  # the physics lacks nothing
    assert any("12 design points x 4" in line for line in report["measurement_system"]["summary"])
    assert report["effects"] == []
    error, covered = coverage(report, {"load_N": np.repeat(loads.ravel(), 30), "speed_m_s":
                                       np.repeat(speeds.ravel(), 30)},
                              truth(np.repeat(loads.ravel(), 30), np.repeat(speeds.ravel(), 30)), rng)
    assert error < 0.5 * NOISE and 0.9 <= covered <= 0.995


# --- 2. time and order -----------------------------------------------------------------------------------


def test_iso_times_are_hours_since_the_start_not_labels():
    start = datetime(2026, 11, 28, 9, 0, tzinfo=UTC)
    stamps = [start + timedelta(minutes=m) for m in (30, 0, 95)]
    text = "load_N,speed_m_s,date,mu_measured\n" + "".join(
        f"0.01,0.1,{t.isoformat().replace('+00:00', 'Z')},0.01\n" for t in stamps)
    dataset = parse_csv(text, fixed={"balls": 4})
    assert dataset.factors == {}
    assert dataset.conditions["date"].tolist() == pytest.approx([0.5, 0.0, 95 / 60])
    assert dataset.clock == {"date": start.isoformat()}
    # A zone on some cells only: the others are UTC; a date alone is midnight.
    mixed = parse_rows([{"load_N": 0.01, "day": d, "mu_measured": 0.01} for d in
                        ("2026-11-28", "2026-11-28T12:00:00+02:00")], fixed={"balls": 4, "speed_m_s": 0.1})
    assert mixed.conditions["day"].tolist() == pytest.approx([0.0, 10.0])
    # Labels stay labels.
    labels = parse_rows([{"load_N": 0.01, "specimen": s, "mu_measured": 0.01} for s in ("S1", "2026-13")],
                        fixed={"balls": 4, "speed_m_s": 0.1})
    assert "specimen" in labels.factors


def test_the_clock_survives_the_stored_form_a_job_is_rebuilt_from():
    """A calibration job stores its data (``calibration_inputs``, JSON) and is rebuilt from them after a
    restart or in another process: the starts of ISO time columns come back with them, so a rebuilt job
    reads those columns as the instrument's clock (no bearing drift against them), as the first one did."""
    import json

    from microbearing.calibrate import Dataset
    from microbearing.service.job_kinds import calibration_inputs

    rows = session_rows(np.random.default_rng(2), 12, 0.0, clock=True)
    dataset = parse_rows(rows, fixed={"balls": 4})
    assert dataset.clock == {"date": "2026-11-28T09:00:00+00:00"}
    again = Dataset.from_columns(dataset.to_columns(), dataset.fixed)
    assert again.clock == dataset.clock
    stored = json.loads(json.dumps(calibration_inputs(dataset, ["mu_pivot"], 3, "median", {})))
    rebuilt = Dataset.from_columns(stored["data"], stored["fixed"])
    assert rebuilt.clock == dataset.clock
    np.testing.assert_array_equal(rebuilt.conditions["date"], dataset.conditions["date"])
    assert inspect(rebuilt, 3).clock == inspect(dataset, 3).clock == dataset.clock


def session_rows(rng, n, drift, clock):
    load = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n))
    speed = rng.uniform(0.01, 0.15, n)
    run = np.arange(n, dtype=float)
    mu = truth(load, speed) * (1 + drift * run / (n - 1)) * np.exp(rng.normal(0.0, NOISE, n))
    start = datetime(2026, 11, 28, 9, 0, tzinfo=UTC)
    column = {"date": [(start + timedelta(minutes=4 * k)).isoformat() for k in range(n)]} if clock \
        else {"run_index": run}
    return as_rows({"load_N": load, "speed_m_s": speed, **column}, mu)


def test_instrument_drift_through_the_api_with_iso_times(client):
    rng = np.random.default_rng(4)
    n = 96
    report = calibrated(client, session_rows(rng, n, 0.08, clock=True))
    assert [e["name"] for e in report["effects"]] == ["measurement_drift"]
    drift = report["effects"][0]["parameters"]["session_drift_log"]
    assert np.expm1(drift) == pytest.approx(0.08, abs=0.03)
    said = report["measurement_system"]["drift"][0]
    assert said.startswith(f"the instrument drifted {100 * np.expm1(drift):+.1f} % over the session")
    # the session's ends as the user wrote them: 95 runs 4 min apart after 09:00 end at 15:20
    assert "(date 2026-11-28T09:00:00+00:00 to 2026-11-28T15:20:00+00:00;" in said
    assert report["measurement_system"]["clock"] == {"date": "2026-11-28T09:00:00+00:00"}
    hours = 4 * (n - 1) / 60
    for at in (0.0, hours):  # the session's start and end
        g = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), 300))
        v = rng.uniform(0.01, 0.15, 300)
        error, covered = coverage(report, {"load_N": g, "speed_m_s": v, "date": np.full(300, at)},
                                  truth(g, v) * (1 + 0.08 * at / hours), rng)
        assert error < 0.5 * NOISE and 0.9 <= covered <= 0.995
    # /v1/friction/batch reads the time column as ISO 8601 times too (any zone; a date alone is midnight
    # UTC), the same answer as its hours since the session's start
    start = datetime(2026, 11, 28, 9, 0, tzinfo=UTC)
    zone = timezone(timedelta(hours=-5))
    stamps = [(start + timedelta(hours=h)).astimezone(zone).isoformat() for h in (0.0, hours)]
    stamps.append("2026-11-29")
    point = {"model": report["model_id"], "outputs": ["mu"], "points": {"balls": BALLS, "load_N": 0.01,
                                                                        "speed_m_s": 0.08}}
    by_time = client.post("/v1/friction/batch", json={**point, "conditions": {"date": stamps}})
    by_hours = client.post("/v1/friction/batch", json={**point, "conditions": {"date": [0.0, hours, 15.0]}})
    assert by_time.status_code == by_hours.status_code == 200, by_time.text
    for key in ("mu", "mu_lower", "mu_upper"):
        assert by_time.json()[key] == pytest.approx(by_hours.json()[key], rel=1e-12)
    one = client.post("/v1/friction", json={**point["points"], "model": report["model_id"],
                                            "conditions": {"date": stamps[1]}})
    assert one.status_code == 200 and one.json()["mu"] == pytest.approx(by_hours.json()["mu"][1], rel=1e-12)
    # a time written otherwise is refused as before, naming the column
    refused = client.post("/v1/friction/batch", json={**point, "conditions": {"date": ["28.11.2026"]}})
    assert refused.status_code == 422 and "/conditions/date" in refused.text


@pytest.mark.parametrize("header", ["Datum", "when"])
def test_a_clock_column_drives_the_instrument_s_drift_whatever_its_name(client, header):
    # before: ISO times under a header with no session word ('Datum') were read as a clock, yet the drift
    # was never a candidate on them (the effect's name words only): a generic term took it, no drift was
    # said, and every prediction then needed the clock column
    rows = [{(header if k == "date" else k): v for k, v in row.items()}
            for row in session_rows(np.random.default_rng(4), 96, 0.08, clock=True)]
    report = calibrated(client, rows)
    assert [e["name"] for e in report["effects"]] == ["measurement_drift"], report["effects"]
    assert report["effects"][0]["drivers"] == [header]
    assert report["measurement_system"]["drift"][0].startswith("the instrument drifted +")
    answer = client.post("/v1/friction", json={"balls": BALLS, "load_N": 0.01, "speed_m_s": 0.05,
                                                "model": report["model_id"], "conditions": {header: 0.0}})
    assert answer.status_code == 200, answer.text  # the reading at the session's start
    assert answer.json()["mu"] == pytest.approx(float(truth(0.01, 0.05)), rel=0.05)


def test_friction_rising_over_the_runs_is_not_a_run_in(client):
    rng = np.random.default_rng(8)
    report = calibrated(client, session_rows(rng, 72, 0.10, clock=False))
    names = [e["name"] for e in report["effects"]]
    assert "run_in" not in names and names == ["measurement_drift"]
    assert report["effects"][0]["drivers"] == ["run_index"]
    assert report["fitted_parameters"]["mu_pivot"]["value"] == pytest.approx(PIVOT, rel=0.03)


def stepped_rows(rng, n, factor, at):
    """Session rows whose reading is multiplied by ``factor`` from run ``at`` on (a recalibrated cell)."""
    load = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n))
    speed = rng.uniform(0.01, 0.15, n)
    run = np.arange(n, dtype=float)
    mu = truth(load, speed) * np.where(run >= at, factor, 1.0) * np.exp(rng.normal(0.0, NOISE, n))
    return as_rows({"load_N": load, "speed_m_s": speed, "run_index": run}, mu)


def test_step_places_are_the_gaps_with_enough_rows_on_each_side():
    # 3 rows at each of 0..9 (30 rows): at least 5 rows a side, so the gaps after 1 (6 below) to after 7
    # (6 above); midpoints by hand
    x = np.repeat(np.arange(10.0), 3)
    places = step_places(x)
    assert [p["step"] for p in places] == [1.5, 2.5, 3.5, 4.5, 5.5, 6.5, 7.5]
    for p in places:  # brute force: the rows either side and the values either side
        assert np.sum(x < p["step"]) >= 5 and np.sum(x >= p["step"]) >= 5
        assert p["before"] == x[x < p["step"]].max() and p["after"] == x[x >= p["step"]].min()
    # the step law's searched place counts as a fitted value, like its size
    term = EffectTerm("measurement_step", ("run_index",), {"step": 4.5})
    assert count_parameters(["mu_pivot"], [term]) == 3
    assert term.label == "measurement_step on run_index at step 4.5"


def test_the_place_s_likelihood_ratio_covers_the_true_place_at_95_percent():
    # brute force: Gaussian rows with a step at the middle, the profile RSS over every place by cumulative
    # sums; the LR at the true place stays below PLACE_LR in about 95 % of data sets (chi-square's 3.84,
    # the naive bound, covers far less: the place is searched, not a smooth parameter)
    rng = np.random.default_rng(0)
    n, sims = 400, 2000
    for delta in (0.5, 1.0):
        y = rng.normal(size=(sims, n))
        y[:, n // 2:] += delta
        c1, c2 = np.cumsum(y, axis=1), np.cumsum(y**2, axis=1)
        k = np.arange(1, n)
        rss = (c2[:, :-1] - c1[:, :-1] ** 2 / k) + (c2[:, -1:] - c2[:, :-1] - (c1[:, -1:] - c1[:, :-1]) ** 2
                                                    / (n - k))
        lr = (rss[:, n // 2 - 1] - rss.min(axis=1)) / (rss.min(axis=1) / (n - 3))
        assert 0.93 <= np.mean(lr <= PLACE_LR) <= 0.99
        assert np.mean(lr <= stats.chi2.ppf(0.95, 1)) < 0.9


def test_a_step_in_the_reading_is_found_at_its_place_and_predicted_after_it(client):
    # before: no step law; the linear drift took a x1.06 step at run 60 of 120 as "drifted +8-10 %", and
    # fresh measurements about the step were covered below 0.90
    rng = np.random.default_rng(11)
    n = 120
    report = calibrated(client, stepped_rows(rng, n, 1.06, 60), folds_=5)
    assert [e["name"] for e in report["effects"]] == ["measurement_step"], report["effects"]
    effect = report["effects"][0]
    step, sd = effect["parameters"]["step_log"], effect["parameter_std"]["step_log"]
    # the size within noise: 3 % on 60 rows a side is 0.0055 in log
    assert abs(step - np.log(1.06)) < 3 * 0.03 * np.sqrt(2 / 60) and 0.003 < sd < 0.01
    after = effect["constants"]["after"]
    assert abs(after - 60) <= 3 and effect["constants"]["before"] == after - 1
    said = report["measurement_system"]["drift"]
    assert len(said) == 1 and said[0].startswith(
        f"the instrument's reading stepped {100 * np.expm1(step):+.1f} % at run_index {after:.0f} (after")
    model = CalibratedModel.from_json(report["model"])
    # later runs are predicted at the level after the step, earlier ones before it
    level = model.predict({"balls": BALLS, "load_N": np.full(2, 0.01), "speed_m_s": np.full(2, 0.05),
                           "run_index": np.array([0.0, n - 1.0])}).mu
    assert level[1] / level[0] == pytest.approx(np.exp(step), rel=1e-9)
    # about the step the interval holds the place's doubt (its rivals): fresh runs 50-70 covered
    runs = np.repeat(np.arange(50.0, 71.0), 20)
    g = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), runs.size))
    v = rng.uniform(0.01, 0.15, runs.size)
    error, covered = coverage(report, {"load_N": g, "speed_m_s": v, "run_index": runs},
                              truth(g, v) * np.where(runs >= 60, 1.06, 1.0), rng)
    assert 0.9 <= covered <= 0.995 and error < NOISE


def test_an_order_column_is_offered_the_drift_not_its_generic_twin():
    # measurement_drift on an order column is the log-linear term with the session's start as reference:
    # the generic log-linear term is not proposed beside it there, and stays on the other columns
    rows = session_rows(np.random.default_rng(3), 30, 0.0, clock=False)
    labels = {t.label for t in candidate_terms(parse_rows(rows, fixed={"balls": BALLS}))}
    assert "measurement_drift on run_index" in labels and "generic_linear on run_index" not in labels
    assert {"generic_quadratic on run_index", "generic_linear on load_N"} <= labels


def test_a_falling_reading_is_named_a_drift_of_the_instrument(client):
    # a reading drifting -6 % over 120 runs: the generic log-linear slope on run_index fitted a hair
    # better (its reference is the session's middle, where mu_pivot's level sits otherwise) and was named,
    # the measurement system saying nothing of a drift
    rows = session_rows(np.random.default_rng(50), 120, -0.06, clock=False)
    report = calibrated(client, rows, folds_=5)
    assert [e["name"] for e in report["effects"]] == ["measurement_drift"]
    d = report["effects"][0]["parameters"]["session_drift_log"]
    sd = report["effects"][0]["parameter_std"]["session_drift_log"]
    assert d - 1.96 * sd <= np.log1p(-0.06) <= d + 1.96 * sd
    assert report["measurement_system"]["drift"][0].startswith(
        f"the instrument drifted {100 * np.expm1(d):+.1f} % over the session (run_index 0 to 119;")


def test_the_bearing_is_answered_without_the_session_column_and_designed_for(client):
    """A model with the instrument's drift on run_index: a prediction that does not give run_index is the
    bearing's (the reading at the session's start, where the drift is 1), said so; a robust design is for
    the bearing, not a reading. Both answered 422 'needs condition column(s) run_index' before, and a
    design over run_index's range would have been made robust to the instrument."""
    rows = session_rows(np.random.default_rng(12), 120, 0.10, clock=False)
    report = calibrated(client, rows, folds_=5)
    assert [e["name"] for e in report["effects"]] == ["measurement_drift"]
    d = report["effects"][0]["parameters"]["session_drift_log"]
    model = CalibratedModel.from_json(report["model"])
    assert model.required_columns == [] and model.column_defaults == {"run_index": 0.0}
    point = {"balls": BALLS, "load_N": 0.01, "speed_m_s": 0.08}
    bearing = model.predict(point)
    start, end = (model.predict({**point, "run_index": r}) for r in (0.0, 119.0))
    assert bearing.mu == pytest.approx(start.mu, rel=1e-12)
    assert bearing.mu_upper == pytest.approx(start.mu_upper, rel=1e-12)
    assert end.mu / start.mu == pytest.approx(np.exp(d), rel=1e-9)  # the drift, by its formula
    answer = client.post("/v1/friction", json={"model": report["model_id"], **point})
    assert answer.status_code == 200, answer.text
    assert answer.json()["mu"] == pytest.approx(float(start.mu), rel=1e-12)
    said = answer.json()["domain_warnings"]
    assert any(w.startswith("run_index not given: the bearing's mu") for w in said), said
    job = client.post("/v1/optimizations", json={
        "model": report["model_id"], "objective": "mu_upper", "speed_m_s": [0.01, 0.1],
        "bounds": {"balls": [4, 8], "groove_angle_deg": [45.5, 59.5], "load_N": [0.0044, 0.0132]}})
    assert job.status_code == 202, job.text
    result = client.get(finished_job(client, job, timeout_s=300, interval_s=0.2)["result_url"]).json()
    assert result["proof"]["proven"] and result["worst_case"]["conditions"] == {"run_index": 0.0}


@pytest.mark.parametrize("kind", ["drift", "clean"])
def test_a_linear_drift_is_no_step_and_clean_data_get_neither(client, kind):
    rng = np.random.default_rng(12)
    rows = session_rows(rng, 120, 0.10 if kind == "drift" else 0.0, clock=False)
    names = [e["name"] for e in calibrated(client, rows, folds_=5)["effects"]]
    assert names == (["measurement_drift"] if kind == "drift" else []), names


def test_a_step_on_iso_times_is_said_at_the_time_the_user_wrote():
    # by hand: the step's first row after it is 4.0 hours after a 09:00 start, 13:00 that day
    effect = {"name": "measurement_step", "drivers": ["date"],
              "parameters": {"step_log": float(np.log(1.06))}, "parameter_std": {"step_log": 0.005},
              "constants": {"step": 3.9667, "before": 3.9333, "after": 4.0}}
    said = drift_words([effect], {"date": "2026-11-28T09:00:00+00:00"})
    assert said[0].startswith("the instrument's reading stepped +6.0 % at date 2026-11-28T13:00:00+00:00 "
                              "(after 2026-11-28T12:56:00+00:00;")
    low, high = np.expm1(np.log(1.06) - 1.96 * 0.005), np.expm1(np.log(1.06) + 1.96 * 0.005)
    assert f"{100 * low:+.1f} to {100 * high:+.1f} %" in said[0]
    # without the clock the place is in the column's own numbers
    assert " at run 4 (after 3.9333;" in drift_words([{**effect, "drivers": ["run"]}])[0]


# --- 3. saturation and constant data ---------------------------------------------------------------------


def test_censored_residual_maximizes_the_tobit_likelihood():
    rng = np.random.default_rng(2)
    x = rng.uniform(0, 1, 200)
    y = 0.3 + 0.5 * x + rng.normal(0, 0.1, 200)
    clip = 0.7
    side = (y >= clip).astype(int)
    y = np.minimum(y, clip)
    s = 0.1

    def tobit(p):  # the censored likelihood written directly: density below the clip, survival at it
        model = p[0] + p[1] * x
        return -(np.sum(stats.norm.logpdf(y[side == 0], model[side == 0], s))
                 + np.sum(stats.norm.logsf(clip, model[side == 1], s)))

    direct = optimize.minimize(tobit, [0.0, 0.0], method="Nelder-Mead",
                               options={"xatol": 1e-8, "fatol": 1e-10}).x
    squares = optimize.least_squares(lambda p: censored_residual(p[0] + p[1] * x - y, side, s), [0.0, 0.0]).x
    assert squares == pytest.approx(direct, abs=1e-4)
    assert abs(direct[1] - 0.5) < 0.1  # and the censored fit is not the flattened one
    assert np.polyfit(x, y, 1)[0] < direct[1] - 0.05
    # The variance counts the clipped rows by their side: near the truth where the measured rows alone
    # (a sample truncated at +0.01) are narrower.
    r = rng.normal(0, 0.03, 3000)
    clipped = np.where(r > 0.01, 1, 0)
    cut = np.minimum(r, 0.01)
    spread = np.sqrt(residual_variance(cut, clipped, np.ones(3000, bool)))
    assert spread == pytest.approx(0.03, rel=0.06)
    assert np.sqrt(np.mean(np.square(cut[clipped == 0]))) < 0.95 * spread


def test_a_clipping_sensor_through_the_api(client):
    rng = np.random.default_rng(6)
    n = 72
    load = np.exp(rng.uniform(np.log(1e-3), np.log(3e-2), n))
    speed = rng.uniform(0.01, 0.15, n)
    true_mu = truth(load, speed)
    level = float(np.quantile(true_mu, 0.72))
    mu = np.minimum(true_mu * np.exp(rng.normal(0.0, NOISE, n)), level)
    assert 0.26 <= np.mean(mu == level) <= 0.31
    report = calibrated(client, as_rows({"load_N": load, "speed_m_s": speed}, mu))
    (clip,) = report["measurement_system"]["saturation"]
    assert clip["side"] == "upper" and clip["level"] == level and clip["rows"] == np.sum(mu == level)
    assert report["effects"] == []  # no law invented for the plateau
    assert report["fitted_parameters"]["mu_pivot"]["value"] == pytest.approx(PIVOT, rel=0.03)
    g = np.exp(rng.uniform(np.log(1e-3), np.log(3e-2), 2000))
    v = rng.uniform(0.01, 0.15, 2000)
    t = truth(g, v)
    beyond = t >= level
    error, covered = coverage(report, {"load_N": g[beyond], "speed_m_s": v[beyond]}, t[beyond], rng)
    assert error < 0.5 * NOISE and 0.88 <= covered <= 0.99


def test_a_run_in_whose_first_cycles_are_clipped_is_fitted_without_bias():
    # The run-in's first cycles beyond the clip (friction 1 + 0.4 exp(-cycle / 300) times the physics,
    # the sensor clipping at the true mu's 80th percentile; bench/measurement_system.py --part
    # clip_runin): the censored fit of the true law at the calibration's scale finds the amplitude as its
    # own standard deviation says, over 20 draws; the clipped readings taken as values, or the censored
    # likelihood at three times that scale (each clipped row pulled beyond the clip), miss it.
    run_in = EffectTerm("run_in", ("cycle",))
    fitted = {"censored": [], "as values": [], "scale x3": []}
    for seed in range(20):
        rng = np.random.default_rng(seed)
        load = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), 140))
        speed = rng.uniform(0.01, 0.15, 140)
        cycle = np.sort(rng.uniform(0.0, 2000.0, 140))
        true_mu = truth(load, speed) * (1 + 0.4 * np.exp(-cycle / 300.0))
        mu = np.minimum(true_mu * np.exp(rng.normal(0.0, NOISE, 140)), np.quantile(true_mu, 0.8))
        data = parse_rows(as_rows({"load_N": load, "speed_m_s": speed, "cycle": cycle}, mu), {"balls": BALLS})
        censored = with_censor_scale(inspect(data, 5).apply(data), ["mu_pivot"], physics.DEFAULT_CONVENTION,
                                     [run_in])
        for name, d in (("censored", censored), ("as values", data),
                        ("scale x3", replace(censored, censor_scale=3 * censored.censor_scale))):
            result = fit(d, ["mu_pivot"], [run_in])
            fitted[name].append((result.term_values[0][0], result.std[1]))
    amplitude, std = np.array(fitted["censored"]).T
    assert abs(amplitude.mean() - 0.4) < 0.03  # about 3 standard errors of the mean (0.04 / sqrt(20))
    assert 0.5 < np.sqrt(np.mean(np.square((amplitude - 0.4) / std))) < 1.5  # its std neither far off
    assert np.array(fitted["as values"])[:, 0].mean() < 0.34
    assert np.array(fitted["scale x3"])[:, 0].mean() > 0.46


def test_constant_data_are_said_and_get_no_term(client):
    rng = np.random.default_rng(9)
    load = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), 40))
    report = calibrated(client, as_rows({"load_N": load, "speed_m_s": rng.uniform(0.01, 0.15, 40)},
                                        np.full(40, 0.012)))
    assert report["effects"] == [] and report["measurement_system"]["constant"] == 0.012
    assert report["measurement_system"]["saturation"] == []
    assert "constant data" in report["decision"]


def test_a_sensor_clipping_at_both_ends_through_the_api(client):
    # before: each end's pile was weighed against every other value's count, the other pile's included, so
    # two piles hid each other: both were fitted as values and a law was invented for them
    rng = np.random.default_rng(16)
    n = 72
    load = np.exp(rng.uniform(np.log(1e-3), np.log(3e-2), n))
    speed = rng.uniform(0.01, 0.15, n)
    true_mu = truth(load, speed) * np.exp(rng.normal(0.0, NOISE, n))
    low, high = (float(q) for q in np.quantile(true_mu, [0.12, 0.85]))
    mu = np.clip(true_mu, low, high)
    report = calibrated(client, as_rows({"load_N": load, "speed_m_s": speed}, mu))
    clips = {c["side"]: c for c in report["measurement_system"]["saturation"]}
    assert set(clips) == {"upper", "lower"}, report["measurement_system"]
    assert clips["upper"]["level"] == high and clips["upper"]["rows"] == np.sum(mu == high)
    assert clips["lower"]["level"] == low and clips["lower"]["rows"] == np.sum(mu == low)
    assert report["effects"] == []  # no law invented for the plateaus
    assert report["fitted_parameters"]["mu_pivot"]["value"] == pytest.approx(PIVOT, rel=0.05)


@pytest.mark.parametrize(("p", "words"), [
    (0.004, "the model misses something the replicates see"),
    (0.0187, "a sign that the model misses something the replicates see (p below 0.05, not below 0.01)"),
    (0.3, "as well as the replicates allow")])
def test_the_lack_of_fit_words_follow_its_p_value_and_name_the_rows_left_out(p, words):
    # before: p = 0.0187 was worded "fits ... as well as the replicates allow", and an outlier left out of
    # the test made its row count one less than the design's without a word
    lof = LackOfFit(18, 18, 71, 0.025, 53, 17, 2.13, p, outliers=1, clipped=0)
    text = lof.words()
    assert text.endswith(words) and "(71 rows, 18 points replicated; 1 outlier left out)" in text, text
    assert "clipped" not in text
    assert "2 clipped rows left out" in LackOfFit(18, 18, 70, 0.025, 52, 17, 2.1, p, clipped=2).words()


@pytest.mark.parametrize("written", ["%d.%m.%Y %H:%M", "%m/%d/%Y %I:%M %p", "%H:%M:%S"])
def test_dates_written_otherwise_than_iso_are_refused_not_read_as_a_group_per_row(written):
    # before: '28.11.2026 08:07' (German Excel), '11/28/2026 08:07 AM' (US) or a time of day became a factor
    # of as many groups as rows: replicates, pure error and drift vanished without a word
    start = datetime(2026, 11, 28, 8, 7)
    rows = [{"load_N": 0.01 * (1 + k % 3), "speed_m_s": 0.05, "mu_measured": 0.01,
             "Datum": (start + timedelta(minutes=7 * k)).strftime(written)} for k in range(12)]
    with pytest.raises(DataError) as refused:
        parse_rows(rows, fixed={"balls": 4})
    (error,) = refused.value.errors
    assert error["column"] == "Datum" and "ISO 8601" in error["message"] and "factor" in error["message"]
    assert rows[0]["Datum"] in error["message"]
    # declared a factor, they are group labels as asked; in ISO 8601, hours since the first
    assert list(parse_rows(rows, fixed={"balls": 4}, factors=["Datum"]).factors) == ["Datum"]
    iso = [{**row, "Datum": (start + timedelta(minutes=7 * k)).isoformat()} for k, row in enumerate(rows)]
    assert parse_rows(iso, fixed={"balls": 4}).conditions["Datum"][-1] == pytest.approx(77 / 60)


def test_a_unit_slip_in_part_of_the_rows_is_said_and_left_out_through_the_api(client):
    # before: 12 of 120 loads written in N in a load_mN column were read as loads of 3-30 uN; no word of
    # it, a Gaussian-process discrepancy absorbed them, the scatter came out 14-20 % for a true 3 % and
    # fresh measurements at the lowest loads were covered 0.76-0.88 (/work/exp76/h46/probe.py b_load)
    rng = np.random.default_rng(461)
    n = 120
    load = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n))
    speed = rng.uniform(0.01, 0.15, n)
    mu = truth(load, speed) * np.exp(rng.normal(0.0, NOISE, n))
    slipped = np.sort(rng.choice(n, 12, replace=False))
    sent = load * 1e3
    sent[slipped] = load[slipped]  # written in N
    report = calibrated(client, as_rows({"load_mN": sent, "speed_m_s": speed}, mu), folds_=5)
    (slip,) = report["measurement_system"]["unit_slips"]
    assert slip["column"] == "load_mN" and slip["factor"] == 1000 and slip["below"]
    assert slip["rows"] == [int(r) + 1 for r in slipped]
    assert any("a unit slip" in line for line in report["measurement_system"]["summary"])
    assert report["effects"] == [] and report["n_points"] == n - 12
    assert report["model"]["noise_std_log"] < 0.04
    points = {"load_N": np.exp(rng.uniform(np.log(3e-3), np.log(4e-3), 400)),
              "speed_m_s": rng.uniform(0.01, 0.15, 400)}
    error, covered = coverage(report, points, truth(**points), rng)
    assert error < 0.5 * NOISE and 0.9 <= covered <= 0.98


def test_unit_slips_need_a_unit_s_factor_an_empty_gap_and_a_minority():
    # rows spread over 4 decades without a gap, a uniform draw from 0, 30 % of rows 1000x off (no
    # minority), 5 rows 37x off (no unit's factor): none is a slip; 5 rows of percent among fractions are
    rng = np.random.default_rng(462)
    n = 100
    base = {"load_N": np.exp(rng.uniform(np.log(1e-5), np.log(1e-1), n)),
            "speed_m_s": rng.uniform(0, 0.15, n), "vibration_um": rng.uniform(0.0, 10.0, n)}
    far = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n))
    share = far.copy()
    share[:30] /= 1000
    odd = far.copy()
    odd[:5] /= 37
    rh = rng.uniform(0.2, 0.8, n)
    rh[[3, 50, 60, 70, 99]] *= 100
    for column, values, expected in (("load_N", base["load_N"], None), ("load_N", share, None),
                                     ("load_N", odd, None), ("relative_humidity", rh, (100.0, False))):
        rows = as_rows({**base, column: values}, np.full(n, 0.01) * (1 + 0.01 * rng.random(n)))
        slips = unit_slips(parse_rows(rows, fixed={"balls": BALLS}))
        assert [(s.factor, s.below) for s in slips] == ([] if expected is None else [expected]), column
    assert slips[0].rows == (3, 50, 60, 70, 99)


def test_a_load_design_of_two_levels_a_hundredfold_apart_is_no_unit_slip():
    # before: 12 of 60 loads at 0.1-0.3 N beside 1-3 mN (a design of two load levels; 100x is no factor
    # between load units) were called a percent slip and left out of the fit; a 1000x minority still is
    rng = np.random.default_rng(466)
    n = 60
    load = np.exp(rng.uniform(np.log(1e-3), np.log(3e-3), n))
    heavy = load.copy()
    heavy[:12] *= 100
    slipped = load.copy()
    slipped[:12] *= 1000
    for values, expected in ((heavy, []), (slipped, [(1000.0, False)])):
        rows = as_rows({"load_N": values, "speed_m_s": np.full(n, 0.05)},
                       np.full(n, 0.01) * (1 + 0.01 * rng.random(n)))
        slips = unit_slips(parse_rows(rows, fixed={"balls": BALLS}))
        assert [(s.factor, s.below) for s in slips] == expected


def test_humidity_in_percent_on_some_rows_is_refused_at_the_first_of_them_converting_those_only(client):
    # before: 15 of 150 humidities in percent among fractions were refused at row 1 with the advice for a
    # whole column ("give fractions (divide by 100)"), which would have made the other 135 rows 0.002-0.008
    rng = np.random.default_rng(465)
    n = 150
    rh = rng.uniform(0.2, 0.8, n)
    slipped = np.sort(rng.choice(n, 15, replace=False))
    rh[slipped] *= 100
    load = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n))
    rows = as_rows({"load_N": load, "speed_m_s": np.full(n, 0.05), "relative_humidity": rh},
                   truth(load, 0.05) * np.exp(rng.normal(0.0, NOISE, n)))
    response = client.post("/v1/calibrations", json={"data": rows, "fit_parameters": ["mu_pivot"],
                                                     "fixed": {"balls": BALLS}})
    assert response.status_code == 422
    (error,) = [e for e in response.json()["errors"] if "relative_humidity" in e["pointer"]]
    assert error["pointer"] == f"/data/{slipped[0]}/relative_humidity"
    assert "15 of 150 values lie above 1: those look like percent" in error["detail"]
    assert "convert those rows only" in error["detail"] and "divide by 100" not in error["detail"]


def test_a_unit_slip_and_an_iso_clock_keep_the_certified_robust_design(client):
    # This release's parts together (/work/exp76/h51/probe.py): 12 of 120 loads written in N in a load_mN
    # column (left out, the header kept with the model) and an instrument's drift on ISO times (the clock
    # kept). A part optimize's bounds do not know refuses the certificate ("its headers has no bound over a
    # box here" an hour before this test); here the design is certified, the worst case at the bearing.
    rng = np.random.default_rng(462)
    rows = session_rows(rng, 120, 0.08, clock=True)
    for k in rng.choice(120, 12, replace=False):
        rows[k]["load_N"] /= 1e3
    rows = [{"load_mN": row.pop("load_N") * 1e3, **row} for row in rows]
    report = calibrated(client, rows, folds_=5)
    assert [s["column"] for s in report["measurement_system"]["unit_slips"]] == ["load_mN"]
    assert report["model"]["headers"] == {"load_N": "load_mN"} and report["model"]["clock"]
    job = client.post("/v1/optimizations", json={
        "model": report["model_id"], "objective": "mu_upper", "speed [mm/s]": [10, 100],
        "bounds": {"balls": [4, 8], "groove_angle_deg": [45.5, 59.5], "load_N": [0.0044, 0.0132]}})
    assert job.status_code == 202, job.text
    result = client.get(finished_job(client, job, timeout_s=300, interval_s=0.2)["result_url"]).json()
    proof = result["proof"]
    assert proof["method"] == "outer-approximation-certified" and proof["proven"], proof["statement"]
    assert proof["relative_gap"] <= proof["gap_target"]
    assert result["worst_case"]["conditions"] == {"date": 0.0}
