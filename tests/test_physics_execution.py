"""Who decides how the physics runs: the caller's ExecutionOptions, and the server's settings passed down."""

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from pydantic import ValidationError

from microbearing import physics
from microbearing.physics import ExecutionOptions, compiled


def test_physics_reads_no_environment(monkeypatch):
    # The variables the server reads leave a library call alone: numpy's kernel in the caller's thread.
    monkeypatch.setenv("MICROBEARING_PHYSICS_KERNEL", "fortran")
    monkeypatch.setenv("MICROBEARING_PHYSICS_THREADS", "two")
    result = physics.evaluate(balls=np.full(200_000, 4.0), load_N=1e-2, speed_m_s=0.1, outputs=["mu"])
    assert np.all(result.mu == physics.evaluate(balls=4, load_N=1e-2, speed_m_s=0.1).mu)


def test_a_large_call_runs_its_parts_on_the_executor_it_is_given():
    submitted = []

    class Recording(ThreadPoolExecutor):
        def submit(self, fn, /, *args, **kwargs):
            submitted.append(args)
            return super().submit(fn, *args, **kwargs)

    size = 12 * 16384 + 5  # 13 blocks of 16,384 points, each part at least 4
    params = {"balls": np.arange(size) % 40 + 1.0, "load_N": 1e-2, "speed_m_s": 0.1}
    with Recording(3) as pool:
        threaded = physics.evaluate(execution=ExecutionOptions(threads=3, executor=pool), **params).mu
    # three contiguous runs of whole blocks covering every point once
    assert submitted == [(0, 4 * 16384), (4 * 16384, 8 * 16384), (8 * 16384, size)]
    np.testing.assert_array_equal(threaded, physics.evaluate(**params).mu)


def test_options_travel_to_another_process_without_their_executor():
    import pickle

    with ThreadPoolExecutor(2) as pool:
        copy = pickle.loads(pickle.dumps(ExecutionOptions("numpy", 2, pool)))
    assert copy == ExecutionOptions("numpy")


def test_the_server_passes_its_settings_down(monkeypatch):
    from microbearing.service import models
    from microbearing.service.app import create_app
    from microbearing.service.settings import Settings

    kernel = "numba" if compiled.AVAILABLE else "numpy"
    monkeypatch.setattr(models, "_physics_execution", models._physics_execution)  # restored after the test
    monkeypatch.setenv("MICROBEARING_PHYSICS_KERNEL", kernel)
    monkeypatch.setenv("MICROBEARING_PHYSICS_THREADS", "3")
    create_app(Settings(data_dir="/nonexistent-not-opened"))
    execution = models.physics_in("olaru2005").execution
    assert (execution.kernel, execution.threads) == (kernel, 3) and execution.executor is not None
    points = {"balls": np.arange(9 * 16384) % 40 + 1.0, "load_N": 1e-2, "speed_m_s": 0.1}
    mu = models.physics_in("olaru2005").evaluate(points, ["mu"]).values["mu"]
    np.testing.assert_allclose(mu, physics.evaluate(**points).mu, rtol=1e-12, atol=0)


@pytest.mark.parametrize(("variable", "value", "match"), [
    ("MICROBEARING_PHYSICS_THREADS", "two", "physics_threads"),
    ("MICROBEARING_PHYSICS_THREADS", "-1", "physics_threads"),
    ("MICROBEARING_PHYSICS_KERNEL", "fortran", "physics_kernel"),
])
def test_a_bad_setting_is_named(monkeypatch, variable, value, match):
    from microbearing.service.settings import Settings

    monkeypatch.setenv(variable, value)
    with pytest.raises(ValidationError, match=match):
        Settings()


def test_numba_without_numba_is_refused_at_start(monkeypatch):
    from microbearing.service.settings import Settings

    monkeypatch.setattr(compiled, "AVAILABLE", False)
    monkeypatch.setenv("MICROBEARING_PHYSICS_KERNEL", "numba")
    with pytest.raises(ValidationError, match=r"needs numba: pip install 'microbearing\[fast\]'"):
        Settings()
