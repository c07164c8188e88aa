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
import os
from collections.abc import Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from . import contact, lubrication, moments, surface
from .parameters import CONVENTIONS, DEFAULT_CONVENTION, checked_inputs

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

    def to_dict(self, outputs=None) -> dict[str, np.ndarray]:
        """The outputs as a dict of arrays: those named, or every one computed."""
        if outputs is None:
            return {name: getattr(self, name) for name in OUTPUTS if getattr(self, name) is not None}
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
        ``None`` in the result. Every output is computed anyway (they are each
        other's intermediates), but only those asked for are stored: on large
        inputs, writing 21 arrays to fresh memory costs as much as the
        arithmetic (``outputs=["mu"]`` is about 1.6x faster on 10^6 points).
    **params : numeric, bool or array_like
        The inputs of :data:`physics.PARAMETERS` by name: ``balls`` [1],
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
        ``MICROBEARING_PHYSICS_THREADS`` that is not a whole number.

    Notes
    -----
    Per contact: Q0 (eq 7), Q (eq 8), a (eq 3), F_R with E', Rx = R, k = 1,
    v = V/2 (eqs 9-12), F_P = 2 F_R (eq 13), M_ER (eq 15) and M_P (eq 16) with
    Q; per ball M_b (eq 17) with F_cb from eqs 5-6 when balls touch. Then F_S
    (eq 20), F_ballrace (eq 21), F_total (eq 22) and μ (eq 23). Speed enters
    only through F_R.

    Inputs are evaluated in blocks of 16,384 points, in place, so that the
    intermediates stay in the CPU's cache and no temporary array is allocated
    per operation; calls of 8 blocks or more share their blocks between
    threads, one per usable CPU or as many as the environment variable
    ``MICROBEARING_PHYSICS_THREADS`` says (numpy releases the GIL in its
    loops; throughput: ``bench/physics.py``). The arithmetic takes tan θ
    directly and sec θ from it, and the power laws of eqs 9 and 15 as exp of
    logarithms; it agrees with the plain composition of the equations'
    functions to ~1e-13 (tested), and every point runs the same operations
    whatever the size of the call or the number of threads, so results do not
    depend on batching.

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
    p, shape = checked_inputs(params)  # scalars as Python numbers: their products fold before arrays
    size = math.prod(shape)
    wanted = list(OUTPUTS) if outputs is None else _output_names(outputs)
    flat = {k: np.broadcast_to(v, shape).reshape(-1) if isinstance(v, np.ndarray) else v
            for k, v in p.items()}
    block_size = max(1, min(size, _BLOCK_POINTS))
    kept = np.empty((len(wanted), size))
    with np.errstate(divide="ignore"):  # log of a zero speed or viscosity: -inf, then exp(-inf) = 0
        flat.update(_coefficients(flat, convention))
    arrays = {k: v for k, v in flat.items() if isinstance(v, np.ndarray) and v.ndim}
    scalars = {k: v for k, v in flat.items() if k not in arrays}
    run = functools.partial(_run_blocks, arrays, scalars, dict(zip(wanted, kept, strict=True)),
                            [k for k in OUTPUTS if k not in wanted], block_size)
    blocks = -(-size // block_size)
    threads = min(_threads(), blocks // _MIN_BLOCKS_PER_THREAD) if blocks >= 2 * _MIN_BLOCKS_PER_THREAD else 1
    if threads < 2:
        run(0, size)
    else:  # contiguous runs of whole blocks, one per thread; numpy releases the GIL in its loops
        edges = [block_size * (blocks * i // threads) for i in range(threads)] + [size]
        for future in [_pool().submit(run, lo, hi) for lo, hi in itertools.pairwise(edges)]:
            future.result()
    values = dict(zip(wanted, kept.reshape(len(wanted), *shape), strict=True))
    return FrictionResult(**{k: values.get(k) for k in OUTPUTS}, convention=convention)


def _output_names(outputs: Iterable[str]) -> list[str]:
    names = [outputs] if isinstance(outputs, str) else list(outputs)
    unknown = [n for n in names if n not in OUTPUTS]
    if unknown or not names:
        raise ValueError(f"outputs must be names from {', '.join(OUTPUTS)}; got {names!r}")
    return list(dict.fromkeys(names))


#: Points per block of :func:`_block`: the block's work arrays stay in the CPU's cache.
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


def _run_blocks(arrays: dict[str, np.ndarray], scalars: dict[str, Any], kept: dict[str, np.ndarray],
                others: list[str], block_size: int, lo: int, hi: int) -> None:
    """Run :func:`_block` over points ``lo:hi``, block by block, into the rows of ``kept``.

    Outputs not asked for go to scratch rows overwritten block by block; each
    call has its own scratch and work arrays, so calls on disjoint ranges can
    run in parallel threads.
    """
    b = dict(scalars)
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
            _block(b, o, *work)


#: The inputs of :func:`_coefficients`: the ball, the materials and the film.
_COEFFICIENT_INPUTS = ("ball_diameter_m", "ball_youngs_modulus_Pa", "ball_poisson_ratio",
                       "race_youngs_modulus_Pa", "race_poisson_ratio", "viscosity_Pa_s",
                       "pressure_viscosity_1_Pa", "water_surface_tension_N_m")


def _coefficients(p: dict[str, Any], convention: str) -> dict[str, Any]:
    """Factors of :func:`_block` that depend on the ball, the materials and the film only.

    Scalars unless one of those inputs varies; then arrays of the inputs' length.
    Power laws are split into a coefficient, taken from the equation's own
    function at unit argument, and the power of the varying quantity.
    """
    values = tuple(p[name] for name in _COEFFICIENT_INPUTS)
    if all(isinstance(v, float) for v in values):
        return _scalar_coefficients(values, convention)
    return _coefficients_of(dict(zip(_COEFFICIENT_INPUTS, values, strict=True)), convention)


@functools.lru_cache(maxsize=64)
def _scalar_coefficients(values: tuple[float, ...], convention: str) -> dict[str, Any]:
    # Repeated single-point calls (the REST API's) mostly share their materials.
    return _coefficients_of(dict(zip(_COEFFICIENT_INPUTS, values, strict=True)), convention)


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
    # "olaru2005" counts M_b in both contact pairs of the ball (eq 21 as printed),
    # "derjaguin" once per ball; with R* twice as large the two agree for equal balls.
    pair_share = 1.0 if convention == "olaru2005" else 0.5
    return {
        "adhesion_per_gamma": surface.adhesion_force_ball_flat(radius, 1.0),  # eq 1 per J/m²
        "radius_over_e_star": radius / e_star,  # eq 3
        "log_rolling": np.log(rolling),
        "log_hysteresis": np.log(moments.hysteresis_moment(d, 1.0)),  # eq 15 at Q = 1 N
        "pressure_per_rolling": lubrication.pressure_force(1.0, ball_radius_m=radius),  # eq 13
        "pivot": moments.pivoting_moment(1.0, 1.0, 1.0),  # eq 16 per unit μs, N, m
        "capillary": surface.capillary_force(surface.ball_ball_radius(radius, radius, convention),
                                             p["water_surface_tension_N_m"]),  # eqs 5-6
        "ball_ball": moments.ball_ball_moment(1.0, 1.0, d),  # eq 17 per unit μb and N
        "pair_share_over_d": pair_share / d,
        "two_over_d": 2.0 / d,
    }


def _block(b: dict[str, Any], o: dict[str, np.ndarray], tan: np.ndarray, sec: np.ndarray,
           w1: np.ndarray, w2: np.ndarray) -> None:
    """Every output of one block into the rows ``o``, in place, with four work arrays.

    ``b`` holds the inputs and :func:`_coefficients` of the block (arrays of
    the block's length or scalars). No array is allocated here: on large inputs
    fresh memory costs more than the arithmetic.
    """
    # Groove geometry: tan in one vectorized pass (numpy's float64 cos is ~9x slower), sec from it.
    np.multiply(b["groove_angle_deg"], np.pi / 180.0, out=tan)
    np.tan(tan, out=tan)
    np.square(tan, out=sec)
    sec += 1.0
    np.sqrt(sec, out=sec)
    # Eq 7: Q0 = G / (2 z cos θ).
    q0 = o["contact_load_N"]
    np.multiply(b["load_N"], sec, out=q0)
    np.divide(q0, b["balls"], out=q0)
    q0 *= 0.5
    # Eq 1: pull-off force F = 3 π γ R. Eq 8: Q = Q0 + 2F + sqrt(4F Q0 + 4F²) = Q0 + 2 (F + sqrt(F (Q0 + F))).
    adhesion = o["adhesion_force_N"]
    np.multiply(b["adhesion_energy_J_m2"], b["adhesion_per_gamma"], out=adhesion)
    q = o["contact_load_adhesive_N"]
    np.add(q0, adhesion, out=w1)
    w1 *= adhesion
    np.sqrt(w1, out=w1)
    np.add(w1, adhesion, out=q)
    q *= 2.0
    q += q0
    # Eq 3: a = (R Q / E*)^(1/3); contact area π a²; peak pressure 3 Q / (2 π a²).
    a = o["contact_radius_m"]
    np.multiply(q, b["radius_over_e_star"], out=a)
    np.cbrt(a, out=a)
    np.square(a, out=o["contact_area_m2"])
    o["contact_area_m2"] *= np.pi
    np.divide(q, o["contact_area_m2"], out=o["max_contact_pressure_Pa"])
    o["max_contact_pressure_Pa"] *= 1.5
    # Eq 9: F_R = coefficient V^0.66 Q^0.47, and eq 15: M_ER = coefficient Q^1.33, as exponentials
    # of logarithms (a power costs a log and an exp; log Q serves both; V = 0 gives exp(-inf) = 0).
    np.log(q, out=w1)
    f_r = o["rolling_force_N"]
    np.log(b["speed_m_s"], out=w2)
    w2 *= lubrication.SPEED_EXPONENT
    np.multiply(w1, lubrication.LOAD_EXPONENT, out=f_r)
    f_r += w2
    f_r += b["log_rolling"]
    np.exp(f_r, out=f_r)
    np.multiply(f_r, b["pressure_per_rolling"], out=o["pressure_force_N"])  # eq 13
    m_er = o["hysteresis_moment_Nm"]
    np.multiply(w1, moments.HYSTERESIS_LOAD_EXPONENT, out=m_er)
    m_er += b["log_hysteresis"]
    np.exp(m_er, out=m_er)
    # Eqs 16-17: pivoting (3/8) μs Q a and ball-ball μb F_cb d moments.
    m_p = o["pivoting_moment_Nm"]
    np.multiply(q, a, out=m_p)
    m_p *= b["mu_pivot"]
    m_p *= b["pivot"]
    np.multiply(b["balls_touching"], b["capillary"], out=o["capillary_force_ball_ball_N"])
    np.multiply(o["capillary_force_ball_ball_N"], b["mu_ball"], out=o["ball_ball_moment_Nm"])
    o["ball_ball_moment_Nm"] *= b["ball_ball"]
    # Eq 20 term by term, F_S = M_b / (d cos θ) + 2 M_P tan θ / d + 2 M_ER / d + F_R; each
    # term, times 2 z / G below, is one part of the breakdown of μ.
    np.multiply(o["ball_ball_moment_Nm"], sec, out=o["mu_ball_ball"])
    o["mu_ball_ball"] *= b["pair_share_over_d"]
    np.multiply(m_p, tan, out=o["mu_pivoting"])
    o["mu_pivoting"] *= b["two_over_d"]
    np.multiply(m_er, b["two_over_d"], out=o["mu_hysteresis"])
    f_s = o["sliding_force_N"]
    np.add(o["mu_ball_ball"], o["mu_pivoting"], out=f_s)
    f_s += o["mu_hysteresis"]
    f_s += f_r
    np.multiply(f_r, 2.0, out=o["mu_rolling"])
    # Eqs 21-23: F_ballrace = 2 (F_S + F_R), F_total = z F_ballrace, μ = F_total / G;
    # per contact F_ballrace / (2 Q0) = μ cos θ.
    np.add(f_s, f_r, out=o["ball_race_force_N"])
    o["ball_race_force_N"] *= 2.0
    np.multiply(o["ball_race_force_N"], b["balls"], out=o["friction_force_N"])
    np.divide(o["friction_force_N"], b["load_N"], out=o["mu"])
    np.divide(o["mu"], sec, out=o["mu_contact"])
    np.divide(b["balls"], b["load_N"], out=w2)
    w2 *= 2.0
    for name in ("mu_pivoting", "mu_hysteresis", "mu_rolling", "mu_ball_ball"):
        o[name] *= w2
