"""Names of condition columns read as a lab writes them (issue 32's seams, second sweep): the unit words of a
name are whole words, a temperature's slip is judged in the unit its brackets state, a column is matched by
its quantity whatever its own spelling, and a factor is never a quantity."""

from __future__ import annotations

import pytest

from microbearing.calibrate.tabular import read_csv
from microbearing.physics.columns import ColumnError, match_column, read_name
from microbearing.physics.drivers import HUMIDITY, TEMPERATURE, temperature_kelvin
from microbearing.physics.slips import read_slip


@pytest.mark.parametrize(("name", "unit"), [
    ("chamber_temperature_K", "K"), ("case temperature [degC]", "degC"), ("kiln_temp", "degC"),
    ("coil_temp_K", "K"), ("temp_kelvin", "K"), ("temp_kelvins", "K"), ("temperature_C", "degC"),
    ("T_K", "K")])
def test_a_temperature_s_unit_is_read_from_whole_words(name, unit):
    # "chamber" and "case" start with c, "kiln" with k: none of them is a unit
    assert TEMPERATURE.unit_of(name).unit == unit


@pytest.mark.parametrize(("name", "unit"), [("rh_pctile", "1"), ("rh_PCT", "%"), ("humidity_percent", "%"),
                                            ("humidity_percentage", "%")])
def test_a_humidity_s_unit_is_read_from_whole_words(name, unit):
    assert HUMIDITY.unit_of(name).unit == unit


@pytest.mark.parametrize(("sent", "known", "value", "expected"), [
    ("humidity_percentage", "relative_humidity", 50.0, 0.5), ("temp_kelvins", "temp_degC", 300.0, 26.85),
    ("temp_kelvins", "temperature_K", 300.0, 300.0)])
def test_plural_unit_words_are_read_as_their_unit(sent, known, value, expected):
    # a plural (kelvins, percentage) is the unit's word too: read, never refused nor taken for the default
    assert match_column(sent, [known]).convert(value) == pytest.approx(expected)
    assert read_slip(match_column(sent, [known]), [value]) is None


def test_a_header_with_a_word_before_temperature_converts_by_its_brackets():
    reading = read_name("chamber temperature [K]")
    assert reading.convert(300.0) == pytest.approx(300.0)
    assert TEMPERATURE.unit_of(reading.name).unit == "K"
    reading = read_name("case temperature [degC]")
    assert reading.convert(30.0) == pytest.approx(303.15) and TEMPERATURE.unit_of(reading.name).unit == "K"


@pytest.mark.parametrize("sent", ["temperature [degC]", "Temp (°C)", "T [degC]"])
def test_degc_above_200_under_a_celsius_name_is_kelvin_on_a_kelvin_model(sent):
    # read in K the value has no upper limit; judged in the unit the name states it is 250 degC
    reading = match_column(sent, ["temperature_K"])
    assert "look like kelvin" in read_slip(reading, [25.0, 250.0])
    assert read_slip(reading, [25.0, 45.0]) is None


@pytest.mark.parametrize(("sent", "known", "value", "expected"), [
    ("temperature [degC]", ["T_K"], 27.0, 300.15),        # a T_K column is a temperature
    ("temp_C", ["T_K"], 27.0, 300.15),
    ("humidity [1]", ["RH"], 0.5, 0.5),                   # brackets state the unit: a fraction
    ("RH [%]", ["rh_PCT"], 50.0, 50.0),
    ("temp_R", ["temp_degC"], 540.27, 27.0),              # Rankine: K x 9/5
])
def test_a_column_is_matched_by_its_quantity_whatever_its_spelling(sent, known, value, expected):
    reading = match_column(sent, known)
    assert reading.name == known[0] and reading.convert(value) == pytest.approx(expected, rel=1e-9)


def test_a_bare_synonym_is_not_guessed():
    with pytest.raises(ColumnError, match="unknown column 'humidity'"):
        match_column("humidity", ["relative_humidity"])
    # nor a count for another count: a cycle of a reciprocating rig may be two passes
    with pytest.raises(ColumnError, match="unknown column 'cycles'"):
        match_column("cycles", ["passes"])


@pytest.mark.parametrize(("known", "expected"), [("rel._humidity", 0.5), ("humidity_pct", 50.0), ("RH", 0.5)])
def test_a_condition_s_canonical_name_reaches_its_quantity_in_any_column(known, expected):
    # relative_humidity declares its unit (a fraction): an upload's 'rel. humidity (%)' column (read as the
    # fraction rel._humidity) or a percent column takes it, converted
    assert match_column("relative_humidity", [known]).convert(0.5) == pytest.approx(expected, rel=1e-12)


def test_a_factor_named_with_a_condition_word_is_no_quantity_at_prediction():
    # A chamber label column RH_chamber beside the humidity rh_PCT: every spelling of humidity reads rh_PCT
    import numpy as np

    from microbearing.calibrate.groups import GroupEffect
    from microbearing.calibrate.model import CalibratedModel
    from microbearing.calibrate.model_view import CalibratedPhysicsModel
    from microbearing.service.calibrations import read_conditions
    from microbearing.service.problems import ProblemError

    chamber = GroupEffect("RH_chamber", "mu", 0.05, (0.0, 0.3), 0.0,
                          {"A": [0.01, 1e-4, 30.0], "B": [-0.01, 1e-4, 30.0], "C": [0.0, 1e-4, 30.0]}, 0.03)
    calibrated = CalibratedModel(fitted={"mu_pivot": 0.6}, covariance=np.diag([1e-4]), noise_std_log=0.03,
                                 conditions=["rh_PCT"], groups=[chamber], domain={"rh_PCT": (20.0, 80.0)})
    model = CalibratedPhysicsModel("calibrated:chamber", calibrated)
    spellings = (("RH [%]", 50.0), ("humidity_pct", 50.0), ("relative_humidity", 0.5), ("rh_PCT", 50.0))
    for sent, value in spellings:
        read = read_conditions(model, {sent: value, "RH_chamber": "B"})
        assert read == {"rh_PCT": pytest.approx(50.0), "RH_chamber": "B"}, (sent, read)
    # an unknown key is said to be unknown, not judged for a slip in a unit nobody stated
    with pytest.raises(ProblemError) as refused:
        read_conditions(model, {"rh_PCT": 50.0, "pressure [kPa]": 50.0})
    assert "unknown condition column 'pressure [kPa]'" in str(refused.value.errors)


@pytest.mark.parametrize("sent", ["RH [mm]", "RH [K]", "relative_humidity [s]", "RH [deg]", "cycles [mm]",
                                  "cycles [m]", "cycles [1/s]", "time [mN]", "temperature [m]",
                                  "humidity [g/kg]", "humidity [dB]", "cycles [%]", "cycles [ppm]"])
def test_a_condition_s_unit_of_another_kind_is_refused_never_read(sent):
    # RH [mm] at 600 had been read as the fraction 0.6 (600 mm = 0.6 m), cycles [mm] at 5 as 0.005 cycles;
    # humidity [g/kg] at 500 (an absolute humidity) as the fraction 0.5, cycles [%] at 50 as 0.5 cycles
    with pytest.raises(ColumnError, match="is read as"):
        read_name(sent)
    with pytest.raises(ColumnError):
        match_column(sent, ["relative_humidity", "cycles", "time_h", "temperature_K"])


@pytest.mark.parametrize(("sent", "value", "expected"), [
    ("cycles [kcycles]", 1.0, 1000.0), ("cycles [cycle]", 1.0, 1.0), ("passes [kpasses]", 2.0, 2000.0),
    ("strokes [1]", 7.0, 7.0), ("cycles [revolutions]", 100.0, 100.0), ("cycles [krev]", 1.0, 1000.0)])
def test_a_count_s_unit_words_are_counts_not_angles(sent, value, expected):
    # pint's cycle is a turn, 2 pi radians: 1 kcycle had been read as 6283 cycles
    assert match_column(sent, ["cycles"]).convert(value) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize(("sent", "value", "expected"), [
    # hand: 1 gf = 9.80665 mN (standard gravity); 1 lbf = 0.45359237 kg x 9.80665 m/s2; 1 ozf = 1/16 lbf
    ("load (gf)", 1.0, 9.80665e-3), ("load [kgf]", 0.001, 9.80665e-3), ("load [lbf]", 1.0, 4.4482216152605),
    ("load_ozf", 16.0, 4.4482216152605), ("load [dyn]", 1e5, 1.0)])
def test_a_force_unit_is_read_whatever_order_pint_writes_its_dimension_in(sent, value, expected):
    # gf's dimension reads [length] * [mass] / [time] ** 2, N's [mass] * [length] / ...: the text had been
    # compared, and every force unit but N's own multiples refused as "not convertible"
    reading = read_name(sent)
    assert reading.name == "load_N" and reading.convert(value) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize(("sent", "value", "words", "not_words"), [
    # -200 degC is 73.15 K: a cold test, no slip, though 73 K under a kelvin name would look like degC
    ("temp [degC]", -200.0, None, None),
    ("temp [degC]", 250.0, ["temp [degC] runs 250 to 250 degC", "send them as 'temp [K]'"], ["temp_K"]),
    ("temp [K]", 27.0, ["temp [K] runs 27 to 27 K", "send them as 'temp [degC]'"], ["temperature_C"]),
    ("RH [1]", 50.0, ["RH [1] runs 50 to 50 [1]", "send them as 'RH [%]'"], None),
])
def test_a_condition_is_judged_for_a_slip_in_the_unit_its_key_states_only(sent, value, words, not_words):
    message = read_slip(match_column(sent, ["temperature_K", "RH"]), [value])
    if words is None:
        assert message is None, message
        return
    assert all(w in message for w in words) and not any(w in message for w in not_words or ()), message


@pytest.mark.parametrize(("sent", "values", "words", "not_words"), [
    # hand: 1e6 gf = 1e6 x 9.80665e-3 N = 9807 N
    ("load (gf)", [1e6], ["load (gf) runs 1e+06 to 1e+06 gf (load_N 9807 to 9807 N)",
                          "its name states the unit"], ["look like mN"]),
    # a negative load is no mN slip, whatever the unit (1 lbf = 4.448 N)
    ("load [lbf]", [-1.0, 1.0], ["load [lbf] runs -1 to 1 lbf", "load_N is not negative"], ["look like mN"]),
    ("load_N", [-2.0, 3.0], ["load_N is not negative"], ["look like mN"]),
    # its own unit stated: the slip's advice stands (5 N looks like 5 mN)
    ("load [N]", [5.0], ["load [N] runs 5 to 5 N", "look like mN (times 0.001: 0.005 to 0.005 N)"], []),
])
def test_a_physics_input_s_slip_is_said_as_sent(sent, values, words, not_words):
    message = read_slip(read_name(sent), values)
    assert all(w in message for w in words) and not any(w in message for w in not_words), message


@pytest.mark.parametrize(("sent", "advice"), [
    ("load (normal) [mN]", "'load [mN]'"), ("normal load [mN]", "'load [mN]'"),
    ("speed (sliding) [mm/s]", "'speed [mm/s]'"), ("ball diameter (nominal) [um]", "'ball diameter [um]'"),
    ("groove angle (measured) [deg]", "'groove angle [deg]'")])
def test_a_physics_input_s_name_among_other_words_is_refused_never_a_new_condition(sent, advice):
    # before: load (normal) [mN] became a force condition load_(normal)_N that the physics never reads
    with pytest.raises(ColumnError) as refused:
        read_name(sent)
    assert advice in str(refused.value) and sent in str(refused.value)


@pytest.mark.parametrize(("sent", "name"), [
    ("load [mN]", "load_N"), ("preload [mN]", "preload_N"), ("motor speed [rpm]", "motor_speed_1_s"),
    ("contact pressure [MPa]", "contact_pressure_Pa"), ("load ratio [1]", "load_ratio"),
    ("pressure_viscosity [1/GPa]", "pressure_viscosity_1_Pa")])
def test_other_quantities_whose_words_touch_an_input_s_stay_conditions(sent, name):
    # another word (preload), another kind of unit (rpm, a ratio) or another input (pressure viscosity)
    assert read_name(sent).name == name


@pytest.mark.parametrize(("sent", "value", "kelvin"), [
    ("tempF", 212.0, 373.15), ("TempF", 32.0, 273.15), ("temperatureF", 80.33, 300.0),
    ("tempDegF", 212.0, 373.15), ("temp_fahrenheit", 212.0, 373.15), ("tempK", 300.0, 300.0),
    ("TempC", 26.85, 300.0), ("temperatureKelvin", 300.0, 300.0)])
def test_a_unit_glued_to_a_temperature_s_word_is_that_unit(sent, value, kelvin):
    # tempF is temp_F: 80.33 degF = (80.33 - 32) x 5/9 + 273.15 = 300.0 K, never 80.33 degC (353.5 K)
    reading = match_column(sent, ["T_K"])
    assert reading.name == "T_K" and reading.convert(value) == pytest.approx(kelvin, abs=1e-9)
    assert read_slip(reading, [value]) is None
    # the upload's reading gives the terms the same kelvin
    first = read_name(sent)
    assert temperature_kelvin(first.name, [first.convert(value)])[0] == pytest.approx(kelvin, abs=1e-9)


@pytest.mark.parametrize(("sent", "unit"), [("tempr", "degC"), ("temps", "degC"), ("temperature", "degC"),
                                            ("RHpct", "%"), ("humidityPercent", "%"), ("rh", "1")])
def test_only_a_unit_s_word_glued_to_a_quantity_is_read_as_a_unit(sent, unit):
    # tempr abbreviates temperature: a bare r is no Rankine
    kind = TEMPERATURE if TEMPERATURE.matches(sent) else HUMIDITY
    assert kind.unit_of(sent).unit == unit


@pytest.mark.parametrize(("sent", "known", "value", "expected"), [
    ("Temperature (C)", "T_K", 26.85, 300.0),           # pint's C is the coulomb
    ("Temp (F)", "T_K", 80.33, 300.0),                  # pint's F is the farad: (80.33 - 32) x 5/9 + 273.15
    ("T [F]", "temperature_K", 212.0, 373.15),
    ("T (C)", "temp_degC", 25.0, 25.0),
    ("Humidity (%RH)", "relative_humidity", 45.0, 0.45),
    ("RH [% RH]", "relative_humidity", 45.0, 0.45),
    ("humidity [%rh]", "RH_pct", 45.0, 45.0)])
def test_a_condition_s_unit_is_read_as_labs_write_it_in_brackets(sent, known, value, expected):
    # a lab's export writes Temperature (C) and Humidity (%RH): they were refused as coulomb, farad, %RH
    assert match_column(sent, [known]).convert(value) == pytest.approx(expected, abs=1e-9)
    assert read_slip(match_column(sent, [known]), [value]) is None


@pytest.mark.parametrize("sent", ["load (F)", "current (C)", "speed [F]"])
def test_a_bare_c_or_f_is_no_temperature_unit_beside_another_quantity(sent):
    with pytest.raises(ColumnError):
        read_name(sent)


@pytest.mark.parametrize(("values", "words", "not_words"), [
    # 2 of 6 loads sent in mN beside 4 in N: times 0.001 they fall inside the others' 0.003-0.03 N
    ([0.003, 0.01, 12.0, 0.02, 0.03, 5.0], ["2 of 6 values lie beyond it", "those look like mN",
                                            "(times 0.001: 0.005 to 0.012 N, within the other values' "
                                            "0.003 to 0.03 N)", "convert those rows only"],
     ["3e-06"]),
    # the whole column in mN (0.5 mN read as 0.5 N is below the limit): the column's advice stands
    ([0.5, 3.0, 30.0], ["values look like mN (times 0.001: 0.0005 to 0.03 N)"], ["of 3 values"]),
])
def test_a_slip_of_some_rows_names_those_rows_not_the_column(values, words, not_words):
    # before: "values look like mN (times 0.001: 3e-06 to 0.012 N)", converting the rows in N as well
    message = read_slip(read_name("load_N"), values)
    assert all(w in message for w in words) and not any(w in message for w in not_words), message


@pytest.mark.parametrize(("sent", "value", "kelvin"), [
    ("temp_degR", 671.67, 373.15), ("temperature_degR", 491.67, 273.15),  # degR = K x 9/5
    ("temp_degK", 300.0, 300.0), ("T_degK", 300.0, 300.0), ("temperatureDegK", 300.0, 300.0),
    ("temp_°F", 212.0, 373.15), ("Temp °F", 32.0, 273.15), ("temperature.F", 212.0, 373.15)])
def test_a_temperature_unit_written_with_deg_or_a_degree_sign_is_read_in_that_unit(sent, value, kelvin):
    # temp_degR was read as degC (671.67 -> 944.82 K), temp_degK as degC (300 -> 573.15 K); temp_°F was
    # converted at the upload and then converted again at prediction (212 degF -> 462.68 K)
    first = read_name(sent)
    assert temperature_kelvin(first.name, [first.convert(value)])[0] == pytest.approx(kelvin, abs=1e-9)
    for known in ("T_K", "temperature_K", first.name):
        reading = match_column(sent, [known])
        assert reading.convert(value) == pytest.approx(kelvin, abs=1e-9)
        assert read_slip(reading, [value]) is None
    assert match_column(sent, ["temp_C"]).convert(value) == pytest.approx(kelvin - 273.15, abs=1e-9)


@pytest.mark.parametrize(("sent", "value", "kelvin", "name"), [
    ("temp_F_avg", 212.0, 373.15, "temp_avg_K"),
    ("temperature_F_setpoint", 32.0, 273.15, "temperature_setpoint_K"),
    ("chamber_temp_F_2", 212.0, 373.15, "chamber_temp_2_K"), ("F_temp", 212.0, 373.15, "temp_K"),
    ("tempF_avg", 212.0, 373.15, "temp_avg_K"), ("Temp F avg", 212.0, 373.15, "Temp_avg_K")])
def test_a_fahrenheit_word_anywhere_in_a_temperature_s_name_is_converted_once(sent, value, kelvin, name):
    # the upload named temp_F_avg temp_F_avg_K, whose words say F and K: another model's temperature_K was
    # then given 212 degF as 462.68 K (converted to kelvin, then read as degF again)
    first = read_name(sent)
    assert first.name == name and first.convert(value) == pytest.approx(kelvin, abs=1e-9)
    assert temperature_kelvin(first.name, [first.convert(value)])[0] == pytest.approx(kelvin, abs=1e-9)
    for known in (["temperature_K"], ["T_K"], [name]):
        assert match_column(sent, known).convert(value) == pytest.approx(kelvin, abs=1e-9), known
    assert match_column(sent, ["temp_C"]).convert(value) == pytest.approx(kelvin - 273.15, abs=1e-9)


@pytest.mark.parametrize("sent", ["temp_K_C", "temp_F_C", "temp_F [K]", "temp_C [degF]", "temp_K [degC]",
                                  "T_F [degC]", "RH_pct [1]", "time_h [min]", "time_min_h", "time_h_min"])
def test_a_condition_s_name_stating_two_units_is_refused_at_every_door(sent):
    # temp_K_C was read as degC (300 -> 573.15 K), temp_F [K] as kelvin though its name says F, RH_pct [1]
    # as a fraction, time_h [min] in minutes and time_min_h in hours (its last word)
    with pytest.raises(ColumnError, match="states two units"):
        read_name(sent)
    with pytest.raises(ColumnError, match="states two units"):
        match_column(sent, ["temperature_K"])
    dataset_error = None
    try:
        read_csv(f"balls,load_N,speed_m_s,{sent},mu_measured\n4,0.01,0.05,300,0.01\n")
    except Exception as exc:  # the upload's own error type
        dataset_error = str(exc)
    assert dataset_error is not None and "states two units" in dataset_error


@pytest.mark.parametrize(("sent", "value", "si"), [
    ("temp_C [degC]", 25.0, 298.15), ("temp_K [K]", 300.0, 300.0), ("temperature_F [degF]", 32.0, 273.15),
    ("T_K [kelvin]", 300.0, 300.0), ("rh_pct [%]", 45.0, 0.45), ("time_h [h]", 1.5, 5400.0)])
def test_a_condition_s_name_and_brackets_agreeing_are_one_unit(sent, value, si):
    assert read_name(sent).convert(value) == pytest.approx(si, rel=1e-12)


# Unit spellings labs write in brackets that pint does not read though they are unambiguous: read in the
# unit they spell, as its usual spelling is (hand: K = degC + 273.15 = (degF - 32) * 5/9 + 273.15; a
# humidity in percent is the fraction x 100).
@pytest.mark.parametrize(("sent", "usual", "value", "expected"), [
    ("temperature [\u2103]", "temperature [degC]", 25.0, 298.15),        # the degree Celsius sign
    ("temperature [\u2109]", "temperature [degF]", 212.0, 373.15),       # the degree Fahrenheit sign
    ("temperature [\u00baC]", "temperature [degC]", 25.0, 298.15),       # the ordinal sign for the degree's
    ("temperature [\u00baF]", "temperature [degF]", 32.0, 273.15),
    ("temperature [deg F]", "temperature [degF]", 98.6, 310.15),
    ("temperature [deg C]", "temperature [degC]", -40.0, 233.15),
    ("temperature [\u00b0 C]", "temperature [degC]", 100.0, 373.15),
    ("temperature (\u2103)", "temperature [degC]", 25.0, 298.15),
    ("temperature [Kelvin]", "temperature [K]", 300.0, 300.0),
    ("temperature [Celsius]", "temperature [degC]", 20.0, 293.15),
    ("temp [\u00b0K]", "temp [K]", 300.0, 300.0),
    ("temperature [deg R]", "temperature [degR]", 491.67, 273.15),     # Rankine: K = degR x 5/9
    ("temperature [Rankine]", "temperature [degR]", 671.67, 373.15),
    ("T [\u2103]", "T [degC]", 0.0, 273.15),
    ("rel. humidity [\uff05]", "rel. humidity [%]", 50.0, 0.5),          # the full-width percent
    ("rel. humidity [percent]", "rel. humidity [%]", 50.0, 0.5),
])
def test_an_unambiguous_unit_spelling_in_brackets_is_read_in_its_unit(sent, usual, value, expected):
    reading = read_name(sent)
    assert reading.name == read_name(usual).name
    assert reading.convert(value) == pytest.approx(expected, rel=1e-12)
    # and a model's column of the quantity takes it, converted (a kelvin column, a fraction column)
    known = "relative_humidity" if "humidity" in usual else "temperature_K"
    assert match_column(sent, [known]).convert(value) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize(("sent", "values", "words"), [
    ("temperature [\u2103]", [25.0, 250.0], "look like kelvin"),   # judged in degC, as [degC] is
    ("temp_F [\u2103]", None, "states two units"),                  # the name says F, the brackets degC
    ("temperature [deg]", None, "not 'deg'"),                       # an angle: no temperature's unit
])
def test_a_respelled_unit_is_judged_and_refused_as_its_usual_spelling(sent, values, words):
    if values is None:
        with pytest.raises(ColumnError, match=words):
            read_name(sent)
    else:
        assert words in read_slip(match_column(sent, ["temperature_K"]), values)
