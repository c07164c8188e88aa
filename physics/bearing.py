"""The ball's equilibrium and the bearing's friction coefficient: :func:`evaluate`.

Equations 7, 14 and 18-23 of Olaru et al. (2005): each ball is held between two
flanks of the slider and two of the stator; the sliding traction F_S at its
contacts follows from the balance of forces (eq 18) and moments (eq 19) with
the rolling, pressure, hysteresis, pivoting and ball-ball terms; the tangential
force the balls exert on the slider, divided by the load, is μ. Eq 14, F_S as
the integral of the shear stress over the contact, is :func:`contact_shear_force`;
the model never needs it, as equilibrium gives F_S.

References
----------
.. [1] Olaru et al., COMEC 2005, eqs. 7, 18-23.
.. [2] M.R.D. Balan, L. Houpert, A. Tufescu, D.N. Olaru, Lubricants 3(2), 2015
   (the ball balance F_S = ΣM/d + F_R).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from . import contact, lubrication, moments, surface
from .parameters import CONVENTIONS, DEFAULT_CONVENTION, validate_all

__all__ = [
    "FrictionResult",
    "OUTPUTS",
    "evaluate",
    "sliding_force",
    "contact_shear_force",
    "ball_race_force",
    "total_friction_force",
    "friction_coefficient",
    "force_balance_residual",
    "moment_balance_residual",
]


def sliding_force(ball_ball_moment_Nm, pivoting_moment_Nm, hysteresis_moment_Nm,
                  rolling_force_N, ball_diameter_m, cos_contact_angle, tan_contact_angle):
    r"""Sliding traction F_S at each ball-race contact, from the ball's equilibrium.

    Parameters
    ----------
    ball_ball_moment_Nm : numeric
        M_b. [N*m]
    pivoting_moment_Nm : numeric
        M_P of one contact. [N*m]
    hysteresis_moment_Nm : numeric
        M_ER of one contact. [N*m]
    rolling_force_N : numeric
        F_R of one contact. [N]
    ball_diameter_m : numeric
        d. [m]
    cos_contact_angle, tan_contact_angle : numeric
        cos θ and tan θ of the contact angle θ from the vertical. [1]

    Returns
    -------
    numeric
        F_S = F_S1 = F_S2. [N]

    Notes
    -----
    Eq 20 of [1]_, the symmetric solution of eqs 18-19 when slider and stator
    are alike (F_R1 = F_R2, M_P1 = M_P2, M_ER1 = M_ER2):

    .. math:: F_S = \frac{1}{d}\left[\frac{M_b}{\cos\theta}
              + 2 M_P \tan\theta + 2 M_{ER}\right] + F_R

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 20; Balan et al. 2015 for the + F_R.

    Examples
    --------
    >>> float(sliding_force(0.0, 0.0, 1.0, 0.5, 2.0, 1.0, 0.0))
    1.5
    """
    return (
        ball_ball_moment_Nm / cos_contact_angle
        + 2.0 * pivoting_moment_Nm * tan_contact_angle
        + 2.0 * hysteresis_moment_Nm
    ) / ball_diameter_m + rolling_force_N


#: Gauss-Legendre nodes on [0, π/2] and their weights for :func:`contact_shear_force`. [rad], [rad]
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(48)  # on [-1, 1]
_PHI_NODES, _PHI_WEIGHTS = np.pi / 4 * (_NODES + 1.0), np.pi / 4 * _WEIGHTS


def contact_shear_force(shear_stress_Pa, contact_radius_m):
    r"""Sliding traction F_S as the integral of a shear stress τ over the circular contact (eq 14).

    Parameters
    ----------
    shear_stress_Pa : callable or numeric
        Axisymmetric shear stress τ in the contact: a callable
        ``tau(r_m, contact_radius_m) -> Pa`` of the distance r from the contact
        centre (an array with one more trailing axis than ``contact_radius_m``,
        0 <= r <= a) and of a broadcast against it; or a number (uniform τ). [Pa]
    contact_radius_m : numeric
        Contact radius a, >= 0. [m]

    Returns
    -------
    numeric
        F_S = ∬ τ dA over the circle r <= a, shaped like ``contact_radius_m``. [N]

    Raises
    ------
    ValueError
        If ``contact_radius_m`` is negative or not finite.

    Notes
    -----
    Eq 14 of [1]_, :math:`F_S = \iint_A \tau\, dA`, for an axisymmetric τ(r):
    :math:`F_S = 2\pi \int_0^a \tau(r)\, r\, dr`. With r = a sin φ this is
    :math:`2\pi a^2 \int_0^{\pi/2} \tau(a\sin\varphi) \sin\varphi\cos\varphi\, d\varphi`,
    integrated by 48-point Gauss-Legendre quadrature; the substitution makes a
    Hertz-shaped τ ∝ sqrt(1 - r²/a²), whose slope is infinite at the edge,
    smooth, so the quadrature is exact to rounding for it and for polynomial
    τ. The model itself does not know τ: :func:`evaluate` finds F_S from the
    ball's equilibrium (eqs 18-20, :func:`sliding_force`); this function
    relates a traction distribution to it.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 14.

    Examples
    --------
    Uniform 1 MPa over a 10 um contact gives τ π a²; a Hertz-shaped
    τ0 sqrt(1 - r²/a²) gives (2/3) τ0 π a²:

    >>> round(float(contact_shear_force(1e6, 10e-6) / (1e6 * np.pi * 1e-10)), 12)
    1.0
    >>> hertz = lambda r, a: 1e6 * np.sqrt(1 - (r / a) ** 2)
    >>> round(float(contact_shear_force(hertz, 10e-6) / (1e6 * np.pi * 1e-10)), 12)
    0.666666666667
    """
    a = np.asarray(contact_radius_m, dtype=float)
    if not np.all(np.isfinite(a) & (a >= 0)):
        raise ValueError(f"contact_radius_m must be finite and >= 0 [m]; got {contact_radius_m!r}")
    r = a[..., None] * np.sin(_PHI_NODES)
    tau = shear_stress_Pa(r, a[..., None]) if callable(shear_stress_Pa) else shear_stress_Pa
    tau = np.broadcast_to(np.asarray(tau, dtype=float), r.shape)
    return 2.0 * np.pi * np.square(a) * np.sum(tau * np.sin(_PHI_NODES) * np.cos(_PHI_NODES) * _PHI_WEIGHTS,
                                               axis=-1)


def ball_race_force(sliding_force_N, rolling_force_N):
    r"""Tangential resistance F_ballrace of one ball on slider and stator.

    Parameters
    ----------
    sliding_force_N : numeric
        F_S of one contact. [N]
    rolling_force_N : numeric
        F_R of one contact. [N]

    Returns
    -------
    numeric
        F_ballrace = 2 (F_S + F_R). [N]

    Notes
    -----
    Eq 21 of [1]_: each ball acts on a race through two contacts, each with
    F_S + F_R + F_P, and F_P has no reaction on a flat race.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 21.

    Examples
    --------
    >>> float(ball_race_force(1.0, 0.5))
    3.0
    """
    return 2.0 * (sliding_force_N + rolling_force_N)


def total_friction_force(ball_race_force_N, balls):
    r"""Total tangential resistance F_total = z F_ballrace on the slider.

    Parameters
    ----------
    ball_race_force_N : numeric
        F_ballrace. [N]
    balls : numeric
        z. [1]

    Returns
    -------
    numeric
        F_total. [N]

    Notes
    -----
    Eq 22 of [1]_.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 22.

    Examples
    --------
    >>> float(total_friction_force(0.5, 4))
    2.0
    """
    return balls * ball_race_force_N


def friction_coefficient(friction_force_N, load_N):
    r"""Global friction coefficient μ = F_total / G.

    Parameters
    ----------
    friction_force_N : numeric
        F_total. [N]
    load_N : numeric
        G. [N]

    Returns
    -------
    numeric
        μ. [1]

    Notes
    -----
    Eq 23 of [1]_.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 23.

    Examples
    --------
    >>> float(friction_coefficient(1.0, 4.0))
    0.25
    """
    return friction_force_N / load_N


def force_balance_residual(sliding_force_1_N, sliding_force_2_N, rolling_force_1_N,
                           rolling_force_2_N, pressure_force_1_N, pressure_force_2_N):
    r"""Residual of the ball's force balance in the rolling direction.

    Parameters
    ----------
    sliding_force_1_N, sliding_force_2_N : numeric
        F_S at the slider (1) and stator (2) contacts. [N]
    rolling_force_1_N, rolling_force_2_N : numeric
        F_R at each contact. [N]
    pressure_force_1_N, pressure_force_2_N : numeric
        F_P at each contact. [N]

    Returns
    -------
    numeric
        F_S1 - F_S2 - (F_R1 - F_R2) + (F_P1 - F_P2), zero in equilibrium. [N]

    Notes
    -----
    Eq 18 of [1]_.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 18.

    Examples
    --------
    >>> float(force_balance_residual(1.0, 1.0, 0.5, 0.5, 1.0, 1.0))
    0.0
    """
    return (sliding_force_1_N - sliding_force_2_N - (rolling_force_1_N - rolling_force_2_N)
            + (pressure_force_1_N - pressure_force_2_N))


def moment_balance_residual(ball_ball_moment_Nm, pivoting_moment_1_Nm, pivoting_moment_2_Nm,
                            hysteresis_moment_1_Nm, hysteresis_moment_2_Nm,
                            sliding_force_1_N, sliding_force_2_N, rolling_force_1_N,
                            rolling_force_2_N, ball_diameter_m, cos_contact_angle,
                            tan_contact_angle):
    r"""Residual of the ball's moment balance about its centre.

    Parameters
    ----------
    ball_ball_moment_Nm : numeric
        M_b. [N*m]
    pivoting_moment_1_Nm, pivoting_moment_2_Nm : numeric
        M_P at each contact. [N*m]
    hysteresis_moment_1_Nm, hysteresis_moment_2_Nm : numeric
        M_ER at each contact. [N*m]
    sliding_force_1_N, sliding_force_2_N : numeric
        F_S at each contact. [N]
    rolling_force_1_N, rolling_force_2_N : numeric
        F_R at each contact. [N]
    ball_diameter_m : numeric
        d. [m]
    cos_contact_angle, tan_contact_angle : numeric
        cos θ and tan θ of the contact angle θ from the vertical. [1]

    Returns
    -------
    numeric
        Left side minus right side of eq 19, zero in equilibrium. [N*m]

    Notes
    -----
    Eq 19 of [1]_:

    .. math:: \frac{M_b}{\cos\theta} + (M_{P1} + M_{P2})\tan\theta + M_{ER1} + M_{ER2}
              = \frac{d}{2}(F_{S1} + F_{S2} - F_{R1} - F_{R2})

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 19.

    Examples
    --------
    >>> float(moment_balance_residual(0.0, 0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 1.0, 1.0, 2.0, 1.0, 0.0))
    0.0
    """
    resisting = (ball_ball_moment_Nm / cos_contact_angle
                 + (pivoting_moment_1_Nm + pivoting_moment_2_Nm) * tan_contact_angle
                 + hysteresis_moment_1_Nm + hysteresis_moment_2_Nm)
    driving = 0.5 * ball_diameter_m * (sliding_force_1_N + sliding_force_2_N
                                       - rolling_force_1_N - rolling_force_2_N)
    return resisting - driving


#: Every output of :func:`evaluate`: name -> (unit, description).
OUTPUTS: dict[str, tuple[str, str]] = {
    "mu": ("1", "Global friction coefficient of the bearing, F_total / G (eq 23)."),
    "mu_contact": ("1", "Per-contact ball-race coefficient F_ballrace / (2 Q0) of the "
                   "paper's Fig. 5; equals mu * cos(theta)."),
    "friction_force_N": ("N", "Total tangential resistance on the slider, z F_ballrace (eq 22)."),
    "mu_pivoting": ("1", "Part of mu due to the pivoting moments."),
    "mu_hysteresis": ("1", "Part of mu due to the elastic-hysteresis moments."),
    "mu_rolling": ("1", "Part of mu due to the hydrodynamic rolling forces."),
    "mu_ball_ball": ("1", "Part of mu due to the ball-ball capillary friction moment."),
    "contact_load_N": ("N", "Applied normal load Q0 on each ball-race contact (eq 7)."),
    "contact_load_adhesive_N": ("N", "JKR apparent load Q = Q0 plus adhesion (eq 8)."),
    "contact_radius_m": ("m", "JKR contact radius a (eq 3)."),
    "contact_area_m2": ("m^2", "Contact area pi a^2 (eq 3)."),
    "max_contact_pressure_Pa": ("Pa", "Peak Hertz pressure 3Q / (2 pi a^2) at a ball-race contact."),
    "adhesion_force_N": ("N", "JKR pull-off force 3 pi gamma R of a ball on a flank (eq 1)."),
    "capillary_force_ball_ball_N": ("N", "Capillary force between touching balls, 4 pi gamma_w R* "
                                    "(eqs 5-6); 0 when balls do not touch."),
    "rolling_force_N": ("N", "Houpert hydrodynamic rolling force F_R of one contact (eq 9)."),
    "pressure_force_N": ("N", "Pressure force F_P = 2 F_R on the ball centre (eq 13)."),
    "sliding_force_N": ("N", "Sliding traction F_S of one contact from the ball balance (eq 20)."),
    "hysteresis_moment_Nm": ("N*m", "Elastic-hysteresis moment M_ER of one contact (eq 15)."),
    "pivoting_moment_Nm": ("N*m", "Pivoting moment M_P of one contact (eq 16)."),
    "ball_ball_moment_Nm": ("N*m", "Ball-ball friction moment M_b of one ball (eq 17)."),
    "ball_race_force_N": ("N", "Tangential resistance F_ballrace of one ball (eq 21)."),
}


@dataclass(frozen=True)
class FrictionResult:
    """Outputs of :func:`evaluate`, each an array of the broadcast input shape.

    The attributes are the keys of :data:`OUTPUTS`, where each has its unit
    and meaning. ``mu_pivoting + mu_hysteresis + mu_rolling + mu_ball_ball``
    equals ``mu``.
    """

    mu: np.ndarray
    mu_contact: np.ndarray
    friction_force_N: np.ndarray
    mu_pivoting: np.ndarray
    mu_hysteresis: np.ndarray
    mu_rolling: np.ndarray
    mu_ball_ball: np.ndarray
    contact_load_N: np.ndarray
    contact_load_adhesive_N: np.ndarray
    contact_radius_m: np.ndarray
    contact_area_m2: np.ndarray
    max_contact_pressure_Pa: np.ndarray
    adhesion_force_N: np.ndarray
    capillary_force_ball_ball_N: np.ndarray
    rolling_force_N: np.ndarray
    pressure_force_N: np.ndarray
    sliding_force_N: np.ndarray
    hysteresis_moment_Nm: np.ndarray
    pivoting_moment_Nm: np.ndarray
    ball_ball_moment_Nm: np.ndarray
    ball_race_force_N: np.ndarray
    convention: str = DEFAULT_CONVENTION

    def to_dict(self, outputs=None) -> dict[str, np.ndarray]:
        """The outputs as a dict of arrays, all of them or those named."""
        names = list(OUTPUTS) if outputs is None else list(outputs)
        return {name: getattr(self, name) for name in names}


if [f.name for f in fields(FrictionResult)][:-1] != list(OUTPUTS):  # explicit: asserts vanish under -O
    raise ImportError("FrictionResult's fields must be OUTPUTS in order, then the convention")


def evaluate(convention: str = DEFAULT_CONVENTION, **params: Any) -> FrictionResult:
    r"""Friction of a micro linear ball bearing by the model of Olaru et al. (2005).

    Parameters
    ----------
    convention : {"olaru2005", "derjaguin"}, default "olaru2005"
        Reading of the paper's ambiguous ball-ball terms; see
        :data:`physics.CONVENTIONS`.
    **params : numeric, bool or array_like
        The inputs of :data:`physics.PARAMETERS` by name: ``balls`` [1],
        ``load_N`` [N] and ``speed_m_s`` [m/s] are required, the rest have
        defaults (stainless-steel balls of 285 um on silicon at 54.7 deg, water
        film, γ = 0.18 J/m²). Scalars and arrays broadcast together.

    Returns
    -------
    FrictionResult
        Every quantity of :data:`OUTPUTS`, as arrays of the broadcast shape.

    Raises
    ------
    ValueError
        For unknown or missing parameters, values out of range (naming the
        parameter and its range), or shapes that do not broadcast.

    Notes
    -----
    Per contact: Q0 (eq 7), Q (eq 8), a (eq 3), F_R with E', Rx = R, k = 1,
    v = V/2 (eqs 9-12), F_P = 2 F_R (eq 13), M_ER (eq 15) and M_P (eq 16) with
    Q; per ball M_b (eq 17) with F_cb from eqs 5-6 when balls touch. Then F_S
    (eq 20), F_ballrace (eq 21), F_total (eq 22) and μ (eq 23). Speed enters
    only through F_R.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005.

    Examples
    --------
    Case A of the paper (4 balls, slider of 0.9 g, no adhesion, μs = 1):

    >>> r = evaluate(balls=4, load_N=0.9e-3 * 9.80665, speed_m_s=0.1,
    ...              mu_pivot=1.0, adhesion_energy_J_m2=0.0)
    >>> round(float(r.mu_contact), 4)
    0.0051
    """
    if convention not in CONVENTIONS:
        raise ValueError(f"convention must be one of {', '.join(CONVENTIONS)}; got {convention!r}")
    p = validate_all(params)
    shape = np.broadcast_shapes(*(a.shape for a in p.values()))

    cos_theta = np.cos(np.deg2rad(p["groove_angle_deg"]))
    # tan from cos: one transcendental pass instead of two (0 < θ < 90 deg)
    tan_theta = np.sqrt(1.0 - np.square(cos_theta)) / cos_theta
    d = p["ball_diameter_m"]
    radius = 0.5 * d
    e_star = contact.jkr_effective_modulus(p["ball_youngs_modulus_Pa"], p["ball_poisson_ratio"],
                                           p["race_youngs_modulus_Pa"], p["race_poisson_ratio"])
    e_prime = contact.reduced_modulus(p["ball_youngs_modulus_Pa"], p["ball_poisson_ratio"],
                                      p["race_youngs_modulus_Pa"], p["race_poisson_ratio"])

    q0 = contact.ball_race_load(p["load_N"], p["balls"], cos_theta)
    q = contact.jkr_contact_load(q0, radius, p["adhesion_energy_J_m2"])
    a = contact.jkr_contact_radius(q, radius, e_star)

    g_bar = lubrication.materials_parameter(p["pressure_viscosity_1_Pa"], e_prime)
    u = lubrication.speed_parameter(p["viscosity_Pa_s"], lubrication.entrainment_speed(p["speed_m_s"]),
                                    e_prime, radius)
    w = lubrication.load_parameter(q, e_prime, radius)
    f_r = lubrication.rolling_force(e_prime, radius, 1.0, materials_parameter=g_bar, speed_parameter=u,
                                    load_parameter=w)

    m_er = moments.hysteresis_moment(d, q)
    m_p = moments.pivoting_moment(p["mu_pivot"], q, a)
    r_star = surface.ball_ball_radius(radius, radius, convention)
    f_cb = np.where(p["balls_touching"], surface.capillary_force(r_star, p["water_surface_tension_N_m"]), 0.0)
    m_b = moments.ball_ball_moment(p["mu_ball"], f_cb, d)
    # "olaru2005" counts M_b in both contact pairs of the ball (eq 21 as printed),
    # "derjaguin" once per ball; with R* twice as large the two agree for equal balls.
    m_b_per_pair = m_b if convention == "olaru2005" else 0.5 * m_b

    f_s = sliding_force(m_b_per_pair, m_p, m_er, f_r, d, cos_theta, tan_theta)
    f_ball = ball_race_force(f_s, f_r)
    f_total = total_friction_force(f_ball, p["balls"])
    mu = friction_coefficient(f_total, p["load_N"])

    per_newton = 2.0 * p["balls"] / p["load_N"]  # z * 2(...) / G
    mu_pivoting = per_newton * 2.0 * m_p * tan_theta / d
    mu_hysteresis = per_newton * 2.0 * m_er / d
    mu_rolling = per_newton * 2.0 * f_r
    mu_ball_ball = per_newton * m_b_per_pair / (cos_theta * d)

    values = {
        "mu": mu,
        "mu_contact": f_ball / (2.0 * q0),
        "friction_force_N": f_total,
        "mu_pivoting": mu_pivoting,
        "mu_hysteresis": mu_hysteresis,
        "mu_rolling": mu_rolling,
        "mu_ball_ball": mu_ball_ball,
        "contact_load_N": q0,
        "contact_load_adhesive_N": q,
        "contact_radius_m": a,
        "contact_area_m2": contact.contact_area(a),
        "max_contact_pressure_Pa": contact.max_contact_pressure(q, a),
        "adhesion_force_N": surface.adhesion_force_ball_flat(radius, p["adhesion_energy_J_m2"]),
        "capillary_force_ball_ball_N": f_cb,
        "rolling_force_N": f_r,
        "pressure_force_N": lubrication.pressure_force(f_r, ball_radius_m=radius),
        "sliding_force_N": f_s,
        "hysteresis_moment_Nm": m_er,
        "pivoting_moment_Nm": m_p,
        "ball_ball_moment_Nm": m_b,
        "ball_race_force_N": f_ball,
    }
    arrays = {k: np.asarray(v, dtype=float) for k, v in values.items()}
    return FrictionResult(
        **{k: v if v.shape == shape else np.broadcast_to(v, shape) for k, v in arrays.items()},
        convention=convention,
    )
