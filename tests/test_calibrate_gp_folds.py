"""The held-out GP on what a calibrated model leaves (calibrate.discrepancy.residual_gp) on data larger
than its training subset: every fold trains its GP on its own random subset of the same size, the first
fold fits the hyperparameters and the others share them. Checked against scikit-learn run by hand in this
file, and against refitting every fold (the shared values must cost the held-out error next to nothing)."""

from __future__ import annotations

import numpy as np
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

from microbearing.calibrate import parse_rows
from microbearing.calibrate.discrepancy import residual_gp

SEED = 11


def _data(n: int = 400):
    rng = np.random.default_rng(SEED)
    humidity = rng.uniform(0.2, 0.8, n)
    temperature = rng.uniform(10.0, 60.0, n)
    # the model leaves a smooth bump in humidity and a slope in temperature, 1 % scatter
    model_mu = np.full(n, 0.01)
    measured = model_mu * np.exp(0.08 * np.sin(6.0 * humidity) + 0.002 * (temperature - 35.0)
                                 + rng.normal(0.0, 0.01, n))
    rows = [{"balls": 4, "load_N": 0.01, "speed_m_s": 0.05, "relative_humidity": float(h),
             "temperature_C": float(t), "mu_measured": float(m)}
            for h, t, m in zip(humidity, temperature, measured, strict=True)]
    folds = np.array_split(rng.permutation(n), 5)
    return parse_rows(rows), [np.sort(f) for f in folds], model_mu, measured


def _by_hand(dataset, folds, model_mu, measured, max_train: int, share: bool) -> np.ndarray:
    """Held-out μ of each row: scikit-learn's GP on each fold's subset of the standardized columns."""
    columns = dataset.columns()
    x = np.column_stack([(columns[c] - columns[c].mean()) / columns[c].std()
                         for c in ("relative_humidity", "temperature_C")])
    rng = np.random.default_rng(SEED)
    kernel = ConstantKernel(1.0, (1e-4, 1e2)) * RBF(np.ones(2), (1e-2, 1e3)) + WhiteKernel(0.1, (1e-8, 1e1))
    oof = np.empty(measured.size)
    for k, test in enumerate(folds):
        train = np.setdiff1d(np.arange(measured.size), test)
        train = np.sort(rng.choice(train, max_train, replace=False))
        fixed = share and k > 0
        gp = GaussianProcessRegressor(kernel, normalize_y=True, random_state=SEED,
                                      **({"optimizer": None} if fixed else {}))
        gp.fit(x[train], np.log(measured[train] / model_mu[train]))
        kernel = gp.kernel_
        oof[test] = model_mu[test] * np.exp(gp.predict(x[test]))
    return oof


def _rms_log(mu, measured) -> float:
    return float(np.sqrt(np.mean(np.log(mu / measured) ** 2)))


def test_larger_data_share_the_first_folds_hyperparameters_at_no_cost_in_held_out_error():
    dataset, folds, model_mu, measured = _data()
    inliers = np.ones(measured.size, dtype=bool)
    found = residual_gp(dataset, folds, [model_mu] * 5, model_mu, inliers, max_train=120, seed=SEED)
    shared = _by_hand(dataset, folds, model_mu, measured, 120, share=True)
    np.testing.assert_allclose(found["errors"]["relative_rmse"], _rms_log(shared, measured), rtol=1e-9)
    refitted = _by_hand(dataset, folds, model_mu, measured, 120, share=False)
    # the GP finds the bump (8 % amplitude) down to about the scatter, shared or refitted alike
    assert found["helps"] and found["errors"]["relative_rmse"] < 0.015
    assert abs(_rms_log(shared, measured) / _rms_log(refitted, measured) - 1.0) < 0.03


def test_data_within_the_training_size_refit_every_fold():
    dataset, folds, model_mu, measured = _data(150)
    inliers = np.ones(measured.size, dtype=bool)
    found = residual_gp(dataset, folds, [model_mu] * 5, model_mu, inliers, max_train=300, seed=SEED)
    # every fold's training rows (120) under 300: no subset, every fold fits its hyperparameters
    columns = dataset.columns()
    x = np.column_stack([(columns[c] - columns[c].mean()) / columns[c].std()
                         for c in ("relative_humidity", "temperature_C")])
    kernel = ConstantKernel(1.0, (1e-4, 1e2)) * RBF(np.ones(2), (1e-2, 1e3)) + WhiteKernel(0.1, (1e-8, 1e1))
    oof = np.empty(measured.size)
    for test in folds:
        train = np.setdiff1d(np.arange(measured.size), test)
        gp = GaussianProcessRegressor(kernel, normalize_y=True, random_state=SEED)
        gp.fit(x[train], np.log(measured[train] / model_mu[train]))
        kernel = gp.kernel_
        oof[test] = model_mu[test] * np.exp(gp.predict(x[test]))
    np.testing.assert_allclose(found["errors"]["relative_rmse"], _rms_log(oof, measured), rtol=1e-9)
