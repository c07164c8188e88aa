"""Trust in a calibration's numbers (issue 33 items 4, 5, 6, 9): few rows, heavy tails, mechanisms, groups.

One representative seed each; bench/calibration_trust.py runs several through the API and prints the
figures. The data are the physics with mu_pivot 0.65 and 3 % scatter, generated here.
"""

from __future__ import annotations

import numpy as np
import pytest
from jobs_helper import finished_job
from scipy import stats

from microbearing import physics
from microbearing.calibrate import CalibratedModel, calibrate, parse_rows
from microbearing.calibrate.candidates import DriftTerm, EffectTerm
from microbearing.calibrate.credibility import REACH, implausible
from microbearing.calibrate.fit import fit
from microbearing.calibrate.groups import within_groups
from microbearing.calibrate.scatter import allowance
from microbearing.calibrate.tails import tail_form
from microbearing.calibrate.uncertainty import outlier_threshold, parameter_warnings
from microbearing.physics.effects import PARAMETER_SHARES

MU_PIVOT = 0.65
NOISE = 0.03


def lab(rng: np.random.Generator, n: int, humidity: bool = True) -> dict[str, np.ndarray]:
    c = {"balls": rng.choice([4.0, 6.0, 8.0], n),
         "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
         "speed_m_s": rng.uniform(0.005, 0.15, n)}
    return {**c, "relative_humidity": rng.uniform(0.2, 0.6, n)} if humidity else c


def mu_of(c, **values) -> np.ndarray:
    return physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"],
                            **{"mu_pivot": MU_PIVOT, **values}).mu


def rows_of(c, measured) -> list[dict]:
    return [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(measured[i])}
            for i in range(measured.size)]


def calibrated(client, body: dict) -> dict:
    response = client.post("/v1/calibrations", json=body)
    assert response.status_code == 202, response.text
    job = finished_job(client, response.headers["location"], timeout_s=300, interval_s=0.1)
    return client.get(job["result_url"]).json()


def coverage(result: dict, points, measured) -> float:
    p = CalibratedModel.from_json(result["model"]).predict(points)
    return float(np.mean((p.mu_lower <= measured) & (measured <= p.mu_upper)))


# Item 5: small data.

def test_ten_rows_are_answered_with_an_allowance_and_no_effect_claimed(client):
    rng = np.random.default_rng(3)
    n = 10
    c = lab(rng, n + 400, humidity=False)
    measured = mu_of(c) * np.exp(rng.normal(0.0, NOISE, n + 400))
    result = calibrated(client, {"data": rows_of({k: v[:n] for k, v in c.items()}, measured[:n]),
                                 "fit_parameters": ["mu_pivot"], "folds": 4})
    assert result["effects"] == []
    few = [u for u in result["undecided"] if u["kind"] == "few_rows"]
    assert len(few) == 1 and "cannot decide" in few[0]["statement"]
    # Nested 4-fold CV keeps 10 x (3/4)^2 = 5.6 rows for an inner fit, two more than its fitted values:
    # mu_pivot and one two-parameter term (3 + 2 = 5) fit; a second term needs 7 / 0.5625 = 12.4 rows.
    assert "at most 1 term could be weighed" in few[0]["statement"]
    assert few[0]["rows_to_settle"] == 13
    form = result["model"]["scatter"]["form"]
    assert form["dof"] == n - 1  # ten held-out residuals, one fitted value
    # One spread everywhere takes the prediction rule at its 9 degrees of freedom: Student's t over the
    # normal quantile (2.262 / 1.960); a spread that varies would take the wider tolerance rule there.
    model = CalibratedModel.from_json(result["model"])
    factor = model.interval_noise_std_log() / model.noise_std_log
    assert factor == pytest.approx(2.2621572 / 1.9599640, rel=1e-7)
    assert float(allowance(9)) > factor
    cover = coverage(result, {k: v[n:] for k, v in c.items()}, measured[n:])
    assert 0.9 <= cover <= 1.0


@pytest.mark.parametrize("n", [8, 12])
def test_few_rows_cover_within_the_band_over_data_sets(n):
    """Eight data sets of n rows, nothing to find (seeds 300-307, apart from the bench's): the 95 %
    intervals cover 0.90-0.98 of 400 fresh measurements pooled over the data sets. The spread of 8-12
    rows is known to a factor of about two, so single data sets scatter widely around that (the least
    above 0.75 here); a tolerance rule on top of Student's t (an upper confidence bound of the spread)
    covered 0.986 and 0.990 on 8 and 12 rows (bench/calibration_trust.py, 12 seeds). One spread everywhere
    takes Student's t alone."""
    covered = []
    for seed in range(300, 308):
        rng = np.random.default_rng(seed)
        c = lab(rng, n + 400, humidity=False)
        measured = mu_of(c) * np.exp(rng.normal(0.0, NOISE, n + 400))
        report = calibrate(rows_of({k: v[:n] for k, v in c.items()}, measured[:n]), ["mu_pivot"],
                           folds=min(5, n // 2), make_plots=False)
        p = report.model.predict({k: v[n:] for k, v in c.items()})
        covered.append(float(np.mean((p.mu_lower <= measured[n:]) & (measured[n:] <= p.mu_upper))))
    assert 0.90 <= np.mean(covered) <= 0.98, covered
    assert min(covered) > 0.75, covered

def test_outliers_on_few_rows_need_a_wider_threshold():
    # The robust scale of 15 rows is known like a standard deviation of about 5 degrees of freedom.
    assert outlier_threshold(15) > 5.0 > stats.norm.isf(0.05 / 30)
    # Gaussian rows: how often a row of 15 is flagged against its own median absolute deviation.
    rng = np.random.default_rng(0)
    r = rng.normal(0.0, 1.0, (4000, 15))
    mad = 1.4826 * np.median(np.abs(r - np.median(r, axis=1, keepdims=True)), axis=1, keepdims=True)
    flagged = np.any(np.abs(r - np.median(r, axis=1, keepdims=True)) > outlier_threshold(15) * mad, axis=1)
    assert flagged.mean() < 0.06


# Item 9: heavy tails.

def test_student_t_residuals_get_the_t_form_and_gaussian_ones_keep_theirs():
    rng = np.random.default_rng(7)
    heavy = NOISE * rng.standard_t(3, 300)
    # What the calibration's Gaussian interval sees: the RMS of the rows inside the outlier threshold.
    robust = 1.4826 * np.median(np.abs(heavy - np.median(heavy)))
    rms = float(np.sqrt(np.mean(heavy[np.abs(heavy) <= outlier_threshold(300) * robust] ** 2)))
    factor, dof = tail_form(heavy, rms)
    assert dof is not None and 2.0 <= dof <= 6.0
    # The true 95 % half-width of 3 % x t(3) is 3.18 x 3 %; the t form comes within 15 % of it, where the
    # Gaussian one of the trimmed RMS falls short by more than 15 %.
    truth = stats.t.isf(0.025, 3) * NOISE
    gaussian = stats.norm.isf(0.025) * rms
    assert gaussian < 0.85 * truth
    assert abs(factor * gaussian / truth - 1.0) < 0.15
    assert tail_form(rng.normal(0.0, NOISE, 300), NOISE) == (1.0, None)


def test_heavy_tailed_scatter_is_covered_through_the_api(client):
    rng = np.random.default_rng(11)
    n = 150
    c = lab(rng, n + 2000, humidity=False)
    measured = mu_of(c) * np.exp(NOISE * rng.standard_t(3, n + 2000))
    result = calibrated(client, {"data": rows_of({k: v[:n] for k, v in c.items()}, measured[:n]),
                                 "fit_parameters": ["mu_pivot"], "folds": 3})
    assert result["effects"] == []
    assert result["model"]["scatter"]["form"]["tail_factor"] > 1.05
    assert 0.93 <= coverage(result, {k: v[n:] for k, v in c.items()}, measured[n:]) <= 0.98


# Item 4: plausibility and credible standard deviations.

def test_published_magnitudes_and_trends_of_micro_ball_bearings_hold_in_the_physics():
    # Dry rolling friction of steel microballs does not depend on speed (spin-down tests over 30-210
    # r/min): without a fluid film the physics' mu is flat in speed.
    c = {"balls": np.full(4, 4.0), "load_N": np.full(4, 0.01), "speed_m_s": np.array([1e-3, 1e-2, 5e-2, 0.1])}
    dry = mu_of(c, viscosity_Pa_s=1e-9)
    assert np.ptp(dry) / dry.mean() < 1e-3
    # Measured coefficients of linear microball bearings in silicon grooves are about 0.007-0.01: the
    # physics at its defaults lies within a factor of three of them, and its defaults within the declared
    # physical ranges.
    assert 0.007 / 3 < float(mu_of(c, mu_pivot=physics.PARAMETERS["mu_pivot"].default)[0]) < 0.01 * 3
    for name, share in PARAMETER_SHARES.items():
        lo, hi = share.plausible
        assert lo <= float(physics.PARAMETERS[name].default) <= hi, name


def test_a_modulus_far_below_its_default_and_a_stribeck_speed_beyond_the_data_are_implausible():
    h = np.linspace(0.2, 0.6, 9)
    columns = {"relative_humidity": h, "speed_m_s": np.linspace(0.005, 0.15, 9)}
    term = DriftTerm("race_youngs_modulus_Pa", "linear", "relative_humidity",
                     {"reference": 0.4, "minimum": 0.2, "maximum": 0.6})
    # A slope of -4.5 per unit RH takes 150 GPa to 150 x (1 - 4.5 x 0.2) = 15 GPa at RH 0.6: ten times
    # below, where no bearing steel or silicon lies.
    (why,) = implausible(term, [-4.5], columns)
    assert "race_youngs_modulus_Pa" in why and "1.5e+10" in why
    assert implausible(term, [-0.5], columns) == []
    stribeck = EffectTerm("stribeck_breakaway", ("speed_m_s",))
    assert implausible(stribeck, [0.01, 0.02], columns) == []
    (far,) = implausible(stribeck, [0.01, 10 * 0.15], columns)
    assert f"{10:.2g}x" in far and 10 > REACH
    run_in = EffectTerm("run_in", ("cycle",))
    assert implausible(run_in, [-0.1, 500.0], {"cycle": np.arange(0.0, 3000.0, 100.0)})


def test_friction_rising_with_temperature_is_not_named_a_thermally_falling_shear_strength():
    """The physics x (1 + 0.25 (T - 20 degC) / 40 K): friction rising 25 % over 20-60 degC, 150 rows.
    thermal_shear_strength's law is Briscoe and Evans' shear strength falling with temperature (its title:
    "friction falls as temperature rises"); it was named with a coefficient of -0.0061 /K here (seed 61;
    -0.0055 to -0.0059 on seeds 62-64), a rise. A negative coefficient is now implausible: the rise goes
    to a law that can rise (here mu_pivot's Arrhenius drift), predicted as well."""
    thermal = EffectTerm("thermal_shear_strength", ("temperature_C",), {"reference": 40.0})
    columns = {"temperature_C": np.linspace(20.0, 60.0, 9)}
    assert implausible(thermal, [0.01], columns) == []
    (why,) = implausible(thermal, [-0.0056], columns)
    assert "thermal_coefficient_1_K" in why
    rng = np.random.default_rng(61)
    c = lab(rng, 150 + 400) | {"temperature_C": rng.uniform(20.0, 60.0, 150 + 400)}
    truth = mu_of(c) * (1.0 + 0.25 * (c["temperature_C"] - 20.0) / 40.0)
    measured = truth * np.exp(rng.normal(0.0, NOISE, truth.size))
    report = calibrate(rows_of({k: v[:150] for k, v in c.items()}, measured[:150]),
                       ["mu_pivot", "adhesion_energy_J_m2"], make_plots=False)
    assert [e["drivers"] for e in report.effects] == [["temperature_C"]]
    for effect in report.effects:
        if effect["name"] == "thermal_shear_strength":
            assert effect["parameters"]["thermal_coefficient_1_K"] >= 0
    p = report.model.predict({k: v[150:] for k, v in c.items()})
    assert np.sqrt(np.mean(np.log(p.mu / truth[150:]) ** 2)) < 0.5 * NOISE

def test_a_value_the_data_do_not_identify_gets_a_wide_standard_deviation():
    # Both moduli enter only through the contact's E*: the data fix a combination, not each. The
    # pseudo-inverse gave each a standard deviation of parts per million; the fit says it does not know.
    rng = np.random.default_rng(5)
    c = lab(rng, 60)
    measured = mu_of(c) * np.exp(rng.normal(0.0, NOISE, 60))
    dataset = parse_rows(rows_of(c, measured))
    result = fit(dataset, ["ball_youngs_modulus_Pa", "race_youngs_modulus_Pa"])
    assert set(result.unidentified) == {"ball_youngs_modulus_Pa", "race_youngs_modulus_Pa"}
    for name, std in result.declared_std.items():
        assert std >= abs(result.declared[name])
    words = parameter_warnings(result, result)
    assert sum("not identified by the data" in w for w in words) == 4  # two values, in both fits
    identified = fit(dataset, ["mu_pivot"])
    assert identified.unidentified == []
    assert identified.declared_std["mu_pivot"] < 0.1 * identified.declared["mu_pivot"]


# Item 6: groups keep the search's power.

def test_the_search_sees_the_measurements_with_each_specimens_level_taken_out():
    # Six specimens of 30 rows, each with its own level of mu (8 % between them), 3 % scatter within: the
    # search's data keep the within-specimen scatter only, and the mean level (which mu_pivot fits).
    rng = np.random.default_rng(2)
    c = lab(rng, 180)
    level = np.repeat(rng.normal(0.0, 0.08, 6), 30)
    truth = mu_of(c)
    measured = truth * np.exp(level + rng.normal(0.0, NOISE, 180))
    rows = [row | {"specimen": f"S{i // 30 + 1}"} for i, row in enumerate(rows_of(c, measured))]
    dataset = parse_rows(rows)
    searched, shift = within_groups(dataset, truth)
    before = np.log(dataset.mu_measured / truth)
    after = np.log(searched.mu_measured / truth)
    assert np.std(before) > 2.0 * NOISE
    # Within a specimen nothing moves: the shift is one number per specimen (its shrunk level).
    for g in range(6):
        assert np.ptp(shift[30 * g:30 * (g + 1)]) < 1e-12
    # What is left scatters like the measurements within a specimen (3 %, known to about 5 % from 180 rows
    # less the 6 levels), not like the specimens' levels.
    assert abs(np.std(after) / NOISE - 1.0) < 0.15
    # Without a factor column the data are the search's as they are.
    plain = parse_rows(rows_of(c, measured))
    assert within_groups(plain, truth)[0] is plain
