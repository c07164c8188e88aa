"""The ball's equilibrium and the bearing's friction coefficient, equation by equation.

Equations 14 and 18-23 of Olaru et al. (2005): each ball is held between two
flanks of the slider and two of the stator; the sliding traction F_S at its
contacts follows from the balance of forces (eq 18) and moments (eq 19) with
the rolling, pressure, hysteresis, pivoting and ball-ball terms; the tangential
force the balls exert on the slider, divided by the load, is μ. Eq 14, F_S as
the integral of the shear stress over the contact, is :func:`contact_shear_force`;
the model never needs it, as equilibrium gives F_S. :func:`physics.evaluate`
composes these functions (:mod:`physics.kernel`).

References
----------
.. [1] Olaru et al., COMEC 2005, eqs. 14, 18-23.
.. [2] M.R.D. Balan, L. Houpert, A. Tufescu, D.N. Olaru, Lubricants 3(2), 2015
   (the ball balance F_S = ΣM/d + F_R).
"""

from __future__ import annotations

import numpy as np

from .parameters import CONVENTIONS, DEFAULT_CONVENTION

__all__ = [
    "PAIR_SHARE",
    "MIN_BALLS_TOUCHING",
    "ball_ball_contact",
    "ball_race_force",
    "checked_convention",
    "contact_shear_force",
    "force_balance_residual",
    "friction_coefficient",
    "moment_balance_residual",
    "sliding_force",
    "sliding_force_terms",
    "total_friction_force",
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
    ball_ball, pivoting, hysteresis, rolling = sliding_force_terms(
        ball_ball_moment_Nm, pivoting_moment_Nm, hysteresis_moment_Nm, rolling_force_N, ball_diameter_m,
        cos_contact_angle, tan_contact_angle)
    return ball_ball + pivoting + hysteresis + rolling


def sliding_force_terms(ball_ball_moment_Nm, pivoting_moment_Nm, hysteresis_moment_Nm,
                        rolling_force_N, ball_diameter_m, cos_contact_angle, tan_contact_angle):
    r"""The four terms of the sliding traction F_S (eq 20), whose sum is :func:`sliding_force`.

    Parameters
    ----------
    As :func:`sliding_force`.

    Returns
    -------
    tuple of numeric
        M_b / (d cos θ), 2 M_P tan θ / d, 2 M_ER / d and F_R: the ball-ball,
        pivoting, hysteresis and rolling parts of F_S. [N]

    Notes
    -----
    Eq 20 of [1]_ term by term; each term, carried through eqs 21-23, is one
    part of the breakdown of μ in :func:`physics.evaluate`.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 20.

    Examples
    --------
    >>> [float(t) for t in sliding_force_terms(1.0, 1.0, 1.0, 0.5, 2.0, 0.5, 2.0)]
    [1.0, 2.0, 1.0, 0.5]
    """
    # 2 / d first: a scalar in most calls, computed once rather than once a point
    ball_ball = ball_ball_moment_Nm / (cos_contact_angle * ball_diameter_m)
    pivoting = 2.0 / ball_diameter_m * pivoting_moment_Nm * tan_contact_angle
    hysteresis = 2.0 / ball_diameter_m * hysteresis_moment_Nm
    return ball_ball, pivoting, hysteresis, rolling_force_N


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
                            tan_contact_angle, convention=DEFAULT_CONVENTION):
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
    convention : {"olaru2005", "derjaguin"}, default "olaru2005"
        The reading of the ball-ball term, as in :func:`evaluate`: ``"olaru2005"``
        takes M_b whole in this balance of one contact pair (eq 19 as printed),
        ``"derjaguin"`` half of it (the ball's M_b counted once over its two pairs).

    Returns
    -------
    numeric
        Left side minus right side of eq 19, zero in equilibrium. [N*m]

    Raises
    ------
    ValueError
        For an unknown ``convention``.

    Notes
    -----
    Eq 19 of [1]_, with s = 1 (``"olaru2005"``) or 1/2 (``"derjaguin"``):

    .. math:: \frac{s M_b}{\cos\theta} + (M_{P1} + M_{P2})\tan\theta + M_{ER1} + M_{ER2}
              = \frac{d}{2}(F_{S1} + F_{S2} - F_{R1} - F_{R2})

    The outputs of :func:`evaluate` satisfy it in the convention they were computed in.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 19.

    Examples
    --------
    >>> float(moment_balance_residual(0.0, 0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 1.0, 1.0, 2.0, 1.0, 0.0))
    0.0
    """
    resisting = (PAIR_SHARE[checked_convention(convention)] * ball_ball_moment_Nm / cos_contact_angle
                 + (pivoting_moment_1_Nm + pivoting_moment_2_Nm) * tan_contact_angle
                 + hysteresis_moment_1_Nm + hysteresis_moment_2_Nm)
    driving = 0.5 * ball_diameter_m * (sliding_force_1_N + sliding_force_2_N
                                       - rolling_force_1_N - rolling_force_2_N)
    return resisting - driving


#: Fewest balls that can touch a neighbour: ``balls`` counts every ball of both grooves, and a single
#: ball has no neighbour, so below two balls ``balls_touching`` adds no ball-ball force or moment. [1]
MIN_BALLS_TOUCHING = 2


def ball_ball_contact(balls_touching, balls):
    r"""Whether the balls touch a neighbour: ``balls_touching`` and at least two balls.

    Parameters
    ----------
    balls_touching : bool or array_like of bool
        Whether neighbouring balls are declared touching. [1]
    balls : numeric
        Total number of balls z of both grooves. [1]

    Returns
    -------
    bool or numpy.ndarray of bool
        True where the ball-ball capillary force (eqs 5-6) and moment (eq 17)
        act. [1]

    Notes
    -----
    The model gives every ball the same ball-ball moment M_b (eq 21 of [1]_; the
    paper's case B, 9 touching balls per groove, counts the balls at the ends of
    a row like the others). A single ball has no neighbour, so with z = 1 there
    is no M_b whatever ``balls_touching`` says; with z >= 2 the flag states that
    the balls are arranged to touch.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eqs. 17, 21.

    Examples
    --------
    >>> ball_ball_contact(True, 1), ball_ball_contact(True, 2)
    (False, True)
    """
    touching = np.logical_and(balls_touching, np.greater_equal(balls, MIN_BALLS_TOUCHING))
    return touching.item() if touching.ndim == 0 else touching


#: Share of a ball's ball-ball moment M_b in the balance of one of its contact pairs, by convention:
#: "olaru2005" counts M_b in both pairs (eq 21 as printed), "derjaguin" once per ball; with R*
#: twice as large (eq 6) the two agree for equal balls.
PAIR_SHARE = {"olaru2005": 1.0, "derjaguin": 0.5}


def checked_convention(convention: str) -> str:
    """``convention`` if it is a key of :data:`physics.CONVENTIONS`; else ValueError naming them."""
    if convention not in CONVENTIONS:
        raise ValueError(f"convention must be one of {', '.join(CONVENTIONS)}; got {convention!r}")
    return convention
