"""The kernel of :func:`physics.evaluate` compiled by numba (optional extra ``fast``).

Installed with ``pip install microbearing[fast]`` and chosen by the caller
(``evaluate(..., execution=ExecutionOptions(kernel="numba"))``). numba compiles the same
functions the numpy path runs: :func:`physics.kernel.point_outputs` and the equation functions it
calls (:data:`physics.kernel.EQUATIONS`), with numba's own implementations of the elementary
functions of :mod:`physics.elementary`. One compiled loop runs the kernel point by point, every
intermediate in registers, and releases the GIL, so the parts of a call can run in parallel
threads sharing no memory traffic but their inputs and outputs. The C library's tan, cbrt, log and
exp may differ from numpy's in the last bit, so the two kernels agree to ~1e-15 relative, not bit
for bit (tested to 1e-12).

References
----------
.. [1] Olaru et al., COMEC 2005, eqs. 1-23 (see :mod:`physics.kernel`).
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable

import numpy as np

from . import elementary, kernel

try:
    import numba
    from numba.extending import overload, register_jitable
except ImportError:  # the optional extra is not installed: the numpy kernel serves every call
    numba = None

__all__ = ["AVAILABLE", "points"]

#: Whether numba is installed (``pip install microbearing[fast]``).
AVAILABLE = numba is not None


def _implemented_by(ufunc):
    """numba's typing of an elementary function: on a float, the numpy ufunc (numba's own)."""
    def typing(x):
        return lambda x: ufunc(x)
    return typing


def _register_elementary() -> None:
    """numba's implementations of :mod:`physics.elementary`'s functions: numpy's ufuncs on a float."""
    for function, ufunc in ((elementary.sqrt, np.sqrt), (elementary.cbrt, np.cbrt), (elementary.tan, np.tan),
                            (elementary.log, np.log), (elementary.exp, np.exp)):
        overload(function)(_implemented_by(ufunc))


def _loop(outputs_of_point):  # pragma: no cover - compiled
    """The compiled loop over points ``lo:hi`` of :func:`physics.kernel.point_outputs` (compiled)."""

    def run(point_columns, material_columns, wanted, out, extras, lo, hi):
        p, m = point_columns, material_columns
        for i in range(lo, hi):
            point = (p[0][i], p[1][i], p[2][i], p[3][i], p[4][i], p[5][i], p[6][i], p[7][i])
            values = outputs_of_point(point, (m[0][i], m[1][i], m[2][i], m[3][i], m[4][i], m[5][i], m[6][i]),
                                      extras)
            for row in range(wanted.size):
                out[row, i] = values[wanted[row]]

    return run


_COMPILE_LOCK = threading.Lock()


@functools.cache
def _compiled():
    """The compiled loop, one signature whatever the layouts (a scalar is a read-only zero-stride view).

    Compiled in memory once per process: numba's disk cache keys on this module's source only, so it
    would keep serving a kernel whose equation functions have changed.
    """
    _register_elementary()
    for function in kernel.EQUATIONS:
        register_jitable(function)
    options = {"nogil": True, "error_model": "numpy"}
    types = numba.types
    column = types.Array(types.float64, 1, "A", readonly=True)
    signature = types.void(types.UniTuple(column, len(kernel.POINT_INPUTS)), types.UniTuple(column, 7),
                           types.Array(types.int64, 1, "A"), types.Array(types.float64, 2, "A"),
                           types.boolean, types.int64, types.int64)
    return numba.njit(signature, **options)(_loop(numba.njit(**options)(kernel.point_outputs)))


def points(point: tuple[np.ndarray, ...], material: tuple[np.ndarray, ...], out: np.ndarray,
           wanted: np.ndarray, extras: bool) -> Callable[[int, int], None]:
    """A function ``run(lo, hi)`` writing every wanted output of points ``lo:hi`` into the rows of ``out``.

    Parameters
    ----------
    point : tuple of numpy.ndarray
        The inputs of :data:`physics.kernel.POINT_INPUTS`: 1-D float64 arrays of the call's length
        (a scalar as a zero-stride view), ``balls_touching`` as 0.0 or 1.0. [SI units]
    material : tuple of numpy.ndarray
        :func:`physics.kernel.material`'s factors, the same way.
    out : numpy.ndarray
        (wanted outputs, points) float64, written in place. [SI units]
    wanted : numpy.ndarray
        int64, for each row of ``out``, the position in :data:`physics.OUTPUTS` of
        the output it receives. [-]
    extras : bool
        Whether to compute the outputs that no other output needs. [-]

    Returns
    -------
    callable
        ``run(lo, hi)``; calls on disjoint ranges may run in parallel threads
        (the loop releases the GIL). [-]
    """
    with _COMPILE_LOCK:  # the first calls of several threads compile once
        loop = _compiled()
    return lambda lo, hi: loop(point, material, wanted, out, extras, lo, hi)
