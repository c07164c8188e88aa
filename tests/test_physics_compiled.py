"""The compiled kernel of large calls (numba, optional) against the numpy kernel, the reference."""

import numpy as np
import pytest
from test_physics_evaluate import _random_inputs

from microbearing import physics
from microbearing.physics import OUTPUTS, bearing, compiled, evaluate

#: The fewest points of a large call (8 blocks): below it neither threads nor numba are used.
LARGE = 2 * bearing._MIN_BLOCKS_PER_THREAD * bearing._BLOCK_POINTS

needs_numba = pytest.mark.skipif(not compiled.AVAILABLE, reason="numba is not installed (the fast extra)")


def _kernel_result(monkeypatch, kernel, **kwargs):
    monkeypatch.setenv(bearing.KERNEL_VARIABLE, kernel)
    return evaluate(**kwargs)


@needs_numba
@pytest.mark.parametrize("convention", list(physics.CONVENTIONS))
def test_numba_agrees_with_numpy_on_every_output(monkeypatch, convention):
    # every input varied over its range (a single ball, zero speeds, viscosities and adhesion included),
    # on both threads and on one
    params = _random_inputs(LARGE + 3, seed=31)
    reference = _kernel_result(monkeypatch, "numpy", convention=convention, **params).to_dict()
    for threads in ("", "1"):
        monkeypatch.setenv(bearing.THREADS_VARIABLE, threads)
        fast = _kernel_result(monkeypatch, "numba", convention=convention, **params).to_dict()
        for name in OUTPUTS:
            np.testing.assert_allclose(fast[name], reference[name], rtol=1e-12, atol=0, err_msg=name)


@needs_numba
def test_numba_stores_only_the_outputs_asked_for(monkeypatch):
    # scalars broadcast (zero-stride inputs), the extras skipped: mu and F_S as with every output
    params = {"balls": np.arange(LARGE) % 40 + 1, "load_N": 8.8e-3, "speed_m_s": 0.05, "balls_touching": True}
    wanted = ["sliding_force_N", "mu"]
    fast = _kernel_result(monkeypatch, "numba", outputs=wanted, **params)
    reference = _kernel_result(monkeypatch, "numpy", **params)
    assert fast.mu_contact is None and fast.max_contact_pressure_Pa is None
    for name in wanted:
        np.testing.assert_allclose(getattr(fast, name), getattr(reference, name), rtol=1e-12, atol=0)
    # the compiled kernel agrees with the single-point path to the rounding of its own instruction
    # choices (1 ulp seen on some processors), as with every output above
    single = evaluate(balls=1, load_N=8.8e-3, speed_m_s=0.05, balls_touching=False).mu
    np.testing.assert_allclose(fast.mu[0], single, rtol=1e-12, atol=0)


def test_without_numba_large_calls_run_numpy(monkeypatch):
    params = _random_inputs(LARGE, seed=33)
    reference = _kernel_result(monkeypatch, "numpy", **params).mu
    monkeypatch.setattr(compiled, "AVAILABLE", False)
    monkeypatch.delenv(bearing.KERNEL_VARIABLE)
    np.testing.assert_array_equal(evaluate(outputs=["mu"], **params).mu, reference)
    with pytest.raises(ValueError, match=r"MICROBEARING_PHYSICS_KERNEL=numba needs numba: pip install"):
        _kernel_result(monkeypatch, "numba", **params)


def test_an_unknown_kernel_is_named():
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(bearing.KERNEL_VARIABLE, "fortran")
        with pytest.raises(ValueError, match="_KERNEL must be numpy or numba; got 'fortran'"):
            evaluate(balls=np.full(LARGE, 4.0), load_N=1e-2, speed_m_s=0.1)
