"""Resistance moments on a ball: elastic hysteresis, pivoting and ball-ball friction.

Equations 15-17 of Olaru et al. (2005).

References
----------
.. [1] Olaru et al., COMEC 2005, eqs. 15-17.
.. [2] M.R.D. Balan, L. Houpert, A. Tufescu, D.N. Olaru, Lubricants 3(2), 2015.
"""

from __future__ import annotations

import numpy as np

__all__ = ["hysteresis_moment", "pivoting_moment", "ball_ball_moment", "HYSTERESIS_LOAD_EXPONENT"]

#: Exponent of the contact load Q in the elastic-hysteresis moment (eq 15). [1]
HYSTERESIS_LOAD_EXPONENT = 1.33


def hysteresis_moment(ball_diameter_m, contact_load_N, radius_ratio=1.0):
    r"""Elastic-hysteresis rolling resistance moment M_ER of one contact.

    Parameters
    ----------
    ball_diameter_m : numeric
        Ball diameter d. [m]
    contact_load_N : numeric
        Normal load Q of the contact (with adhesion). [N]
    radius_ratio : numeric, default 1
        k = Ry / Rx, in [1, inf) (the correlation's range). [1]

    Returns
    -------
    numeric
        M_ER. [N*m]

    Raises
    ------
    ValueError
        If ``radius_ratio`` is below 1 (the fractional power of k - 1 < 0
        would be NaN).

    Notes
    -----
    Eq 15 of [1]_, empirical, in SI units as restated in [2]_:

    .. math:: M_{ER} = 7.48\times10^{-7} (d/2)^{0.33} Q^{1.33}
              [1 - 3.519\times10^{-3}(k-1)^{0.806}]

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 15.
    .. [2] Balan et al. 2015.

    Examples
    --------
    >>> round(float(hysteresis_moment(2.0, 1.0)), 12)
    7.48e-07
    """
    k = np.asarray(radius_ratio, dtype=float)
    if not np.all(k >= 1.0):
        raise ValueError(f"radius_ratio (k = Ry / Rx) must be in [1, inf) [1]; got {radius_ratio!r}")
    shape = 1.0 - 3.519e-3 * np.power(k - 1.0, 0.806)
    load_term = np.power(contact_load_N, HYSTERESIS_LOAD_EXPONENT)
    return 7.48e-7 * np.power(0.5 * ball_diameter_m, 0.33) * load_term * shape


def pivoting_moment(mu_pivot, contact_load_N, contact_radius_m):
    r"""Pivoting (spin) friction moment M_P = (3/8) μs Q a of one contact.

    Parameters
    ----------
    mu_pivot : numeric
        Sliding friction coefficient μs in the contact. [1]
    contact_load_N : numeric
        Normal load Q (with adhesion). [N]
    contact_radius_m : numeric
        Contact radius a. [m]

    Returns
    -------
    numeric
        M_P. [N*m]

    Notes
    -----
    Eq 16 of [1]_: Coulomb shear μs p integrated over a Hertz pressure
    distribution on a circle of radius a gives (3π/16) μs Q a; the paper uses
    3/8, as [2]_ does.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 16.
    .. [2] Balan et al. 2015.

    Examples
    --------
    >>> float(pivoting_moment(1.0, 8.0, 1.0))
    3.0
    """
    return 0.375 * mu_pivot * contact_load_N * contact_radius_m


def ball_ball_moment(mu_ball, capillary_force_N, ball_diameter_m):
    r"""Friction moment M_b = μb F_cb d between touching balls.

    Parameters
    ----------
    mu_ball : numeric
        Ball-ball friction coefficient μb. [1]
    capillary_force_N : numeric
        Ball-ball capillary force F_cb (eq 5 with R*). [N]
    ball_diameter_m : numeric
        Ball diameter d. [m]

    Returns
    -------
    numeric
        M_b. [N*m]

    Notes
    -----
    Eq 17 of [1]_.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 17.

    Examples
    --------
    >>> float(ball_ball_moment(0.5, 2.0, 3.0))
    3.0
    """
    return mu_ball * capillary_force_N * ball_diameter_m
