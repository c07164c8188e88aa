"""Tests of the surrogate package: space, designs, GP estimator, adaptive sampling, metrics,
persistence and Sobol' indices. Reference numbers are computed independently in the tests
(physics.evaluate, brute-force refits, closed-form indices, Monte Carlo)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import binom, norm, qmc
from sklearn.gaussian_process import GaussianProcessRegressor

from microbearing import physics
from microbearing.surrogate import (
    GaussianProcessSurrogate,
    Hyperparameters,
    SamplingPlan,
    Space,
    accuracy,
    design,
    dumps,
    fit_adaptive,
    from_dict,
    holdout_metrics,
    loads,
    select_batch,
    sobol_indices,
    to_dict,
)
from microbearing.surrogate.model import RELATIVE_RESOLUTION, fit_prior_mean, prior_mean
from microbearing.surrogate.sampling import (
    default_initial_size,
    predicted_error_quantile,
    quantile_upper_bound,
)

TARGET_BOUNDS = {"balls": (3, 40), "groove_angle_deg": (30, 75), "load_N": (0.001, 0.05),
                 "speed_m_s": (0.001, 0.2)}

# Small spaces covering float, log, power, integer and boolean dimensions.
SPACES = {
    "load": Space({"load_N": (0.001, 0.05)}, fixed={"balls": 6, "speed_m_s": 0.02}),
    "balls+speed0": Space({"balls": (3, 20), "speed_m_s": (0.0, 0.2)}, fixed={"load_N": 0.01}),
    "angle+load": Space({"groove_angle_deg": (30, 75), "load_N": (0.001, 0.05)},
                        fixed={"balls": 8, "speed_m_s": 0.05}),
    "touching+mu_ball": Space({"balls_touching": (False, True), "mu_ball": (0.2, 1.0),
                               "load_N": (0.002, 0.02)}, fixed={"balls": 5, "speed_m_s": 0.01}),
}


@pytest.fixture(scope="module")
def fitted():
    """One fitted surrogate per small space, on a 24-point Sobol' design."""
    models = {}
    for key, space in SPACES.items():
        X = design(space, 24, "sobol", seed=3)
        models[key] = GaussianProcessSurrogate(space, random_state=0).fit(X, space.evaluate(X))
    return models


# ----------------------------------------------------------------------------- space
def test_space_scales_follow_the_ranges():
    space = Space({**TARGET_BOUNDS, "mu_pivot": (0.4, 0.6), "adhesion_energy_J_m2": (0.0, 0.3)})
    assert space.scale_of == {"balls": "log", "groove_angle_deg": "linear", "load_N": "log",
                              "speed_m_s": "log", "mu_pivot": "linear", "adhesion_energy_J_m2": "power"}
    speed0 = Space({"speed_m_s": (0.0, 0.2)}, fixed={"balls": 4, "load_N": 0.01})
    assert speed0.scale_of["speed_m_s"] == "power"
    # speed^0.66: the middle of the unit interval is the speed whose 0.66th power is halfway.
    assert speed0.from_unit([[0.5]])[0, 0] == pytest.approx((0.5 * 0.2**0.66) ** (1 / 0.66))


def test_from_unit_corners_are_the_bounds_and_integers_are_whole():
    space = Space(TARGET_BOUNDS)
    corners = space.from_unit(np.array([[0.0] * 4, [1.0] * 4]))
    np.testing.assert_array_equal(corners, [space.lower, space.upper])
    X = space.from_unit(qmc.Sobol(4, rng=1).random(256))
    assert np.all(X[:, 0] == np.round(X[:, 0]))
    assert set(np.unique(X[:, 0])) <= set(range(3, 41))
    assert space.contains(X).all()


def test_log_scale_is_log_uniform():
    space = Space({"load_N": (0.001, 0.1)}, fixed={"balls": 4, "speed_m_s": 0.01})
    X = space.from_unit(np.linspace(0, 1, 5)[:, None])
    np.testing.assert_allclose(X[:, 0], [1e-3, 10**-2.5, 1e-2, 10**-1.5, 1e-1], rtol=1e-12)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(0.0, 1.0), min_size=3, max_size=3))
def test_unit_round_trip_on_continuous_dimensions(u):
    space = Space({"load_N": (0.001, 0.05), "speed_m_s": (0.0, 0.2), "groove_angle_deg": (30, 75)},
                  fixed={"balls": 4})
    U = np.array([u])
    np.testing.assert_allclose(space.to_unit(space.from_unit(U)), U, atol=1e-12)


def test_boolean_dimension_is_balanced_and_maps_to_bool():
    space = SPACES["touching+mu_ball"]
    X = design(space, 64, seed=0)
    assert set(np.unique(X[:, 0])) == {0.0, 1.0}
    assert abs(X[:, 0].mean() - 0.5) <= 1 / 16
    points = space.points(X)
    assert points["balls_touching"].dtype == np.bool_
    expected = physics.evaluate(balls=5, speed_m_s=0.01, balls_touching=X[:, 0] == 1, mu_ball=X[:, 1],
                                load_N=X[:, 2]).mu
    np.testing.assert_array_equal(space.evaluate(X), expected)


@pytest.mark.parametrize(("bounds", "fixed", "scales", "message"), [
    ({"bogus": (0, 1)}, {}, {}, "unknown parameter"),
    ({"load_N": (0.05, 0.001)}, {"balls": 4, "speed_m_s": 0.1}, {}, "lower < upper"),
    ({"groove_angle_deg": (30, 95)}, {"balls": 4, "load_N": 0.01, "speed_m_s": 0.1}, {}, "groove_angle_deg"),
    ({"balls": (2.5, 10)}, {"load_N": 0.01, "speed_m_s": 0.1}, {}, "whole number"),
    ({"load_N": (0.001, 0.05)}, {"load_N": 0.01, "balls": 4, "speed_m_s": 0.1}, {}, "both a dimension"),
    ({"load_N": (0.001, 0.05)}, {"balls": 4}, {}, "speed_m_s must be given"),
    ({"speed_m_s": (0.0, 0.2)}, {"balls": 4, "load_N": 0.01}, {"speed_m_s": "log"}, "lower bound > 0"),
    ({"balls_touching": (False, 0.5)}, {"balls": 4, "load_N": 0.01, "speed_m_s": 0.1}, {}, "true/false"),
    ({"load_N": 0.01}, {"balls": 4, "speed_m_s": 0.1}, {}, "pair"),
    ({}, {"balls": 4, "load_N": 0.01, "speed_m_s": 0.1}, {}, "at least one"),
])
def test_space_rejects_bad_definitions(bounds, fixed, scales, message):
    with pytest.raises(ValueError, match=message):
        Space(bounds, fixed, scales=scales)


def test_from_points_flags_points_outside_the_space():
    space = Space({"load_N": (0.001, 0.05), "balls": (3, 40)}, fixed={"speed_m_s": 0.01})
    X, outside = space.from_points({"load_N": [0.01, 0.2, 0.01, 0.01, 0.01],
                                    "balls": [4, 4, 50, 4, 4],
                                    "speed_m_s": [0.01, 0.01, 0.01, 0.02, 0.01],
                                    "mu_pivot": [0.5, 0.5, 0.5, 0.5, 0.9]})
    np.testing.assert_array_equal(outside, [False, True, True, True, True])
    np.testing.assert_array_equal(X[:, 1], [4, 4, 50, 4, 4])
    with pytest.raises(ValueError, match="missing balls"):
        space.from_points({"load_N": [0.01]})
    with pytest.raises(ValueError, match=r"load_N must be in \[1e-09"):
        space.from_points({"load_N": [-1.0], "balls": [4]})


def test_physics_features_use_load_per_ball():
    space = Space(TARGET_BOUNDS)
    X = np.array([[4, 54.7, 0.004, 0.01], [8, 54.7, 0.008, 0.01]])
    Z = space.features(X)
    assert Z.shape[1] == len(space.feature_names()) == 5
    # Same load per ball and angle: every feature but log(balls) agrees.
    np.testing.assert_allclose(Z[0, 1:], Z[1, 1:])
    assert space.feature_names()[3] == "log(load_N/balls)"
    assert Space({**TARGET_BOUNDS, "adhesion_energy_J_m2": (0, 0.3)}).feature_names()[-1] == "log(Q)"


def test_space_data_round_trip():
    space = Space({**TARGET_BOUNDS, "balls_touching": (False, True)}, fixed={"mu_pivot": 0.7},
                  convention="derjaguin")
    again = Space.from_dict(json.loads(json.dumps(space.to_dict())))
    assert again == space


# ----------------------------------------------------------------------------- designs
def test_latin_hypercube_has_one_point_per_stratum():
    space = Space({"groove_angle_deg": (30, 75), "mu_pivot": (0.4, 0.6)},
                  fixed={"balls": 4, "load_N": 0.01, "speed_m_s": 0.01})
    U = space.to_unit(design(space, 20, "latin_hypercube", seed=2))
    for column in U.T:
        np.testing.assert_array_equal(np.sort(np.floor(column * 20)), np.arange(20))


def test_design_rejects_bad_arguments():
    space = SPACES["load"]
    with pytest.raises(ValueError, match="n must be"):
        design(space, 0)
    with pytest.raises(ValueError, match="method must be one of"):
        design(space, 4, "grid")


# ----------------------------------------------------------------------------- model
@pytest.mark.parametrize("key", SPACES)
def test_model_near_interpolates_training_points(fitted, key):
    model = fitted[key]
    relative = np.abs(model.predict(model.X_train_) / model.y_train_ - 1)
    # Near interpolation: the fitted noise term lets the mean miss training values slightly
    # (more across the jump of a boolean input), far below held-out errors.
    assert np.median(relative) < 1e-4 and relative.max() < 1e-3


@pytest.mark.parametrize("key", SPACES)
def test_model_held_out_error_and_interval(fitted, key):
    model = fitted[key]
    X = design(model.space, 256, "sobol", seed=77)
    truth = model.space.evaluate(X)
    p = model.predict_interval(X)
    assert np.median(np.abs(p.mu / truth - 1)) < 2e-3
    assert np.all((p.mu_lower < p.mu) & (p.mu < p.mu_upper))
    # The interval is exp(log mu ± 1.96 σ), never narrower than the float64 resolution of μ.
    np.testing.assert_allclose(np.log(p.mu_upper / p.mu),
                               np.maximum(norm.ppf(0.975) * p.log_std, RELATIVE_RESOLUTION),
                               rtol=1e-8, atol=1e-14)


def test_coverage_of_the_95_interval_is_in_a_band():
    space = Space({"load_N": (0.001, 0.05), "speed_m_s": (0.001, 0.2), "groove_angle_deg": (30, 75)},
                  fixed={"balls": 6})
    coverages, median_z = [], []
    for seed in range(4):
        X = design(space, 40, "sobol", seed=seed)
        # The cross-validation calibration of the estimator with the linear mean on the physics features
        # (the default before issue 35; the default's intervals are tested through fit_adaptive below).
        model = GaussianProcessSurrogate(space, random_state=0, features="physics", mean="linear")
        model.fit(X, space.evaluate(X))
        coverages.append(holdout_metrics(model, n_test=512, seed=1000 + seed)["coverage_95"])
        test = design(space, 512, "sobol", seed=1000 + seed)
        p = model.predict_interval(test)
        median_z.append(np.median(np.abs(np.log(space.evaluate(test) / p.mu)) / p.log_std))
    # Measured: coverage 0.986, 0.947, 0.875, 0.977; median |z| 0.27, 0.78, 0.72, 0.46. Neither
    # overconfident (coverage well below 0.95) nor needlessly wide (coverage 1, tiny standardized errors):
    # for Gaussian errors the median |error| / sigma is 0.674.
    assert 0.9 <= np.mean(coverages) <= 0.99
    assert 0.4 <= np.mean(median_z) <= 1.0


@pytest.mark.parametrize("calibration", ["kfold", "loo"])
@pytest.mark.parametrize("variance_scale", ["rms", "central"])
def test_calibration_is_nominal_when_the_errors_are_known(calibration, variance_scale):
    # log mu drawn from a Gaussian process with an RBF kernel in the unit square: the model is well
    # specified, its standardized held-out errors are N(0, 1) up to the hyperparameters' estimation,
    # so the calibrated 95 % interval should cover 95 % and the scale be near 1, whichever the errors
    # (k-fold refits or closed-form leave-one-out) and the rule (for N(0, 1) errors the root mean square
    # and the central-80 % quantile rule both give 1).
    space = Space({"load_N": (0.001, 0.05), "speed_m_s": (0.001, 0.2)}, fixed={"balls": 6})
    coverages, median_z, scales = [], [], []
    for draw in range(12):
        X, X_test = design(space, 60, "sobol", seed=draw), design(space, 400, "sobol", seed=100 + draw)
        U = space.to_unit(np.vstack([X, X_test]))
        K = np.exp(-0.5 * ((U[:, None, :] - U[None, :, :]) ** 2).sum(-1) / 0.3**2) + 1e-10 * np.eye(len(U))
        mu = np.exp(np.linalg.cholesky(K) @ np.random.default_rng(draw).standard_normal(len(U)))
        model = GaussianProcessSurrogate(space, features="scaled", mean="constant", kernel="rbf",
                                         calibrate_variance=calibration, variance_scale=variance_scale,
                                         random_state=0)
        model.fit(X, mu[:60])
        p = model.predict_interval(X_test)
        coverages.append(np.mean((p.mu_lower <= mu[60:]) & (mu[60:] <= p.mu_upper)))
        median_z.append(np.median(np.abs(np.log(mu[60:] / p.mu)) / p.log_std))
        scales.append(model.std_scale_)
    # Measured (mean coverage, mean median |z|, mean scale; single draws cover 0.82-1.0, as 60 points
    # estimate the length scales loosely): kfold 0.956, 0.67, 1.10 (rms) and 0.959, 0.66, 1.11 (central);
    # loo 0.925, 0.79, 0.89 for both rules (the hyperparameters held fixed: slightly overconfident).
    # For N(0, 1) errors: 0.95, 0.674, 1.
    assert 0.92 <= np.mean(coverages) <= 0.98
    assert 0.55 <= np.mean(median_z) <= 0.8
    assert 0.85 <= np.mean(scales) <= 1.25


def test_predict_points_matches_predict_and_flags_outside(fitted):
    model = fitted["balls+speed0"]
    X = np.array([[4.0, 0.0], [12.0, 0.1], [30.0, 0.1]])
    direct = model.predict(X)
    p = model.predict_points({"balls": X[:, 0], "speed_m_s": X[:, 1], "load_N": 0.01})
    np.testing.assert_array_equal(p.mu, direct)
    np.testing.assert_array_equal(p.outside_space, [False, False, True])
    np.testing.assert_array_equal(model.mu_model({"balls": X[:, 0], "speed_m_s": X[:, 1]}), direct)


@pytest.mark.parametrize("kernel", ["rbf", "matern52"])
def test_loo_errors_match_brute_force_refits(kernel):
    space = SPACES["angle+load"]
    X = design(space, 24, "sobol", seed=3)
    model = GaussianProcessSurrogate(space, kernel=kernel, random_state=0).fit(X, space.evaluate(X))
    gp = model.gaussian_process_
    Zs = model.design_matrix(model.X_train_)
    residual = np.log(model.y_train_) - prior_mean(model.mean_coef_, Zs)
    centre, spread = residual.mean(), residual.std()
    normalized = (residual - centre) / spread
    brute = []
    for i in range(len(Zs)):
        keep = np.arange(len(Zs)) != i
        refit = GaussianProcessRegressor(gp.kernel_, alpha=gp.alpha, optimizer=None)
        refit.fit(Zs[keep], normalized[keep])
        brute.append((normalized[i] - refit.predict(Zs[i:i + 1])[0]) * spread)
    # Matern 5/2 (the default kernel, a new case): its nearly noise-free kernel matrix is ill-conditioned
    # enough that the smallest errors (1e-6 of log mu) differ by ~1e-10 between the two routes, so its
    # absolute tolerance is 1e-5 of the largest error.
    brute = np.array(brute)
    atol = 1e-12 if kernel == "rbf" else 1e-5 * np.abs(brute).max()
    np.testing.assert_allclose(model.loo_log_errors(), brute, rtol=1e-5, atol=atol)


@pytest.mark.parametrize(("variance_scale", "rows"), [("rms", None), ("central", None), ("rms", 16)])
def test_variance_scale_follows_its_rule_on_brute_force_leave_one_out(variance_scale, rows):
    space = SPACES["angle+load"]
    X = design(space, 24, "sobol", seed=3)
    model = GaussianProcessSurrogate(space, random_state=0, variance_scale=variance_scale,
                                     calibrate_variance="loo", calibration_rows=rows)
    model.fit(X, space.evaluate(X))
    gp = model.gaussian_process_
    Zs = model.design_matrix(model.X_train_)
    residual = np.log(model.y_train_) - prior_mean(model.mean_coef_, Zs)
    centre, spread = residual.mean(), residual.std()
    z = []
    for i in range(len(Zs)):  # each point predicted by the process refitted without it
        keep = np.arange(len(Zs)) != i
        refit = GaussianProcessRegressor(gp.kernel_, alpha=gp.alpha, optimizer=None)
        refit.fit(Zs[keep], (residual[keep] - centre) / spread)
        mean, std = refit.predict(Zs[i:i + 1], return_std=True)
        z.append(((residual[i] - centre) / spread - mean[0]) / std[0])
    z = np.abs(z)[:rows]  # only the first rows (a space-filling design) when calibration_rows is given
    # rms: s^2 = mean z^2 (Bachoc 2013); central: the 80th percentile of |z| over that of |N(0, 1)|.
    expected = np.sqrt(np.mean(z**2)) if variance_scale == "rms" else np.quantile(z, 0.8) / 1.2815515655446004
    assert model.std_scale_ == pytest.approx(expected, rel=1e-4)


@pytest.mark.parametrize(("n", "expected"), [(29, "kfold"), (30, "loo")])
def test_auto_calibration_refits_folds_below_ten_points_per_feature(n, expected):
    space = SPACES["angle+load"]  # 3 features: log(load per ball), log tan, log cos of the angle
    X = design(space, n, "sobol", seed=3)
    model = GaussianProcessSurrogate(space, random_state=0, features="physics").fit(X, space.evaluate(X))
    assert model.variance_calibration_ == expected
    same = GaussianProcessSurrogate(space, random_state=0, features="physics", calibrate_variance=expected)
    assert model.std_scale_ == same.fit(X, space.evaluate(X)).std_scale_


@pytest.mark.parametrize(("params", "y", "message"), [
    ({"calibration_rows": 1}, None, "calibration_rows must be"),
    ({"kernel": "cubic"}, None, "kernel must be one of"),
    ({"features": "magic"}, None, "features must be one of"),
    ({"mean": "quadratic"}, None, "mean must be one of"),
    ({"hyperparameters": Hyperparameters(n_restarts_optimizer=-1)}, None, "n_restarts_optimizer"),
    ({"calibrate_variance": True}, None, "calibrate_variance must be one of"),
    ({"variance_scale": "mad"}, None, "variance_scale must be one of"),
    ({"features": "physics", "hyperparameters": Hyperparameters(initial_theta=[0.0, 0.0])}, None,
     "initial_theta must hold 3"),
    ({"hyperparameters": Hyperparameters(optimize=False)}, None, "needs initial_theta"),
    ({}, -1.0, "y must be > 0"),
    ({}, "short", "y must be a 1-D array"),
])
def test_model_validation_errors(params, y, message):
    space = SPACES["load"]
    X = design(space, 8, seed=0)
    target = space.evaluate(X)
    if y == "short":
        target = target[:-1]
    elif y is not None:
        target = np.full(len(X), y)
    with pytest.raises(ValueError, match=message):
        GaussianProcessSurrogate(space, **params).fit(X, target)


def test_model_rejects_wrong_columns(fitted):
    with pytest.raises(ValueError, match=r"shape \(n, 2\)"):
        fitted["angle+load"].predict(np.ones((3, 3)))


# ----------------------------------------------------------------------------- persistence
@pytest.mark.parametrize("key", SPACES)
def test_persistence_round_trip_is_exact(fitted, key):
    model = fitted[key]
    text = dumps(model)
    data = json.loads(text)
    assert data["convention"] == model.space.convention and data["package_version"]
    again = loads(text)
    X = design(model.space, 200, "sobol", seed=5)
    a, b = model.predict_interval(X), again.predict_interval(X)
    np.testing.assert_allclose(b.mu, a.mu, rtol=1e-12, atol=0)
    np.testing.assert_allclose(b.mu_upper, a.mu_upper, rtol=1e-12, atol=0)
    np.testing.assert_allclose(b.log_std, a.log_std, rtol=1e-12, atol=1e-15)


def test_a_surrogate_stored_before_the_auto_calibration_loads_as_stored(fitted):
    # The stored layout of earlier versions: no optimize_hyperparameters, calibration_rows or
    # variance_calibration, and "loo" requested by name.
    model = fitted["load"]
    data = to_dict(model)
    old = {**data, "params": {k: v for k, v in data["params"].items()
                              if k not in ("optimize_hyperparameters", "calibration_rows")}}
    old["params"]["calibrate_variance"] = "loo"
    del old["variance_calibration"]
    again = loads(json.dumps(old))
    assert again.variance_calibration_ == "loo" and again.std_scale_ == model.std_scale_
    X = design(model.space, 50, "sobol", seed=5)
    np.testing.assert_allclose(again.predict_interval(X).mu_upper, model.predict_interval(X).mu_upper,
                               rtol=1e-12, atol=0)


def test_a_surrogate_of_the_earlier_defaults_loads_and_a_posynomial_mean_keeps_its_two_terms(fitted):
    # Records stored before issue 35 hold features "physics" and a linear mean (k + 1 coefficients).
    space = SPACES["angle+load"]
    X = design(space, 24, "sobol", seed=3)
    earlier = GaussianProcessSurrogate(space, random_state=0, features="physics", mean="linear")
    earlier.fit(X, space.evaluate(X))
    data = json.loads(dumps(earlier))
    stored = (data["params"]["features"], data["params"]["mean"], len(data["mean_coef"]))
    assert stored == ("physics", "linear", 4)
    Xt = design(space, 50, "sobol", seed=5)
    np.testing.assert_allclose(loads(json.dumps(data)).predict(Xt), earlier.predict(Xt), rtol=1e-12, atol=0)
    # The default: 4 features (3 physics + log mu_dry), two terms of 5 coefficients.
    now = json.loads(dumps(fitted["angle+load"]))
    assert (now["params"]["features"], now["params"]["mean"], len(now["mean_coef"])) == (
        "dry_contact", "posynomial", 10)
    with pytest.raises(ValueError, match="mean_coef must hold 10"):
        loads(json.dumps({**now, "mean_coef": now["mean_coef"][:5]}))


def test_persistence_rejects_other_data(fitted):
    data = to_dict(fitted["load"])
    with pytest.raises(ValueError, match="format"):
        loads(json.dumps({**data, "format": "pickle"}))
    with pytest.raises(ValueError, match="convention"):
        loads(json.dumps({**data, "convention": "mine"}))
    with pytest.raises(ValueError, match="fitted"):
        to_dict(GaussianProcessSurrogate(SPACES["load"]))
    other = next(c for c in physics.CONVENTIONS if c != data["convention"])
    with pytest.raises(ValueError, match="differs from its space"):
        loads(json.dumps({**data, "convention": other}))


def test_loading_flags_another_package_version(fitted):
    data = to_dict(fitted["load"])
    assert loads(json.dumps(data)).version_warning_ is None
    older = loads(json.dumps({**data, "package_version": "0.0.1"}))
    assert older.package_version_ == "0.0.1"
    running = data["package_version"]
    assert older.version_warning_.startswith(f"trained with microbearing 0.0.1, running is {running}")


# ----------------------------------------------------------------------------- sampling
def test_predicted_error_quantile_against_closed_form_and_monte_carlo():
    assert predicted_error_quantile(np.array([2.0]), 0.5) == pytest.approx(2.0 * norm.ppf(0.75), rel=1e-9)
    sigmas = np.array([0.1, 1.0, 3.0])
    draws = np.abs(np.random.default_rng(0).normal(0, np.repeat(sigmas, 200_000)))
    assert predicted_error_quantile(sigmas, 0.95) == pytest.approx(np.percentile(draws, 95), rel=0.01)


def test_select_batch_by_variance_starts_at_the_largest_std(fitted):
    model = fitted["angle+load"]
    candidates = design(model.space, 128, "sobol", seed=11)
    picked = select_batch(model, candidates, 5, criterion="variance")
    _, std = model.predict(candidates, return_std=True)
    assert picked[0] == np.argmax(std)
    assert len(set(picked)) == 5
    imse = select_batch(model, candidates, 5)
    assert len(set(imse)) == 5


def test_select_batch_conditions_on_picks():
    space = SPACES["angle+load"]
    X = design(space, 6, seed=0)
    model = GaussianProcessSurrogate(space, random_state=0).fit(X, space.evaluate(X))
    candidates = design(space, 64, seed=9)
    picked = select_batch(model, candidates, 2, criterion="variance")
    # Brute force: refit with the first pick added (same hyperparameters, fantasized value):
    # its largest posterior variance is the second pick.
    gp = model.gaussian_process_
    Z = model.design_matrix(np.vstack([X, candidates[picked[:1]]]))
    refit = GaussianProcessRegressor(gp.kernel_.k1, alpha=gp.kernel_.k2.noise_level + gp.alpha,
                                     optimizer=None).fit(Z, np.zeros(len(Z)))
    _, std = refit.predict(model.design_matrix(candidates), return_std=True)
    assert picked[1] == np.argmax(std)


def test_fit_adaptive_respects_budget_and_reports_progress():
    space = Space({"load_N": (0.001, 0.05), "speed_m_s": (0.001, 0.2)}, fixed={"balls": 6})
    fractions = []
    fit = fit_adaptive(space, budget=22, target_relative_error=1e-12,
                       plan=SamplingPlan(initial_size=10, batch_size=5, n_candidates=256),
                       progress=fractions.append)
    assert fit.n_train == 22 and fit.stop_reason == "budget_exhausted"
    assert [h["n_train"] for h in fit.history] == [10, 15, 20, 22]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert len({tuple(x) for x in fit.X}) == 22
    np.testing.assert_array_equal(fit.y, space.evaluate(fit.X))
    # The final model is warm-started; its starting point is stored with it.
    assert len(fit.model.hyperparameters.initial_theta) == 2 + len(space.feature_names(fit.model.features))
    X = design(space, 50, seed=4)
    np.testing.assert_allclose(loads(dumps(fit.model)).predict(X), fit.model.predict(X), rtol=1e-12)


def test_fit_adaptive_stops_at_the_target():
    space = Space({"load_N": (0.001, 0.05), "speed_m_s": (0.001, 0.2)}, fixed={"balls": 6})
    fit = fit_adaptive(space, budget=100, target_relative_error=0.05,
                       plan=SamplingPlan(initial_size=8, batch_size=8, n_candidates=256))
    # A 95th percentile is bounded at 95 % confidence by no order statistic of fewer than 59 values
    # (1 - 0.95**58 < 0.95): the rule cannot stop before, however small the errors.
    assert fit.stop_reason == "target_reached" and fit.n_train == 64
    assert [h["n_train"] for h in fit.history] == list(range(8, 65, 8))
    assert all("loo_p95_upper_bound" not in h for h in fit.history[:-1])
    last = fit.history[-1]
    assert last["loo_median_upper_bound"] <= 0.05 and last["loo_p95_upper_bound"] <= 5 * 0.05
    assert holdout_metrics(fit.model, n_test=256)["median_relative_error"] < 0.05


def test_quantile_upper_bound_by_order_statistics():
    values = np.arange(1.0, 101.0)
    # Conover (1999) Sect. 3.2: the k-th smallest of 100 bounds the median at 95 % for k = 59
    # (P(Binomial(100, 0.5) <= 58) = 0.956, <= 57: 0.933).
    assert quantile_upper_bound(values, 0.5) == 59.0
    assert binom.cdf(58, 100, 0.5) >= 0.95 > binom.cdf(57, 100, 0.5)
    # The 95th percentile needs 59 values: the largest of 59 exceeds it with probability 1 - 0.95**59.
    assert quantile_upper_bound(values[:58], 0.95) == np.inf
    assert quantile_upper_bound(values[:59], 0.95) == 59.0
    assert quantile_upper_bound([], 0.5) == np.inf
    with pytest.raises(ValueError, match="q and confidence must be in"):
        quantile_upper_bound(values, 1.0)


def test_quantile_upper_bound_covers_the_true_quantile_and_tightens_with_n():
    rng = np.random.default_rng(7)
    # |N(0, 1)|: true median 0.674, true 95th percentile 1.960.
    for q, true in ((0.5, norm.ppf(0.75)), (0.95, norm.ppf(0.975))):
        widths = []
        for n in (60, 200, 1000):
            samples = np.abs(rng.standard_normal((2000, n)))
            bounds = np.array([quantile_upper_bound(s, q) for s in samples])
            points = np.quantile(samples, q, axis=1)
            assert np.all(bounds >= np.sort(samples, axis=1)[:, int(np.floor(q * (n - 1)))])
            assert np.mean(bounds >= points) > 0.99
            covered = np.mean(bounds >= true)
            # At least 95 % (Monte Carlo standard error 0.005), not the whole sample's maximum.
            assert 0.94 <= covered <= 0.995, (q, n, covered)
            widths.append(np.median(bounds) - true)
        assert widths[0] > widths[1] > widths[2] > 0


def test_the_bound_does_not_stop_where_point_estimates_would():
    # bench/surrogate.py's target request, seed 13: after the 50-point starting design the
    # leave-one-out point estimates (and the predictive spread) met the 0.1 % target, and the rule
    # on point estimates stopped there with a held-out median error of 0.114 %. That was the RBF kernel
    # (the default then) and a starting design of half the budget (also the default then); Matern 5/2's
    # estimates do not meet the target at 50 points.
    space = Space(TARGET_BOUNDS)
    fit = fit_adaptive(space, budget=100, target_relative_error=1e-3, seed=13,
                       plan=SamplingPlan(initial_size=50), model_params={"kernel": "rbf"})
    first = fit.history[0]
    assert first["n_train"] == 50
    assert first["loo_median_relative_error"] <= 1e-3 and first["loo_p95_relative_error"] <= 5e-3
    assert first["estimated_median_relative_error"] <= 1e-3 and first["estimated_p95_relative_error"] <= 5e-3
    # 50 values cannot bound a 95th percentile: the rule goes on.
    assert "loo_p95_upper_bound" not in first and fit.n_train > 50
    assert holdout_metrics(fit.model, n_test=1024, seed=5)["median_relative_error"] < 1e-3


def test_fit_adaptive_stops_when_no_candidate_is_uncertain():
    space = Space({"balls": (3, 6)}, fixed={"load_N": 0.01, "speed_m_s": 0.01})
    fit = fit_adaptive(space, budget=30, target_relative_error=1e-12,
                       plan=SamplingPlan(initial_size=8, n_candidates=64))
    # Four possible ball counts: each evaluated exactly once, although the starting design asked for 8.
    assert sorted(fit.X[:, 0]) == [3, 4, 5, 6] and fit.n_train == 4
    assert fit.stop_reason == "candidates_exhausted"
    # Every point of the space is a training point: nothing is held out, and the note says so.
    metrics = holdout_metrics(fit.model, n_test=64)
    assert metrics["n_test"] == 0 and metrics["coverage_95"] is None
    assert metrics["median_relative_error"] is None
    assert metrics["note"].startswith("4 of the 4 points of the space are training points")
    np.testing.assert_allclose(fit.model.predict(fit.X), space.evaluate(fit.X), rtol=1e-3)


@pytest.mark.parametrize("adaptive", [True, False])
def test_a_finite_space_is_evaluated_once_per_point(adaptive):
    space = Space({"balls": (3, 5), "balls_touching": (False, True)},
                  fixed={"load_N": 0.01, "speed_m_s": 0.01})
    fit = fit_adaptive(space, budget=10, target_relative_error=1e-12, plan=SamplingPlan(adaptive=adaptive))
    # 3 ball counts x 2 booleans = 6 distinct points, fewer than the budget of 10.
    assert fit.n_train == 6 and len({tuple(x) for x in fit.X}) == 6
    assert fit.stop_reason == "candidates_exhausted"
    np.testing.assert_array_equal(fit.y, space.evaluate(fit.X))
    # Trained on 4 of the 6 points, the other 2 are the held-out set, each once.
    part = GaussianProcessSurrogate(space, random_state=0).fit(fit.X[:4], fit.y[:4])
    assert holdout_metrics(part, n_test=1024)["n_test"] == 2


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"budget": 1}, "budget must be"),
    ({"target_relative_error": 0}, "target_relative_error must be > 0"),
    ({"plan": SamplingPlan(initial_size=50)}, "initial_size must be in"),
    ({"plan": SamplingPlan(batch_size=0)}, "batch_size must be"),
    ({"plan": SamplingPlan(design_method="grid")}, "method must be one of"),
])
def test_fit_adaptive_validation(kwargs, message):
    with pytest.raises(ValueError, match=message):
        fit_adaptive(SPACES["load"], **{"budget": 10, **kwargs})


# ----------------------------------------------------------------------------- metrics
def test_accuracy_by_hand():
    m = accuracy([1.0, 2.0, 4.0, 5.0], [1.1, 2.0, 3.0, 5.0], [0.9, 2.1, 2.0, 4.0], [1.2, 2.2, 5.0, 6.0])
    relative = [0.1, 0.0, 0.25, 0.0]
    assert m["median_relative_error"] == pytest.approx(0.05)
    assert m["p95_relative_error"] == pytest.approx(np.percentile(relative, 95))
    assert m["nrmse"] == pytest.approx(np.sqrt((0.01 + 1.0) / 4) / np.std([1.0, 2.0, 4.0, 5.0]))
    assert m["coverage_95"] == 0.75
    with pytest.raises(ValueError, match="same length"):
        accuracy([1.0, 2.0], [1.0], [1.0], [1.0])


def test_holdout_metrics_never_use_training_points():
    space = Space({"balls": (3, 6)}, fixed={"load_N": 0.01, "speed_m_s": 0.01})
    X = np.array([[3.0], [4.0], [5.0]])
    model = GaussianProcessSurrogate(space, mean="constant", random_state=0).fit(X, space.evaluate(X))
    # A finite space is tested on each of its points that is not a training point, once: only balls = 6.
    m = holdout_metrics(model, n_test=64)
    assert m["n_test"] == 1 and m["median_relative_error"] is None
    assert m["note"].startswith("3 of the 4 points of the space are training points: only 1 held-out")
    # Sampled (space larger than n_test) and every sample a training point or balls = 6: too few.
    with pytest.raises(ValueError, match="fewer than 2"):
        holdout_metrics(model, n_test=1)
    two = GaussianProcessSurrogate(space, mean="constant", random_state=0).fit(X[:2], space.evaluate(X[:2]))
    held = np.array([[5.0], [6.0]])
    p = two.predict_interval(held)
    truth = space.evaluate(held)
    by_hand = accuracy(truth, p.mu, p.mu_lower, p.mu_upper)
    assert holdout_metrics(two, n_test=64) == {**by_hand, "note": None} and by_hand["n_test"] == 2
    # A continuous space: the Sobol' test design less the training points among it.
    load = SPACES["load"]
    train = design(load, 16, "sobol", 9_999)[:8]
    model = GaussianProcessSurrogate(load, random_state=0).fit(train, load.evaluate(train))
    assert holdout_metrics(model, n_test=1024, seed=9_999)["n_test"] == 1024 - 8


# ----------------------------------------------------------------------------- sensitivity
UNIT_SPACE = Space({"mu_pivot": (0, 1), "mu_ball": (0, 1), "viscosity_Pa_s": (0, 1)},
                   fixed={"balls": 4, "load_N": 0.01, "speed_m_s": 0.1})


def test_sobol_indices_of_the_ishigami_function():
    a, b = 7.0, 0.1

    def ishigami(X):
        x = -np.pi + 2 * np.pi * X
        return np.sin(x[:, 0]) + a * np.sin(x[:, 1]) ** 2 + b * x[:, 2] ** 4 * np.sin(x[:, 0])

    variance = a**2 / 8 + b * np.pi**4 / 5 + b**2 * np.pi**8 / 18 + 0.5
    v1, v2, v13 = 0.5 * (1 + b * np.pi**4 / 5) ** 2, a**2 / 8, 8 * b**2 * np.pi**8 / 225
    result = sobol_indices(ishigami, UNIT_SPACE, n=4096)
    np.testing.assert_allclose(result.first_order, np.array([v1, v2, 0.0]) / variance, atol=0.02)
    np.testing.assert_allclose(result.total_order, np.array([v1 + v13, v2, v13]) / variance, atol=0.02)
    # The bootstrap intervals hold the analytic indices and are narrow at n = 4096.
    for estimate, exact in ((result.first_order_interval, np.array([v1, v2, 0.0]) / variance),
                            (result.total_order_interval, np.array([v1 + v13, v2, v13]) / variance)):
        assert np.all((estimate[:, 0] <= exact + 1e-3) & (exact - 1e-3 <= estimate[:, 1]))
        assert np.all(estimate[:, 1] - estimate[:, 0] < 0.1)


def test_sobol_indices_of_an_additive_function():
    weights = np.array([1.0, 2.0, 3.0])
    result = sobol_indices(lambda X: X @ weights, UNIT_SPACE, n=2048)
    expected = weights**2 / np.sum(weights**2)
    np.testing.assert_allclose(result.first_order, expected, atol=0.01)
    np.testing.assert_allclose(result.total_order, expected, atol=0.01)
    assert result.to_dict()["first_order"]["mu_ball"] == pytest.approx(expected[1], abs=0.01)
    with pytest.raises(ValueError, match="power of 2"):
        sobol_indices(lambda X: X[:, 0], UNIT_SPACE, n=1000)


def test_sobol_indices_of_the_friction_model_on_a_surrogate():
    space = Space(TARGET_BOUNDS)
    X = design(space, 64, seed=0)
    model = GaussianProcessSurrogate(space, random_state=0, calibrate_variance="none")
    model.fit(X, space.evaluate(X))
    result = sobol_indices(lambda P: np.log(model.predict(P)), space, n=1024)
    exact = sobol_indices(lambda P: np.log(space.evaluate(P)), space, n=1024)
    np.testing.assert_allclose(result.total_order, exact.total_order, atol=0.02)
    # Load per ball drives μ: balls and load dominate, speed least.
    assert np.argmin(exact.total_order) == space.names.index("speed_m_s")


@pytest.mark.parametrize(("adaptive", "model_params", "expected"), [
    (True, None, 8), (False, None, None), (True, {"calibration_rows": 10}, 10)])
def test_fit_adaptive_calibrates_on_the_space_filling_design(adaptive, model_params, expected):
    # Adaptive batches crowd the edges, where leave-one-out is extrapolation: only the starting design
    # (8 of 16 points here) sets the variance scale; a plain design uses every point; an explicit choice wins.
    space = SPACES["angle+load"]
    fit = fit_adaptive(space, budget=16, target_relative_error=1e-9,
                       plan=SamplingPlan(initial_size=8, batch_size=4, adaptive=adaptive),
                       model_params={"calibrate_variance": "loo", **(model_params or {})},
                       validation_points=0)
    assert fit.model.calibration_rows == expected and fit.n_train == 16 and fit.validation_points == 0
    errors, variances = fit.model.loo_log_errors(), fit.model.loo_log_variances()
    z = (errors / np.sqrt(variances))[:expected]
    assert fit.model.std_scale_ == pytest.approx(np.sqrt(np.mean(z**2)), rel=1e-12)


@pytest.mark.parametrize(("budget", "dimension", "starting"), [
    (20, 1, 10), (49, 4, 24), (50, 4, 40), (79, 7, 40), (100, 4, 50), (300, 4, 150), (20, 9, 20)])
def test_small_budgets_start_with_enough_space_filling_points_to_calibrate(budget, dimension, starting):
    # The starting design's errors set the variance scale: 40 of them when a fifth of the budget is
    # still left to adaptive batches, else half the budget; never fewer than 2 (d + 1) points.
    assert default_initial_size(budget, dimension) == starting


def test_fit_adaptive_starts_with_the_default_design_and_calibrates_on_it():
    fit = fit_adaptive(SPACES["load"], budget=50, target_relative_error=1e-12, seed=0)
    assert fit.history[0]["n_train"] == 40 and fit.model.calibration_rows == 40


def test_calibrate_sets_the_split_conformal_quantile_of_the_validation_errors():
    space = SPACES["angle+load"]
    X = design(space, 20, seed=0)
    model = GaussianProcessSurrogate(space, random_state=0).fit(X, space.evaluate(X))
    X_valid = design(space, 99, seed=5)
    y_valid = space.evaluate(X_valid)
    model.calibrate(X_valid, y_valid)
    assert (model.variance_calibration_, model.calibration_points_) == ("validation", 99)
    # std_scale_, the factor of all 99 together: k = ceil(0.95 x 100) = 95 of them within 1.96 of it.
    Zs = model.design_matrix(X_valid)
    mean, std = model.gaussian_process_.predict(Zs, return_std=True)
    z = np.abs(np.log(y_valid) - mean - prior_mean(model.mean_coef_, Zs)) / std
    assert np.sum(z <= 1.96 * model.std_scale_ * (1 + 1e-9)) == 95
    # Each bin of distance from the centre with 19 points or more holds k = ceil(0.95 (n + 1)) of them in
    # its own interval: exactly k where its factor is its own conformal quantile, at least k where a bin
    # nearer the centre asked for more (never less than those: the running maximum outward).
    prediction = model.predict_interval(X_valid)
    inside = (prediction.mu_lower <= y_valid * (1 + 1e-12)) & (y_valid <= prediction.mu_upper * (1 + 1e-12))
    edges, scales = model.radius_scales_.edges, model.radius_scales_.scales
    bins = np.searchsorted(edges, space.radius(X_valid), side="right")
    # 99 points: 5 bins (99 // 19) of 19-20 points, the factors never decreasing outward
    assert len(scales) == 5 and scales == sorted(scales) and np.bincount(bins).min() >= 19
    checked = 0
    for b in range(5):
        n = int(np.sum(bins == b))
        if n < 19:
            continue
        k = math.ceil(0.95 * (n + 1))
        own = np.sort(z[bins == b])[k - 1] / 1.959963984540054
        assert scales[b] >= own * (1 - 1e-9)
        held = int(inside[bins == b].sum())
        assert held == k if scales[b] == pytest.approx(own, rel=1e-9) else held >= k
        checked += 1
    assert checked >= 2
    # Whatever the process's own scale, the same conformal quantile: refitting with another calibration
    # and calibrating again gives the same factor.
    other = GaussianProcessSurrogate(space, random_state=0, calibrate_variance="none")
    other.fit(X, space.evaluate(X))
    assert other.calibrate(X_valid, y_valid).std_scale_ == pytest.approx(model.std_scale_, rel=1e-12)
    # Kept through JSON.
    restored = loads(dumps(model))
    assert (restored.std_scale_, restored.variance_calibration_, restored.calibration_points_) == \
        (model.std_scale_, "validation", 99)
    assert restored.radius_scales_ == model.radius_scales_
    np.testing.assert_array_equal(restored.predict_interval(X_valid).mu_upper, prediction.mu_upper)


def test_calibrate_refuses_training_points_and_too_few_points():
    space = SPACES["angle+load"]
    X = design(space, 20, seed=0)
    model = GaussianProcessSurrogate(space, random_state=0).fit(X, space.evaluate(X))
    with pytest.raises(ValueError, match="must not be training points"):
        model.calibrate(X, space.evaluate(X))
    few = design(space, 18, seed=3)
    with pytest.raises(ValueError, match="at least 19 validation points"):
        model.calibrate(few, space.evaluate(few))


def test_fit_adaptive_calibrates_on_validation_points_beyond_the_budget():
    space = SPACES["angle+load"]
    fit = fit_adaptive(space, budget=24, seed=0, validation_points=200)
    assert fit.n_train == 24 and fit.validation_points == 200
    assert (fit.model.variance_calibration_, fit.model.calibration_points_) == ("validation", 200)
    # Coverage of fresh points (another scramble) is that of a split-conformal interval on 200 points:
    # Beta(191, 10) has 99 % of its mass in [0.91, 0.985].
    X_test = design(space, 2048, seed=123_456)
    y_test = space.evaluate(X_test)
    prediction = fit.model.predict_interval(X_test)
    coverage = np.mean((prediction.mu_lower <= y_test) & (y_test <= prediction.mu_upper))
    assert 0.91 <= coverage <= 0.985
    # A space of integer and boolean dimensions only keeps cross-validation (its points are finitely many).
    finite = Space({"balls": (3, 40), "balls_touching": (False, True)},
                   fixed={"load_N": 0.01, "speed_m_s": 0.01})
    assert fit_adaptive(finite, budget=20, seed=0).validation_points == 0
    with pytest.raises(ValueError, match="validation_points"):
        fit_adaptive(space, budget=24, validation_points=-1)


def test_an_input_mu_ignores_gets_intervals_no_narrower_than_float64_resolution():
    # Without touching balls, mu_ball has no effect: mu is one constant, which the process reproduces to
    # the last bit at some points and not at others; the interval still holds it everywhere.
    space = Space({"mu_ball": (0.05, 0.5)}, fixed={"balls": 4, "load_N": 0.01, "speed_m_s": 0.01})
    fit = fit_adaptive(space, budget=20, seed=0)
    metrics = holdout_metrics(fit.model, n_test=512, seed=7)
    assert metrics["median_relative_error"] < 1e-13 and metrics["coverage_95"] == 1.0
    prediction = fit.model.predict_interval(design(space, 8, seed=9))
    np.testing.assert_allclose(prediction.mu_upper / prediction.mu, np.exp(1e-12), rtol=1e-15)


def test_kept_hyperparameters_are_the_given_ones_and_the_adaptive_final_model_is_optimized():
    space = SPACES["load"]
    X = design(space, 12, seed=0)
    optimized = GaussianProcessSurrogate(space, random_state=0, features="physics").fit(X, space.evaluate(X))
    theta = optimized.gaussian_process_.kernel_.theta + np.array([0.0, 0.3, 0.0])  # a longer length scale
    kept = GaussianProcessSurrogate(space, features="physics",
                                    hyperparameters=Hyperparameters(theta.tolist(), optimize=False))
    np.testing.assert_array_equal(kept.fit(X, space.evaluate(X)).gaussian_process_.kernel_.theta, theta)
    # rounds may keep earlier hyperparameters; the returned model maximizes the likelihood on every point
    fit = fit_adaptive(space, budget=16, plan=SamplingPlan(initial_size=8, batch_size=2), seed=0)
    assert fit.model.hyperparameters.optimize
    gp = fit.model.gaussian_process_
    refit = GaussianProcessSurrogate(space, hyperparameters=Hyperparameters(gp.kernel_.theta.tolist(),
                                                                            n_restarts_optimizer=0))
    refit.fit(fit.X, fit.y)
    assert gp.log_marginal_likelihood_value_ >= refit.gaussian_process_.log_marginal_likelihood_value_ - 1e-6
    # The round that spends the budget optimizes; when the final calibration differs from the rounds'
    # (k-fold below 10 points per feature: 24 points of 3 features), only the calibration is redone.
    space = SPACES["angle+load"]
    fit = fit_adaptive(space, budget=24, plan=SamplingPlan(initial_size=12, batch_size=6), seed=0,
                       validation_points=0)
    assert (fit.model.calibrate_variance, fit.model.variance_calibration_) == ("auto", "kfold")
    gp = fit.model.gaussian_process_
    refit = GaussianProcessSurrogate(space, hyperparameters=Hyperparameters(gp.kernel_.theta.tolist(),
                                                                            n_restarts_optimizer=0))
    refit.fit(fit.X, fit.y)
    assert gp.log_marginal_likelihood_value_ >= refit.gaussian_process_.log_marginal_likelihood_value_ - 1e-6


def test_a_lower_bound_near_the_smallest_double_gets_a_log_scale_without_overflow():
    # Found by schemathesis (POST /v1/surrogates with mu_ball in [2.2e-308, 4]): hi / lo overflowed,
    # a RuntimeWarning that the test suite turns into an error (was: 500 in the tests).
    from microbearing.surrogate.space import Space

    space = Space({"mu_ball": [2.2250738585072014e-308, 4.0]}, fixed={"balls": 4, "load_N": 0.01,
                                                                      "speed_m_s": 0.05})
    assert space.scale_of["mu_ball"] == "log"


def test_sobol_intervals_of_an_ignored_input_survive_another_thread_resetting_the_warning_filters():
    """An input the function ignores has no BCa interval (its jackknife divides 0 by 0): its interval is
    the index itself, 0. Warning filters are process-wide and a thread leaving ``catch_warnings`` puts back
    the filters it saw, so a filter set here can vanish while the bootstrap runs (under this suite's
    ``error::RuntimeWarning`` a 500 of the sensitivity route, seen once in the service's stateful test);
    numpy's error state is per thread and holds."""
    import threading
    import warnings

    stop = threading.Event()

    def reset_filters():
        while not stop.is_set():
            with warnings.catch_warnings():
                pass

    other = threading.Thread(target=reset_filters)
    other.start()
    try:
        result = sobol_indices(lambda X: X[:, 0] + 2.0 * X[:, 1], UNIT_SPACE, n=256, seed=1)
        assert result.total_order[2] == 0.0 and np.all(result.total_order_interval[2] == 0.0)
        np.testing.assert_allclose(result.total_order[:2], [0.2, 0.8], atol=0.1)
    finally:
        stop.set()
        other.join()


# ----------------------------------------------------------------------------- physics-informed mean
def test_the_dry_contact_share_is_mu_less_its_rolling_term():
    space = Space({"speed_m_s": (0.0, 0.2), "adhesion_energy_J_m2": (0.0, 0.4),
                   "balls_touching": (False, True)}, {"balls": 6, "load_N": 0.004}, "derjaguin")
    X = design(space, 64, "sobol", seed=1)
    r = physics.evaluate(convention="derjaguin", **space.points(X))
    np.testing.assert_allclose(space.dry_contact_mu(X), r.mu - r.mu_rolling, rtol=1e-12)
    at_rest = X.copy()
    at_rest[:, 0] = 0.0  # no rolling force without speed (eq 9: U^0.66)
    np.testing.assert_allclose(space.dry_contact_mu(at_rest), space.evaluate(at_rest), rtol=1e-14)
    np.testing.assert_allclose(space.dry_contact_mu(at_rest), space.dry_contact_mu(X), rtol=1e-14)
    Z = space.features(X, "dry_contact")
    np.testing.assert_array_equal(Z[:, :-1], space.features(X, "physics"))
    np.testing.assert_allclose(np.exp(Z[:, -1]), space.dry_contact_mu(X), rtol=1e-14)
    assert space.feature_names("dry_contact")[-1] == "log(mu_dry)"


def test_a_posynomial_mean_recovers_a_sum_of_two_power_laws_a_linear_one_cannot():
    Z = design(Space({"load_N": (0.001, 0.05), "speed_m_s": (0.001, 0.2)}, fixed={"balls": 4}), 40, seed=2)
    Zs = (np.log(Z) - np.log(Z).mean(axis=0)) / np.log(Z).std(axis=0)
    t = np.logaddexp(-1.0 + 0.8 * Zs[:, 0], -2.5 + 0.6 * Zs[:, 1] - 0.3 * Zs[:, 0])
    coef = fit_prior_mean("posynomial", Zs, t)
    assert coef.shape == (6,)
    np.testing.assert_allclose(prior_mean(coef, Zs), t, atol=1e-7)
    linear = fit_prior_mean("linear", Zs, t)
    assert np.max(np.abs(prior_mean(linear, Zs) - t)) > 1e-2
    # Too few points for two terms: the linear fit, the second term off.
    few = fit_prior_mean("posynomial", Zs[:6], t[:6])
    linear_few = fit_prior_mean("linear", Zs[:6], t[:6])
    np.testing.assert_allclose(prior_mean(few, Zs[:6]), prior_mean(linear_few, Zs[:6]))


def test_the_default_surrogate_is_more_accurate_than_the_earlier_one_on_a_ball_ball_space():
    # A space not tuned on, of ball-ball friction (balls touching): mu_dry holds the ball-ball moment.
    space = Space({"mu_ball": (0.2, 1.0), "ball_diameter_m": (200e-6, 800e-6), "load_N": (0.002, 0.05)},
                  fixed={"balls": 10, "balls_touching": True, "speed_m_s": 0.1})
    X, Xt = design(space, 30, "sobol", seed=0), design(space, 256, "sobol", seed=9)
    truth = space.evaluate(Xt)
    errors = []
    for params in ({"features": "physics", "mean": "linear"}, {}):
        model = GaussianProcessSurrogate(space, random_state=0, **params).fit(X, space.evaluate(X))
        errors.append(np.median(np.abs(model.predict(Xt) / truth - 1)))
    assert errors[1] < errors[0] / 3


def test_a_large_prediction_runs_in_blocks_with_the_same_answer(fitted, monkeypatch):
    # A call's memory is one block's covariances, whatever its size; the blocks give the whole call's
    # numbers (the process's prediction is row by row), an empty call an empty answer.
    from microbearing.surrogate import model as surrogate_model

    model = next(iter(fitted.values()))
    X = design(model.space, 50, "sobol", seed=5)
    whole_mu, whole_std = model.predict(X, return_std=True)
    monkeypatch.setattr(surrogate_model, "_PREDICT_BLOCK", 7)
    mu, std = model.predict(X, return_std=True)
    np.testing.assert_allclose(mu, whole_mu, rtol=1e-12)
    np.testing.assert_allclose(std, whole_std, rtol=1e-9, atol=1e-15)
    assert model.predict(X[:0]).shape == (0,)


def test_a_log_spaced_whole_number_range_gives_each_count_its_log_share():
    # Sweeps' Sobol' and Latin-hypercube designs: balls 3-30 on a log scale give k the share
    # log((k + 1) / k) / log(31 / 3) (the grid's log axis spaces them so too); linear, 1/28 each.
    from microbearing.surrogate.designs import sampled_values

    for method in ("sobol", "latin_hypercube"):
        logged = sampled_values({"balls": (3, 30, "log")}, 4096, method, seed=2)["balls"]
        linear = sampled_values({"balls": (3, 30, "linear")}, 4096, method, seed=2)["balls"]
        counts = np.arange(3, 31)
        share = np.array([np.mean(logged == k) for k in counts])
        np.testing.assert_allclose(share, np.log((counts + 1) / counts) / np.log(31 / 3), atol=0.006)
        assert logged.min() == 3 and logged.max() == 30 and np.median(logged) in (9, 10)
        np.testing.assert_allclose([np.mean(linear == k) for k in counts], 1 / 28, atol=0.006)


def test_radius_is_the_rms_distance_from_the_centre_on_the_design_scale():
    # load on a log scale (centre: the geometric mean), the angle linear, a boolean left out.
    space = Space({"load_N": (0.001, 0.1), "groove_angle_deg": (40, 60), "balls_touching": (False, True)},
                  fixed={"balls": 4, "speed_m_s": 0.01})
    X = np.array([[0.01, 50.0, 0.0],     # the centre
                  [0.1, 50.0, 1.0],      # one input at its end: sqrt(1 / 2)
                  [10 ** -1.5, 45.0, 1.0],  # each halfway to an end: 0.5
                  [0.001, 60.0, 0.0],    # a corner
                  [0.5, 80.0, 1.0]])     # beyond the bounds: the corner
    np.testing.assert_allclose(space.radius(X), [0.0, np.sqrt(0.5), 0.5, 1.0, 1.0], atol=1e-12)
    only_booleans = Space({"balls_touching": (False, True)}, fixed={"balls": 4, "load_N": 0.01,
                                                                     "speed_m_s": 0.01})
    np.testing.assert_array_equal(only_booleans.radius([[0.0], [1.0]]), [0.0, 0.0])


def test_radial_design_spreads_its_points_over_the_distance_from_the_centre():
    from microbearing.surrogate.sampling import radial_design

    space = Space({"groove_angle_deg": (30, 75), "load_N": (0.001, 0.05), "speed_m_s": (0.0, 0.2),
                   "mu_pivot": (0.2, 1.0)}, fixed={"balls": 6})
    X = radial_design(space, 512, seed=3)
    assert X.shape == (512, 4) and np.all(space.contains(X))
    radius = space.radius(X)
    uniform = space.radius(design(space, 512, seed=3))
    # A uniform design leaves the outer fifth of the distance (r >= 0.8) and the inner fifth nearly
    # empty (in 4-D, 3 % and 0.4 % of a uniform space); the radial one puts a tenth of its points or
    # more in each fifth.
    assert np.mean(uniform >= 0.8) < 0.05 and np.mean(uniform < 0.2) < 0.02
    assert np.histogram(radius, bins=5, range=(0, 1))[0].min() >= 51
    # Each input is on either side of its middle alike (a two-sided binomial bound at 99.9 %).
    above = np.mean(space.to_unit(X) > 0.5, axis=0)
    assert np.all(np.abs(above - 0.5) < 3.3 * np.sqrt(0.25 / 512))


def test_intervals_cover_the_corners_of_the_space_as_they_cover_its_middle():
    # One conformal factor for the whole space left the corners under-covered (a Gaussian process has
    # neighbours on one side only there); one per bin of distance from the centre covers both.
    space = Space({"groove_angle_deg": (30, 75), "load_N": (0.001, 0.05), "speed_m_s": (0.001, 0.2),
                   "mu_pivot": (0.2, 1.0)}, fixed={"balls": 6})
    fit = fit_adaptive(space, budget=40, target_relative_error=1e-3, seed=1)
    model = fit.model
    assert model.variance_calibration_ == "validation" and len(model.radius_scales_.scales) == 8
    rng = np.random.default_rng(11)
    offset = rng.uniform(0.0, 0.1, (1000, 4))  # every input within 10 % of one of its ends
    corners = space.from_unit(np.where(rng.random((1000, 4)) < 0.5, offset, 1.0 - offset))
    middle = space.from_unit(rng.uniform(0.3, 0.7, (1000, 4)))

    def coverage(X):
        y, p = space.evaluate(X), model.predict_interval(X)
        return float(np.mean((p.mu_lower <= y) & (y <= p.mu_upper)))

    by_radius = coverage(corners), coverage(middle)
    # 64 validation points a bin: a bin's coverage is Beta(62, 3), 99 % of it in [0.86, 0.995]
    assert 0.86 <= by_radius[0] and 0.86 <= by_radius[1], by_radius
    # the factor grows outward: the corners' intervals wider than the middle's, relative to the process's
    assert np.median(model.scale_at(corners)) > np.median(model.scale_at(middle))
    single = loads(dumps(model))
    single.radius_scales_ = None  # as stored before the factors by distance: std_scale_ alone
    y, p = space.evaluate(corners), single.predict_interval(corners)
    assert np.mean((p.mu_lower <= y) & (y <= p.mu_upper)) < by_radius[0]


def test_a_surrogate_stored_before_the_factors_by_distance_loads_with_its_one_scale():
    space = SPACES["angle+load"]
    X = design(space, 20, seed=0)
    model = GaussianProcessSurrogate(space, random_state=0).fit(X, space.evaluate(X))
    X_valid = design(space, 60, seed=5)
    model.calibrate(X_valid, space.evaluate(X_valid))
    data = to_dict(model)
    del data["radius_scales"]
    old = from_dict(data)
    assert old.radius_scales_ is None
    np.testing.assert_allclose(old.predict_interval(X_valid).log_std,
                               model.predict(X_valid, return_std=True)[1] / model.scale_at(X_valid)
                               * model.std_scale_, rtol=1e-9)
    for broken in ({"edges": [0.5, 0.4], "scales": [1.0, 1.0, 1.0]}, {"edges": [0.5], "scales": [1.0]},
                   {"edges": [0.5], "scales": [1.0, -2.0]}):
        with pytest.raises(ValueError, match="radius_scales"):
            from_dict({**data, "radius_scales": broken})
