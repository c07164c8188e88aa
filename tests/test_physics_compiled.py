"""The compiled kernel of large calls (numba, optional) against the numpy kernel, the reference."""

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from test_physics_evaluate import _random_inputs

from microbearing import physics
from microbearing.physics import OUTPUTS, ExecutionOptions, bearing, compiled, evaluate

#: The fewest points of a large call (8 blocks): below it neither threads nor numba are used.
LARGE = 2 * bearing._MIN_BLOCKS_PER_THREAD * bearing._BLOCK_POINTS

needs_numba = pytest.mark.skipif(not compiled.AVAILABLE, reason="numba is not installed (the fast extra)")


def _kernel_result(kernel, threads=1, **kwargs):
    with ThreadPoolExecutor(threads) as pool:
        return evaluate(execution=ExecutionOptions(kernel=kernel, threads=threads, executor=pool), **kwargs)


@needs_numba
@pytest.mark.parametrize("convention", list(physics.CONVENTIONS))
def test_numba_agrees_with_numpy_on_every_output(convention):
    # every input varied over its range (a single ball, zero speeds, viscosities and adhesion included),
    # on both threads and on one
    params = _random_inputs(LARGE + 3, seed=31)
    reference = _kernel_result("numpy", convention=convention, **params).to_dict()
    for threads in (2, 1):
        fast = _kernel_result("numba", threads, convention=convention, **params).to_dict()
        for name in OUTPUTS:
            np.testing.assert_allclose(fast[name], reference[name], rtol=1e-12, atol=0, err_msg=name)


@needs_numba
def test_numba_stores_only_the_outputs_asked_for():
    # scalars broadcast (zero-stride inputs), the extras skipped: mu and F_S as with every output
    params = {"balls": np.arange(LARGE) % 40 + 1, "load_N": 8.8e-3, "speed_m_s": 0.05, "balls_touching": True}
    wanted = ["sliding_force_N", "mu"]
    fast = _kernel_result("numba", outputs=wanted, **params)
    reference = _kernel_result("numpy", **params)
    assert fast.mu_contact is None and fast.max_contact_pressure_Pa is None
    for name in wanted:
        np.testing.assert_allclose(getattr(fast, name), getattr(reference, name), rtol=1e-12, atol=0)
    # the compiled kernel agrees with the single-point path to the rounding of its own instruction
    # choices (1 ulp seen on some processors), as with every output above
    single = evaluate(balls=1, load_N=8.8e-3, speed_m_s=0.05, balls_touching=False).mu
    np.testing.assert_allclose(fast.mu[0], single, rtol=1e-12, atol=0)


def test_without_numba_large_calls_run_numpy(monkeypatch):
    params = _random_inputs(LARGE, seed=33)
    reference = _kernel_result("numpy", **params).mu
    monkeypatch.setattr(compiled, "AVAILABLE", False)
    np.testing.assert_array_equal(evaluate(outputs=["mu"], **params).mu, reference)
    with pytest.raises(ValueError, match=r"kernel numba needs numba: pip install"):
        _kernel_result("numba", **params)


def test_an_unknown_kernel_is_named():
    with pytest.raises(ValueError, match="kernel must be numpy or numba; got 'fortran'"):
        evaluate(balls=np.full(LARGE, 4.0), load_N=1e-2, speed_m_s=0.1, execution=ExecutionOptions("fortran"))


def _parameter_values():
    """A strategy of one value of every parameter of physics.PARAMETERS, over its whole declared range."""
    from hypothesis import strategies as st

    values = {}
    for name, spec in physics.PARAMETERS.items():
        if spec.kind == "bool":
            values[name] = st.booleans()
        elif spec.kind == "int":
            values[name] = st.integers(int(spec.minimum), int(spec.maximum))
        else:
            values[name] = st.floats(spec.minimum, spec.maximum, allow_nan=False, allow_infinity=False,
                                     exclude_min=spec.exclusive_minimum, exclude_max=spec.exclusive_maximum)
    return st.fixed_dictionaries(values)


@needs_numba
def test_numba_and_numpy_agree_anywhere_in_the_declared_ranges():
    # Points drawn by hypothesis over every parameter's whole range (its ends included), evaluated as
    # arrays by both kernels: the same equation functions, numba's tan, cbrt, log and exp against
    # numpy's. Extreme corners overflow to inf or lose the outputs to nan the same way in both.
    from hypothesis import given, settings
    from hypothesis import strategies as st

    @settings(max_examples=60, deadline=None)
    @given(st.lists(_parameter_values(), min_size=1, max_size=20), st.sampled_from(list(physics.CONVENTIONS)))
    def agree(points, convention):
        params = {name: np.array([point[name] for point in points]) for name in physics.PARAMETERS}
        with np.errstate(all="ignore"):
            reference = evaluate(convention=convention, **params).to_dict()
            fast = evaluate(convention=convention, execution=ExecutionOptions("numba"), **params).to_dict()
        for name in OUTPUTS:
            np.testing.assert_allclose(fast[name], reference[name], rtol=1e-10, atol=0, err_msg=name)

    agree()


def test_the_fused_stages_are_generated_from_the_equation_functions(monkeypatch):
    # Eq 16 is written once, in physics.moments: a different coefficient there reaches the numpy
    # kernel, the single point and the stages the numba kernel compiles alike.
    from microbearing.physics import fused, moments

    assert "0.4375" not in fused.plan(True).source and "0.375" in fused.plan(True).source
    point = {"balls": 4, "load_N": 8.8e-3, "speed_m_s": 0.05}
    before = evaluate(**point).pivoting_moment_Nm
    monkeypatch.setattr(moments, "pivoting_moment", lambda mu, load, radius: 0.4375 * mu * load * radius)
    assert "0.4375" in fused.plan(True).source and "0.375" not in fused.plan(True).source
    assert evaluate(**point).pivoting_moment_Nm == pytest.approx(before * 0.4375 / 0.375, rel=1e-15)


def test_the_generated_stages_are_cached_beside_the_package_or_run_in_memory(monkeypatch, tmp_path):
    # numba caches functions of a file: the generated source is written once (named by its hash)
    # and imported from there; where the folder cannot be written (a read-only install) it runs in
    # memory, uncached, with the same functions
    source = "def twice(x):\n    return 2.0 * x\n"
    monkeypatch.setattr(compiled, "_CACHE_DIR", tmp_path / "fused")
    namespace, cached = compiled._namespace(source)
    assert cached and namespace["twice"](1.5) == 3.0
    assert [p.read_text() for p in (tmp_path / "fused").glob("stages_*.py")] == [source]
    blocked = tmp_path / "a-file"
    blocked.write_text("")  # a file where the folder would be: it cannot be created
    monkeypatch.setattr(compiled, "_CACHE_DIR", blocked / "fused")
    namespace, cached = compiled._namespace(source)
    assert not cached and namespace["twice"](1.5) == 3.0
