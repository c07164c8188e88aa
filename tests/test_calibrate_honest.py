"""Issue 24, items 4-8: honest answers off the data, unit slips, drifts with their level, undecided data,
and a GP discrepancy that joins only when it helps a correct model.

The data are drawn here from the physics with hidden mechanisms written independently of
physics.effects; every figure is compared with the generating truth, a hand calculation or fresh draws.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from folds_helper import two_folds_miss_the_term
from jobs_helper import finished_job

from microbearing import physics
from microbearing.calibrate import CalibratedModel, DataError, calibrate, parse_rows
from microbearing.calibrate.plausibility import check_plausible, plausibility_findings
from microbearing.calibrate.search import bump_factor

PROBLEM = "application/problem+json"


def lab_rows(n: int, seed: int, **columns) -> list[dict]:
    """Rows of a plain physics data set (mu_pivot 0.7, 2 % noise) with extra columns overriding."""
    rng = np.random.default_rng(seed)
    c = {"balls": rng.choice([4, 8], n).astype(float),
         "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
         "speed_m_s": rng.uniform(0.005, 0.15, n)}
    mu = physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"], mu_pivot=0.7).mu
    mu = mu * np.exp(rng.normal(0.0, 0.02, n))
    c.update({k: np.asarray(v, dtype=float) for k, v in columns.items()})
    return [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(n)]


# --- item 5: implausible values and unit slips --------------------------------------------------------

@pytest.mark.parametrize(("column", "scale", "words"), [
    ("speed_m_s", 1000.0, "values look like mm/s"),
    ("load_N", 1000.0, "values look like mN"),
])
def test_a_physics_column_in_milli_units_is_refused_naming_column_and_cause(column, scale, words):
    rows = lab_rows(30, 1)
    for row in rows:
        row[column] *= scale
    with pytest.raises(DataError) as caught:
        calibrate(rows, ["mu_pivot"], make_plots=False)
    (error,) = caught.value.errors
    assert error["column"] == column and words in error["message"]
    # the range quoted is the data's own, and the suggested SI range is it times 1e-3 (hand check)
    values = np.array([r[column] for r in rows])
    assert f"{values.min():.4g} to {values.max():.4g}" in error["message"]
    assert f"{values.min() / scale:.4g} to {values.max() / scale:.4g}" in error["message"]


@pytest.mark.parametrize(("name", "values", "severity", "words"), [
    ("relative_humidity", np.linspace(20.0, 80.0, 30), "error", "look like percent"),
    ("relative_humidity_pct", np.linspace(20.0, 80.0, 30), None, ""),
    ("relative_humidity_pct", np.linspace(0.2, 180.0, 30), "error", "[0, 100]"),
    ("relative_humidity", np.linspace(0.2, 0.8, 30), None, ""),
    ("temperature_C", np.linspace(293.0, 313.0, 30), "error", "look like kelvin"),
    ("temperature_K", np.linspace(20.0, 40.0, 30), "error", "look like degC"),
    ("temperature_K", np.linspace(293.0, 313.0, 30), None, ""),
    ("temperature_C", np.linspace(-300.0, 20.0, 30), "error", "absolute zero"),
])
def test_condition_columns_are_judged_by_their_names_unit(name, values, severity, words):
    found = plausibility_findings(parse_rows(lab_rows(30, 2, **{name: values})))
    if severity is None:
        assert found == []
    else:
        (finding,) = found
        assert (finding.column, finding.severity) == (name, severity) and words in finding.message


def test_friction_above_one_is_a_warning_in_the_report_not_a_refusal():
    rows = lab_rows(30, 3)
    rows[0]["mu_measured"] = 1.5
    assert [w.split(" ")[0] for w in check_plausible(parse_rows(rows))] == ["mu_measured"]


def test_plausible_lab_data_pass_silently():
    assert plausibility_findings(parse_rows(lab_rows(40, 4, relative_humidity=np.full(40, 0.4)))) == []


def test_the_sensitivity_step_stays_inside_a_parameters_range():
    # mu_pivot's range is [0, 10]: on its top bound a step up would leave it, so the step goes down
    assert bump_factor("mu_pivot", np.array(10.0)) < 1.0
    assert bump_factor("mu_pivot", np.array(0.7)) > 1.0
    assert 10.0 * bump_factor("mu_pivot", np.array(10.0)) <= physics.PARAMETERS["mu_pivot"].maximum


def test_a_fitted_parameter_on_its_bound_is_reported_there_not_a_crash():
    # mu four times what mu_pivot = 10 gives: the fit runs into mu_pivot's top bound, 10
    rng = np.random.default_rng(5)
    n = 40
    c = {"balls": rng.choice([4, 8], n).astype(float), "load_N": np.exp(rng.uniform(-6, -3.5, n)),
         "speed_m_s": rng.uniform(0.005, 0.15, n)}
    mu = 4 * physics.evaluate(**c, mu_pivot=10.0).mu * np.exp(rng.normal(0, 0.02, n))
    rows = [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(n)]
    result = calibrate(rows, ["mu_pivot"], make_plots=False, max_terms=1)
    assert result.fitted_declared["mu_pivot"]["value"] == pytest.approx(10.0, rel=1e-6)
    assert any(w.startswith("mu_pivot ended on a bound") for w in result.warnings), result.warnings


def test_a_unit_slip_is_a_422_naming_the_column_through_json_and_csv(client):
    rows = lab_rows(30, 6)
    for row in rows:
        row["speed_m_s"] *= 1000.0
    response = client.post("/v1/calibrations", json={"data": rows, "fit_parameters": ["mu_pivot"]})
    assert response.status_code == 422 and response.headers["content-type"] == PROBLEM
    (error,) = response.json()["errors"]
    # the field: the column's key in the first row (a JSON pointer names a key, not a column)
    assert error["pointer"] == "/data/0/speed_m_s"
    assert error["detail"].startswith("column speed_m_s: speed_m_s runs")
    assert "values look like mm/s" in error["detail"]
    text = "\n".join([",".join(rows[0]), *(",".join(f"{v:.9g}" for v in r.values()) for r in rows)]) + "\n"
    response = client.post("/v1/calibrations/csv", content=text, headers={"content-type": "text/csv"})
    assert response.status_code == 422 and response.headers["content-type"] == PROBLEM
    (error,) = response.json()["errors"]
    assert error["pointer"] == "/body" and "values look like mm/s" in error["detail"]


# --- item 4: rival laws off the data ------------------------------------------------------------------

def kelvin_adhesion(h):
    """Adhesion energy [J/m^2] growing with the Kelvin radius, 1/ln(1/h)."""
    return 0.05 * (1 + 1.5 / np.log(1 / h))


def humidity_rows(seed: int, n: int = 200, rh=(0.2, 0.5), fresh_rh: float | None = None):
    """Rows with adhesion drifting with humidity by the Kelvin law (3 % noise), the columns of every lab
    data set, and ``fresh_rh``: 400 fresh measurements at that humidity (columns, measured mu)."""
    rng = np.random.default_rng(seed)
    m = n + 400
    c = {"balls": rng.choice([4, 6, 8, 12], m).astype(float),
         "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), m)),
         "speed_m_s": rng.uniform(0.0, 0.15, m),
         "relative_humidity": np.concatenate([rng.uniform(*rh, n), np.full(400, fresh_rh or rh[0])]),
         "temperature_C": rng.uniform(20.0, 40.0, m)}
    mu = physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"], mu_pivot=0.7,
                          adhesion_energy_J_m2=kelvin_adhesion(c["relative_humidity"])).mu
    mu = mu * np.exp(rng.normal(0.0, 0.03, m))
    rows = [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(n)]
    return rows, {k: v[n:] for k, v in c.items()}, mu[n:]


def covered(prediction, measured) -> float:
    return float(np.mean((prediction.mu_lower <= measured) & (measured <= prediction.mu_upper)))


@pytest.fixture(scope="module")
def kelvin_result(client):
    # seed 0: the linear law is named (it asks less of its parameter), the Kelvin law within 2 SE
    rows, _, _ = humidity_rows(0)
    response = client.post("/v1/calibrations", json={"data": rows, "fit_parameters": ["mu_pivot",
                                                                                      "adhesion_energy_J_m2"]})
    assert response.status_code == 202, response.text
    location = response.headers["location"]
    job = finished_job(client, location, timeout_s=300, interval_s=0.2)
    return client.get(job["result_url"]).json()


def test_rival_laws_hold_their_disagreement_at_80_rh_and_leave_the_data_alone(kelvin_result):
    assert [e["label"] for e in kelvin_result["effects"]] == [
        "adhesion_energy_J_m2 drifts with relative_humidity (linear)"]
    (rival,) = kelvin_result["rivals"]
    assert rival["label"].startswith("adhesion_energy_J_m2 drifts with relative_humidity (kelvin) instead")
    assert rival["gap_se"] <= 2.0
    # where they part: above the data's 50 % RH (the scan reaches 80 %), not inside it
    (part,) = rival["where"]
    assert any(lo > 0.5 and hi >= 0.79 for lo, hi in part["differ"]), part
    assert not any(lo < 0.45 < hi for lo, hi in part["differ"]), part
    # the same rival is listed among what the data cannot decide
    assert [u["terms"] for u in kelvin_result["undecided"] if u["kind"] == "rivals"] == [[rival["label"]]]
    model = CalibratedModel.from_json(kelvin_result["model"])
    alone = dataclasses.replace(model, rivals=[])
    _, fresh, measured = humidity_rows(0, fresh_rh=0.8)
    # the truth (Kelvin) at 80 % RH: the named law alone misses it, the envelope covers it
    assert covered(alone.predict(fresh), measured) < 0.5
    assert covered(model.predict(fresh), measured) >= 0.9
    # inside the data (fresh draws at 20-50 % RH) coverage stays 90-98 % and the width within 10 %
    rows, _, _ = humidity_rows(77)
    inside = {k: np.array([r[k] for r in rows]) for k in fresh}
    measured_inside = np.array([r["mu_measured"] for r in rows])
    with_rivals, without = model.predict(inside), alone.predict(inside)
    assert 0.9 <= covered(with_rivals, measured_inside) <= 0.98
    ratio = np.log(with_rivals.mu_upper / with_rivals.mu_lower) / np.log(without.mu_upper / without.mu_lower)
    assert 1.0 <= float(np.median(ratio)) < 1.1


def test_friction_and_batch_answer_the_envelope_of_the_stored_rivals(client, kelvin_result):
    model = CalibratedModel.from_json(kelvin_result["model"])
    point = {"balls": 8, "load_N": 0.01, "speed_m_s": 0.05}
    conditions = {"relative_humidity": 0.8, "temperature_C": 30.0}
    expected = model.predict({**point, **conditions})
    answer = client.post("/v1/friction", json={**point, "model": kelvin_result["model_id"],
                                               "conditions": conditions})
    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert body["mu_lower"] == pytest.approx(float(expected.mu_lower), rel=1e-9)
    assert body["mu_upper"] == pytest.approx(float(expected.mu_upper), rel=1e-9)
    assert body["in_domain"] is False
    humidity = [0.3, 0.8]
    batch = client.post("/v1/friction/batch", json={"points": {**point, "speed_m_s": [0.05, 0.05]},
                                                     "model": kelvin_result["model_id"], "outputs": ["mu"],
                                                     "conditions": {"relative_humidity": humidity,
                                                                    "temperature_C": 30.0}})
    assert batch.status_code == 200, batch.text
    both = model.predict({**point, "relative_humidity": np.array(humidity), "temperature_C": 30.0})
    np.testing.assert_allclose(batch.json()["mu_upper"], both.mu_upper, rtol=1e-9)
    np.testing.assert_allclose(batch.json()["mu_lower"], both.mu_lower, rtol=1e-9)


# --- item 8: a GP joins only when it helps the chosen model held out ---------------------------------

def meniscus_rows(seed: int, n: int):
    """Menisci growing with humidity on top of the physics (2 % noise), and the columns."""
    rng = np.random.default_rng(seed)
    c = {"balls": rng.choice([4, 8], n).astype(float),
         "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
         "speed_m_s": rng.uniform(0.0, 0.15, n), "relative_humidity": rng.uniform(0.2, 0.8, n),
         "vibration_um": rng.uniform(0.0, 10.0, n)}
    mu = physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"], mu_pivot=0.7).mu
    mu = (mu + c["balls"] * 2e-5 / (c["load_N"] * np.log(1 / c["relative_humidity"]))) * np.exp(
        rng.normal(0.0, 0.02, n))
    return [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(n)], c, mu


def test_a_gp_that_only_fills_what_some_folds_missed_does_not_join_a_correct_model(monkeypatch):
    from microbearing.calibrate import report

    # As when the selection in two outer folds adds nothing: those folds' rows are predicted by the
    # declared model, whose residual (the menisci) a GP takes up.
    missing = two_folds_miss_the_term(report.nested_cross_validate)
    monkeypatch.setattr(report, "nested_cross_validate", missing)
    rows, _, _ = meniscus_rows(3, 150)
    result = calibrate(rows, ["mu_pivot"], folds=3, max_terms=1, make_plots=False)
    assert [e["name"] for e in result.effects] == ["humidity_meniscus"]
    gp = result.discrepancy_gp
    # the nested test alone would have let it in; on the chosen term's own folds it does not help
    assert gp["calibrated_z"] > 2.33 and gp["chosen_terms_z"] < 2.33 and not gp["in_model"], gp
    assert result.model.discrepancy is None
    fresh_rows, fresh, _ = meniscus_rows(99, 400)
    measured = np.array([r["mu_measured"] for r in fresh_rows])
    prediction = result.model.predict(fresh)
    # the model's mean is the chosen term's alone, at the noise floor on fresh draws (2 %)
    assert float(np.sqrt(np.mean(np.log(prediction.mu / measured) ** 2))) < 1.2 * 0.02
    # (its intervals, from the nested held-out scatter, are wide here: the two folds that missed the term
    # inflate it; the GP's white noise would have hidden that)
    assert covered(prediction, measured) >= 0.9


# --- item 6: a drift with its level --------------------------------------------------------------------

GAS_CONSTANT = 8.314462618


def viscous_rows(seed: int, n: int, activation_J_mol: float = 26e3, level_Pa_s: float = 1e-2):
    """A water film ten times as viscous as the default, thinning with temperature (Arrhenius, reference
    40 degC), 2 % noise; only mu_pivot (0.7) is declared."""
    rng = np.random.default_rng(seed)
    c = {"balls": rng.choice([4, 6, 8, 12], n).astype(float),
         "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
         "speed_m_s": rng.uniform(0.0, 0.15, n), "temperature_C": rng.uniform(20.0, 60.0, n),
         "relative_humidity": rng.uniform(0.2, 0.8, n)}
    kelvin = c["temperature_C"] + 273.15
    eta = level_Pa_s * np.exp(activation_J_mol / GAS_CONSTANT * (1 / kelvin - 1 / 313.15))
    mu = physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"], mu_pivot=0.7,
                          viscosity_Pa_s=eta).mu * np.exp(rng.normal(0.0, 0.02, n))
    return [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(n)]


def test_a_viscosity_drift_fits_its_level_and_the_activation_energy_comes_out_near_truth():
    rows = viscous_rows(0, 150)
    result = calibrate(rows, ["mu_pivot"], folds=4, make_plots=False)
    (drift,) = result.effects  # no spurious second term
    assert drift["label"] == "viscosity_Pa_s drifts with temperature_C (arrhenius)" and drift["level_fitted"]
    values, std = drift["parameters"], drift["parameter_std"]
    # the level at the data's median temperature, against the truth there (hand: 1e-2 exp(E/R (1/T - 1/T40)))
    t_ref = drift["constants"]["reference"]
    level = 1e-2 * np.exp(26e3 / GAS_CONSTANT * (1 / t_ref - 1 / 313.15))
    assert values["viscosity_Pa_s_ref"] == pytest.approx(level, rel=0.1)
    assert abs(values["viscosity_Pa_s_ref"] - level) < 3 * std["viscosity_Pa_s_ref"] + 0.02 * level
    assert values["activation_energy_J_mol"] == pytest.approx(26e3, rel=0.15)
    assert abs(values["activation_energy_J_mol"] - 26e3) < 3 * std["activation_energy_J_mol"] + 1e3
    assert result.fitted_parameters["mu_pivot"]["value"] == pytest.approx(0.7, rel=0.03)
    assert drift["parameter_units"]["viscosity_Pa_s_ref"] == "Pa*s"
    # the stored model predicts like the physics with the fitted level and law (hand check at one point)
    model = CalibratedModel.from_json(result.model.to_json())
    point = {"balls": 8, "load_N": 0.01, "speed_m_s": 0.1, "temperature_C": 55.0, "relative_humidity": 0.5}
    eta = values["viscosity_Pa_s_ref"] * np.exp(values["activation_energy_J_mol"] / GAS_CONSTANT
                                                * (1 / 328.15 - 1 / t_ref))
    expected = physics.evaluate(balls=8, load_N=0.01, speed_m_s=0.1, viscosity_Pa_s=eta,
                                mu_pivot=result.fitted_parameters["mu_pivot"]["value"]).mu
    assert float(model(point)) == pytest.approx(float(expected), rel=1e-9)


def test_a_level_drift_screened_to_first_order_matches_the_physics():
    from microbearing.calibrate.candidates import DriftTerm, FrozenBase, mu_of, term_from_json

    term = DriftTerm("viscosity_Pa_s", "linear", "run", {"reference": 1.0, "minimum": 0.0, "maximum": 2.0},
                     level=True)
    assert term.parameter_names == ["slope", "viscosity_Pa_s_ref"]
    assert term_from_json(term.to_json([0.1, 2e-3])) == (term, [0.1, 2e-3])
    inputs = {"balls": 4.0, "load_N": 0.01, "speed_m_s": np.array([0.05, 0.1])}
    conditions = {"run": np.array([0.5, 1.5])}
    mu0 = physics.evaluate(**inputs).mu
    step = 1e-6
    s = np.log(physics.evaluate(**inputs, viscosity_Pa_s=1e-3 * (1 + step)).mu / mu0) / np.log1p(step)
    base = FrozenBase(mu0, {"viscosity_Pa_s": s})
    values = [[0.02, 1.01e-3]]  # a small change: first order holds
    exact = mu_of(inputs, conditions, [term], values)
    hand = physics.evaluate(**inputs, viscosity_Pa_s=1.01e-3 * (1 + 0.02 * (conditions["run"] - 1.0))).mu
    np.testing.assert_allclose(exact, hand, rtol=1e-12)
    np.testing.assert_allclose(mu_of(inputs, conditions, [term], values, base=base), exact, rtol=1e-3)


# --- item 7: what the data cannot decide ---------------------------------------------------------------

def run_in_rows(seed: int, n: int):
    """Friction twice as high at the start, decaying over 800 cycles (2 % noise), with the usual columns."""
    rng = np.random.default_rng(seed)
    c = {"balls": rng.choice([4, 6, 8, 12], n).astype(float),
         "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
         "speed_m_s": rng.uniform(0.0, 0.15, n), "temperature_C": rng.uniform(20.0, 40.0, n),
         "cycle": rng.integers(0, 5000, n).astype(float)}
    mu = physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"], mu_pivot=0.7).mu
    mu = mu * (1 + np.exp(-c["cycle"] / 800)) * np.exp(rng.normal(0.0, 0.02, n))
    return [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(n)]


def test_a_run_in_too_few_rows_can_show_is_said_with_where_more_rows_would_settle_it():
    # 24 rows: the run-in lowers the score but its paired z (~2.3-3.2) cannot reach the ~3.6 needed
    result = calibrate(run_in_rows(1, 24), ["mu_pivot"], make_plots=False)
    assert result.effects == []
    (item,) = [u for u in result.undecided if u["kind"] == "near_threshold"]
    assert item["terms"] == ["run_in on cycle"]
    assert 2.0 <= item["z"] < item["z_needed"]
    # z grows as sqrt(n): n (z_needed / z)^2 rows (hand calculation from the item's own figures)
    assert item["rows_to_settle"] == int(np.ceil(24 * (item["z_needed"] / item["z"]) ** 2)) > 24
    # where: the first cycles, where the true run-in (1/e over 800 cycles) acts, not the whole test
    _, hi = item["where"]["range"]
    assert item["where"]["driver"] == "cycle" and hi < 1200 and hi < item["where"]["data_range"][1] / 3
    assert "cannot decide on run_in on cycle" in item["statement"] and "rows" in item["statement"]
    assert any(line.startswith("undecided: the data cannot decide") for line in result.text().splitlines())


def test_clean_data_leave_nothing_undecided():
    rows = lab_rows(120, 11, temperature_C=np.random.default_rng(11).uniform(20.0, 40.0, 120))
    result = calibrate(rows, ["mu_pivot"], make_plots=False)
    assert result.effects == [] and result.undecided == [] and result.rivals == []


def test_an_optimization_with_a_calibrated_model_answers_the_rivals_envelope(client):
    from microbearing.calibrate.candidates import EffectTerm
    from microbearing.calibrate.model import RivalModel
    from microbearing.service.deps import get_runtime

    meniscus = EffectTerm("humidity_meniscus", ("relative_humidity",))
    # a rival that puts twice the meniscus force on the same data (hand-made: its own covariance)
    rival = RivalModel("humidity_meniscus twice", {"mu_pivot": 0.55}, [(meniscus, [4e-5])],
                       np.diag([1e-4, 1e-12]), 1.5)
    model = CalibratedModel(fitted={"mu_pivot": 0.6}, terms=[(meniscus, [2e-5])],
                            covariance=np.diag([1e-4, 1e-12]), noise_std_log=0.02,
                            domain={"load_N": [0.001, 0.05], "relative_humidity": [0.2, 0.8]},
                            conditions=["relative_humidity"], rivals=[rival])
    assert CalibratedModel.from_json(model.to_json()).rivals[0].to_json() == rival.to_json()
    model_id = get_runtime(client.app).store.save_model("calibration", {"model": model.to_json()}, {})
    request = {"bounds": {"balls": [4, 8], "groove_angle_deg": [40, 60], "load_N": [0.001, 0.05]},
               "speed_m_s": 0.05, "model": f"calibrated:{model_id}", "conditions": {"relative_humidity": 0.5},
               "starts": 1}
    response = client.post("/v1/optimizations", json=request)
    assert response.status_code == 202, response.text
    job = finished_job(client, response.headers["location"], timeout_s=300, interval_s=0.2)
    result = client.get(job["result_url"]).json()
    point = {**result["design"], "speed_m_s": 0.05, "relative_humidity": 0.5}
    # the design as the service passes it carries the model's fitted mu_pivot: the rival keeps its own
    assert model.predict({**point, "mu_pivot": 0.6}).mu_upper == pytest.approx(model.predict(point).mu_upper)
    expected = model.predict(point)
    alone = dataclasses.replace(model, rivals=[]).predict(point)
    rival_alone = model.rival_models()[0].predict(point)
    assert result["mu_upper"] == pytest.approx(float(expected.mu_upper), rel=1e-9)
    assert result["mu_lower"] == pytest.approx(float(expected.mu_lower), rel=1e-9)
    # the envelope by hand: the wider of the model's own interval and the rival's
    envelope = (min(float(alone.mu_lower), float(rival_alone.mu_lower)),
                max(float(alone.mu_upper), float(rival_alone.mu_upper)))
    assert (result["mu_lower"], result["mu_upper"]) == pytest.approx(envelope, rel=1e-9)
    assert float(rival_alone.mu_upper) > float(alone.mu_upper)  # the rival's larger meniscus widens it


def test_a_rival_that_cannot_predict_a_point_is_said_not_dropped_silently():
    # before: at time 0 a power-law rival (x > 0 only) left the envelope without a word, so the interval
    # at 0 was as narrow as inside the data while 1e-12 later the rival made it 35 times wider
    from microbearing.calibrate.candidates import EffectTerm
    from microbearing.calibrate.model import RivalModel

    run_in = EffectTerm("run_in", ("time_s",))
    power = EffectTerm("generic_power", ("time_s",), {"reference": 1800.0})
    rival = RivalModel("generic_power on time_s instead of run_in on time_s", {"mu_pivot": 0.6},
                       [(power, [-0.2])], np.diag([1e-4, 1e-4]), 1.5)
    model = CalibratedModel(fitted={"mu_pivot": 0.6}, terms=[(run_in, [0.3, 600.0])],
                            covariance=np.diag([1e-4, 1e-4, 1e2]), noise_std_log=0.02,
                            domain={"time_s": [900.0, 7200.0]}, conditions=["time_s"], rivals=[rival])
    point = {"balls": 6, "load_N": 0.01, "speed_m_s": 0.05}
    both = model.predict({**point, "time_s": np.array([0.0, 1800.0])})
    said = [w for w in both.warnings if "the rival generic_power" in w]
    assert said and "cannot predict" in said[0] and "other rivals only" in said[0], both.warnings
    alone = dataclasses.replace(model, rivals=[]).predict({**point, "time_s": np.array([0.0, 1800.0])})
    assert both.mu_upper[0] == alone.mu_upper[0]  # at 0 the model's own interval, said
    assert both.mu_upper[1] >= alone.mu_upper[1]
    inside = model.predict({**point, "time_s": np.array([1800.0])})
    assert not [w for w in inside.warnings if "cannot predict" in w]  # where the rival holds, no word
