"""The optional effects of physics.effects against hand calculations."""

import math

import numpy as np
import pytest

from microbearing import physics
from microbearing.physics.effects import (
    DRIFT_LAWS,
    DRIFT_PARAMETERS,
    EFFECTS,
    apply_effect,
    humidity_fraction,
)


def test_constant_drag_adds_force_over_load():
    # mu = 0.01 + 1e-4 N / 0.02 N = 0.015
    out = apply_effect(np.array([0.01]), "constant_drag", {"load_N": np.array([0.02])},
                       {"drag_force_N": 1e-4})
    assert out[0] == pytest.approx(0.015)


def test_viscous_drag_is_linear_in_speed_and_zero_at_rest():
    columns = {"speed_m_s": np.array([0.0, 0.1, 0.2]), "load_N": np.array([0.01, 0.01, 0.01])}
    out = apply_effect(np.full(3, 0.01), "viscous_drag", columns, {"drag_coefficient_N_s_m": 1e-3})
    # 1e-3 N s/m * 0.1 m/s / 0.01 N = 0.01
    assert out.tolist() == pytest.approx([0.01, 0.02, 0.03])


def test_humidity_meniscus_matches_kelvin_form_and_accepts_percent():
    h = math.exp(-1.0)  # ln(1/h) = 1
    columns = {"balls": 4.0, "load_N": 0.01, "relative_humidity": np.array([h])}
    out = apply_effect(np.array([0.01]), "humidity_meniscus", columns, {"meniscus_force_N": 1e-5},
                       drivers=("relative_humidity",))
    assert out[0] == pytest.approx(0.01 + 4 * 1e-5 / 0.01)
    percent = {"balls": 4.0, "load_N": 0.01, "rh_pct": np.array([100 * h])}
    out_pct = apply_effect(np.array([0.01]), "humidity_meniscus", percent, {"meniscus_force_N": 1e-5},
                           drivers=("rh_pct",))
    assert out_pct[0] == pytest.approx(out[0])
    assert humidity_fraction("relative_humidity_percent", [55.0]).tolist() == [0.55]


def test_humidity_outside_zero_one_is_rejected():
    columns = {"balls": 4.0, "load_N": 0.01, "relative_humidity": np.array([40.0])}
    with pytest.raises(ValueError, match="relative_humidity"):
        apply_effect(np.array([0.01]), "humidity_meniscus", columns, {"meniscus_force_N": 1e-5},
                     drivers=("relative_humidity",))


def test_thermal_and_run_in_limits():
    temperature = {"temperature_C": np.array([25.0, 35.0])}
    out = apply_effect(np.array([0.01, 0.01]), "thermal_shear_strength", temperature,
                       {"thermal_coefficient_1_K": 0.02}, ("temperature_C",), {"reference": 25.0})
    assert out.tolist() == pytest.approx([0.01, 0.01 * math.exp(-0.2)])
    cycles = {"cycle": np.array([0.0, 1e9])}
    out = apply_effect(np.array([0.01, 0.01]), "run_in", cycles,
                       {"run_in_amplitude": 0.5, "run_in_length": 100.0}, ("cycle",))
    assert out.tolist() == pytest.approx([0.015, 0.01])


def test_generic_terms_are_neutral_at_their_reference():
    x = {"vibration": np.array([2.0, 4.0])}
    lin = apply_effect(np.array([1.0, 1.0]), "generic_linear", x, {"c1": 0.5}, ("vibration",),
                       {"centre": 2.0, "scale": 2.0})
    assert lin.tolist() == pytest.approx([1.0, math.exp(0.5)])
    power = apply_effect(np.array([1.0, 1.0]), "generic_power", x, {"c1": 2.0}, ("vibration",),
                         {"reference": 2.0})
    assert power.tolist() == pytest.approx([1.0, 4.0])


def test_generic_quadratic_is_continued_along_its_tangent_beyond_the_data_range():
    # Loads of 2-10 mN: centre 5 mN, scale 2 mN, so the data's z spans [-1.5, 2.5]. At 30 mN (z = 12.5)
    # exp(c1 z + c2 z^2) with c2 = 0.02 is exp(3.1 + ...): the curvature seen inside the data extrapolated.
    data = {"load_N": np.array([2e-3, 4e-3, 6e-3, 10e-3])}
    constants = EFFECTS["generic_quadratic"].constants(data, ("load_N",))
    assert constants["low"] == 2e-3 and constants["high"] == 10e-3
    constants.update(centre=5e-3, scale=2e-3)
    c1, c2 = -0.1, 0.02
    load = np.array([0.5e-3, 2e-3, 6e-3, 10e-3, 30e-3])
    out = apply_effect(np.ones(5), "generic_quadratic", {"load_N": load}, {"c1": c1, "c2": c2}, ("load_N",),
                       constants)
    z = (load - 5e-3) / 2e-3
    # inside: the quadratic; beyond: its value at the end plus its slope there (c1 + 2 c2 z_end) times the
    # rest; below, z_end = -1.5: z_end^2 + 2 z_end (z - z_end) = 2.25 + 2.25
    expected = [c1 * -2.25 + c2 * (2.25 + 2 * -1.5 * (-2.25 + 1.5)),
                c1 * z[1] + c2 * z[1] ** 2, c1 * z[2] + c2 * z[2] ** 2, c1 * z[3] + c2 * z[3] ** 2,
                c1 * 12.5 + c2 * (6.25 + 2 * 2.5 * (12.5 - 2.5))]
    assert np.log(out).tolist() == pytest.approx(expected, rel=1e-12)
    # -1.25 + 0.02 (6.25 + 50) = -0.125 there, where the quadratic says -1.25 + 0.02 x 156.25 = 1.875 (6.6x)
    assert math.log(out[-1]) == pytest.approx(-0.125)
    # a term stored before the data's range was kept (no low, high) is the quadratic everywhere
    old = apply_effect(np.ones(1), "generic_quadratic", {"load_N": np.array([30e-3])}, {"c1": c1, "c2": c2},
                       ("load_N",), {"centre": 5e-3, "scale": 2e-3})
    assert math.log(old[0]) == pytest.approx(-1.25 + 0.02 * 156.25)


def test_drivers_are_matched_by_column_name():
    names = ["balls", "load_N", "speed_m_s", "relative_humidity_pct", "temperature_C", "cycle", "vibration"]
    assert EFFECTS["humidity_meniscus"].candidate_drivers(names) == [("relative_humidity_pct",)]
    assert EFFECTS["thermal_shear_strength"].candidate_drivers(names) == [("temperature_C",)]
    assert EFFECTS["run_in"].candidate_drivers(names) == [("cycle",)]
    assert EFFECTS["viscous_drag"].candidate_drivers(names) == [("speed_m_s", "load_N")]
    assert ("vibration",) in EFFECTS["generic_linear"].candidate_drivers(names)
    named = [e for e in EFFECTS.values() if not e.generic]
    assert not any(("vibration",) in e.candidate_drivers(names) for e in named)


def test_composes_with_physics_evaluate():
    r = physics.evaluate(balls=4, load_N=0.009, speed_m_s=0.05)
    out = apply_effect(r.mu, "constant_drag", {"load_N": 0.009}, {"drag_force_N": 9e-5})
    assert float(out) == pytest.approx(float(r.mu) + 0.01)


def test_missing_parameter_or_driver_is_a_value_error():
    with pytest.raises(ValueError, match="drag_force_N"):
        apply_effect(np.array([0.01]), "constant_drag", {"load_N": 0.01}, {})
    with pytest.raises(ValueError, match="cycle"):
        apply_effect(np.array([0.01]), "run_in", {}, {"run_in_amplitude": 0.1, "run_in_length": 1.0},
                     ("cycle",))
    with pytest.raises(ValueError, match="effect must be one of"):
        apply_effect(np.array([0.01]), "gremlins", {}, {})


def test_every_effect_is_documented():
    for effect in EFFECTS.values():
        assert effect.formula.startswith("mu = ")
        assert effect.reference and effect.title and effect.driver_description
        for p in effect.parameters:
            assert p.unit and p.description and p.minimum < p.maximum


def test_stribeck_breakaway_decays_from_its_excess_at_rest():
    columns = {"speed_m_s": np.array([0.0, 0.01, 1.0])}
    out = apply_effect(np.full(3, 0.01), "stribeck_breakaway", columns,
                       {"breakaway_excess": 0.02, "breakaway_speed_m_s": 0.01})
    assert out.tolist() == pytest.approx([0.03, 0.01 + 0.02 / math.e, 0.01 + 0.02 * math.exp(-100)])


def test_viscous_power_law_scales_with_a_power_of_speed():
    columns = {"speed_m_s": np.array([0.05, 0.2]), "load_N": np.array([0.01, 0.01])}
    constants = EFFECTS["viscous_power_law"].constants(columns, ("speed_m_s", "load_N"))
    assert constants == {"reference": pytest.approx(0.125)}
    out = apply_effect(np.zeros(2), "viscous_power_law", columns,
                       {"drag_force_N": 1e-4, "speed_exponent": 0.5}, ("speed_m_s", "load_N"),
                       {"reference": 0.05})
    # 1e-4 N (V / 0.05)^0.5 / 0.01 N: 0.01 at the reference, twice that at four times the speed
    assert out.tolist() == pytest.approx([0.01, 0.02])


def test_drift_laws_against_hand_calculations():
    linear = DRIFT_LAWS["linear"]
    c = linear.constants("coated", [0.0, 0.0, 1.0])
    assert c == {"reference": 0.0, "minimum": 0.0, "maximum": 1.0}
    assert linear.factor("coated", np.array([0.0, 1.0]), -0.4, c).tolist() == pytest.approx([1.0, 0.6])
    # A linear factor stays within [0.1, 10] over the data: slope in [-0.9, 9] per unit here.
    assert linear.bounds(c) == pytest.approx((-0.9, 9.0))
    kelvin = DRIFT_LAWS["kelvin"]
    c = kelvin.constants("relative_humidity_pct", [20.0, math.exp(-1) * 100, 80.0])
    assert c["reference"] == pytest.approx(1.0)  # 1/ln(1/h) at h = 1/e
    h = 0.5
    assert float(kelvin.factor("relative_humidity_pct", 100 * h, 0.3, c)) == pytest.approx(
        1 + 0.3 * (1 / math.log(1 / h) - 1))
    arrhenius = DRIFT_LAWS["arrhenius"]
    c = arrhenius.constants("temperature_K", [290.0, 300.0, 310.0])
    assert float(arrhenius.factor("temperature_K", 310.0, 16e3, c)) == pytest.approx(
        math.exp(16e3 / 8.314462618 * (1 / 310 - 1 / 300)))
    assert arrhenius.matches("temperature_C") and not arrhenius.matches("cycle")
    assert kelvin.accepts("rh", [0.2, 0.8]) and not kelvin.accepts("rh", [0.2, 1.0])
    assert set(DRIFT_PARAMETERS) <= set(physics.PARAMETERS)
