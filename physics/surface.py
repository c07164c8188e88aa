"""Surface forces of micro contacts: JKR adhesion and water capillarity.

Equations 1, 2, 5 and 6 of Olaru et al. (2005).

References
----------
.. [1] Olaru et al., COMEC 2005.
.. [2] K.L. Johnson, K. Kendall, A.D. Roberts, Proc. R. Soc. A 324, 1971.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "adhesion_force_ball_flat",
    "adhesion_force_two_balls",
    "capillary_force",
    "ball_ball_radius",
]


def adhesion_force_ball_flat(radius_m, adhesion_energy_J_m2):
    r"""JKR pull-off force F_a = 3πγR of a ball on a flat.

    Parameters
    ----------
    radius_m : numeric
        Ball radius R. [m]
    adhesion_energy_J_m2 : numeric
        Interfacial energy γ. [J/m^2]

    Returns
    -------
    numeric
        F_a. [N]

    Notes
    -----
    Eq 1 of [1]_; the JKR pull-off force [2]_.

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 1.
    .. [2] Johnson, Kendall, Roberts 1971.

    Examples
    --------
    >>> round(float(adhesion_force_ball_flat(142.5e-6, 0.18)) * 1e6, 1)
    241.7
    """
    return 3.0 * np.pi * radius_m * adhesion_energy_J_m2  # the ball's factors first: one array pass


def adhesion_force_two_balls(radius1_m, radius2_m, adhesion_energy_J_m2):
    r"""JKR pull-off force between two balls, F_a = 3πγ / (1/R1 + 1/R2).

    Parameters
    ----------
    radius1_m, radius2_m : numeric
        Ball radii. [m]
    adhesion_energy_J_m2 : numeric
        Interfacial energy γ. [J/m^2]

    Returns
    -------
    numeric
        F_a. [N]

    Notes
    -----
    Eq 2 of [1]_: eq 1 with the radius R1 R2 / (R1 + R2).

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 2.

    Examples
    --------
    >>> round(float(adhesion_force_two_balls(2.0, 2.0, 1.0 / np.pi)), 6)
    3.0
    """
    return 3.0 * np.pi * adhesion_energy_J_m2 / (1.0 / radius1_m + 1.0 / radius2_m)


def capillary_force(radius_m, surface_tension_N_m):
    r"""Capillary force F_c = 4πγ_w R of a wetted sphere on a flat.

    Parameters
    ----------
    radius_m : numeric
        Sphere radius R, or the equivalent radius R* of two balls. [m]
    surface_tension_N_m : numeric
        Surface tension γ_w of the condensed water. [N/m]

    Returns
    -------
    numeric
        F_c. [N]

    Notes
    -----
    Eq 5 of [1]_, for a fully wetting meniscus (the paper prints no
    contact-angle cosine).

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 5.

    Examples
    --------
    >>> round(float(capillary_force(142.5e-6, 0.0717)) * 1e6, 2)
    128.39
    """
    return 4.0 * np.pi * surface_tension_N_m * radius_m


def ball_ball_radius(radius1_m, radius2_m, convention="olaru2005"):
    r"""Equivalent radius R* of two touching balls for the capillary force.

    Parameters
    ----------
    radius1_m, radius2_m : numeric
        Ball radii. [m]
    convention : {"olaru2005", "derjaguin"}
        ``"olaru2005"`` reads eq 6 as printed, :math:`1/R^* = 2(1/R_1 + 1/R_2)`
        (R/4 for equal balls); ``"derjaguin"`` uses the Derjaguin radius
        :math:`R^* = R_1 R_2 / (R_1 + R_2)` (R/2 for equal balls).

    Returns
    -------
    numeric
        R*. [m]

    Notes
    -----
    Eq 6 of [1]_; its print is ambiguous (see ``physics.CONVENTIONS``).

    References
    ----------
    .. [1] Olaru et al., COMEC 2005, eq. 6.

    Examples
    --------
    >>> float(ball_ball_radius(4.0, 4.0)), float(ball_ball_radius(4.0, 4.0, "derjaguin"))
    (1.0, 2.0)
    """
    harmonic = 1.0 / (1.0 / radius1_m + 1.0 / radius2_m)
    if convention == "olaru2005":
        return 0.5 * harmonic
    if convention == "derjaguin":
        return harmonic
    raise ValueError(f"convention must be 'olaru2005' or 'derjaguin'; got {convention!r}")
