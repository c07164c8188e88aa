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

import functools
import itertools
import math
import operator
import os
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from . import compiled, contact, lubrication, moments, surface
from .parameters import CONVENTIONS, DEFAULT_CONVENTION, checked_inputs

__all__ = [
    "FrictionResult",
    "OUTPUTS",
    "evaluate",
    "evaluate_point",
    "sliding_force",
    "contact_shear_force",
    "ball_race_force",
    "total_friction_force",
    "friction_coefficient",
    "force_balance_residual",
    "MIN_BALLS_TOUCHING",
    "ball_ball_contact",
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
    resisting = (_PAIR_SHARE[_checked_convention(convention)] * ball_ball_moment_Nm / cos_contact_angle
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
_PAIR_SHARE = {"olaru2005": 1.0, "derjaguin": 0.5}


def _checked_convention(convention: str) -> str:
    if convention not in CONVENTIONS:
        raise ValueError(f"convention must be one of {', '.join(CONVENTIONS)}; got {convention!r}")
    return convention


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
    "max_contact_pressure_Pa": ("Pa", "Peak pressure 3Q / (2 pi a^2) at a ball-race contact: the Hertz "
                                "peak of the adhesion-enhanced JKR load Q (eq 8) over the JKR contact "
                                "radius a (eq 3), not the applied load Q0 (the JKR distribution itself "
                                "is not Hertzian: it turns tensile at the edge)."),
    "adhesion_force_N": ("N", "JKR pull-off force 3 pi gamma R of a ball on a flank (eq 1)."),
    "capillary_force_ball_ball_N": ("N", "Capillary force between touching balls, 4 pi gamma_w R* "
                                    "(eqs 5-6); 0 when balls do not touch or balls = 1."),
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
    equals ``mu``. Outputs left out by ``evaluate(outputs=...)`` are ``None``.
    """

    mu: np.ndarray | None
    mu_contact: np.ndarray | None
    friction_force_N: np.ndarray | None
    mu_pivoting: np.ndarray | None
    mu_hysteresis: np.ndarray | None
    mu_rolling: np.ndarray | None
    mu_ball_ball: np.ndarray | None
    contact_load_N: np.ndarray | None
    contact_load_adhesive_N: np.ndarray | None
    contact_radius_m: np.ndarray | None
    contact_area_m2: np.ndarray | None
    max_contact_pressure_Pa: np.ndarray | None
    adhesion_force_N: np.ndarray | None
    capillary_force_ball_ball_N: np.ndarray | None
    rolling_force_N: np.ndarray | None
    pressure_force_N: np.ndarray | None
    sliding_force_N: np.ndarray | None
    hysteresis_moment_Nm: np.ndarray | None
    pivoting_moment_Nm: np.ndarray | None
    ball_ball_moment_Nm: np.ndarray | None
    ball_race_force_N: np.ndarray | None
    convention: str = DEFAULT_CONVENTION

    @classmethod
    def _of_point(cls, values: dict[str, float], wanted: list[str], convention: str) -> FrictionResult:
        """The result of one point from the kernel's floats, as ``numpy.float64`` like an array's items.

        Filled through the instance's ``__dict__``: the frozen dataclass's ``__init__`` sets its 22
        fields one ``object.__setattr__`` call at a time, which would cost a third of the point. Each
        float becomes a ``numpy.float64`` by itself (exact): a one-point array and its items would
        cost twice as much.
        """
        result = object.__new__(cls)
        result.__dict__.update(dict.fromkeys(OUTPUTS), convention=convention)
        result.__dict__.update(zip(wanted, map(np.float64, map(values.__getitem__, wanted)), strict=True))
        return result

    def to_dict(self, outputs=None) -> dict[str, np.ndarray]:
        """The outputs as a dict of arrays: those named, or every one computed."""
        if outputs is None:
            return {name: value for name in OUTPUTS if (value := getattr(self, name)) is not None}
        values = {name: getattr(self, name) for name in _output_names(outputs)}
        missing = [name for name, value in values.items() if value is None]
        if missing:
            raise ValueError(f"outputs {', '.join(missing)} were not computed; "
                             "name them in evaluate(outputs=...)")
        return values


if [f.name for f in fields(FrictionResult)][:-1] != list(OUTPUTS):  # explicit: asserts vanish under -O
    raise ImportError("FrictionResult's fields must be OUTPUTS in order, then the convention")


def evaluate(convention: str = DEFAULT_CONVENTION, outputs: Iterable[str] | None = None,
             **params: Any) -> FrictionResult:
    r"""Friction of a micro linear ball bearing by the model of Olaru et al. (2005).

    Parameters
    ----------
    convention : {"olaru2005", "derjaguin"}, default "olaru2005"
        Reading of the paper's ambiguous ball-ball terms; see
        :data:`physics.CONVENTIONS`.
    outputs : iterable of str, optional
        Names from :data:`OUTPUTS` to return; by default all. The others are
        ``None`` in the result. Most outputs are each other's intermediates and
        are computed anyway, but only those asked for are stored (on large
        inputs, writing 21 arrays to fresh memory costs as much as the
        arithmetic); the area, peak pressure, F_P, mu_contact and the breakdown
        of μ, which nothing else needs, are computed only when one of them is
        asked for.
    **params : numeric, bool or array_like
        The inputs of :data:`physics.PARAMETERS` by name: ``balls`` [1] (every
        ball of both grooves: the paper's case B, 9 per groove, is 18),
        ``load_N`` [N] and ``speed_m_s`` [m/s] are required, the rest have
        defaults (stainless-steel balls of 285 um on silicon at 54.7 deg, water
        film, γ = 0.18 J/m²). Scalars and arrays broadcast together.

    Returns
    -------
    FrictionResult
        Every quantity of :data:`OUTPUTS` (or those of ``outputs``), as arrays
        of the broadcast shape.

    Raises
    ------
    ValueError
        For unknown or missing parameters, values out of range (naming the
        parameter and its range), shapes that do not broadcast, unknown
        output names, or (on calls large enough for threads) a
        ``MICROBEARING_PHYSICS_THREADS`` that is not a whole number or a
        ``MICROBEARING_PHYSICS_KERNEL`` other than numpy or numba (numba when
        it is not installed).

    Notes
    -----
    Per contact: Q0 (eq 7), Q (eq 8), a (eq 3), F_R with E', Rx = R, k = 1,
    v = V/2 (eqs 9-12), F_P = 2 F_R (eq 13), M_ER (eq 15) and M_P (eq 16) with
    Q; per ball M_b (eq 17) with F_cb from eqs 5-6 when balls touch and there
    are at least two of them (:func:`ball_ball_contact`; ``balls`` counts the
    balls of both grooves, and one ball has no neighbour). Then F_S
    (eq 20), F_ballrace (eq 21), F_total (eq 22) and μ (eq 23). Speed enters
    only through F_R.

    Inputs are evaluated in blocks of 16,384 points, in place, so that the
    intermediates stay in the CPU's cache and no temporary array is allocated
    per operation; calls of 8 blocks or more share their blocks between
    threads, one per usable CPU or as many as the environment variable
    ``MICROBEARING_PHYSICS_THREADS`` says (numpy releases the GIL in its
    loops; throughput: ``bench/physics.py``). With numba installed
    (``pip install microbearing[fast]``), ``MICROBEARING_PHYSICS_KERNEL=numba``
    runs such large calls through the same operations compiled
    (:mod:`physics.compiled`), which hold the GIL only once per thread: it
    scales better over threads but was no faster overall on the 2-core
    machine of bench/RESULTS.md, so numpy is the default. The two kernels
    agree to 1e-12 relative (tested), bit for bit where numpy and numba use
    the same C library's tan, cbrt, log and exp. The arithmetic takes tan θ
    directly and sec θ from it, and the power laws of eqs 9 and 15 as exp of
    logarithms; it agrees with the plain composition of the equations'
    functions to ~1e-13 (tested), and every point runs the same operations
    whatever the size of the call or the number of threads, so results do not
    depend on batching. A call whose inputs are all scalars runs the same
    operations on Python floats (numpy's tan, cbrt, log and exp), after the
    same checks, without numpy's per-call overhead, and returns
    ``numpy.float64`` values equal bit for bit to the same point inside an array.

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
    _checked_convention(convention)
    p, shape = checked_inputs(params)  # scalars as Python numbers: their products fold before arrays
    wanted = list(OUTPUTS) if outputs is None else _output_names(outputs)
    if not shape:  # one point: the same operations on Python floats, without numpy's per-call overhead
        values = _point(p, convention, not _EXTRAS.isdisjoint(wanted))
        return FrictionResult._of_point(values, wanted, convention)
    size = math.prod(shape)
    flat = {k: np.broadcast_to(v, shape).reshape(-1) if isinstance(v, np.ndarray) else v
            for k, v in p.items()}
    block_size = max(1, min(size, _BLOCK_POINTS))
    kept = np.empty((len(wanted), size))
    flat.update(_coefficients(flat, convention))
    arrays = {k: v for k, v in flat.items() if isinstance(v, np.ndarray) and v.ndim}
    scalars = {k: v for k, v in flat.items() if k not in arrays}
    run = functools.partial(_run_blocks, arrays, scalars, dict(zip(wanted, kept, strict=True)),
                            [k for k in OUTPUTS if k not in wanted], block_size)
    blocks = -(-size // block_size)
    large = blocks >= 2 * _MIN_BLOCKS_PER_THREAD
    threads = min(_threads(), blocks // _MIN_BLOCKS_PER_THREAD) if large else 1
    if large and _compiled_kernel():
        run = _compiled_run(flat, kept, wanted, size)
    if threads < 2:
        run(0, size)
    else:  # contiguous runs of whole blocks, one per thread; numpy and numba release the GIL in their loops
        edges = [block_size * (blocks * i // threads) for i in range(threads)] + [size]
        for future in [_pool().submit(run, lo, hi) for lo, hi in itertools.pairwise(edges)]:
            future.result()
    values = dict(zip(wanted, kept.reshape(len(wanted), *shape), strict=True))
    return FrictionResult(**{k: values.get(k) for k in OUTPUTS}, convention=convention)


def evaluate_point(convention: str = DEFAULT_CONVENTION, **params: Any) -> dict[str, float]:
    """Every output of :func:`evaluate` at one point, as Python floats by name (in :data:`OUTPUTS` order).

    The same checks and operations as :func:`evaluate` with scalar inputs, whose outputs are
    these floats as ``numpy.float64``: for callers of one point at a time (the REST API's
    ``/v1/friction``), to whom building those scalars and a :class:`FrictionResult` would cost
    half as much again as the point itself.

    Parameters
    ----------
    convention : {"olaru2005", "derjaguin"}, default "olaru2005"
        As in :func:`evaluate`.
    **params : float, int or bool
        Scalar inputs of :data:`physics.PARAMETERS` by name, as in :func:`evaluate`.

    Returns
    -------
    dict of float
        Every output of :data:`OUTPUTS` in its unit.

    Raises
    ------
    ValueError
        As :func:`evaluate` does, and for an input that is an array (naming it).

    Examples
    --------
    >>> point = evaluate_point(balls=4, load_N=0.9e-3 * 9.80665, speed_m_s=0.1)
    >>> type(point["mu"]).__name__, point["mu"] == float(evaluate(balls=4, load_N=0.9e-3 * 9.80665,
    ...                                                           speed_m_s=0.1).mu)
    ('float', True)
    """
    _checked_convention(convention)
    p, shape = checked_inputs(params)
    if shape:
        arrays = [name for name, value in p.items() if isinstance(value, np.ndarray)]
        raise ValueError(f"{arrays[0]} must be a scalar for evaluate_point; use evaluate for arrays")
    values = _point(p, convention, True)
    return {name: values[name] for name in OUTPUTS}


def _point(p: dict[str, Any], convention: str, extras: bool) -> dict[str, float]:
    """The outputs of one checked point (Python numbers) by :func:`_kernel` on floats."""
    p.update(_coefficients(p, convention))
    return _kernel(p, _NO_BUFFERS, None, None, None, None, _PointOps, extras)


#: Outputs that no other output needs: :func:`_kernel` skips them when none is asked for.
_EXTRAS = frozenset({"contact_area_m2", "max_contact_pressure_Pa", "pressure_force_N", "mu_contact",
                     "mu_pivoting", "mu_hysteresis", "mu_rolling", "mu_ball_ball"})

#: The output buffers of a one-point :func:`_kernel` call: none, it returns Python floats.
_NO_BUFFERS = dict.fromkeys(OUTPUTS)


def _output_names(outputs: Iterable[str]) -> list[str]:
    names = [outputs] if isinstance(outputs, str) else list(outputs)
    unknown = [n for n in names if n not in OUTPUTS]
    if unknown or not names:
        raise ValueError(f"outputs must be names from {', '.join(OUTPUTS)}; got {names!r}")
    return list(dict.fromkeys(names))


#: Points per block of :func:`_kernel`: the block's work arrays stay in the CPU's cache.
_BLOCK_POINTS = 16384
#: Fewest blocks a thread is given: below 2 x 4 blocks a call runs in the caller's thread.
_MIN_BLOCKS_PER_THREAD = 4
#: Environment variable capping the threads of large calls (default: the usable CPUs).
THREADS_VARIABLE = "MICROBEARING_PHYSICS_THREADS"


def _threads() -> int:
    """Threads for large calls: ``MICROBEARING_PHYSICS_THREADS`` if set, else the usable CPUs."""
    value = os.environ.get(THREADS_VARIABLE, "").strip()
    if value:
        try:
            return max(1, int(value))
        except ValueError:
            raise ValueError(f"{THREADS_VARIABLE} must be a whole number >= 1; got {value!r}") from None
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


@functools.cache
def _pool() -> ThreadPoolExecutor:
    return ThreadPoolExecutor(thread_name_prefix="physics")


if hasattr(os, "register_at_fork"):  # a forked child has none of the parent's threads: a new pool
    os.register_at_fork(after_in_child=_pool.cache_clear)


#: Environment variable choosing the kernel of large calls: ``numpy`` (the default) or ``numba``
#: (``pip install microbearing[fast]``).
KERNEL_VARIABLE = "MICROBEARING_PHYSICS_KERNEL"


def _compiled_kernel() -> bool:
    """Whether large calls run :mod:`physics.compiled`: asked for (numba installed)."""
    value = os.environ.get(KERNEL_VARIABLE, "").strip().lower()
    if value not in ("", "numpy", "numba"):
        raise ValueError(f"{KERNEL_VARIABLE} must be numpy or numba; got {value!r}")
    if value == "numba" and not compiled.AVAILABLE:
        raise ValueError(f"{KERNEL_VARIABLE}=numba needs numba: pip install microbearing[fast]")
    return value == "numba"


def _compiled_run(flat: dict[str, Any], kept: np.ndarray, wanted: list[str], size: int):
    """``run(lo, hi)`` of :func:`physics.compiled.points` over the call's inputs, into ``kept``."""
    inputs = {name: np.broadcast_to(np.asarray(flat[name], dtype=np.float64), (size,))
              for name in compiled.INPUTS}
    positions = np.array([list(OUTPUTS).index(name) for name in wanted], dtype=np.int64)
    return compiled.points(inputs, kept, positions, not _EXTRAS.isdisjoint(wanted), float(MIN_BALLS_TOUCHING))


def _run_blocks(arrays: dict[str, np.ndarray], scalars: dict[str, Any], kept: dict[str, np.ndarray],
                others: list[str], block_size: int, lo: int, hi: int) -> None:
    """Run :func:`_kernel` over points ``lo:hi``, block by block, into the rows of ``kept``.

    Outputs not asked for go to scratch rows overwritten block by block; each
    call has its own scratch and work arrays, so calls on disjoint ranges can
    run in parallel threads.
    """
    b = dict(scalars)
    extras = not _EXTRAS.isdisjoint(kept)
    scratch = np.empty((len(others), block_size))
    all_work = np.empty((4, block_size))
    o = dict(zip(others, scratch, strict=True))
    work = all_work
    with np.errstate(divide="ignore"):  # per thread: log of a zero speed or viscosity is -inf, exp(-inf) = 0
        for start in range(lo, hi, block_size):
            stop = min(start + block_size, hi)
            if stop - start < block_size:  # the last, shorter block
                o.update((k, row[:stop - start]) for k, row in zip(others, scratch, strict=True))
                work = all_work[:, :stop - start]
            b.update((k, v[start:stop]) for k, v in arrays.items())
            o.update((k, row[start:stop]) for k, row in kept.items())
            _kernel(b, o, *work, _ArrayOps, extras)


#: The inputs of :func:`_coefficients`: the ball, the materials and the film.
_COEFFICIENT_INPUTS = ("ball_diameter_m", "ball_youngs_modulus_Pa", "ball_poisson_ratio",
                       "race_youngs_modulus_Pa", "race_poisson_ratio", "viscosity_Pa_s",
                       "pressure_viscosity_1_Pa", "water_surface_tension_N_m")


_coefficient_inputs = operator.itemgetter(*_COEFFICIENT_INPUTS)


def _coefficients(p: dict[str, Any], convention: str) -> dict[str, Any]:
    """Factors of :func:`_kernel` that depend on the ball, the materials and the film only.

    Scalars unless one of those inputs varies; then arrays of the inputs' length.
    Power laws are split into a coefficient, taken from the equation's own
    function at unit argument, and the power of the varying quantity.
    """
    values = _coefficient_inputs(p)
    if all(type(v) is float for v in values):
        return _scalar_coefficients(values, convention)
    return _coefficients_of(dict(zip(_COEFFICIENT_INPUTS, values, strict=True)), convention)


@functools.lru_cache(maxsize=64)
def _scalar_coefficients(values: tuple[float, ...], convention: str) -> dict[str, Any]:
    # Repeated single-point calls (the REST API's) mostly share their materials; Python floats
    # keep the one-point kernel in Python's own arithmetic.
    coefficients = _coefficients_of(dict(zip(_COEFFICIENT_INPUTS, values, strict=True)), convention)
    return {name: float(value) for name, value in coefficients.items()}


def _coefficients_of(p: dict[str, Any], convention: str) -> dict[str, Any]:
    d = p["ball_diameter_m"]
    radius = 0.5 * d
    moduli = (p["ball_youngs_modulus_Pa"], p["ball_poisson_ratio"], p["race_youngs_modulus_Pa"],
              p["race_poisson_ratio"])
    e_star = contact.jkr_effective_modulus(*moduli)
    e_prime = contact.reduced_modulus(*moduli)
    # Eq 9 is a product of powers: F_R = F_R(V = 1 m/s, Q = 1 N) V^0.66 Q^0.47.
    rolling = lubrication.rolling_force(
        e_prime, radius, 1.0, lubrication.materials_parameter(p["pressure_viscosity_1_Pa"], e_prime),
        lubrication.speed_parameter(p["viscosity_Pa_s"], lubrication.entrainment_speed(1.0), e_prime, radius),
        lubrication.load_parameter(1.0, e_prime, radius))
    return {
        "adhesion_per_gamma": surface.adhesion_force_ball_flat(radius, 1.0),  # eq 1 per J/m²
        "radius_over_e_star": radius / e_star,  # eq 3
        "log_rolling": _log_or_minus_infinity(rolling),
        "log_hysteresis": np.log(moments.hysteresis_moment(d, 1.0)),  # eq 15 at Q = 1 N
        "pressure_per_rolling": lubrication.pressure_force(1.0, ball_radius_m=radius),  # eq 13
        "pivot": moments.pivoting_moment(1.0, 1.0, 1.0),  # eq 16 per unit μs, N, m
        "capillary": surface.capillary_force(surface.ball_ball_radius(radius, radius, convention),
                                             p["water_surface_tension_N_m"]),  # eqs 5-6
        "ball_ball": moments.ball_ball_moment(1.0, 1.0, d),  # eq 17 per unit μb and N
        "pair_share_over_d": _PAIR_SHARE[convention] / d,
        "two_over_d": 2.0 / d,
    }


class _ArrayOps:
    """The operations of :func:`_kernel` on a block of arrays: numpy's ufuncs, each into ``out``."""

    multiply, add, divide, square, sqrt = np.multiply, np.add, np.divide, np.square, np.sqrt
    tan, cbrt, log, exp = np.tan, np.cbrt, np.log, np.exp
    at_least = np.greater_equal  # into a float row: 1.0 or 0.0


class _PointOps:
    """The operations of :func:`_kernel` on Python floats (one point; ``out`` is ignored).

    +, *, / and sqrt are correctly rounded in IEEE arithmetic, so they give the bits of
    numpy's loops; tan, cbrt, log and exp are numpy's own functions. One point therefore
    gets exactly the result it gets inside a large array (tested), at a fraction of the
    cost of numpy's per-call overhead on one-element arrays.
    """

    @staticmethod
    def multiply(x, y, out):
        return x * y

    @staticmethod
    def add(x, y, out):
        return x + y

    @staticmethod
    def divide(x, y, out):
        return x / y

    @staticmethod
    def square(x, out):
        return x * x

    @staticmethod
    def sqrt(x, out):
        return math.sqrt(x)

    @staticmethod
    def at_least(x, y, out):
        return 1.0 if x >= y else 0.0

    @staticmethod
    def tan(x, out):
        return float(np.tan(x))

    @staticmethod
    def cbrt(x, out):
        return float(np.cbrt(x))

    @staticmethod
    def log(x, out):  # log 0 = -inf as in the array path, where the divide warning is silenced
        return float(np.log(x)) if x else -math.inf

    @staticmethod
    def exp(x, out):
        return float(np.exp(x))


def _log_or_minus_infinity(value):
    """log of a coefficient that is 0 for a zero viscosity: -inf, so that exp(-inf) = 0 in :func:`_kernel`."""
    with np.errstate(divide="ignore"):
        return np.log(value)


def _kernel(b: dict[str, Any], o: dict[str, Any], tan: Any, sec: Any, w1: Any, w2: Any,
            f: type = _ArrayOps, extras: bool = True) -> dict[str, Any]:
    """Every output of one block (or one point) by the operations ``f``.

    With :class:`_ArrayOps`, ``b`` holds the inputs and :func:`_coefficients` of
    a block (arrays of the block's length or scalars), and every output is
    written in place into its row of ``o``, with four work arrays: no array is
    allocated here, as on large inputs fresh memory costs more than the
    arithmetic. With :class:`_PointOps`, ``b`` holds Python floats and the
    buffers are ignored. Both run the same operations in the same order and
    return the outputs by name. ``extras=False`` leaves out the outputs of
    :data:`_EXTRAS`, which no other output needs (their rows are then not
    written).
    """
    multiply, add, divide, square, sqrt = f.multiply, f.add, f.divide, f.square, f.sqrt
    # Groove geometry: tan in one vectorized pass (numpy's float64 cos is ~9x slower), sec from it.
    tan = f.tan(multiply(b["groove_angle_deg"], np.pi / 180.0, tan), tan)
    sec = sqrt(add(square(tan, sec), 1.0, sec), sec)
    # Eq 7: Q0 = G / (2 z cos θ).
    q0 = multiply(b["load_N"], sec, o["contact_load_N"])
    q0 = multiply(divide(q0, b["balls"], q0), 0.5, q0)
    # Eq 1: pull-off force F = 3 π γ R. Eq 8: Q = Q0 + 2F + sqrt(4F Q0 + 4F²) = Q0 + 2 (F + sqrt(F (Q0 + F))).
    adhesion = multiply(b["adhesion_energy_J_m2"], b["adhesion_per_gamma"], o["adhesion_force_N"])
    w1 = sqrt(multiply(add(q0, adhesion, w1), adhesion, w1), w1)
    q = add(w1, adhesion, o["contact_load_adhesive_N"])
    q = add(multiply(q, 2.0, q), q0, q)
    # Eq 3: a = (R Q / E*)^(1/3).
    a = f.cbrt(multiply(q, b["radius_over_e_star"], o["contact_radius_m"]), o["contact_radius_m"])
    # Eq 9: F_R = coefficient V^0.66 Q^0.47, and eq 15: M_ER = coefficient Q^1.33, as exponentials
    # of logarithms (a power costs a log and an exp; log Q serves both; V = 0 gives exp(-inf) = 0).
    log_q = f.log(q, w1)
    log_speed = multiply(f.log(b["speed_m_s"], w2), lubrication.SPEED_EXPONENT, w2)
    f_r = multiply(log_q, lubrication.LOAD_EXPONENT, o["rolling_force_N"])
    f_r = f.exp(add(add(f_r, log_speed, f_r), b["log_rolling"], f_r), f_r)
    m_er = multiply(log_q, moments.HYSTERESIS_LOAD_EXPONENT, o["hysteresis_moment_Nm"])
    m_er = f.exp(add(m_er, b["log_hysteresis"], m_er), m_er)
    # Eqs 16-17: pivoting (3/8) μs Q a and ball-ball μb F_cb d moments.
    m_p = multiply(q, a, o["pivoting_moment_Nm"])
    m_p = multiply(multiply(m_p, b["mu_pivot"], m_p), b["pivot"], m_p)
    # A ball touches a neighbour only when balls touch and there are at least two of them.
    capillary = f.at_least(b["balls"], MIN_BALLS_TOUCHING, o["capillary_force_ball_ball_N"])
    capillary = multiply(multiply(capillary, b["balls_touching"], capillary), b["capillary"], capillary)
    m_b = multiply(capillary, b["mu_ball"], o["ball_ball_moment_Nm"])
    m_b = multiply(m_b, b["ball_ball"], m_b)
    # Eq 20 term by term, F_S = M_b / (d cos θ) + 2 M_P tan θ / d + 2 M_ER / d + F_R; each
    # term, times 2 z / G below, is one part of the breakdown of μ.
    mu_ball_ball = multiply(m_b, sec, o["mu_ball_ball"])
    mu_ball_ball = multiply(mu_ball_ball, b["pair_share_over_d"], mu_ball_ball)
    mu_pivoting = multiply(m_p, tan, o["mu_pivoting"])
    mu_pivoting = multiply(mu_pivoting, b["two_over_d"], mu_pivoting)
    mu_hysteresis = multiply(m_er, b["two_over_d"], o["mu_hysteresis"])
    f_s = add(mu_ball_ball, mu_pivoting, o["sliding_force_N"])
    f_s = add(add(f_s, mu_hysteresis, f_s), f_r, f_s)
    # Eqs 21-23: F_ballrace = 2 (F_S + F_R), F_total = z F_ballrace, μ = F_total / G.
    ball_race = add(f_s, f_r, o["ball_race_force_N"])
    ball_race = multiply(ball_race, 2.0, ball_race)
    total = multiply(ball_race, b["balls"], o["friction_force_N"])
    mu = divide(total, b["load_N"], o["mu"])
    values = {
        "mu": mu, "friction_force_N": total, "contact_load_N": q0, "contact_load_adhesive_N": q,
        "contact_radius_m": a, "adhesion_force_N": adhesion, "capillary_force_ball_ball_N": capillary,
        "rolling_force_N": f_r, "sliding_force_N": f_s, "hysteresis_moment_Nm": m_er,
        "pivoting_moment_Nm": m_p, "ball_ball_moment_Nm": m_b, "ball_race_force_N": ball_race,
    }
    if not extras:
        return values
    # What nothing above needs. Contact area π a² and peak pressure 3 Q / (2 π a²) (eq 3), F_P (eq 13),
    # the per-contact F_ballrace / (2 Q0) = μ cos θ, and the breakdown of μ: each term of F_S times 2 z / G.
    area = multiply(square(a, o["contact_area_m2"]), np.pi, o["contact_area_m2"])
    pressure = divide(q, area, o["max_contact_pressure_Pa"])
    per_newton = multiply(divide(b["balls"], b["load_N"], w2), 2.0, w2)
    mu_rolling = multiply(f_r, 2.0, o["mu_rolling"])
    return {
        **values, "contact_area_m2": area, "max_contact_pressure_Pa": multiply(pressure, 1.5, pressure),
        "pressure_force_N": multiply(f_r, b["pressure_per_rolling"], o["pressure_force_N"]),
        "mu_contact": divide(mu, sec, o["mu_contact"]),
        "mu_pivoting": multiply(mu_pivoting, per_newton, mu_pivoting),
        "mu_hysteresis": multiply(mu_hysteresis, per_newton, mu_hysteresis),
        "mu_rolling": multiply(mu_rolling, per_newton, mu_rolling),
        "mu_ball_ball": multiply(mu_ball_ball, per_newton, mu_ball_ball),
    }
