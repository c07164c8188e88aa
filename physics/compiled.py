"""The kernel of :func:`physics.evaluate` compiled by numba (optional extra ``fast``).

Installed with ``pip install microbearing[fast]`` and chosen by the caller
(``evaluate(..., execution=ExecutionOptions(kernel="numba"))``). The kernel is generated from the
functions the numpy path runs (:func:`physics.kernel.point_outputs` and the equation functions it
calls) by :mod:`physics.fused`: its arithmetic, cut at the expensive elementary functions, is
compiled by numba into one loop per stage that keeps every intermediate in registers and releases
the GIL, and numpy's vectorized loops compute tan, cbrt, log and exp over each block between the
stages. A block's buffers stay in the CPU's cache, so a call reads its inputs and writes its
outputs once. The operations are the numpy kernel's in its order, with numpy's elementary
functions, so the two agree bit for bit where numba emits the same IEEE operations (tested to
1e-12).

References
----------
.. [1] Olaru et al., COMEC 2005, eqs. 1-23 (see :mod:`physics.kernel`).
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable

import numpy as np

from . import fused

try:
    import numba
except ImportError:  # the optional extra is not installed: the numpy kernel serves every call
    numba = None

__all__ = ["AVAILABLE", "BLOCK_POINTS", "points"]

#: Whether numba is installed (``pip install microbearing[fast]``).
AVAILABLE = numba is not None

#: Points per block: the block's buffers (about 25 rows of 8 bytes a point) stay in a core's L2 cache.
BLOCK_POINTS = 4096

_COMPILE_LOCK = threading.Lock()


@functools.cache
def _compiled(extras: bool) -> tuple[fused.Plan, tuple]:
    """The plan of :func:`physics.fused.plan` and its stages compiled, one signature whatever the layouts.

    Compiled in memory once per process and choice of ``extras`` (a scalar input is a read-only
    zero-stride view, so every call has the same types).
    """
    plan = fused.plan(extras)
    namespace = {"np": np}
    exec(compile(plan.source, "<physics.fused stages>", "exec"), namespace)  # the source of physics.fused
    types = numba.types
    column = types.Array(types.float64, 1, "A", readonly=True)
    signature = types.void(types.UniTuple(column, fused.INPUTS), types.Array(types.float64, 2, "C"),
                           types.Array(types.float64, 2, "A"), types.Array(types.int64, 1, "C"),
                           types.int64, types.int64)
    stages = tuple(numba.njit(signature, nogil=True, error_model="numpy")(namespace[f"stage_{level}"])
                   for level in range(plan.levels))
    return plan, stages


def points(inputs: tuple[np.ndarray, ...], out: np.ndarray, rows: np.ndarray,
           extras: bool) -> Callable[[int, int], None]:
    """A function ``run(lo, hi)`` writing every wanted output of points ``lo:hi`` into the rows of ``out``.

    Parameters
    ----------
    inputs : tuple of numpy.ndarray
        The inputs of :data:`physics.kernel.POINT_INPUTS` then the factors of
        :func:`physics.kernel.material`: 1-D float64 arrays of the call's length (a scalar as a
        zero-stride view), ``balls_touching`` as 0.0 or 1.0. [SI units]
    out : numpy.ndarray
        (wanted outputs, points) float64, written in place. [SI units]
    rows : numpy.ndarray
        int64, for each output of :data:`physics.OUTPUTS`, its row in ``out``, or -1. [-]
    extras : bool
        Whether to compute the outputs that no other output needs. [-]

    Returns
    -------
    callable
        ``run(lo, hi)``; calls on disjoint ranges may run in parallel threads (numba's loops and
        numpy's release the GIL). [-]
    """
    with _COMPILE_LOCK:  # the first calls of several threads compile once
        plan, stages = _compiled(extras)
    def run(lo: int, hi: int) -> None:
        buffers = np.empty((max(plan.buffers, 1), BLOCK_POINTS))
        with np.errstate(divide="ignore"):  # per thread: log of a zero speed is -inf, exp(-inf) = 0
            for start in range(lo, hi, BLOCK_POINTS):
                n = min(BLOCK_POINTS, hi - start)
                stages[0](inputs, buffers, out, rows, start, n)
                for level, calls in enumerate(plan.vectorized, start=1):
                    for name, (kind, index), row in calls:
                        argument = inputs[index][start:start + n] if kind == "input" else buffers[index, :n]
                        fused.VECTORIZED[name](argument, out=buffers[row, :n])
                    stages[level](inputs, buffers, out, rows, start, n)

    return run
