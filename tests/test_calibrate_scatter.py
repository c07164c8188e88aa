"""Issue 24, item 2: scatter that grows with the load. The log-linear scatter model's form (the column or
its log, chosen by cross-validation), the allowance its fit's uncertainty gives the interval (Student's t
of the degrees of freedom that inform the local spread), and whole calibrations whose 95 % intervals cover
fresh draws of the generating truth in every region of the load. Seeds are this file's own, not the
bench's."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from microbearing import physics
from microbearing.calibrate import calibrate
from microbearing.calibrate.scatter import ScatterModel, fit_scatter

# Scatter of log mu: 1 % at 3 mN growing as a power of the load to 8 % at 30 mN.
EXPONENT = np.log(8.0) / np.log(10.0)


def load_scatter(load_N):
    return 0.01 * (np.asarray(load_N) / 3e-3) ** EXPONENT


def _loads(rng, n):
    return np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n))


def test_a_power_of_the_load_over_less_than_a_decade_is_log_linear_in_log_load():
    """3-30 mN drawn: the rows span a little less than a decade. The spread is a power of the load, so
    log sd is linear in log load; the fit is the gamma GLM of the squared residuals, whose coefficients'
    inverse Fisher information is (X'X)^-1 / 2 in log sd (computed here by hand)."""
    rng = np.random.default_rng(61)
    n = 300
    load = _loads(rng, n)
    assert load.max() < 10 * load.min()
    residual = rng.normal(0.0, 1.0, n) * load_scatter(load)
    model = fit_scatter({"load_N": load, "speed_m_s": rng.uniform(0.001, 0.15, n)}, residual)
    assert (model.kind, model.column, model.transform) == ("loglinear", "load_N", "log")
    assert "log-linear in log load_N" in model.summary()
    t = (np.log(load) - model.centre) / model.scale
    assert model.centre == pytest.approx(np.mean(np.log(load)))
    assert model.scale == pytest.approx(np.std(np.log(load)))
    design = np.column_stack([np.ones(n), t])
    covariance = 0.5 * np.linalg.inv(design.T @ design)  # no row beyond the outlier threshold here
    np.testing.assert_allclose(np.reshape(model.covariance, (2, 2)), covariance, rtol=1e-9, atol=1e-15)
    # The exponent within three standard errors of the truth; the spread at 3 and 30 mN within 20 %.
    slope, slope_se = model.coefficients[1] / model.scale, np.sqrt(covariance[1, 1]) / model.scale
    assert abs(slope - EXPONENT) < 3 * slope_se, (slope, slope_se)
    at = model.std_log({"load_N": np.array([3e-3, 3e-2])}, (2,))
    np.testing.assert_allclose(at, [0.01, 0.08], rtol=0.2)
    # The allowance at a point, for nu = 1 / (2 Var[log sd]) degrees of freedom: the larger of Student's t
    # over z and the tolerance rule (the spread's one-sided 95 % upper bound, chi-square of nu, on the
    # normal quantile of 90 % content) over z.
    z = stats.norm.isf(0.025)
    for x in (3e-3, 1e-2, 3e-2, 0.1):  # 0.1 N: beyond the data, the column is clipped to its range
        tx = (np.log(np.clip(x, load.min(), load.max())) - model.centre) / model.scale
        nu = 1.0 / (2.0 * (np.array([1.0, tx]) @ covariance @ np.array([1.0, tx])))
        tolerance = stats.norm.isf(0.05) * np.sqrt(nu / stats.chi2.ppf(0.05, nu))
        by_hand = max(stats.t.isf(0.025, nu), tolerance) / z
        assert model.quantile_factor({"load_N": np.array([x])}, (1,))[0] == pytest.approx(by_hand, rel=1e-9)
    # The ends, where fewer rows inform the trend, get the larger allowance.
    ends = model.quantile_factor({"load_N": np.array([3e-3, 1e-2, 3e-2])}, (3,))
    assert ends[1] < ends[0] and ends[1] < ends[2] and ends[1] > 1.0
    # Stored and read back, the same; stored before the covariance was kept: no allowance.
    again = ScatterModel.from_json(model.to_json())
    assert again == model
    older = {k: v for k, v in model.to_json().items() if k != "covariance"}
    assert ScatterModel.from_json(older).quantile_factor({"load_N": np.array([3e-2])}, (1,))[0] == 1.0


def test_the_allowance_brings_a_fitted_log_linear_spread_to_its_coverage_at_the_noisy_end():
    """Fresh draws of the generating truth: 100 rows, the spread fitted, then 400 new residuals from the
    top half of the loads (15-30 mN), 150 times. The interval ± 1.96 ŝ(x) times the allowance covers 95 %
    on average (Monte Carlo error about 0.3 %) and less than 90 % in few data sets (the tolerance rule's
    promise: 90 % content in 95 % of them, here up to the noise of 400 fresh draws); without the allowance
    it covers less on average and falls below 90 % more often."""
    with_allowance, plain = [], []
    for rep in range(150):
        rng = np.random.default_rng(7000 + rep)
        load = _loads(rng, 100)
        model = fit_scatter({"load_N": load}, rng.normal(0.0, 1.0, 100) * load_scatter(load), seed=rep)
        fresh = np.exp(rng.uniform(np.log(1.5e-2), np.log(3e-2), 400))
        new = rng.normal(0.0, 1.0, 400) * load_scatter(fresh)
        half = 1.96 * model.std_log({"load_N": fresh}, (400,))
        plain.append(np.mean(np.abs(new) <= half))
        with_allowance.append(np.mean(np.abs(new) <= half * model.quantile_factor({"load_N": fresh}, (400,))))
    with_allowance, plain = np.array(with_allowance), np.array(plain)
    assert 0.94 <= with_allowance.mean() <= 0.965, with_allowance.mean()
    assert plain.mean() < with_allowance.mean() - 0.005, (plain.mean(), with_allowance.mean())
    assert np.mean(with_allowance < 0.9) <= 0.08 and np.mean(plain < 0.9) > np.mean(with_allowance < 0.9)


def _rows(c, measured, n):
    return [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(measured[i])} for i in range(n)]


@pytest.mark.parametrize("seed", [71, 72, 73])
def test_a_calibration_on_scatter_that_grows_with_the_load_covers_every_region_of_the_load(seed):
    """200 rows with a hidden humidity meniscus and the scatter above; 3,000 fresh measurements of the
    generating truth. The 95 % interval covers 90-98 % in each third of the loads (log scale: below 6 mN,
    6-15 mN, above 15 mN), and its width follows the scatter."""
    rng = np.random.default_rng(seed)
    n, fresh = 200, 3000
    m = n + fresh
    c = {"balls": rng.choice([4, 6, 8], m).astype(float), "load_N": _loads(rng, m),
         "speed_m_s": rng.uniform(0.001, 0.15, m), "relative_humidity": rng.uniform(0.2, 0.6, m)}
    mu = physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"], mu_pivot=0.7).mu
    mu = mu + c["balls"] * 2e-5 / (c["load_N"] * np.log(1 / c["relative_humidity"]))
    measured = mu * np.exp(rng.normal(0.0, 1.0, m) * load_scatter(c["load_N"]))
    result = calibrate(_rows(c, measured, n), ["mu_pivot"], make_plots=False, seed=seed)
    scatter = result.scatter
    assert (scatter["kind"], scatter["column"]) == ("loglinear", "load_N"), scatter["summary"]
    p = result.model.predict({k: v[n:] for k, v in c.items()})
    inside = (p.mu_lower <= measured[n:]) & (measured[n:] <= p.mu_upper)
    load = c["load_N"][n:]
    regions = [load < 6e-3, (load >= 6e-3) & (load < 1.5e-2), load >= 1.5e-2]
    coverage = [float(inside[r].mean()) for r in regions]
    assert all(0.9 <= v <= 0.98 for v in coverage), coverage
    width = np.log(p.mu_upper / p.mu_lower)
    assert np.median(width[regions[2]]) > 3 * np.median(width[regions[0]])


def test_a_step_in_the_scatter_is_the_minimum_of_its_profile_likelihood_by_brute_force():
    """Scatter 1 % below a coating thickness of 0.6 and 5 % above it, 900 rows (the choice runs on all of
    them), Gaussian: no row beyond the outlier threshold. The fitted step is, over the candidate splits
    (the column's 2-98 % quantiles, 200 of them, each leaving 8 rows or more on either side), the one of
    least negative log-likelihood, recomputed here split by split with the rows' own means, its levels the
    root mean squares on each side and its band the splits within half the chi-square 95 % point of it."""
    rng = np.random.default_rng(73)
    n = 900
    x = rng.uniform(0.0, 1.0, n)
    residual = rng.normal(0.0, 1.0, n) * np.where(x < 0.6, 0.01, 0.05)
    model = fit_scatter({"coating_um": x}, residual)
    assert (model.kind, model.column) == ("step", "coating_um")
    profile = []
    for split in np.unique(np.quantile(x, np.linspace(0.02, 0.98, 200))):
        below = x < split
        if min(below.sum(), (~below).sum()) < 8:
            continue
        low, high = np.mean(residual[below] ** 2), np.mean(residual[~below] ** 2)
        profile.append((0.5 * (below.sum() * np.log(low) + (~below).sum() * np.log(high)), split, low, high,
                        below.sum()))
    nll, split, low, high, rows_below = min(profile, key=lambda item: item[0])
    assert model.split == pytest.approx(split, rel=1e-12)
    np.testing.assert_allclose(model.coefficients, [0.5 * np.log(low), 0.5 * np.log(high)], rtol=1e-10)
    assert model.rows == [float(rows_below), float(n - rows_below)]
    near = [s for value, s, *_ in profile if value <= nll + stats.chi2.ppf(0.95, 1) / 2]
    assert model.band == pytest.approx([min(near), max(near)], rel=1e-12)
    assert 0.55 < split < 0.65
