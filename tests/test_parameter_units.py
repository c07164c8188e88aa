"""A fitted parameter declared per unit of its driver is reported in the driver's unit (issue 32, units).

The catalogue declares such units by the word ``driver`` (``run_in_length``: a length of the run/cycle
column; a linear drift's ``slope``: per unit of the condition); the report gave them so, "1/driver", where a
reader needs "1/K" or "cycles".
"""

from __future__ import annotations

import pytest

from microbearing.calibrate.candidates import DriftTerm, EffectTerm


@pytest.mark.parametrize(("driver", "unit"), [
    ("temperature_K", "1/K"), ("temperature_C", "1/degC"), ("temp_F", "1/degF"), ("time_h", "1/h"),
    ("relative_humidity", "1"), ("RH_pct", "1/%"), ("coating", "1/coating")])
def test_a_linear_drift_s_slope_is_per_unit_of_its_driver(driver, unit):
    term = DriftTerm("mu_pivot", "linear", driver, {"reference": 1.0, "minimum": 0.0, "maximum": 2.0})
    assert term.units == {"slope": unit}
    # by hand: the slope multiplies (x - x_ref) in the driver's own unit, so 1/K makes it a number


@pytest.mark.parametrize(("driver", "length"), [("cycles", "cycles"), ("time_h", "h"), ("time_min", "min"),
                                                ("run_index", "run_index")])
def test_a_run_in_length_is_in_the_unit_of_its_count_or_clock(driver, length):
    term = EffectTerm("run_in", (driver,), {})
    assert term.units == {"run_in_amplitude": "1", "run_in_length": length}


def test_a_unit_without_a_driver_is_as_declared():
    term = DriftTerm("viscosity_Pa_s", "arrhenius", "temperature_C",
                     {"reference": 298.15, "minimum": 290.0, "maximum": 310.0}, level=True)
    assert term.units == {"activation_energy_J_mol": "J/mol", "viscosity_Pa_s_ref": "Pa*s"}
