"""The family-wise threshold of forward selection (Westfall-Young max-T by sign flips) against
numbers computed independently: the Šidák value for independent candidates, the single test's value
for identical ones, and, for equicorrelated Gaussian candidates, the exact quantile of their maximum
by one-dimensional quadrature."""

import numpy as np
import pytest
from scipy import integrate, optimize, stats

from microbearing.calibrate import parse_rows
from microbearing.calibrate.select import SearchOptions, forward_select, max_t_threshold

ALPHA = 0.01
ROWS = 500
# Monte Carlo error of a 99 % quantile from 4,000 flips, with the finite-row error of sign flips.
TOLERANCE = 0.1


def test_independent_candidates_give_the_sidak_threshold():
    m = 40
    differences = np.random.default_rng(0).normal(size=(ROWS, m))
    sidak = stats.norm.isf(1 - (1 - ALPHA) ** (1 / m))
    assert max_t_threshold(differences, ALPHA) == pytest.approx(sidak, abs=TOLERANCE)


def test_identical_candidates_give_the_single_test_threshold():
    one = np.random.default_rng(1).exponential(size=(ROWS, 1))  # skewed: the flips centre it
    threshold = max_t_threshold(np.repeat(one, 40, axis=1), ALPHA)
    assert threshold == pytest.approx(stats.norm.isf(ALPHA), abs=TOLERANCE)


@pytest.mark.parametrize("rho", [0.5, 0.9])
def test_equicorrelated_candidates_give_the_exact_quantile_of_their_maximum(rho):
    # z_j = sqrt(rho) u + sqrt(1 - rho) e_j: P(max z <= t) = E_u[Phi((t - sqrt(rho) u) / sqrt(1 - rho))^m].
    m = 30

    def below(t):
        def integrand(u):
            return stats.norm.pdf(u) * stats.norm.cdf((t - np.sqrt(rho) * u) / np.sqrt(1 - rho)) ** m

        return integrate.quad(integrand, -10, 10)[0]

    exact = optimize.brentq(lambda t: below(t) - (1 - ALPHA), 0.0, 6.0)
    rng = np.random.default_rng(2)
    differences = np.sqrt(rho) * rng.normal(size=(ROWS, 1)) + np.sqrt(1 - rho) * rng.normal(size=(ROWS, m))
    assert stats.norm.isf(ALPHA) < exact < stats.norm.isf(ALPHA / m)  # strictly between the bounds
    assert max_t_threshold(differences, ALPHA) == pytest.approx(exact, abs=TOLERANCE)


def test_a_gain_on_a_few_rows_has_a_light_tailed_null():
    # Sign flips condition on each row's size: a candidate whose differences sit on k = 4 rows cannot
    # reach a paired z much above sqrt(k) = 2 under any flips (z ~ sum(s d) / sqrt(sum d^2) <= sqrt(k)
    # by Cauchy-Schwarz), where a normal null would ask for 2.33.
    differences = np.zeros((ROWS, 1))
    differences[:4, 0] = [1.0, 2.0, 3.0, 4.0]
    assert max_t_threshold(differences, ALPHA) < 2.0 + TOLERANCE < stats.norm.isf(ALPHA)


def test_the_threshold_is_reproducible_and_the_selection_uses_it_within_the_bonferroni_bound():
    differences = np.random.default_rng(3).normal(size=(100, 5))
    assert max_t_threshold(differences, ALPHA) == max_t_threshold(differences, ALPHA)
    rng = np.random.default_rng(4)
    n = 80
    rows = [
        {
            "balls": 6.0,
            "load_N": float(load),
            "speed_m_s": float(speed),
            "relative_humidity": float(h),
            "temperature_C": float(t),
            "mu_measured": float(0.02 * (1 + 0.1 * h) * np.exp(rng.normal(0, 0.02))),
        }
        for load, speed, h, t in zip(rng.uniform(3e-3, 3e-2, n), rng.uniform(0, 0.1, n),
                                     rng.uniform(0.2, 0.8, n), rng.uniform(20, 40, n), strict=True)
    ]
    step = forward_select(parse_rows(rows), ["mu_pivot"], folds=4, options=SearchOptions(max_terms=1))
    step = step.steps[0]
    bonferroni = stats.norm.isf(ALPHA / len(step.ranked))
    # A union bound holds whatever the correlation: max-T never asks more than Bonferroni; and never
    # less than the single-test floor z_threshold (3).
    assert 3.0 <= step.z_needed <= bonferroni + TOLERANCE
