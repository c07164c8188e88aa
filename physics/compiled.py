"""The kernel of :func:`physics.evaluate` compiled by numba (optional extra ``fast``).

Installed with ``pip install microbearing[fast]`` and chosen by the caller
(``evaluate(..., execution=ExecutionOptions(kernel="numba"))``). The kernel is generated from the
functions the numpy path runs (:func:`physics.kernel.point_outputs` and the equation functions it
calls) by :mod:`physics.fused`: its arithmetic, cut at the expensive elementary functions, is
compiled by numba into one loop per stage that keeps every intermediate in registers and releases
the GIL. Between the stages, tan, cbrt, log and exp run over each block four points at a time
through glibc's vector math library where the machine has it (:mod:`physics.vectormath`: x86-64
with AVX2 but not AVX-512, glibc 2.35 or later; about 6x numpy's one-point-at-a-time functions
there), else as numpy's vectorized loops. Everything a block's stages share lives in one workspace per thread
that stays in the CPU's cache, so a call reads its inputs and writes its outputs once; what
depends on the materials alone is computed once a call. The operations are the numpy kernel's in
its order; with numpy's elementary functions the two agree bit for bit where numba emits the same
IEEE operations, with libmvec's (4 ulp against numpy's 1) to a few ulp (both tested to 1e-12).

Compiling takes seconds, so the generated source is written to a file beside the package (in
``__pycache__``, named by its hash) and numba caches the machine code next to it: a later process
loads it (what remains is numba's own start, about a second). A read-only install compiles in
memory at each process's first compiled call.

References
----------
.. [1] Olaru et al., COMEC 2005, eqs. 1-23 (see :mod:`physics.kernel`).
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import os
import sys
import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np

from . import fused, kernel, vectormath

__all__ = ["AVAILABLE", "BLOCK_POINTS", "points"]

#: Whether numba is installed (``pip install microbearing[fast]``); it is imported at the first
#: compiled call, so that importing the physics does not pay for it.
AVAILABLE = importlib.util.find_spec("numba") is not None

#: Points per block: a block's workspace (about 46 rows of 8 bytes a point) stays in a core's L2 cache.
BLOCK_POINTS = 4096
#: Points between two rows of the workspace beyond a block's: one cache line, so that rows do not
#: start 4 KiB apart (where they would share the L1 cache's sets and alias in its store buffer),
#: and room for the spare lanes of a block's last four-point call (:mod:`physics.vectormath`).
_PAD = 8

#: Where the generated stages are written as a module, so that numba caches their machine code
#: beside it (``cache=True``) and a later process loads it instead of compiling (seconds); where
#: this folder cannot be written (a read-only install), they are compiled in memory each process.
_CACHE_DIR = Path(__file__).resolve().parent / "__pycache__" / "fused"

_COMPILE_LOCK = threading.Lock()

#: The loop storing a block's outputs, appended to the generated stages (``STRIDE`` filled in);
#: slices, which numba copies as a whole (an element loop would check each index).
_STORE_SOURCE = """
def store(n, w, out, rows, slots, start):
    for k in range(rows.size):
        base = slots[k] * STRIDE
        out[rows[k], start:start + n] = w[base:base + n]
"""


def _vector_source(plan: fused.Plan) -> str:
    """``vector_<level>(n, w)`` for each level 1 ... levels - 1: that level's elementary functions
    over a block, four points a call of :mod:`physics.vectormath` (a workspace row has room past
    the block's last point for the last call's spare lanes)."""
    functions = []
    for level, calls in enumerate(plan.vectorized, start=1):
        body = "\n".join(f"        {name}4(w, {argument * plan.stride} + j, {result * plan.stride} + j)"
                         for name, argument, result in calls)
        loop = f"    for j in range(0, n, {vectormath.WIDTH}):"
        functions.append(f"def vector_{level}(n, w):\n{loop}\n{body}\n")
    return "\n\n" + "\n\n".join(functions)


@functools.cache
def _compiled(extras: bool, block: int, vector: bool) -> tuple[fused.Plan, tuple, Callable, tuple]:
    """The plan of :func:`physics.fused.plan` for blocks of ``block`` points, its prelude and stages
    compiled, the function ``store(n, w, out, rows, slots, start)`` copying ``n`` points of
    workspace slot ``slots[k]`` to ``out[rows[k], start:]``, and (``vector``) the compiled
    elementary functions of each level (:func:`_vector_source`); once per process and choice.
    """
    import numba

    plan = fused.plan(extras, block + _PAD)
    header = "import numpy as np\n"
    if vector:  # the intrinsics' own code is named too: a change of it is a new file, so a new cache
        names = ", ".join(f"{name}4" for name in vectormath.FUNCTIONS)
        header += (f"from {__package__} import vectormath\n\n# vectormath {vectormath.source_hash()}\n"
                   f"{names} = vectormath.intrinsics()\n")
    namespace, cached = _namespace(header + "\n\n" + plan.source
                                   + _STORE_SOURCE.replace("STRIDE", str(plan.stride))
                                   + (_vector_source(plan) if vector else ""))
    types = numba.types
    workspace, indices = types.Array(types.float64, 1, "C"), types.Array(types.int64, 1, "C")
    vectors = [f"vector_{level}" for level in range(1, plan.levels)] if vector else []
    signatures = {name: types.void(types.int64, workspace)
                  for name in ("prelude", *(f"stage_{level}" for level in range(plan.levels)), *vectors)}
    signatures["store"] = types.void(types.int64, workspace, types.Array(types.float64, 2, "C"), indices,
                                     indices, types.int64)
    functions = {}
    for name, signature in signatures.items():
        options = {"nogil": True, "error_model": "numpy"}
        try:
            functions[name] = numba.njit(signature, cache=cached, **options)(namespace[name])
        except RuntimeError:  # numba found no folder to write its cache in: compiled in memory
            functions[name] = numba.njit(signature, **options)(namespace[name])
    store = functions.pop("store")
    vectored = tuple(functions.pop(name) for name in vectors)
    return plan, tuple(functions.values()), store, vectored


def _namespace(source: str) -> tuple[dict, bool]:
    """The functions of ``source`` (generated by :mod:`physics.fused`), and whether numba may cache them.

    The source is written once to a file named by its hash in :data:`_CACHE_DIR` and run from
    there (numba's cache is keyed by the file); where that folder cannot be written, in memory.
    """
    name = "stages_" + hashlib.sha256(source.encode()).hexdigest()[:20]
    path = _CACHE_DIR / f"{name}.py"
    try:
        if not path.is_file() or path.read_text() != source:
            path.parent.mkdir(parents=True, exist_ok=True)
            partial = path.with_name(f"{name}.{os.getpid()}.{threading.get_ident()}.tmp")
            partial.write_text(source)
            os.replace(partial, path)  # whole or absent, when processes race
    except OSError:
        namespace: dict = {}
        exec(compile(source, "<physics.fused stages>", "exec"), namespace)
        return namespace, False
    spec = importlib.util.spec_from_file_location(f"{__name__}_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    sys.modules[spec.name] = module  # numba's cache finds the functions' globals by module name
    return vars(module), True


def points(inputs: tuple, out: np.ndarray, rows: list[int], extras: bool) -> Callable[[int, int], None]:
    """A function ``run(lo, hi)`` writing every wanted output of points ``lo:hi`` into the rows of ``out``.

    Parameters
    ----------
    inputs : tuple
        The inputs of :data:`physics.kernel.POINT_INPUTS` then the factors of
        :func:`physics.kernel.material`: Python floats, or 1-D arrays of the call's length
        (``balls_touching`` may be boolean). [SI units]
    out : numpy.ndarray
        (wanted outputs, points) float64, written in place. [SI units]
    rows : list of int
        For each output of :data:`physics.OUTPUTS`, its row in ``out``, or -1. [-]
    extras : bool
        Whether to compute the outputs that no other output needs. [-]

    Returns
    -------
    callable
        ``run(lo, hi)``; calls on disjoint ranges may run in parallel threads (numba's loops and
        numpy's release the GIL). [-]
    """
    size = BLOCK_POINTS
    with _COMPILE_LOCK:  # the first calls of several threads compile once
        plan, (prelude, *stages), store, vectors = _compiled(extras, size, vectormath.available())
    for position, value in plan.constants:
        if rows[position] >= 0:
            out[rows[position]] = value
    stored = [(row, plan.outputs[position]) for position, row in enumerate(rows)
              if row >= 0 and plan.outputs[position] is not None]
    stored_rows = np.array([row for row, _ in stored], dtype=np.int64)
    stored_slots = np.array([slot for _, slot in stored], dtype=np.int64)
    varying = [k for k, value in enumerate(inputs) if isinstance(value, np.ndarray)]
    uniform = all(k < len(kernel.POINT_INPUTS) for k in varying)  # the material factors are scalars

    def run(lo: int, hi: int) -> None:
        w = np.empty(plan.slots * plan.stride)
        slots = w.reshape(plan.slots, plan.stride)
        for k, value in enumerate(inputs):
            if k not in varying:  # a scalar: its row is filled once
                slots[k, :size] = value
        if uniform:
            prelude(size, w)
        full = [row[:size] for row in slots]
        with np.errstate(divide="ignore"):  # per thread: log of a zero speed is -inf, exp(-inf) = 0
            for start in range(lo, hi, size):
                stop = min(start + size, hi)
                n = stop - start
                block = full if n == size else [row[:n] for row in slots]
                for k in varying:
                    block[k][...] = inputs[k][start:stop]
                if not uniform:
                    prelude(n, w)
                stages[0](n, w)
                for level, calls in enumerate(plan.vectorized, start=1):
                    if vectors:
                        vectors[level - 1](n, w)
                    else:
                        for name, argument, result in calls:
                            fused.VECTORIZED[name](block[argument], out=block[result])
                    stages[level](n, w)
                store(n, w, out, stored_rows, stored_slots, start)

    return run
