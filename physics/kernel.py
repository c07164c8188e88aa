"""Every output of :func:`physics.evaluate` at a point, composed of the equations' own functions.

:func:`point_outputs` is the model's one kernel: it calls the functions of :mod:`physics.contact`,
:mod:`physics.surface`, :mod:`physics.moments` and :mod:`physics.balance`, one per equation, and
:func:`material` takes the factors that depend on the ball, the materials and the film only from
the same modules. The same function text runs on Python floats (one point), on numpy arrays (a
block of points, :mod:`physics.bearing`) and on traced values, from which :mod:`physics.fused`
generates the numba kernel (:mod:`physics.compiled`), so no equation is written twice. The
elementary functions come from :mod:`physics.elementary`, whose float path has the bits of numpy's
ufuncs: a point computes exactly what it computes inside an array.

References
----------
.. [1] Olaru et al., COMEC 2005, eqs. 1-23.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from . import balance, contact, elementary, lubrication, moments, surface

__all__ = ["MATERIAL_FACTORS", "MATERIAL_INPUTS", "POINT_INPUTS", "material", "point_outputs"]

#: The per-point inputs of :func:`point_outputs`, in order (names of :data:`physics.PARAMETERS`).
POINT_INPUTS = ("groove_angle_deg", "load_N", "balls", "adhesion_energy_J_m2", "speed_m_s", "mu_pivot",
                "balls_touching", "mu_ball")

#: The inputs of :func:`material`: the ball, the materials and the film.
MATERIAL_INPUTS = ("ball_diameter_m", "ball_youngs_modulus_Pa", "ball_poisson_ratio",
                   "race_youngs_modulus_Pa", "race_poisson_ratio", "viscosity_Pa_s",
                   "pressure_viscosity_1_Pa", "water_surface_tension_N_m")

#: The factors :func:`material` returns, in order.
MATERIAL_FACTORS = ("ball_diameter_m", "jkr_modulus_Pa", "log_rolling_force", "log_hysteresis_moment",
                    "pressure_per_rolling_force", "capillary_force_N", "pair_share")

_RADIANS_PER_DEGREE = math.pi / 180.0


def material(p: dict[str, Any], convention: str) -> tuple:
    """The factors of :func:`point_outputs` that depend on the ball, the materials and the film only.

    Parameters
    ----------
    p : dict
        At least the inputs of :data:`MATERIAL_INPUTS`, checked (floats, or arrays of one length). [SI]
    convention : {"olaru2005", "derjaguin"}
        Reading of the ball-ball terms (:data:`physics.CONVENTIONS`).

    Returns
    -------
    tuple
        Ball diameter d [m], JKR modulus E* [Pa] (eq 4), log of F_R at V = 1 m/s and Q = 1 N
        [log N] (eqs 9-12; -inf for a zero viscosity), log of M_ER at Q = 1 N [log N*m] (eq 15),
        F_P per newton of F_R [1] (eq 13), the ball-ball capillary force F_cb [N] (eqs 5-6) and the
        share of M_b in one contact pair's balance [1]: floats, or arrays where an input varies.

    Notes
    -----
    Eqs 9 and 15 are products of powers: F_R = F_R(V = 1, Q = 1) V^0.66 Q^0.47 and
    M_ER = M_ER(Q = 1) Q^1.33. Their coefficients are the equations' own functions at unit
    arguments; :func:`point_outputs` raises the varying quantities to the declared exponents
    (:data:`physics.lubrication.SPEED_EXPONENT`, ``LOAD_EXPONENT``,
    :data:`physics.moments.HYSTERESIS_LOAD_EXPONENT`).
    """
    d = p["ball_diameter_m"]
    radius = 0.5 * d
    moduli = (p["ball_youngs_modulus_Pa"], p["ball_poisson_ratio"], p["race_youngs_modulus_Pa"],
              p["race_poisson_ratio"])
    e_prime = contact.reduced_modulus(*moduli)
    rolling = lubrication.rolling_force(
        e_prime, radius, 1.0, lubrication.materials_parameter(p["pressure_viscosity_1_Pa"], e_prime),
        lubrication.speed_parameter(p["viscosity_Pa_s"], lubrication.entrainment_speed(1.0), e_prime, radius),
        lubrication.load_parameter(1.0, e_prime, radius))
    with np.errstate(divide="ignore"):  # a zero viscosity: log 0 = -inf, so that exp(-inf) = 0 below
        log_rolling = np.log(rolling)
    return (d, contact.jkr_effective_modulus(*moduli), log_rolling, np.log(moments.hysteresis_moment(d, 1.0)),
            lubrication.pressure_force(1.0, ball_radius_m=radius),
            surface.capillary_force(surface.ball_ball_radius(radius, radius, convention),
                                    p["water_surface_tension_N_m"]),
            balance.PAIR_SHARE[convention])


def point_outputs(point, material, extras):
    """Every output of :data:`physics.OUTPUTS`, in its order, at a point (or a block of points).

    Parameters
    ----------
    point : tuple
        The inputs of :data:`POINT_INPUTS` in order: Python floats, numpy arrays (or scalars) that
        broadcast, or (compiled) float64 values with ``balls_touching`` as 0.0 or 1.0. [SI, deg]
    material : tuple
        :func:`material`'s factors, of the same kinds.
    extras : bool
        Whether to compute the contact area, the peak pressure, F_P, mu_contact and the breakdown
        of μ, which no other output needs; when False they are 0.0.

    Returns
    -------
    tuple
        The 21 outputs of :data:`physics.OUTPUTS` in order, in their units.
    """
    theta_deg, load, balls, gamma, speed, mu_pivot, touching, mu_ball = point
    d, e_star, log_rolling, log_hysteresis, pressure_per_rolling, capillary, pair_share = material
    radius = 0.5 * d
    # Groove geometry: tan in one pass (numpy's float64 cos is several times slower), cos from it.
    tan = elementary.tan(theta_deg * _RADIANS_PER_DEGREE)
    cos = 1.0 / elementary.sqrt(tan * tan + 1.0)
    q0 = contact.ball_race_load(load, balls, cos)  # eq 7
    adhesion = surface.adhesion_force_ball_flat(radius, gamma)  # eq 1
    q = contact.jkr_contact_load(q0, radius, gamma)  # eq 8
    a = contact.jkr_contact_radius(q, radius, e_star)  # eq 3
    # Eqs 9 and 15 (see material): the powers as exponentials of logarithms, log Q serving both (a
    # power costs a log and an exp); V = 0 or a zero viscosity give exp(-inf) = 0.
    log_q = elementary.log(q)
    log_speed = elementary.log(speed)
    f_r = elementary.exp(lubrication.LOAD_EXPONENT * log_q + lubrication.SPEED_EXPONENT * log_speed
                         + log_rolling)
    m_er = elementary.exp(moments.HYSTERESIS_LOAD_EXPONENT * log_q + log_hysteresis)
    m_p = moments.pivoting_moment(mu_pivot, q, a)  # eq 16
    # Eqs 5-6 and 17 where balls touch a neighbour (balance.ball_ball_contact: touching, two balls or more).
    f_cb = capillary * ((balls >= balance.MIN_BALLS_TOUCHING) * touching)
    m_b = moments.ball_ball_moment(mu_ball, f_cb, d)
    m_b_pair = pair_share * m_b
    f_s = balance.sliding_force(m_b_pair, m_p, m_er, f_r, d, cos, tan)  # eq 20
    ball_race = balance.ball_race_force(f_s, f_r)  # eq 21
    total = balance.total_friction_force(ball_race, balls)  # eq 22
    mu = balance.friction_coefficient(total, load)  # eq 23
    if extras:
        # The breakdown of μ: each term of F_S (and the F_R eq 21 adds) carried through eqs 21-23.
        per_newton = balance.friction_coefficient(balance.total_friction_force(
            balance.ball_race_force(1.0, 0.0), balls), load)
        ball_ball, pivoting, hysteresis, rolling = balance.sliding_force_terms(m_b_pair, m_p, m_er, f_r, d,
                                                                               cos, tan)
        mu_ball_ball, mu_pivoting = ball_ball * per_newton, pivoting * per_newton
        mu_hysteresis, mu_rolling = hysteresis * per_newton, (rolling + f_r) * per_newton
        mu_contact = ball_race / (2.0 * q0)  # the paper's Fig. 5 coefficient
        area = contact.contact_area(a)  # eq 3
        pressure = contact.max_contact_pressure(q, a)
        f_p = pressure_per_rolling * f_r  # eq 13
    else:
        mu_contact = mu_pivoting = mu_hysteresis = mu_rolling = mu_ball_ball = area = pressure = f_p = 0.0
    return (mu, mu_contact, total, mu_pivoting, mu_hysteresis, mu_rolling, mu_ball_ball, q0, q, a, area,
            pressure, adhesion, f_cb, f_r, f_p, f_s, m_er, m_p, m_b, ball_race)
