"""physics.evaluate: shapes, properties of the model, and validation of its inputs."""

import math

import numpy as np
import pytest

from microbearing import physics
from microbearing.physics import OUTPUTS, PARAMETERS, evaluate

BASE = {"balls": 4, "load_N": 8.8e-3, "speed_m_s": 0.05}


@pytest.mark.parametrize(
    ("speed", "shape"),
    [(0.05, ()), ([0.0, 0.05, 0.1], (3,)), (np.linspace(0, 0.1, 6).reshape(2, 3), (2, 3))],
)
def test_scalar_list_and_array_inputs_keep_their_shapes(speed, shape):
    r = evaluate(**{**BASE, "speed_m_s": speed})
    for name in OUTPUTS:
        assert np.shape(getattr(r, name)) == shape, name


def test_arrays_broadcast_like_numpy_and_match_pointwise_evaluation():
    balls = np.array([3, 4, 10])[:, None]
    load = np.array([1e-3, 1e-2])[None, :]
    grid = evaluate(balls=balls, load_N=load, speed_m_s=0.02, balls_touching=True)
    assert grid.mu.shape == (3, 2)
    for i, z in enumerate([3, 4, 10]):
        for j, g in enumerate([1e-3, 1e-2]):
            point = evaluate(balls=z, load_N=g, speed_m_s=0.02, balls_touching=True)
            assert grid.mu[i, j] == pytest.approx(float(point.mu), rel=1e-14)


def test_breakdown_sums_to_mu():
    rng = np.random.default_rng(1)
    n = 500
    r = evaluate(balls=rng.integers(1, 50, n), load_N=rng.uniform(1e-4, 1e-1, n),
                 speed_m_s=rng.uniform(0, 0.3, n), groove_angle_deg=rng.uniform(5, 85, n),
                 balls_touching=rng.random(n) < 0.5, adhesion_energy_J_m2=rng.uniform(0, 0.3, n))
    parts = r.mu_pivoting + r.mu_hysteresis + r.mu_rolling + r.mu_ball_ball
    np.testing.assert_allclose(parts, r.mu, rtol=1e-12)
    assert np.all(r.mu > 0)


def test_mu_grows_with_mu_pivot_and_mu_ball():
    mu_s = evaluate(**BASE, mu_pivot=[0.1, 0.5, 1.0, 2.0]).mu
    assert np.all(np.diff(mu_s) > 0)
    mu_b = evaluate(**BASE, balls_touching=True, mu_ball=[0.1, 0.5, 1.0, 2.0]).mu
    assert np.all(np.diff(mu_b) > 0)
    # pivoting is linear in mu_s
    r = evaluate(**BASE, mu_pivot=[0.5, 1.0])
    assert r.mu_pivoting[1] == pytest.approx(2 * r.mu_pivoting[0], rel=1e-12)


def test_adhesion_only_adds():
    r = evaluate(**BASE, balls_touching=True, adhesion_energy_J_m2=[0.0, 0.05, 0.18, 0.3])
    assert np.all(np.diff(r.mu) > 0)
    assert np.all(np.diff(r.contact_load_adhesive_N) > 0)


def test_speed_enters_only_through_the_rolling_term():
    r = evaluate(**{**BASE, "speed_m_s": [0.0, 0.01, 0.1, 0.15]}, balls_touching=True)
    for name in ("mu_pivoting", "mu_hysteresis", "mu_ball_ball", "contact_radius_m"):
        values = getattr(r, name)
        np.testing.assert_allclose(values, values[0], rtol=1e-14)
    assert r.mu_rolling[0] == 0.0
    # F_R grows as V^0.66
    assert r.rolling_force_N[2] / r.rolling_force_N[1] == pytest.approx(10**0.66, rel=1e-12)
    assert np.all(np.diff(r.mu) > 0)


def test_balls_apart_have_no_ball_ball_term():
    r = evaluate(**BASE, balls_touching=False)
    assert r.mu_ball_ball == 0.0
    assert r.capillary_force_ball_ball_N == 0.0


def test_conventions_agree_for_equal_balls():
    a = evaluate(**BASE, balls_touching=True, convention="olaru2005")
    b = evaluate(**BASE, balls_touching=True, convention="derjaguin")
    assert a.mu == pytest.approx(float(b.mu), rel=1e-14)
    assert b.ball_ball_moment_Nm == pytest.approx(2 * float(a.ball_ball_moment_Nm), rel=1e-14)


def test_material_presets_feed_evaluate():
    soft = evaluate(**BASE, **physics.material_parameters("stainless_steel", "borosilicate_glass"))
    stiff = evaluate(**BASE, **physics.material_parameters("silicon_nitride", "silicon"))
    # a softer race gives a larger contact and a larger pivoting moment
    assert soft.contact_radius_m > stiff.contact_radius_m
    assert soft.mu_pivoting > stiff.mu_pivoting
    with pytest.raises(ValueError, match="ball material"):
        physics.material_parameters("unobtainium", "silicon")


def test_defaults_are_the_papers_conditions():
    d = physics.defaults()
    assert d["ball_diameter_m"] == 285e-6
    assert d["groove_angle_deg"] == 54.7
    assert d["water_surface_tension_N_m"] == 0.0717
    assert (d["viscosity_Pa_s"], d["pressure_viscosity_1_Pa"]) == (1e-3, 1e-8)
    assert {p.name for p in PARAMETERS.values() if p.required} == {"balls", "load_N", "speed_m_s"}


@pytest.mark.parametrize(
    ("override", "match"),
    [
        ({"load_N": -1.0}, r"load_N must be in \[1e-09, 1e\+06\] \[N\]; got -1.0"),
        ({"load_N": 0.0}, r"load_N must be in \[1e-09, "),
        ({"load_N": 5e-324}, r"load_N must be in \[1e-09, .*got 5e-324"),
        ({"groove_angle_deg": 90.0}, r"groove_angle_deg must be in \[0.01, 89.99\] \[deg\]"),
        ({"groove_angle_deg": 0.0}, r"groove_angle_deg must be in \[0.01, 89.99\]"),
        ({"groove_angle_deg": 5e-324}, r"groove_angle_deg must be in \[0.01, 89.99\]"),
        ({"balls": 0}, r"balls must be a whole number in \[1, 1e\+06\]"),
        ({"balls": 2.5}, r"balls must be a whole number"),
        ({"speed_m_s": math.nan}, r"speed_m_s must be .* and finite; got nan"),
        ({"speed_m_s": [0.1, math.inf]}, r"speed_m_s .* finite; got inf at index 1"),
        ({"load_N": "heavy"}, r"load_N must be in \[1e-09, 1e\+06\] \[N\]; got 'heavy'"),
        ({"load_N": True}, r"load_N .* got a boolean"),
        ({"balls_touching": 1.0}, r"balls_touching must be true or false"),
        ({"ball_poisson_ratio": 0.5}, r"ball_poisson_ratio must be in \[0, 0.5\)"),
        ({"adhesion_energy_J_m2": -0.1}, r"adhesion_energy_J_m2 must be in \[0, 10\]"),
        ({"mu_pivot": -1}, r"mu_pivot must be in \[0, 10\]"),
        ({"colour": "red"}, r"unknown parameter\(s\) colour"),
    ],
)
def test_bad_input_raises_value_error_naming_parameter_and_range(override, match):
    with pytest.raises(ValueError, match=match):
        evaluate(**{**BASE, **override})


def test_missing_required_parameter_is_named():
    with pytest.raises(ValueError, match=r"missing required parameter.*speed_m_s"):
        evaluate(balls=4, load_N=1e-3)


def test_shapes_that_do_not_broadcast_are_rejected():
    with pytest.raises(ValueError, match="do not broadcast"):
        evaluate(balls=[3, 4], load_N=[1e-3, 2e-3, 3e-3], speed_m_s=0.0)


def test_unknown_convention_is_rejected():
    with pytest.raises(ValueError, match="convention must be one of"):
        evaluate(**BASE, convention="hertz")


def test_every_output_is_finite_at_every_corner_of_the_parameter_box():
    # 2**16 designs: each parameter at the lowest and highest value it accepts
    corners = {}
    for p in PARAMETERS.values():
        if p.kind == "bool":
            corners[p.name] = [False, True]
            continue
        lo = np.nextafter(p.minimum, np.inf) if p.exclusive_minimum else p.minimum
        hi = np.nextafter(p.maximum, -np.inf) if p.exclusive_maximum else p.maximum
        corners[p.name] = [lo, hi]
    grid = np.meshgrid(*[np.arange(2)] * len(corners), indexing="ij")
    points = {n: np.asarray(v)[g.ravel()] for (n, v), g in zip(corners.items(), grid, strict=True)}
    with np.errstate(over="raise", invalid="raise", divide="raise"):
        r = evaluate(**points)
    for name in OUTPUTS:
        assert np.all(np.isfinite(getattr(r, name))), name
        assert np.all(getattr(r, name) >= 0), name


def test_no_nan_anywhere_on_a_wide_random_domain():
    rng = np.random.default_rng(7)
    n = 20_000
    specs = [p for p in PARAMETERS.values() if p.kind == "float"]
    params = {}
    for p in specs:
        lo = p.minimum if p.minimum is not None else 0.0
        hi = min(p.maximum, 10 * (p.default or 1.0)) if p.maximum is not None else 10 * (p.default or 1.0)
        params[p.name] = rng.uniform(lo, hi, n)
    params["groove_angle_deg"] = rng.uniform(1, 89, n)
    params["load_N"] = 10 ** rng.uniform(-6, 1, n)
    params["ball_diameter_m"] = 10 ** rng.uniform(-6, -2, n)
    params["balls"] = rng.integers(1, 100, n)
    params["balls_touching"] = rng.random(n) < 0.5
    r = evaluate(**params)
    for name in OUTPUTS:
        assert np.all(np.isfinite(getattr(r, name))), name


def _random_inputs(n, seed):
    """Every input varied over (most of) its allowed range."""
    rng = np.random.default_rng(seed)
    return {
        "balls": rng.integers(1, 60, n), "groove_angle_deg": rng.uniform(0.01, 89.99, n),
        "load_N": 10 ** rng.uniform(-9, 6, n), "speed_m_s": np.where(rng.random(n) < 0.1, 0.0,
                                                                     rng.uniform(0, 1e3, n)),
        "balls_touching": rng.random(n) < 0.5, "mu_pivot": rng.uniform(0, 10, n),
        "mu_ball": rng.uniform(0, 10, n),
        "adhesion_energy_J_m2": np.where(rng.random(n) < 0.1, 0.0, rng.uniform(0, 10, n)),
        "ball_diameter_m": 10 ** rng.uniform(-7, -1, n), "water_surface_tension_N_m": rng.uniform(0, 1, n),
        "viscosity_Pa_s": np.where(rng.random(n) < 0.1, 0.0, 10 ** rng.uniform(-5, 3, n)),
        "pressure_viscosity_1_Pa": 10 ** rng.uniform(-12, -6, n),
        "ball_youngs_modulus_Pa": 10 ** rng.uniform(6, 13, n), "ball_poisson_ratio": rng.uniform(0, 0.499, n),
        "race_youngs_modulus_Pa": 10 ** rng.uniform(6, 13, n), "race_poisson_ratio": rng.uniform(0, 0.499, n),
    }


def _composed(convention, **params):
    """Every output by the plain composition of the equations' functions (the reference)."""
    from microbearing.physics import bearing, contact, lubrication, moments, surface

    p = physics.validate_all(params)
    theta = np.radians(p["groove_angle_deg"])
    cos, tan = np.cos(theta), np.tan(theta)
    d = p["ball_diameter_m"]
    moduli = (p["ball_youngs_modulus_Pa"], p["ball_poisson_ratio"], p["race_youngs_modulus_Pa"],
              p["race_poisson_ratio"])
    e_prime = contact.reduced_modulus(*moduli)
    q0 = contact.ball_race_load(p["load_N"], p["balls"], cos)
    q = contact.jkr_contact_load(q0, d / 2, p["adhesion_energy_J_m2"])
    a = contact.jkr_contact_radius(q, d / 2, contact.jkr_effective_modulus(*moduli))
    f_r = lubrication.rolling_force(
        e_prime, d / 2, 1.0, lubrication.materials_parameter(p["pressure_viscosity_1_Pa"], e_prime),
        lubrication.speed_parameter(p["viscosity_Pa_s"], lubrication.entrainment_speed(p["speed_m_s"]),
                                    e_prime, d / 2),
        lubrication.load_parameter(q, e_prime, d / 2))
    m_er, m_p = moments.hysteresis_moment(d, q), moments.pivoting_moment(p["mu_pivot"], q, a)
    # one ball (balls counts both grooves) has no neighbour to touch
    f_cb = np.where(p["balls_touching"] & (p["balls"] > 1), surface.capillary_force(
        surface.ball_ball_radius(d / 2, d / 2, convention), p["water_surface_tension_N_m"]), 0.0)
    m_b = moments.ball_ball_moment(p["mu_ball"], f_cb, d)
    m_b_pair = m_b if convention == "olaru2005" else 0.5 * m_b
    f_s = bearing.sliding_force(m_b_pair, m_p, m_er, f_r, d, cos, tan)
    f_ball = bearing.ball_race_force(f_s, f_r)
    f_total = bearing.total_friction_force(f_ball, p["balls"])
    per_newton = 2 * p["balls"] / p["load_N"]
    return {
        "mu": bearing.friction_coefficient(f_total, p["load_N"]), "mu_contact": f_ball / (2 * q0),
        "friction_force_N": f_total, "mu_pivoting": per_newton * 2 * m_p * tan / d,
        "mu_hysteresis": per_newton * 2 * m_er / d, "mu_rolling": per_newton * 2 * f_r,
        "mu_ball_ball": per_newton * m_b_pair / (cos * d), "contact_load_N": q0,
        "contact_load_adhesive_N": q, "contact_radius_m": a, "contact_area_m2": contact.contact_area(a),
        "max_contact_pressure_Pa": contact.max_contact_pressure(q, a),
        "adhesion_force_N": surface.adhesion_force_ball_flat(d / 2, p["adhesion_energy_J_m2"]),
        "capillary_force_ball_ball_N": f_cb, "rolling_force_N": f_r,
        "pressure_force_N": lubrication.pressure_force(f_r, ball_radius_m=d / 2), "sliding_force_N": f_s,
        "hysteresis_moment_Nm": m_er, "pivoting_moment_Nm": m_p, "ball_ball_moment_Nm": m_b,
        "ball_race_force_N": f_ball,
    }


@pytest.mark.parametrize("convention", list(physics.CONVENTIONS))
def test_every_output_agrees_with_the_composition_of_the_equations(convention):
    # evaluate runs an in-place blocked kernel (power laws as exp of logs, tan instead of cos); the
    # reference composes the equations' own functions. Several blocks and a short last one, every
    # input varied over its whole range; angles kept >= 1 deg, where cos-based tan is still accurate.
    from microbearing.physics import bearing

    n = 2 * bearing._BLOCK_POINTS + 1234
    params = _random_inputs(n, seed=7)
    params["groove_angle_deg"] = np.random.default_rng(8).uniform(1, 89, n)
    result = evaluate(convention=convention, **params)
    with np.errstate(all="ignore"):  # 0 ** 0.66 and friends in the reference
        reference = _composed(convention, **params)
    for name in OUTPUTS:
        np.testing.assert_allclose(getattr(result, name), reference[name], rtol=1e-12, atol=0, err_msg=name)


def test_results_do_not_depend_on_how_the_points_are_batched():
    # Every point runs the same operations whatever the size of the call: chunked or single-point
    # calls reproduce a large call bit for bit (the service's executors rely on it).
    params = _random_inputs(3 * 4096 + 17, seed=9)
    whole = evaluate(**params).to_dict()
    for start, stop in [(0, 1), (5, 6), (100, 2148), (12_000, 12_305)]:
        part = evaluate(**{k: v[start:stop] for k, v in params.items()}).to_dict()
        for name in OUTPUTS:
            np.testing.assert_array_equal(whole[name][start:stop], part[name], err_msg=name)
    single = evaluate(**{k: v[3].item() for k, v in params.items()})
    assert float(single.mu) == whole["mu"][3]


@pytest.mark.parametrize("threads", [2, 3])
def test_threaded_calls_reproduce_a_single_thread_bit_for_bit(threads):
    # Large calls split their blocks into contiguous runs, one per thread; every point still runs the
    # same operations, so the result cannot depend on the thread count. 9 blocks and a short tenth: the
    # runs are uneven for 3 threads, and outputs not asked for use each thread's own scratch rows.
    from concurrent.futures import ThreadPoolExecutor

    from microbearing.physics import ExecutionOptions, bearing

    params = _random_inputs(9 * bearing._BLOCK_POINTS + 77, seed=11)
    wanted = ["mu", "contact_radius_m", "friction_force_N"]
    serial_all, serial_some = evaluate(**params).to_dict(), evaluate(outputs=wanted, **params)
    with ThreadPoolExecutor(threads) as pool:
        execution = ExecutionOptions(threads=threads, executor=pool)
        threaded_all = evaluate(execution=execution, **params).to_dict()
        threaded_some = evaluate(outputs=wanted, execution=execution, **params)
        # and a zero speed (log 0 = -inf inside the kernel) stays silent in the worker threads too
        zero = evaluate(execution=execution, **{**params, "speed_m_s": 0.0})
    for name in OUTPUTS:
        np.testing.assert_array_equal(threaded_all[name], serial_all[name], err_msg=name)
    for name in wanted:
        np.testing.assert_array_equal(getattr(threaded_some, name), getattr(serial_some, name), err_msg=name)
    assert np.all(zero.rolling_force_N == 0) and np.all(np.isfinite(zero.mu))


@pytest.mark.parametrize("value", ["two", 1.5, 0])
def test_a_bad_thread_count_is_named(value):
    from microbearing.physics import ExecutionOptions

    with pytest.raises(ValueError, match="threads must be a whole number >= 1"):
        ExecutionOptions(threads=value)


def test_threads_need_an_executor_as_physics_starts_none():
    from microbearing.physics import ExecutionOptions

    with pytest.raises(ValueError, match="threads=2 needs an executor"):
        ExecutionOptions(threads=2)


def test_large_inputs_match_a_hand_composition_of_the_equation_functions():
    from microbearing.physics import contact, lubrication, moments, surface

    n = 40_000
    rng = np.random.default_rng(3)
    z, theta = rng.integers(3, 41, n), rng.uniform(30, 75, n)
    load, speed = 10 ** rng.uniform(-3, -1.3, n), rng.uniform(0, 0.2, n)
    gamma, mu_s = rng.uniform(0, 0.3, n), rng.uniform(0.1, 1, n)
    r = evaluate(balls=z, groove_angle_deg=theta, load_N=load, speed_m_s=speed, adhesion_energy_J_m2=gamma,
                 mu_pivot=mu_s, balls_touching=True)
    d, e1, e2, nu = 285e-6, 2.1e11, 1.5e11, 0.3
    cos, tan = np.cos(np.radians(theta)), np.tan(np.radians(theta))
    q0 = load / (2 * z * cos)
    q = contact.jkr_contact_load(q0, d / 2, gamma)
    a = contact.jkr_contact_radius(q, d / 2, contact.jkr_effective_modulus(e1, nu, e2, nu))
    e_prime = contact.reduced_modulus(e1, nu, e2, nu)
    f_r = lubrication.rolling_force(e_prime, d / 2, 1.0, lubrication.materials_parameter(1e-8, e_prime),
                                    lubrication.speed_parameter(1e-3, speed / 2, e_prime, d / 2),
                                    lubrication.load_parameter(q, e_prime, d / 2))
    m_b = moments.ball_ball_moment(0.5, surface.capillary_force(d / 8, 0.0717), d)
    f_s = (m_b / cos + 2 * moments.pivoting_moment(mu_s, q, a) * tan
           + 2 * moments.hysteresis_moment(d, q)) / d + f_r
    np.testing.assert_allclose(r.contact_load_adhesive_N, q, rtol=1e-13)
    np.testing.assert_allclose(r.rolling_force_N, f_r, rtol=1e-13)
    np.testing.assert_allclose(r.mu, z * 2 * (f_s + f_r) / load, rtol=1e-12)


@pytest.mark.parametrize("n", [1, 50_000])
def test_tan_of_small_groove_angles_is_accurate(n):
    # tan θ = sqrt(1 - cos²) / cos loses ~1e-8 to cancellation at θ = 0.01 deg; the pivoting term
    # carries tan θ: mu_pivoting = (2 z / G) (2 / d) M_P tan θ.
    theta = 0.01
    r = evaluate(balls=4, load_N=np.full(n, 8.8e-3), speed_m_s=0.05, groove_angle_deg=theta)
    expected_tan = (r.mu_pivoting / (2 * 4 / 8.8e-3) / (2 / 285e-6) / r.pivoting_moment_Nm)
    np.testing.assert_allclose(expected_tan, math.tan(math.radians(theta)), rtol=1e-13)


@pytest.mark.parametrize("n", [3, 30_000])
def test_outputs_selects_what_is_stored(n):
    params = {**BASE, "load_N": np.linspace(1e-3, 5e-2, n)}
    full = evaluate(**params)
    some = evaluate(outputs=["mu", "contact_radius_m"], **params)
    np.testing.assert_array_equal(some.mu, full.mu)
    np.testing.assert_array_equal(some.contact_radius_m, full.contact_radius_m)
    assert some.friction_force_N is None and some.mu_pivoting is None
    assert list(some.to_dict()) == ["mu", "contact_radius_m"]
    with pytest.raises(ValueError, match="friction_force_N were not computed"):
        some.to_dict(["friction_force_N"])
    np.testing.assert_array_equal(evaluate(outputs="mu", **params).mu, full.mu)
    with pytest.raises(ValueError, match="outputs must be names from mu, "):
        evaluate(outputs=["mu", "torque"], **params)


def test_large_inputs_of_any_layout_keep_their_shapes():
    rng = np.random.default_rng(4)
    fortran = np.asfortranarray(rng.uniform(1e-3, 5e-2, (300, 40)))
    reversed_speed = rng.uniform(0, 0.2, (300, 40))[:, ::-1]
    r = evaluate(balls=np.arange(3, 43)[None, :], load_N=fortran, speed_m_s=reversed_speed)
    assert r.mu.shape == (300, 40)
    point = evaluate(balls=10, load_N=float(fortran[123, 7]), speed_m_s=float(reversed_speed[123, 7]))
    assert r.mu[123, 7] == pytest.approx(float(point.mu), rel=1e-12)
    assert r.friction_force_N[123, 7] == pytest.approx(float(point.friction_force_N), rel=1e-12)
    assert evaluate(balls=4, load_N=np.ones((0, 3000)), speed_m_s=0.1).mu.shape == (0, 3000)


@pytest.mark.parametrize(("name", "bad", "match"), [
    ("load_N", np.nan, "load_N must be .* and finite; got nan at index 5000"),
    ("load_N", -1e-3, r"load_N must be in \[1e-09, 1e\+06\] \[N\]; got -0.001 at index 5000"),
    ("speed_m_s", np.inf, "speed_m_s .* got inf at index 5000"),
    ("balls", 2.5, "balls must be a whole number .* got 2.5 at index 5000"),
])
def test_large_arrays_report_the_first_bad_value(name, bad, match):
    values = np.full(10_000, 3.0 if name == "balls" else 1e-3)
    values[5000] = bad
    values[7000] = bad
    with pytest.raises(ValueError, match=match):
        evaluate(**{**BASE, name: values})


@pytest.mark.parametrize("varied", [("load_N",), ("balls", "balls_touching", "speed_m_s"),
                                    ("groove_angle_deg", "viscosity_Pa_s", "ball_diameter_m"), None])
@pytest.mark.parametrize("outputs", [["mu"], ["contact_load_N", "mu", "mu"], None])
def test_large_calls_compute_what_the_equation_functions_compute_on_the_arrays(monkeypatch, varied, outputs):
    # A large call replays the trace of kernel.point_outputs as numpy calls into a workspace
    # (physics.replay), folding what only scalars feed: the bits of point_outputs run on the arrays
    # themselves, whichever inputs vary (some, the materials, all) and whichever outputs are asked.
    from microbearing.physics import bearing, kernel

    monkeypatch.setattr(bearing, "_BLOCK_POINTS", 1500)  # several blocks and a short last one
    n = bearing._REPLAY_POINTS + 3000
    params = _random_inputs(n, seed=13)
    if varied is not None:
        params = {k: (v if k in varied else v[0].item()) for k, v in params.items()}
    result = evaluate(outputs=outputs, **params).to_dict(outputs)
    checked, _ = physics.parameters.checked_inputs(params)
    point = tuple(checked[name] for name in kernel.POINT_INPUTS)
    material = kernel.material({name: checked[name] for name in kernel.MATERIAL_INPUTS}, "olaru2005")
    with np.errstate(all="ignore"):
        reference = dict(zip(OUTPUTS, kernel.point_outputs(point, material, True), strict=True))
    for name, values in result.items():
        np.testing.assert_array_equal(values, np.broadcast_to(reference[name], (n,)), err_msg=name)
