"""glibc's 4-wide elementary functions (libmvec) in the numba kernel, against numpy's, and the kernel
without them."""

import numpy as np
import pytest
from test_physics_compiled import LARGE, _kernel_result
from test_physics_evaluate import _random_inputs

from microbearing.physics import OUTPUTS, vectormath

needs_libmvec = pytest.mark.skipif(not vectormath.available(),
                                   reason="no numba, AVX2 without AVX-512, or libmvec with tan and cbrt")

#: What libmvec documents for its AVX2 variants (numpy's scalar functions are within 1 ulp).
ULPS = 4


def _four_at_a_time(x: np.ndarray) -> dict[str, np.ndarray]:
    """Each function of vectormath over ``x``, called four points at a time from a compiled loop."""
    import numba

    tan4, cbrt4, log4, exp4 = vectormath.intrinsics()

    @numba.njit
    def run(w, n):
        for j in range(0, n, vectormath.WIDTH):
            tan4(w, j, n + j)
            cbrt4(w, j, 2 * n + j)
            log4(w, j, 3 * n + j)
            exp4(w, j, 4 * n + j)

    n = -(-x.size // vectormath.WIDTH) * vectormath.WIDTH
    w = np.zeros(5 * n)
    w[:x.size] = x
    run(w, n)
    return {name: w[(k + 1) * n:(k + 1) * n + x.size] for k, name in enumerate(vectormath.FUNCTIONS)}


@needs_libmvec
def test_each_function_is_numpys_to_a_few_ulps_and_its_special_values_exactly():
    rng = np.random.default_rng(7)
    # the kernel's arguments: angles in radians, loads, speeds and their logs, over wide decades
    ordinary = np.concatenate([rng.uniform(-1.5, 1.5, 4001), 10.0 ** rng.uniform(-300, 300, 4001),
                               rng.uniform(-700, 700, 4001)])
    special = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, 5e-324, 1e-310, 709.7, 710.0, -745.2, -750.0])
    got = _four_at_a_time(np.concatenate([ordinary, special]))
    with np.errstate(all="ignore"):
        for name, values in got.items():
            reference = getattr(np, name)(np.concatenate([ordinary, special]))
            finite = np.isfinite(reference) & (reference != 0)
            ulps = np.abs(values[finite] - reference[finite]) / np.spacing(np.abs(reference[finite]))
            assert ulps.max() <= ULPS, (name, ulps.max())
            # zeros, infinities, nan and underflow exactly as numpy gives them (log 0 = -inf, exp(-inf) = 0)
            np.testing.assert_array_equal(values[~finite], reference[~finite], err_msg=name)


@needs_libmvec
def test_the_kernel_with_and_without_libmvec_agrees_with_numpy(monkeypatch):
    # the numba kernel calls libmvec where the machine has it, numpy's functions where not: both give
    # the numpy kernel's outputs to 1e-12 (every input varied, a single ball and zero speeds included)
    params = _random_inputs(LARGE + 5, seed=41)
    reference = _kernel_result("numpy", **params).to_dict()
    vectors = _kernel_result("numba", **params).to_dict()
    monkeypatch.setattr(vectormath, "available", lambda: False)
    scalars = _kernel_result("numba", **params).to_dict()
    differ = 0
    for name in OUTPUTS:
        np.testing.assert_allclose(vectors[name], reference[name], rtol=1e-12, atol=0, err_msg=name)
        np.testing.assert_allclose(scalars[name], reference[name], rtol=1e-12, atol=0, err_msg=name)
        differ += int(np.sum(vectors[name] != scalars[name]))
    # the two runs did take different paths: libmvec rounds some points otherwise than numpy
    assert differ > 0

