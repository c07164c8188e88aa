"""How :func:`physics.evaluate` runs a call: the kernel, and the threads a large call is shared between.

The caller decides (the service from its settings, ``MICROBEARING_PHYSICS_KERNEL`` and
``MICROBEARING_PHYSICS_THREADS``); physics reads no environment and owns no thread: the threads
are an executor the caller passes in.
"""

from __future__ import annotations

from concurrent.futures import Executor
from dataclasses import dataclass

from . import compiled

__all__ = ["KERNELS", "ExecutionOptions"]

#: The kernels of :func:`physics.evaluate`: numpy's ufuncs over blocks, or the numba-compiled loop.
KERNELS = ("numpy", "numba")


@dataclass(frozen=True)
class ExecutionOptions:
    """The kernel of a :func:`physics.evaluate` call on arrays, and the threads that share a large call.

    Parameters
    ----------
    kernel : {"numpy", "numba"}, default "numpy"
        ``"numpy"``: numpy's ufuncs over cache-sized blocks of points. ``"numba"``: the same
        functions compiled by numba (:mod:`physics.compiled`, ``pip install microbearing[fast]``),
        fused loops between tan, cbrt, log and exp four points at a time (glibc's libmvec on
        x86-64 with AVX2 but not AVX-512, :mod:`physics.vectormath`; else numpy's), about 2.5x
        faster for μ there (``bench/physics.py``); agrees with numpy to ~1e-15 relative. Its first call in a
        process costs numba's start (about a second; seconds more where its cache beside the
        package cannot be written). One point (scalar inputs) always runs on Python floats.
    threads : int, default 1
        Most parts a large call (8 blocks of 16,384 points or more) is split into, each run by
        ``executor``; each part has at least 4 blocks. [1]
    executor : concurrent.futures.Executor, optional
        Runs the parts (a thread pool: numpy's loops and the compiled loop release the GIL);
        required when ``threads`` > 1. None: the caller's thread runs the whole call.

    Raises
    ------
    ValueError
        For an unknown kernel, numba when it is not installed, a thread count that is not a
        whole number >= 1, or threads > 1 without an executor.

    Examples
    --------
    >>> ExecutionOptions().kernel, ExecutionOptions().threads
    ('numpy', 1)
    """

    kernel: str = "numpy"
    threads: int = 1
    executor: Executor | None = None

    def __post_init__(self):
        if self.kernel not in KERNELS:
            raise ValueError(f"kernel must be numpy or numba; got {self.kernel!r}")
        if self.kernel == "numba" and not compiled.AVAILABLE:
            raise ValueError("kernel numba needs numba: pip install microbearing[fast]")
        if type(self.threads) is not int or self.threads < 1:
            raise ValueError(f"threads must be a whole number >= 1; got {self.threads!r}")
        if self.threads > 1 and self.executor is None:
            raise ValueError(f"threads={self.threads} needs an executor to run them; physics starts none")

    def __reduce__(self):
        # An executor does not travel: a copy sent to another process (a dask worker evaluating a
        # model's chunk) keeps the kernel and runs in its caller's thread there.
        return (ExecutionOptions, (self.kernel,))
