"""Hydrodynamic forces of the water film: Houpert's rolling force and the pressure force.

Equations 9-13 of Olaru et al. (2005), after Houpert and Biboulet.

References
----------
.. [1] Olaru et al., COMEC 2005, eqs. 9-13.
.. [2] N. Biboulet, L. Houpert, "Hydrodynamic force and moment in pure rolling
   lubricated contacts", Proc. IMechE J 224, 2010.
.. [3] M.R.D. Balan, L. Houpert, A. Tufescu, D.N. Olaru, "Rolling friction
   torque in ball-race contacts operating in mixed lubrication conditions",
   Lubricants 3(2), 2015.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "materials_parameter",
    "speed_parameter",
    "load_parameter",
    "rolling_force",
    "pressure_force",
    "entrainment_speed",
    "SPEED_EXPONENT",
    "LOAD_EXPONENT",
]

#: Exponents of the speed parameter U and the load parameter W in Houpert's rolling force (eq 9). [1]
SPEED_EXPONENT = 0.66
LOAD_EXPONENT = 0.47


def materials_parameter(pressure_viscosity_1_Pa, reduced_modulus_Pa):
    r"""Dimensionless materials parameter Ḡ = α E'.

    Parameters
    ----------
    pressure_viscosity_1_Pa : numeric
        Pressure-viscosity coefficient α. [1/Pa]
    reduced_modulus_Pa : numeric
        E'. [Pa]

    Returns
    -------
    numeric
        Ḡ. [1]

    Notes
    -----
    Eq 10 of [1]_.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 10.

    Examples
    --------
    >>> round(float(materials_parameter(1e-8, 1.923e11)), 1)
    1923.0
    """
    return pressure_viscosity_1_Pa * reduced_modulus_Pa


def entrainment_speed(speed_m_s):
    r"""Mean entrainment speed v = V/2 of a ball rolling under a slider at V.

    Parameters
    ----------
    speed_m_s : numeric
        Slider speed V relative to the stator. [m/s]

    Returns
    -------
    numeric
        v. [m/s]

    Notes
    -----
    The ball centre moves at V/2; in each contact both surfaces move at V/2
    relative to it, so the mean speed of eq 11 is V/2 ([3]_, as used by the
    group of Olaru).

    References
    ----------
    .. [3] Balan et al., Lubricants 3(2), 2015.

    Examples
    --------
    >>> float(entrainment_speed(0.1))
    0.05
    """
    return 0.5 * speed_m_s


def speed_parameter(viscosity_Pa_s, speed_m_s, reduced_modulus_Pa, radius_x_m):
    r"""Dimensionless speed parameter U = η0 v / (E' Rx).

    Parameters
    ----------
    viscosity_Pa_s : numeric
        Viscosity η0. [Pa*s]
    speed_m_s : numeric
        Mean entrainment speed v. [m/s]
    reduced_modulus_Pa : numeric
        E'. [Pa]
    radius_x_m : numeric
        Equivalent radius Rx in the rolling direction. [m]

    Returns
    -------
    numeric
        U. [1]

    Notes
    -----
    Eq 11 of [1]_.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 11.

    Examples
    --------
    >>> float(speed_parameter(1.0, 2.0, 4.0, 0.5))
    1.0
    """
    return viscosity_Pa_s * speed_m_s / (reduced_modulus_Pa * radius_x_m)


def load_parameter(contact_load_N, reduced_modulus_Pa, radius_x_m):
    r"""Dimensionless load parameter W = Q / (E' Rx²).

    Parameters
    ----------
    contact_load_N : numeric
        Normal load Q of the contact. [N]
    reduced_modulus_Pa : numeric
        E'. [Pa]
    radius_x_m : numeric
        Rx. [m]

    Returns
    -------
    numeric
        W. [1]

    Notes
    -----
    Eq 12 of [1]_.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 12.

    Examples
    --------
    >>> float(load_parameter(8.0, 2.0, 2.0))
    1.0
    """
    return contact_load_N / (reduced_modulus_Pa * np.square(radius_x_m))


def rolling_force(reduced_modulus_Pa, radius_x_m, radius_ratio, materials_parameter, speed_parameter,
                  load_parameter):
    r"""Houpert's hydrodynamic rolling force F_R of one contact.

    Parameters
    ----------
    reduced_modulus_Pa : numeric
        E'. [Pa]
    radius_x_m : numeric
        Rx, the ball radius on a flat flank. [m]
    radius_ratio : numeric
        k = Ry / Rx, 1 for a ball on a flat. [1]
    materials_parameter : numeric
        Dimensionless materials parameter Ḡ from :func:`materials_parameter`. [1]
    speed_parameter : numeric
        Dimensionless speed parameter U from :func:`speed_parameter`. [1]
    load_parameter : numeric
        Dimensionless load parameter W from :func:`load_parameter`. [1]

    Returns
    -------
    numeric
        F_R. [N]

    Notes
    -----
    Eq 9 of [1]_ ([2]_, [3]_):

    .. math:: F_R = 2.86\, E' R_x^2\, k^{0.348}\, \bar G^{0.022} U^{0.66} W^{0.47}

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 9.
    .. [2] Biboulet and Houpert 2010.
    .. [3] Balan et al. 2015.

    Examples
    --------
    >>> round(float(rolling_force(1.0, 1.0, 1.0, 1.0, 1.0, 1.0)), 2)
    2.86
    """
    return (
        2.86
        * reduced_modulus_Pa
        * np.square(radius_x_m)
        * np.power(radius_ratio, 0.348)
        * np.power(materials_parameter, 0.022)
        * np.power(speed_parameter, SPEED_EXPONENT)
        * np.power(load_parameter, LOAD_EXPONENT)
    )


def pressure_force(rolling_force_N, *, ball_radius_m, race_radius_m=np.inf):
    r"""Pressure force F_P on the ball centre from the film's pressure asymmetry.

    Parameters
    ----------
    rolling_force_N : numeric
        F_R. [N]
    ball_radius_m : numeric
        Ball radius R_b, > 0; required (keyword only), as F_P on a curved race
        depends on it. [m]
    race_radius_m : numeric, default inf
        Radius R_R of the race, > 0; infinite for the flat flank of a linear
        groove. [m]

    Returns
    -------
    numeric
        F_P. [N]

    Raises
    ------
    ValueError
        If ``ball_radius_m`` or ``race_radius_m`` is not > 0.

    Notes
    -----
    Eq 13 of [1]_: :math:`F_P = 2 F_R R_R / (R_R + R_b)`, which is
    :math:`2F_R` on a flat race, where the reaction of F_P on the race is zero.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 13; Biboulet and Houpert 2010.

    Examples
    --------
    A 142.5 um ball on a flat flank, and on a 1 mm race:

    >>> float(pressure_force(1.0, ball_radius_m=142.5e-6))
    2.0
    >>> round(float(pressure_force(1.0, ball_radius_m=142.5e-6, race_radius_m=1e-3)), 4)
    1.7505
    """
    ball = np.asarray(ball_radius_m, dtype=float)
    race = np.asarray(race_radius_m, dtype=float)
    for name, value in (("ball_radius_m", ball), ("race_radius_m", race)):
        if not np.all(value > 0):
            raise ValueError(f"{name} must be > 0 [m]; got {value!r}")
    return 2.0 * rolling_force_N / (1.0 + ball / race)
