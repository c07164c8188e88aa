"""physics.evaluate on odd inputs, and the one-point path against the array path."""

import math

import numpy as np
import pytest
from test_physics_evaluate import _random_inputs

from microbearing import physics
from microbearing.physics import OUTPUTS, bearing, evaluate

BASE = {"balls": 4, "load_N": 8.8e-3, "speed_m_s": 0.05}


@pytest.mark.parametrize(("value", "match"), [
    ("4", r"balls must be a whole number in \[1, 1e\+06\] \[1\]; got '4' \(str, not a number\)"),
    (["4", "5"], r"balls must be a whole number .* got '4' \(str, not a number\) at index 0"),
    (np.array(["4"]), r"balls must be a whole number .* got '4' \(str, not a number\) at index 0"),
    (b"4", r"balls must be a whole number .* got b'4' \(bytes, not a number\)"),
])
def test_a_number_written_as_a_string_is_refused(value, match):
    with pytest.raises(ValueError, match=match):
        evaluate(**{**BASE, "balls": value})


@pytest.mark.parametrize(("value", "match"), [
    (None, r"load_N must be in \[1e-09, 1e\+06\] \[N\]; got None \(no value\)$"),
    ([1e-3, 2e-3, None], r"load_N must be in .* got None \(no value\) at index 2$"),
])
def test_none_is_reported_as_a_missing_value_not_as_nan(value, match):
    with pytest.raises(ValueError, match=match) as error:
        evaluate(**{**BASE, "load_N": value})
    assert "nan" not in str(error.value)


def test_none_for_an_optional_parameter_is_refused_too():
    with pytest.raises(ValueError, match=r"balls_touching must be true or false \[1\]; got None"):
        evaluate(**BASE, balls_touching=None)


@pytest.mark.parametrize("convention", list(physics.CONVENTIONS))
def test_evaluate_balances_the_ball_in_its_own_convention(convention):
    # The conventions differ in the share of M_b in one contact pair's balance (eq 19): the outputs
    # of each satisfy the balance read the same way, and fail the other reading.
    rng = np.random.default_rng(5)
    n = 200
    theta = rng.uniform(5, 85, n)
    r = evaluate(balls=rng.integers(2, 40, n), load_N=10 ** rng.uniform(-4, -1, n),
                 speed_m_s=rng.uniform(0, 0.3, n), groove_angle_deg=theta, balls_touching=True,
                 mu_ball=rng.uniform(0.1, 1, n), convention=convention)
    cos, tan = np.cos(np.radians(theta)), np.tan(np.radians(theta))
    args = (r.ball_ball_moment_Nm, r.pivoting_moment_Nm, r.pivoting_moment_Nm, r.hysteresis_moment_Nm,
            r.hysteresis_moment_Nm, r.sliding_force_N, r.sliding_force_N, r.rolling_force_N,
            r.rolling_force_N, 285e-6, cos, tan)
    scale = 285e-6 * r.sliding_force_N
    own = bearing.moment_balance_residual(*args, convention=convention)
    np.testing.assert_array_less(np.abs(own), 1e-12 * scale)
    other = "derjaguin" if convention == "olaru2005" else "olaru2005"
    assert np.all(np.abs(bearing.moment_balance_residual(*args, convention=other)) > 1e-3 * scale)
    with pytest.raises(ValueError, match="convention must be one of"):
        bearing.moment_balance_residual(*args, convention="hertz")


def test_max_contact_pressure_is_the_hertz_peak_of_the_adhesive_load():
    unit, meaning = OUTPUTS["max_contact_pressure_Pa"]
    assert unit == "Pa" and "adhesion-enhanced" in meaning and "JKR" in meaning
    r = evaluate(**BASE, adhesion_energy_J_m2=[0.0, 0.18])
    area = math.pi * r.contact_radius_m**2
    np.testing.assert_allclose(r.max_contact_pressure_Pa, 1.5 * r.contact_load_adhesive_N / area, rtol=1e-14)
    # without adhesion Q = Q0; with it the peak is that of Q, well above that of the applied load
    assert r.contact_load_adhesive_N[0] == r.contact_load_N[0]
    assert r.max_contact_pressure_Pa[1] > 2 * 1.5 * r.contact_load_N[1] / area[1]


@pytest.mark.parametrize("convention", list(physics.CONVENTIONS))
def test_a_single_ball_has_no_neighbour_so_touching_adds_nothing(convention):
    # balls counts the balls of both grooves; one ball has nothing to touch, two have eq 17's M_b
    varied = {"load_N": [1e-4, 8.8e-3, 0.3], "speed_m_s": [0.0, 0.05, 0.15], "mu_ball": [0.5, 1.0, 2.0]}
    for params in ({"balls": 1, "load_N": 8.8e-3, "speed_m_s": 0.05, "mu_ball": 1.0}, {"balls": 1, **varied}):
        touching = evaluate(convention=convention, **params, balls_touching=True).to_dict()
        apart = evaluate(convention=convention, **params, balls_touching=False).to_dict()
        for name in OUTPUTS:
            np.testing.assert_array_equal(touching[name], apart[name], err_msg=name)
        assert np.all(touching["ball_ball_moment_Nm"] == 0) and np.all(touching["mu_ball_ball"] == 0)
    # in one array with larger counts: only balls=1 loses the moment
    mixed = evaluate(convention=convention, balls=[1, 2, 1, 18], load_N=4e-3, speed_m_s=0.05,
                     balls_touching=[True, True, False, True], mu_ball=1.0)
    # eq 17 by hand at balls >= 2: M_b = μb 4 π γ_w R* d, R* = R/4 (olaru2005) or R/2 (derjaguin)
    radius = 285e-6 / 2 / (4 if convention == "olaru2005" else 2)
    by_hand = 1.0 * 4 * math.pi * 0.0717 * radius * 285e-6
    np.testing.assert_allclose(mixed.ball_ball_moment_Nm, [0.0, by_hand, 0.0, by_hand], rtol=1e-14, atol=0)
    assert bearing.ball_ball_contact(True, 1) is False and bearing.ball_ball_contact(True, 2) is True
    contact = bearing.ball_ball_contact([True, True, False], [1, 2, 2])
    np.testing.assert_array_equal(contact, [False, True, False])


@pytest.mark.parametrize("convention", list(physics.CONVENTIONS))
def test_one_point_reproduces_its_value_in_an_array_bit_for_bit(convention):
    # A one-point call runs the kernel on Python floats; an array call runs numpy's loops. Every
    # input varied over (most of) its range, zero speeds, viscosities and adhesion included.
    # evaluate_point answers the same point as Python floats, every output in OUTPUTS order.
    n = 1500
    params = _random_inputs(n, seed=21)
    whole = evaluate(convention=convention, **params).to_dict()
    for i in range(n):
        inputs = {k: v[i].item() for k, v in params.items()}
        point = evaluate(convention=convention, **inputs)
        floats = physics.evaluate_point(convention=convention, **inputs)
        assert list(floats) == list(OUTPUTS)
        for name in OUTPUTS:
            value = getattr(point, name)
            assert isinstance(value, np.float64) and value == whole[name][i], (i, name)
            assert type(floats[name]) is float and floats[name] == whole[name][i], (i, name)


def test_evaluate_point_refuses_what_evaluate_refuses_and_arrays():
    # The same checks as evaluate, by the same messages; an array input is named.
    cases = [{"balls": 4, "load_N": -1e-3, "speed_m_s": 0.1},
             {"balls": "4", "load_N": 1e-3, "speed_m_s": 0.1}, {"balls": 4, "load_N": None, "speed_m_s": 0.1},
             {"balls": 4, "speed_m_s": 0.1},
             {"balls": 4, "load_N": 1e-3, "speed_m_s": 0.1, "colour": 1.0},
             {"balls": 4, "load_N": 1e-3, "speed_m_s": float("nan")}]
    for case in cases:
        with pytest.raises(ValueError) as by_evaluate:
            evaluate(**case)
        with pytest.raises(ValueError) as by_point:
            physics.evaluate_point(**case)
        assert str(by_point.value) == str(by_evaluate.value), case
    with pytest.raises(ValueError, match="convention"):
        physics.evaluate_point(convention="nonsense", balls=4, load_N=1e-3, speed_m_s=0.1)
    with pytest.raises(ValueError, match=r"^speed_m_s must be a scalar"):
        physics.evaluate_point(balls=4, load_N=1e-3, speed_m_s=[0.1, 0.2])


@pytest.mark.parametrize("n", [None, 3 * bearing._BLOCK_POINTS + 5])
def test_outputs_that_skip_the_extras_keep_their_bits(n):
    # Asking only for outputs that others need (mu, forces, moments) skips the rest of the kernel;
    # what is returned is what a call with every output returns. n None: one scalar point.
    params = _random_inputs(1 if n is None else n, seed=23)
    if n is None:
        params = {k: v[0].item() for k, v in params.items()}
    core = ["mu", "friction_force_N", "contact_radius_m", "sliding_force_N", "ball_ball_moment_Nm"]
    some, full = evaluate(outputs=core, **params), evaluate(**params)
    for name in core:
        np.testing.assert_array_equal(getattr(some, name), getattr(full, name), err_msg=name)
    assert some.mu_contact is None and some.max_contact_pressure_Pa is None


@pytest.mark.parametrize(("name", "bad", "match"), [
    ("speed_m_s", math.nan, "speed_m_s must be in .* and finite; got nan at index 200001$"),
    ("load_N", -1.0, r"load_N must be in \[1e-09, 1e\+06\] \[N\]; got -1.0 at index 200001$"),
    ("balls", 4.5, "balls must be a whole number .*; got 4.5 at index 200001$")])
def test_a_large_array_is_checked_to_its_last_chunk(name, bad, match):
    # Large arrays are checked chunk by chunk: a refused value past the first chunks is found and
    # named with its index, in a contiguous array and in a strided view of one.
    n = 300_000
    values = np.full(n, 4.0 if name == "balls" else 1e-2)
    values[200_001] = bad
    with pytest.raises(ValueError, match=match):
        physics.validate(name, values)
    strided = np.full(2 * n, 4.0 if name == "balls" else 1e-2)[::2]
    strided[200_001] = bad
    with pytest.raises(ValueError, match=match):
        physics.validate(name, strided)
    values[200_001] = values[0]
    assert physics.validate(name, values) is values  # accepted as it is, not copied


def test_whole_numbers_given_as_integers_are_accepted_at_any_size():
    balls = np.arange(1, 200_001) % 50 + 1
    checked = physics.validate("balls", balls)
    assert checked.dtype == np.float64 and np.array_equal(checked, balls)
    with pytest.raises(ValueError, match=r"balls must be .*; got 0.0 at index 7$"):
        physics.validate("balls", np.where(np.arange(200_000) == 7, 0, balls))
