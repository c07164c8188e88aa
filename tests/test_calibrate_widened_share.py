"""Issue 33, item 7: beyond the data only the share of the interval no fitted value explains is widened.

The fitted values' uncertainty at a point beyond the data is propagated there by the model's form (a generic
quadratic in load goes on along its tangent: its coefficient's standard error times a z of 11 at 30 mN over
data at 2-10 mN); multiplying it again by the extrapolation allowance counted the distance twice (log
half-widths of 1.6-4.4 at 30 mN where the truth's error needs 0.26-0.64, ``bench/offdata_inputs.py``).
Now sigma^2 = g'Cg + (noise W)^2: the allowance W widens the scatter, the departure no term holds.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from microbearing.calibrate import CalibratedModel
from microbearing.calibrate.candidates import EffectTerm

LOW, HIGH, NOISE, Z95 = 2e-3, 10e-3, 0.03, 1.959963984540054
CONSTANTS = {"centre": 4.8e-3, "scale": 2.3e-3, "low": LOW, "high": HIGH}
SE_C1, SE_C2 = 0.004, 0.01


def quadratic_model() -> CalibratedModel:
    term = EffectTerm("generic_quadratic", ("load_N",), CONSTANTS)
    return CalibratedModel(fitted={"mu_pivot": 0.65}, terms=[(term, [-0.036, 0.022])],
                           covariance=np.diag([0.0, SE_C1**2, SE_C2**2]), noise_std_log=NOISE,
                           domain={"load_N": [LOW, HIGH], "balls": [4.0, 8.0]}, domain_rows=110)


def parameters_variance(load: float) -> float:
    """g'Cg by hand: log mu = c1 z + c2 q(z), q = z^2 inside, its tangent at the high end beyond it."""
    z, top = ((x - CONSTANTS["centre"]) / CONSTANTS["scale"] for x in (load, HIGH))
    q = z * z if load <= HIGH else top * top + 2.0 * top * (z - top)
    return (SE_C1 * z) ** 2 + (SE_C2 * q) ** 2


@pytest.mark.parametrize("load", [30e-3, 60e-3])
def test_beyond_the_data_the_allowance_widens_the_scatter_not_the_fitted_values_share(load):
    model = quadratic_model()
    point = {"load_N": load, "balls": 6.0, "speed_m_s": 0.1}
    widening = float(model.extrapolation_ratio(point))
    assert widening > 3.0  # well beyond the data
    p = model.predict(point)
    half = math.log(float(p.mu_upper) / float(p.mu))
    expected = Z95 * math.sqrt(parameters_variance(load) + (NOISE * widening) ** 2)
    assert half == pytest.approx(expected, rel=1e-4)
    # the old composition counted the fitted values' share W times: several times wider here
    assert Z95 * math.sqrt(parameters_variance(load) + NOISE**2) * widening > 2.0 * half
    # the departure the allowance holds is all there: at least z noise W
    assert half >= Z95 * NOISE * widening


def test_inside_the_data_the_interval_is_the_fitted_values_and_the_scatter():
    model = quadratic_model()
    p = model.predict({"load_N": 5e-3, "balls": 6.0, "speed_m_s": 0.1})
    half = math.log(float(p.mu_upper) / float(p.mu))
    assert half == pytest.approx(Z95 * math.sqrt(parameters_variance(5e-3) + NOISE**2), rel=1e-4)
