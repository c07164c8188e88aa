"""One test per equation of Olaru et al. (2005), each against a hand calculation.

The worked example is the paper's case A: stainless-steel balls of 285 um
(E = 2.1e11 Pa, nu = 0.3) on silicon (E = 1.5e11 Pa, nu = 0.3), 4 balls,
slider of 0.9 g, theta = 54.7 deg, water film (eta0 = 1e-3 Pa s,
alpha = 1e-8 1/Pa), gamma = 0.18 J/m^2, V = 0.1 m/s. Every expected value is
computed here with the math module, independently of numpy broadcasting.
"""

import math

import numpy as np
import pytest

from microbearing.physics import bearing, contact, lubrication, moments, surface

D = 285e-6
R = D / 2
E1, NU1, E2, NU2 = 2.1e11, 0.3, 1.5e11, 0.3
G = 0.9e-3 * 9.80665
Z = 4
THETA = math.radians(54.7)
GAMMA = 0.18
GAMMA_W = 0.0717
ETA0, ALPHA = 1e-3, 1e-8
V = 0.1

COMPLIANCE = (1 - NU1**2) / E1 + (1 - NU2**2) / E2
E_STAR = 1 / (0.75 * COMPLIANCE)
E_PRIME = 2 / COMPLIANCE
Q0 = G / (2 * Z * math.cos(THETA))
C_ADH = 6 * math.pi * GAMMA * R
Q = Q0 + C_ADH + math.sqrt(12 * math.pi * GAMMA * R * Q0 + C_ADH**2)
A = (R * Q / E_STAR) ** (1 / 3)


def test_eq1_adhesion_ball_flat():
    # 3 pi gamma R: 3 * 3.14159 * 0.18 * 142.5e-6 = 241.7 uN, inside the paper's 200-300 uN
    expected = 3 * math.pi * 0.18 * 142.5e-6
    assert surface.adhesion_force_ball_flat(R, GAMMA) == pytest.approx(expected, rel=1e-12)
    assert 200e-6 < expected < 300e-6


def test_eq2_adhesion_two_balls_equal_radii_is_half_the_flat_value():
    expected = 3 * math.pi * GAMMA / (2 / R)
    assert surface.adhesion_force_two_balls(R, R, GAMMA) == pytest.approx(expected, rel=1e-12)
    assert expected == pytest.approx(0.5 * 3 * math.pi * GAMMA * R)


def test_eq3_contact_radius_and_area():
    assert contact.jkr_contact_radius(Q, R, E_STAR) == pytest.approx(A, rel=1e-12)
    assert contact.contact_area(A) == pytest.approx(math.pi * A * A, rel=1e-12)
    # without adhesion a is the Hertz radius (3 Q R / (4 E))^(1/3), E the plane-strain modulus
    hertz = (3 * Q0 * R / (4 * (1 / COMPLIANCE))) ** (1 / 3)
    assert contact.jkr_contact_radius(Q0, R, E_STAR) == pytest.approx(hertz, rel=1e-12)


def test_eq4_effective_moduli_match_the_printed_values():
    assert contact.jkr_effective_modulus(E1, NU1, E2, NU2) == pytest.approx(E_STAR, rel=1e-12)
    assert E_STAR == pytest.approx(1.282e11, rel=1e-3)
    assert contact.reduced_modulus(E1, NU1, E2, NU2) == pytest.approx(1.923e11, rel=1e-3)


def test_eq5_capillary_force():
    assert surface.capillary_force(R, GAMMA_W) == pytest.approx(4 * math.pi * 0.0717 * 142.5e-6, rel=1e-12)


@pytest.mark.parametrize(("convention", "expected"), [("olaru2005", R / 4), ("derjaguin", R / 2)])
def test_eq6_ball_ball_radius(convention, expected):
    assert surface.ball_ball_radius(R, R, convention) == pytest.approx(expected, rel=1e-12)


def test_eq6_unknown_convention_is_rejected():
    with pytest.raises(ValueError, match="convention"):
        surface.ball_ball_radius(R, R, "hertz")


def test_eq7_ball_race_load():
    # 0.9 g slider on 4 balls at 54.7 deg: 8.826e-3 / (8 * 0.5779) = 1.909 mN
    assert contact.ball_race_load(G, Z, math.cos(THETA)) == pytest.approx(Q0, rel=1e-12)
    assert Q0 == pytest.approx(1.909e-3, rel=1e-3)


def test_eq8_jkr_load_adds_adhesion_and_reduces_to_hertz():
    assert contact.jkr_contact_load(Q0, R, GAMMA) == pytest.approx(Q, rel=1e-12)
    assert contact.jkr_contact_load(Q0, R, 0.0) == pytest.approx(Q0, rel=1e-15)
    # at zero applied load the ball still sticks: Q = 12 pi gamma R
    assert contact.jkr_contact_load(0.0, R, GAMMA) == pytest.approx(12 * math.pi * GAMMA * R, rel=1e-12)


def test_eqs9_to_12_houpert_rolling_force():
    g_bar = ALPHA * E_PRIME
    u = ETA0 * (V / 2) / (E_PRIME * R)
    w = Q / (E_PRIME * R**2)
    expected = 2.86 * E_PRIME * R**2 * 1.0**0.348 * g_bar**0.022 * u**0.66 * w**0.47
    assert lubrication.materials_parameter(ALPHA, E_PRIME) == pytest.approx(g_bar, rel=1e-12)
    assert lubrication.entrainment_speed(V) == pytest.approx(V / 2)
    assert lubrication.speed_parameter(ETA0, V / 2, E_PRIME, R) == pytest.approx(u, rel=1e-12)
    assert lubrication.load_parameter(Q, E_PRIME, R) == pytest.approx(w, rel=1e-12)
    assert lubrication.rolling_force(E_PRIME, R, 1.0, g_bar, u, w) == pytest.approx(expected, rel=1e-12)
    by_name = lubrication.rolling_force(reduced_modulus_Pa=E_PRIME, radius_x_m=R, radius_ratio=1.0,
                                        materials_parameter=g_bar, speed_parameter=u, load_parameter=w)
    assert by_name == pytest.approx(expected, rel=1e-12)


def test_eq13_pressure_force_flat_and_curved_race():
    assert lubrication.pressure_force(3.0, ball_radius_m=R) == pytest.approx(6.0)
    assert lubrication.pressure_force(3.0, race_radius_m=3 * R, ball_radius_m=R) == pytest.approx(4.5)
    # 2 F_R R_R / (R_R + R_b) = 2 * 1 mm / 1.1425 mm for a 142.5 um ball on a 1 mm race
    assert lubrication.pressure_force(1.0, ball_radius_m=142.5e-6, race_radius_m=1e-3) == pytest.approx(
        2e-3 / 1.1425e-3, rel=1e-12)
    with pytest.raises(TypeError):  # no silent default ball radius, and no positional radii
        lubrication.pressure_force(1.0, 1e-3)
    with pytest.raises(ValueError, match="ball_radius_m"):
        lubrication.pressure_force(1.0, ball_radius_m=0.0)


def test_eq15_hysteresis_moment():
    expected = 7.48e-7 * (D / 2) ** 0.33 * Q**1.33
    assert moments.hysteresis_moment(D, Q) == pytest.approx(expected, rel=1e-12)
    elongated = expected * (1 - 3.519e-3 * 3**0.806)
    assert moments.hysteresis_moment(D, Q, 4.0) == pytest.approx(elongated, rel=1e-12)
    for k in (0.5, [1.0, 0.99], np.nan):  # (k - 1)^0.806 is NaN below 1: an error naming k, not a NaN
        with pytest.raises(ValueError, match=r"radius_ratio .*\[1, inf\)"):
            moments.hysteresis_moment(D, Q, k)


def test_eq16_pivoting_moment():
    assert moments.pivoting_moment(0.5, Q, A) == pytest.approx(3 / 8 * 0.5 * Q * A, rel=1e-12)


def test_eq17_ball_ball_moment():
    f_cb = 4 * math.pi * GAMMA_W * R / 4
    assert moments.ball_ball_moment(0.5, f_cb, D) == pytest.approx(0.5 * f_cb * D, rel=1e-12)


def _contact_terms(mu_b=0.5, mu_s=1.0):
    f_r = float(lubrication.rolling_force(
        E_PRIME, R, 1.0, ALPHA * E_PRIME, ETA0 * V / 2 / (E_PRIME * R), Q / (E_PRIME * R**2)))
    m_er = 7.48e-7 * (D / 2) ** 0.33 * Q**1.33
    m_p = 3 / 8 * mu_s * Q * A
    m_b = mu_b * 4 * math.pi * GAMMA_W * (R / 4) * D
    return f_r, m_er, m_p, m_b


def test_eq20_sliding_force_and_eqs18_19_balance_the_ball():
    f_r, m_er, m_p, m_b = _contact_terms()
    f_s = (m_b / math.cos(THETA) + 2 * m_p * math.tan(THETA) + 2 * m_er) / D + f_r
    computed = bearing.sliding_force(m_b, m_p, m_er, f_r, D, math.cos(THETA), math.tan(THETA))
    assert computed == pytest.approx(f_s, rel=1e-12)
    # eq 18: identical contacts, F_P on the centre cancels between slider and stator
    assert bearing.force_balance_residual(f_s, f_s, f_r, f_r, 2 * f_r, 2 * f_r) == 0.0
    # eq 19: the moments about the ball centre balance with F_S from eq 20
    residual = bearing.moment_balance_residual(m_b, m_p, m_p, m_er, m_er, f_s, f_s, f_r, f_r, D,
                                               math.cos(THETA), math.tan(THETA))
    assert abs(residual) < 1e-12 * (m_b + m_p + m_er)


def test_eq21_to_23_ball_race_force_total_and_mu():
    f_r, m_er, m_p, m_b = _contact_terms()
    f_ball = (2 * m_b / math.cos(THETA) + 4 * m_p * math.tan(THETA) + 4 * m_er) / D + 4 * f_r
    f_s = bearing.sliding_force(m_b, m_p, m_er, f_r, D, math.cos(THETA), math.tan(THETA))
    assert bearing.ball_race_force(f_s, f_r) == pytest.approx(f_ball, rel=1e-12)
    assert bearing.total_friction_force(f_ball, Z) == pytest.approx(Z * f_ball, rel=1e-12)
    assert bearing.friction_coefficient(Z * f_ball, G) == pytest.approx(Z * f_ball / G, rel=1e-12)


def test_evaluate_matches_the_hand_calculation_end_to_end():
    from microbearing.physics import evaluate

    f_r, m_er, m_p, m_b = _contact_terms(mu_b=0.5, mu_s=1.0)
    f_ball = (2 * m_b / math.cos(THETA) + 4 * m_p * math.tan(THETA) + 4 * m_er) / D + 4 * f_r
    r = evaluate(balls=Z, load_N=G, speed_m_s=V, mu_pivot=1.0, mu_ball=0.5, balls_touching=True)
    assert r.contact_load_N == pytest.approx(Q0, rel=1e-12)
    assert r.contact_load_adhesive_N == pytest.approx(Q, rel=1e-12)
    assert r.contact_radius_m == pytest.approx(A, rel=1e-12)
    assert r.max_contact_pressure_Pa == pytest.approx(3 * Q / (2 * math.pi * A * A), rel=1e-12)
    assert r.rolling_force_N == pytest.approx(f_r, rel=1e-12)
    assert r.hysteresis_moment_Nm == pytest.approx(m_er, rel=1e-12)
    assert r.pivoting_moment_Nm == pytest.approx(m_p, rel=1e-12)
    assert r.ball_ball_moment_Nm == pytest.approx(m_b, rel=1e-12)
    assert r.ball_race_force_N == pytest.approx(f_ball, rel=1e-12)
    assert r.friction_force_N == pytest.approx(Z * f_ball, rel=1e-12)
    assert r.mu == pytest.approx(Z * f_ball / G, rel=1e-12)
    assert r.mu_contact == pytest.approx(f_ball / (2 * Q0), rel=1e-12)
    assert r.mu_contact == pytest.approx(r.mu * math.cos(THETA), rel=1e-12)
    assert np.ndim(r.mu) == 0


def test_eq14_shear_stress_integrated_over_the_contact():
    radii = np.array([[0.0, 1e-6], [10e-6, 37e-6]])
    tau0 = 2.5e6
    # uniform tau: tau pi a^2
    uniform = bearing.contact_shear_force(tau0, radii)
    assert np.allclose(uniform, tau0 * math.pi * radii**2, rtol=1e-13, atol=0)
    # Hertz-shaped tau0 sqrt(1 - r^2/a^2): 2 pi tau0 a^2 int_0^1 sqrt(1 - s^2) s ds = (2/3) tau0 pi a^2
    hertz = bearing.contact_shear_force(lambda r, a: tau0 * np.sqrt(1 - (r / a) ** 2), radii[1])
    assert np.allclose(hertz, 2 / 3 * tau0 * math.pi * radii[1] ** 2, rtol=1e-13, atol=0)
    # linear tau0 r / a: 2 pi tau0 a^2 int_0^1 s^2 ds = (2/3) pi tau0 a^2; quadratic (r/a)^2: pi tau0 a^2 / 2
    a = 20e-6
    assert bearing.contact_shear_force(lambda r, aa: tau0 * r / aa, a) == pytest.approx(
        2 / 3 * math.pi * tau0 * a**2, rel=1e-13)
    assert bearing.contact_shear_force(lambda r, aa: tau0 * (r / aa) ** 2, a) == pytest.approx(
        math.pi * tau0 * a**2 / 2, rel=1e-13)
    # Coulomb shear mu_s p under the JKR-free Hertz pressure p0 sqrt(1 - r^2/a^2), p0 = 3Q/(2 pi a^2): mu_s Q
    p0 = 3 * Q / (2 * math.pi * A**2)
    coulomb = bearing.contact_shear_force(lambda r, aa: 0.3 * p0 * np.sqrt(1 - (r / aa) ** 2), A)
    assert coulomb == pytest.approx(0.3 * Q, rel=1e-12)
    with pytest.raises(ValueError, match="contact_radius_m"):
        bearing.contact_shear_force(tau0, -1e-6)
