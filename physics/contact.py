"""Contact mechanics of the ball-race contact: moduli, loads, JKR radius, pressure.

Equations 3, 4, 7 and 8 of Olaru et al. (2005), with the JKR theory of
Johnson (1985).

References
----------
.. [1] D.N. Olaru, G. Prisacaru, G. Ianus, P. Lorenz, "Friction modeling in
   micro linear rolling systems for MEMS applications", COMEC 2005, Brasov.
.. [2] K.L. Johnson, Contact Mechanics, Cambridge University Press, 1985.
"""

from __future__ import annotations

import numpy as np

from . import elementary

__all__ = [
    "jkr_effective_modulus",
    "reduced_modulus",
    "ball_race_load",
    "jkr_contact_load",
    "jkr_load_elasticity",
    "jkr_contact_radius",
    "contact_area",
    "max_contact_pressure",
]


def _compliance(e1, nu1, e2, nu2):
    return (1.0 - np.square(nu1)) / e1 + (1.0 - np.square(nu2)) / e2


def jkr_effective_modulus(e1, nu1, e2, nu2):
    r"""Effective modulus E* of the JKR contact radius.

    Parameters
    ----------
    e1, e2 : numeric
        Young's moduli of ball and race. [Pa]
    nu1, nu2 : numeric
        Poisson's ratios of ball and race. [1]

    Returns
    -------
    numeric
        E*. [Pa]

    Notes
    -----
    Eq 4 of [1]_: :math:`1/E^* = \frac{3}{4}[(1-\nu_1^2)/E_1 + (1-\nu_2^2)/E_2]`,
    so that :math:`a^3 = R Q / E^*` (Johnson's :math:`a^3 = 3RQ/(4E)`).

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 4; Johnson 1985, eq. 4.22.

    Examples
    --------
    >>> round(float(jkr_effective_modulus(2.1e11, 0.3, 1.5e11, 0.3)) / 1e11, 3)
    1.282
    """
    return 1.0 / (0.75 * _compliance(e1, nu1, e2, nu2))


def reduced_modulus(e1, nu1, e2, nu2):
    r"""Reduced modulus E' of elastohydrodynamic lubrication.

    Parameters
    ----------
    e1, e2 : numeric
        Young's moduli of ball and race. [Pa]
    nu1, nu2 : numeric
        Poisson's ratios of ball and race. [1]

    Returns
    -------
    numeric
        E'. [Pa]

    Notes
    -----
    :math:`E' = 2 / [(1-\nu_1^2)/E_1 + (1-\nu_2^2)/E_2]`, the modulus used by
    Houpert's rolling force, eqs 9-12 of [1]_ (convention of [2]_).

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eqs. 9-12.
    .. [2] N. Biboulet, L. Houpert, Proc. IMechE J 224, 2010.

    Examples
    --------
    >>> round(float(reduced_modulus(2.1e11, 0.3, 1.5e11, 0.3)) / 1e11, 3)
    1.923
    """
    return 2.0 / _compliance(e1, nu1, e2, nu2)


def ball_race_load(load_N, balls, cos_contact_angle):
    r"""Normal load Q0 on each of the four ball-race contacts of a ball.

    Parameters
    ----------
    load_N : numeric
        Normal load G on the slider. [N]
    balls : numeric
        Number of balls z. [1]
    cos_contact_angle : numeric
        cos θ of the contact angle θ from the vertical. [1]

    Returns
    -------
    numeric
        Q0. [N]

    Notes
    -----
    Eq 7 of [1]_: :math:`Q_0 = G / (2 z \cos\theta)`: each ball carries G/z
    on two inclined contacts with the slider.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 7.

    Examples
    --------
    >>> float(ball_race_load(1.0, 4, 0.5))
    0.25
    """
    return load_N / (2.0 * balls * cos_contact_angle)


def jkr_contact_load(load_N, radius_m, adhesion_energy_J_m2):
    r"""Apparent Hertz load Q of a JKR contact, the load plus adhesion.

    Parameters
    ----------
    load_N : numeric
        Applied normal load Q0. [N]
    radius_m : numeric
        Ball radius R. [m]
    adhesion_energy_J_m2 : numeric
        Interfacial energy γ. [J/m^2]

    Returns
    -------
    numeric
        Q. [N]

    Notes
    -----
    Eq 8 of [1]_ (eq 3's bracket, Johnson's JKR apparent load [2]_):

    .. math:: Q = Q_0 + 6\pi\gamma R + \sqrt{12\pi\gamma R Q_0 + (6\pi\gamma R)^2}

    γ = 0 gives Q = Q0 (Hertz).

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 8.
    .. [2] Johnson 1985, eq. 5.21.

    Examples
    --------
    >>> round(float(jkr_contact_load(1e-3, 1e-4, 0.0)), 9)
    0.001
    """
    c = 6.0 * np.pi * radius_m * adhesion_energy_J_m2  # the ball's factors first: one array pass
    return load_N + c + elementary.sqrt(c * (2.0 * load_N + c))


def jkr_load_elasticity(load_N, adhesion_force_N):
    r"""Elasticity of the JKR apparent load Q in the adhesion energy γ, d ln Q / d ln γ at a fixed Q0.

    Parameters
    ----------
    load_N : numeric
        Applied normal load Q0 (> 0). [N]
    adhesion_force_N : numeric
        Pull-off force A = 3 π γ R (:func:`physics.surface.adhesion_force_ball_flat`, >= 0). [N]

    Returns
    -------
    numeric
        e in [0, 1). [1]

    Notes
    -----
    Eq 8 with c = 6 π γ R = 2 A is Q = Q0 f(u), f(u) = 1 + u + sqrt(u (2 + u)), u = 2 A / Q0 ∝ γ, so
    e = u f'(u) / f(u), f'(u) = 1 + (1 + u) / sqrt(u (2 + u)): a function of u alone, 0 at u = 0 (Hertz),
    sqrt(u / 2) for small u, tending to 1 for large u, and non-decreasing in u (checked by the tests). So
    over a range of γ and Q0 it lies between its values at the least γ / Q0 and the largest, and
    ln Q(γ r) - ln Q(γ) = ln r x (a value of e between γ and γ r).

    Examples
    --------
    >>> float(jkr_load_elasticity(1.0, 0.0))
    0.0
    >>> round(float(jkr_load_elasticity(1.0, 1e6)), 4)
    1.0
    """
    u = 2.0 * np.asarray(adhesion_force_N, dtype=float) / np.asarray(load_N, dtype=float)
    root = elementary.sqrt(u * (2.0 + u))
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(u > 0, u + u * (1.0 + u) / np.where(u > 0, root, 1.0), 0.0)
    return slope / (1.0 + u + root)


def jkr_contact_radius(contact_load_N, radius_m, effective_modulus_Pa):
    r"""Radius a of the circular JKR contact.

    Parameters
    ----------
    contact_load_N : numeric
        Apparent load Q from :func:`jkr_contact_load`. [N]
    radius_m : numeric
        Ball radius R (ball on a flat flank). [m]
    effective_modulus_Pa : numeric
        E* from :func:`jkr_effective_modulus`. [Pa]

    Returns
    -------
    numeric
        a. [m]

    Notes
    -----
    Eq 3 of [1]_: :math:`a^3 = (R/E^*) Q`.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 3; Johnson 1985, eq. 5.21.

    Examples
    --------
    >>> round(float(jkr_contact_radius(1.0, 1.0, 1e9)) * 1e3, 6)
    1.0
    """
    return elementary.cbrt(radius_m / effective_modulus_Pa * contact_load_N)


def contact_area(contact_radius_m):
    r"""Area A_c = π a² of the circular contact.

    Parameters
    ----------
    contact_radius_m : numeric
        Contact radius a. [m]

    Returns
    -------
    numeric
        A_c. [m^2]

    Notes
    -----
    Eq 3 of [1]_.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 3.

    Examples
    --------
    >>> round(float(contact_area(1.0)), 4)
    3.1416
    """
    return np.pi * (contact_radius_m * contact_radius_m)


def max_contact_pressure(contact_load_N, contact_radius_m):
    r"""Peak Hertz pressure p0 = 3Q / (2π a²) of the ball-race contact.

    Parameters
    ----------
    contact_load_N : numeric
        Apparent load Q. [N]
    contact_radius_m : numeric
        Contact radius a. [m]

    Returns
    -------
    numeric
        p0. [Pa]

    Notes
    -----
    The Hertz pressure of the apparent load Q that sets the JKR radius; the
    adhesive tension ring at the edge of a JKR contact is not included.

    References
    ----------
    .. [1] Johnson 1985, eq. 4.24.

    Examples
    --------
    >>> round(float(max_contact_pressure(2 * np.pi, 1.0)), 6)
    3.0
    """
    return 1.5 * contact_load_N / (np.pi * (contact_radius_m * contact_radius_m))
