"""Four points at a time: glibc's vector math library (libmvec) inside the numba kernel.

numpy computes tan, cbrt, log and exp of float64 one point at a time on CPUs without AVX-512
(its SIMD loops for them need AVX-512), and those four functions cost the numba kernel
(:mod:`physics.compiled`) most of its time there. glibc ships 4-wide AVX2 versions of each
(``libmvec``, since glibc 2.35 for tan and cbrt; accurate to 4 ulp, numpy's to 1 ulp). Each
function here is a numba intrinsic that loads four float64 of a workspace, calls libmvec's AVX2
version on them and stores the four results: the kernel's stages call them in a loop over a
block, with no Python between. :func:`available` says whether this machine wants them (numba, an
x86-64 CPU with AVX2 but without AVX-512, glibc's libmvec with the four functions); where it does
not, the kernel keeps numpy's functions. On a CPU with AVX-512 numpy's own loops for these
functions are already 8-wide (Intel's SVML, bench/RESULTS.md: a numba loop vectorized with SVML
gained nothing over them there), so they stay.

Importing this module does nothing: :func:`available` reads the CPU's flags and the library's
symbols, and :func:`intrinsics` builds the intrinsics (importing numba), when the numba kernel
first asks (a process that never calls it loads no library).

References
----------
.. [1] The GNU C Library, "Vector math library" (libmvec), x86-64 AVX2 variants
   ``_ZGVdN4v_<name>``: https://sourceware.org/glibc/wiki/libmvec
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import importlib.util
import platform
from pathlib import Path

__all__ = ["FUNCTIONS", "LIBRARY", "WIDTH", "available", "intrinsics", "source_hash"]

#: The elementary functions of the kernel that run four points at a time here.
FUNCTIONS = ("tan", "cbrt", "log", "exp")

#: The shared library that holds them (glibc's).
LIBRARY = "libmvec.so.1"

#: Points per call of a libmvec function (its AVX2 variant: four float64).
WIDTH = 4


@functools.cache
def source_hash() -> str:
    """A hash of this module's text: the generated stages name it, so that numba's cache of machine
    code compiled with an earlier version of these intrinsics is not reused."""
    return hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:16]


@functools.cache
def available() -> bool:
    """Whether the numba kernel may call libmvec: numba, an x86-64 CPU with AVX2 and without AVX-512
    (where numpy's loops are 8-wide) and libmvec's four AVX2 functions are all here."""
    if platform.machine().lower() not in ("x86_64", "amd64") or importlib.util.find_spec("numba") is None:
        return False
    try:
        flags = next((line for line in Path("/proc/cpuinfo").read_text().splitlines()
                      if line.startswith("flags")), "")
        library = ctypes.CDLL(LIBRARY)
    except OSError:  # not Linux, or no glibc vector library
        return False
    features = set(flags.split())
    return ("avx2" in features and "avx512f" not in features
            and all(hasattr(library, f"_ZGVdN4v_{name}") for name in FUNCTIONS))



def _intrinsic(name: str):
    """A numba intrinsic ``f(w, source, result)``: ``w[result:result + 4] = name(w[source:source + 4])``."""
    from llvmlite import ir
    from numba.core import cgutils, types
    from numba.extending import intrinsic

    @intrinsic
    def four(typingctx, workspace, source, result):
        signature = types.void(workspace, types.int64, types.int64)

        def codegen(context, builder, sig, args):
            array, start, end = args
            data = context.make_array(sig.args[0])(context, builder, array).data
            vector = ir.VectorType(ir.DoubleType(), WIDTH)
            function = cgutils.get_or_insert_function(builder.module, ir.FunctionType(vector, [vector]),
                                                      f"_ZGVdN4v_{name}")
            loaded = builder.load(builder.bitcast(builder.gep(data, [start]), vector.as_pointer()), align=8)
            builder.store(builder.call(function, [loaded]),
                          builder.bitcast(builder.gep(data, [end]), vector.as_pointer()), align=8)
            return context.get_dummy_value()

        return signature, codegen

    four.__name__ = f"{name}4"
    return four


@functools.cache
def intrinsics() -> tuple:
    """numba intrinsics ``f(w, source, result)`` of :data:`FUNCTIONS`, in order: each sets
    ``w[result:result + 4]`` to the function of ``w[source:source + 4]`` (``w`` a 1-D float64
    array, both ranges inside it). Loads libmvec into numba's linker; only where :func:`available`.
    """
    if not available():
        raise RuntimeError("glibc's libmvec with AVX2 (and numba) is not available on this machine")
    import llvmlite.binding as llvm

    llvm.load_library_permanently(LIBRARY)
    return tuple(_intrinsic(name) for name in FUNCTIONS)
