"""A drift chosen for its parameter's level, and the standard deviation of a large value beside tiny ones.

The search names a drift of a parameter that is neither fitted nor fixed with its level (calibrate.candidates
.DriftTerm.level): when the parameter's default is wrong (a film eight times more viscous than 1 mPa s), every
drift of it on any column carries the level and passes alike, and the column named is a preference among
equals. The report must say when the drift's coefficient shows no change (calibrate.prose.level_not_drift),
which needs that coefficient's standard deviation to be right: the sandwich covariance of calibrate.fit gave
an activation energy of 44 kJ/mol beside a meniscus force of 2e-5 N a standard deviation of 6e-9 J/mol (J^T J
singular to the pseudo-inverse's precision), against a spread of ~1e4 J/mol over fresh noise.
"""

from __future__ import annotations

import numpy as np

from microbearing import physics
from microbearing.calibrate import calibrate, parse_rows
from microbearing.calibrate.candidates import DriftTerm, EffectTerm
from microbearing.calibrate.fit import fit
from microbearing.calibrate.prose import level_not_drift

GAS_CONSTANT_J_MOL_K = 8.314462618
VISCOSITY = DriftTerm("viscosity_Pa_s", "kelvin", "relative_humidity", {"reference": 1.0}, level=True)


def _columns(rng, n):
    return {"balls": rng.choice([4.0, 6.0, 8.0], n),
            "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
            "speed_m_s": rng.uniform(0.005, 0.15, n), "relative_humidity": rng.uniform(0.2, 0.8, n),
            "temperature_C": rng.uniform(20.0, 40.0, n)}


def _mu(c, activation_J_mol, level_Pa_s=0.01, meniscus_N=2e-5):
    kelvin = c["temperature_C"] + 273.15
    eta = level_Pa_s * np.exp(activation_J_mol / GAS_CONSTANT_J_MOL_K * (1.0 / kelvin - 1.0 / 298.15))
    mu = physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"], mu_pivot=0.65,
                          viscosity_Pa_s=eta).mu
    return mu + c["balls"] * meniscus_N / (c["load_N"] * np.log(1.0 / c["relative_humidity"]))


def _rows(c, measured):
    return parse_rows([{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(measured[i])}
                       for i in range(measured.size)])


def test_the_std_of_an_activation_energy_beside_a_meniscus_force_is_its_spread_over_fresh_noise():
    rng = np.random.default_rng(3)
    c = _columns(rng, 120)
    mu = _mu(c, 40e3)
    kelvin = c["temperature_C"] + 273.15
    terms = (EffectTerm("humidity_meniscus", ("relative_humidity",)),
             DriftTerm("viscosity_Pa_s", "arrhenius", "temperature_C",
                       {"reference": float(np.median(kelvin)), "minimum": float(kelvin.min()),
                        "maximum": float(kelvin.max())}, level=True))
    activation, reported = [], []
    for _ in range(24):
        result = fit(_rows(c, mu * np.exp(rng.normal(0.0, 0.03, mu.size))), ["mu_pivot"], terms)
        activation.append(result.term_values[1][0])
        reported.append(result.term_std()[1][0])
    spread = float(np.std(activation, ddof=1))  # ~9e3 J/mol; the old sandwich said ~1e-8
    assert spread > 2e3
    # 24 draws know a standard deviation to about 15 %
    assert 0.6 < float(np.median(reported)) / spread < 1.6


def test_a_drift_whose_coefficient_shows_no_change_is_named_for_its_level():
    words = level_not_drift([VISCOSITY], [[0.061, 0.0115]], [[0.19, 0.0033]])
    assert len(words) == 1
    assert "chosen for the level of viscosity_Pa_s, 0.0115 Pa*s (12x its default 0.001)" in words[0]
    assert "95 % interval -0.311 to 0.433 that holds 0" in words[0]  # 0.061 -/+ 1.96 x 0.19
    assert "declare viscosity_Pa_s fitted" in words[0]
    # a coefficient 2.1 standard deviations from 0 shows a change; so does a negative one
    assert level_not_drift([VISCOSITY], [[0.4, 0.0115]], [[0.19, 0.0033]]) == []
    assert level_not_drift([VISCOSITY], [[-0.4, 0.0115]], [[0.19, 0.0033]]) == []
    # without a fitted level the drift's own test chose it; an effect has no level; no std, nothing said
    plain = DriftTerm("viscosity_Pa_s", "kelvin", "relative_humidity", {"reference": 1.0})
    assert level_not_drift([plain], [[0.061]], [[0.19]]) == []
    meniscus = EffectTerm("humidity_meniscus", ("relative_humidity",))
    assert level_not_drift([meniscus], [[2e-5]], [[1e-6]]) == []
    assert level_not_drift([VISCOSITY], [[0.061, 0.0115]], [[float("nan"), 0.0033]]) == []


def test_a_viscosity_wrong_by_eight_is_said_to_be_a_level_not_a_drift_with_humidity():
    # slow tier (tests/tiers.py)
    # The viscosity 8 mPa s everywhere (default 1): the search names a viscosity drift on a column (humidity
    # in this draw, temperature in others) whose coefficient's interval holds 0; the report says so.
    rng = np.random.default_rng(1)
    c = _columns(rng, 150)
    mu = physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"], mu_pivot=0.65,
                          viscosity_Pa_s=0.008).mu
    report = calibrate(_rows(c, mu * np.exp(rng.normal(0.0, 0.03, mu.size))), ["mu_pivot"], make_plots=False)
    drifts = [e for e in report.effects if e.get("parameter") == "viscosity_Pa_s"]
    assert drifts and drifts[0]["level_fitted"]
    said = [w for w in report.confounding if "chosen for the level of viscosity_Pa_s" in w]
    assert said and "declare viscosity_Pa_s fitted" in said[0]
