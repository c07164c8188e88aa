"""The kernel of :func:`physics.evaluate` compiled by numba, for large calls (optional).

Installed with ``pip install microbearing[fast]``. It runs, point by point, the
operations of the numpy kernel (:func:`physics.bearing._kernel`) in the same
order, in one compiled loop that keeps every intermediate in registers and
releases the GIL, so that the threads of a large call share no memory traffic
but their inputs and outputs. numpy's and the C library's tan, cbrt, log and exp
may differ in the last bit, so the two kernels agree to ~1e-15 relative, not
bit for bit (tested to 1e-12); the numpy kernel stays the reference and the
default. This one runs when ``MICROBEARING_PHYSICS_KERNEL=numba``: it spreads
better over threads, but on the 2-core machine of bench/RESULTS.md one thread of
it is slower than one of numpy, and two threads were no faster overall.

References
----------
.. [1] Olaru et al., COMEC 2005, eqs. 1-23 (see :mod:`physics.bearing`).
"""

from __future__ import annotations

import functools
import math
import threading
from collections.abc import Callable

import numpy as np

from . import lubrication, moments

try:
    import numba
except ImportError:  # the optional extra is not installed: the numpy kernel serves every call
    numba = None

__all__ = ["AVAILABLE", "INPUTS", "points"]

#: Whether numba is installed (``pip install microbearing[fast]``).
AVAILABLE = numba is not None

#: The kernel's inputs in order: the parameters and coefficients of :func:`physics.bearing._kernel`.
INPUTS = ("groove_angle_deg", "load_N", "balls", "adhesion_energy_J_m2", "speed_m_s", "mu_pivot",
          "balls_touching", "mu_ball", "adhesion_per_gamma", "radius_over_e_star", "log_rolling",
          "log_hysteresis", "pressure_per_rolling", "pivot", "capillary", "ball_ball", "pair_share_over_d",
          "two_over_d")

_DEG = np.pi / 180.0
_SPEED_EXPONENT = lubrication.SPEED_EXPONENT
_LOAD_EXPONENT = lubrication.LOAD_EXPONENT
_HYSTERESIS_EXPONENT = moments.HYSTERESIS_LOAD_EXPONENT


#: Points per chunk of :func:`_points`: its stages run over a chunk one after another.
_CHUNK = 256


def _points(inputs, wanted, out, extras, lo, hi, min_balls_touching):  # pragma: no cover - compiled
    (theta, load, balls, gamma, speed, mu_pivot, touching, mu_ball, adhesion_per_gamma, radius_over_e_star,
     log_rolling, log_hysteresis, pressure_per_rolling, pivot, capillary_per_touch, ball_ball,
     pair_share_over_d, two_over_d) = inputs
    # The operations of physics.bearing._kernel, in its order (see the comments there), in stages over
    # a chunk of points: each stage's points are independent, so the CPU overlaps the long latencies
    # of tan, cbrt, log and exp of successive points, as numpy's loops over whole arrays do.
    work = np.empty((10, _CHUNK))
    tan_, sec_, q0_, adhesion_, q_, a_, log_q_, log_speed_, f_r_, m_er_ = work
    values = np.zeros(21)  # one point's outputs, in the order of physics.OUTPUTS
    for start in range(lo, hi, _CHUNK):
        n = min(_CHUNK, hi - start)
        for j in range(n):
            tan_[j] = np.tan(theta[start + j] * _DEG)
        for j in range(n):
            i = start + j
            sec = math.sqrt(tan_[j] * tan_[j] + 1.0)
            q0 = load[i] * sec
            q0 = q0 / balls[i]
            q0 = q0 * 0.5
            adhesion = gamma[i] * adhesion_per_gamma[i]
            w1 = math.sqrt((q0 + adhesion) * adhesion)
            q = w1 + adhesion
            sec_[j], q0_[j], adhesion_[j], q_[j] = sec, q0, adhesion, q * 2.0 + q0
        for j in range(n):
            a_[j] = np.cbrt(q_[j] * radius_over_e_star[start + j])
        for j in range(n):
            log_q_[j] = np.log(q_[j])
            log_speed_[j] = np.log(speed[start + j]) * _SPEED_EXPONENT
        for j in range(n):
            i = start + j
            f_r_[j] = np.exp(log_q_[j] * _LOAD_EXPONENT + log_speed_[j] + log_rolling[i])
            m_er_[j] = np.exp(log_q_[j] * _HYSTERESIS_EXPONENT + log_hysteresis[i])
        for j in range(n):
            i = start + j
            tan, sec, q, a, f_r, m_er = tan_[j], sec_[j], q_[j], a_[j], f_r_[j], m_er_[j]
            m_p = q * a
            m_p = m_p * mu_pivot[i] * pivot[i]
            capillary = 1.0 if balls[i] >= min_balls_touching else 0.0
            capillary = capillary * touching[i] * capillary_per_touch[i]
            m_b = capillary * mu_ball[i] * ball_ball[i]
            mu_ball_ball = m_b * sec * pair_share_over_d[i]
            mu_pivoting = m_p * tan * two_over_d[i]
            mu_hysteresis = m_er * two_over_d[i]
            f_s = mu_ball_ball + mu_pivoting + mu_hysteresis + f_r
            ball_race = (f_s + f_r) * 2.0
            total = ball_race * balls[i]
            mu = total / load[i]
            values[0], values[2], values[3], values[4] = mu, total, mu_pivoting, mu_hysteresis
            values[6], values[7], values[8], values[9] = mu_ball_ball, q0_[j], q, a
            values[12], values[13], values[14], values[16] = adhesion_[j], capillary, f_r, f_s
            values[17], values[18], values[19], values[20] = m_er, m_p, m_b, ball_race
            if extras:  # what no other output needs, only when asked for
                area = a * a * np.pi
                per_newton = balls[i] / load[i] * 2.0
                values[1], values[10], values[11] = mu / sec, area, q / area * 1.5
                values[3], values[4] = mu_pivoting * per_newton, mu_hysteresis * per_newton
                values[5], values[6] = f_r * 2.0 * per_newton, mu_ball_ball * per_newton
                values[15] = f_r * pressure_per_rolling[i]
            for row in range(wanted.size):
                out[row, i] = values[wanted[row]]


_COMPILE_LOCK = threading.Lock()


@functools.cache
def _compiled():
    """The compiled loop, one signature whatever the layouts (a scalar is a read-only zero-stride view)."""
    types = numba.types
    column = types.Array(types.float64, 1, "A", readonly=True)
    signature = types.void(types.UniTuple(column, len(INPUTS)), types.Array(types.int64, 1, "A"),
                           types.Array(types.float64, 2, "A"), types.boolean, types.int64, types.int64,
                           types.float64)
    try:  # compiled once per machine: cached on disk where numba finds a writable place
        return numba.njit(signature, nogil=True, error_model="numpy", cache=True)(_points)
    except RuntimeError:  # no writable cache location: compile in memory on each start
        return numba.njit(signature, nogil=True, error_model="numpy")(_points)


def points(inputs: dict[str, np.ndarray], out: np.ndarray, wanted: np.ndarray, extras: bool,
           min_balls_touching: float) -> Callable[[int, int], None]:
    """A function ``run(lo, hi)`` writing every wanted output of points ``lo:hi`` into the rows of ``out``.

    Parameters
    ----------
    inputs : dict
        The names of :data:`INPUTS`: 1-D float arrays of the call's length (a
        scalar as a zero-stride view), ``balls_touching`` as 0.0 or 1.0. [SI units]
    out : numpy.ndarray
        (wanted outputs, points) float64, written in place. [SI units]
    wanted : numpy.ndarray
        int64, for each row of ``out``, the position in :data:`physics.OUTPUTS` of
        the output it receives. [-]
    extras : bool
        Whether to compute the outputs that no other output needs
        (``physics.bearing._EXTRAS``). [-]
    min_balls_touching : float
        The fewest balls that touch a neighbour. [1]

    Returns
    -------
    callable
        ``run(lo, hi)``; calls on disjoint ranges may run in parallel threads
        (the loop releases the GIL). [-]
    """
    with _COMPILE_LOCK:  # the first large calls of several threads compile once
        kernel = _compiled()
    columns = tuple(inputs[name] for name in INPUTS)
    return lambda lo, hi: kernel(columns, wanted, out, extras, lo, hi, min_balls_touching)
