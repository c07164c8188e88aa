"""Accuracy, calibration and speed of the Gaussian-process surrogates, measured side by side.

Run: ``.venv/bin/python -m bench.surrogate`` from the repository root (about 12 minutes on the
shared 2-core machine; ``--quick`` skips the ablations and the larger spaces, about 2 minutes).

Every figure is on held-out physics evaluations (2048 scrambled Sobol' points of
each space, a seed never used for training). Rows:

* the issue's target: ``fit_adaptive`` with budget 100 and target relative
  error 0.001 (it may stop before the budget), for three seeds of the design,
  and with the whole budget;
* ablations at budget 100 (Sobol' design, one change at a time) that measure
  the choices of the model: features, prior mean, kernel, log target;
* the baseline: a plain GP (RBF, constant mean, μ itself as target) on raw
  inputs with a Latin-hypercube design of the same budget; ratios baseline /
  ours of the median and 95th-percentile errors;
* larger spaces (friction coefficients, adhesion energy, ball diameter, balls
  touching as inputs) at budgets 100 and 200.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from surrogate import GaussianProcessSurrogate, Space, accuracy, design, fit_adaptive

TARGET_SPACE = {"balls": (3, 40), "groove_angle_deg": (30, 75), "load_N": (0.001, 0.05),
                "speed_m_s": (0.001, 0.2)}
LARGER_SPACES = {
    "6-D (+ mu_pivot, adhesion)": {
        **TARGET_SPACE, "mu_pivot": (0.2, 1.0), "adhesion_energy_J_m2": (0.0, 0.5)},
    "8-D (+ mu_pivot, mu_ball, adhesion, diameter)": {
        **TARGET_SPACE, "mu_pivot": (0.2, 1.0), "mu_ball": (0.2, 1.0), "adhesion_energy_J_m2": (0.0, 0.5),
        "ball_diameter_m": (100e-6, 1e-3)},
    "9-D (8-D + balls_touching)": {
        **TARGET_SPACE, "mu_pivot": (0.2, 1.0), "mu_ball": (0.2, 1.0), "adhesion_energy_J_m2": (0.0, 0.5),
        "ball_diameter_m": (100e-6, 1e-3), "balls_touching": (False, True)},
}
N_TEST = 2048
TEST_SEED = 20_251_122
SEEDS = (0, 1, 2)


def held_out(space: Space) -> tuple[np.ndarray, np.ndarray]:
    X = design(space, N_TEST, "sobol", TEST_SEED)
    return X, space.evaluate(X)


def score(model: GaussianProcessSurrogate, X: np.ndarray, y: np.ndarray) -> dict[str, float]:
    p = model.predict_interval(X)
    return accuracy(y, p.mu, p.mu_lower, p.mu_upper)


def row(label: str, n_train: int, fit_s: float, m: dict[str, float]) -> str:
    return (f"| {label} | {n_train} | {100 * m['median_relative_error']:.4f} | "
            f"{100 * m['p95_relative_error']:.4f} | {m['nrmse']:.2e} | {100 * m['coverage_95']:.1f} | "
            f"{fit_s:.1f} |")


HEADER = ("| model | n_train | median rel. err. [%] | p95 rel. err. [%] | NRMSE | 95 % coverage [%] "
          "| fit [s] |\n|---|---|---|---|---|---|---|")


def fixed_design(space: Space, budget: int, method: str, **params) -> tuple[GaussianProcessSurrogate, float]:
    X = design(space, budget, method, 0)
    start = time.perf_counter()
    model = GaussianProcessSurrogate(space, random_state=0, **params).fit(X, space.evaluate(X))
    return model, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="only the target rows and the baseline")
    args = parser.parse_args()

    space = Space(TARGET_SPACE)
    X_test, y_test = held_out(space)
    print(f"4-D space {space}; {N_TEST} held-out Sobol' points\n")
    print(HEADER)
    runs = []
    for seed in SEEDS:
        start = time.perf_counter()
        fit = fit_adaptive(space, budget=100, target_relative_error=1e-3, seed=seed)
        seconds = time.perf_counter() - start
        runs.append((fit, seconds, score(fit.model, X_test, y_test)))
        print(row(f"adaptive, target 0.001, seed {seed} (stop: {fit.stop_reason})", fit.n_train, seconds,
                  runs[-1][2]))
    target, fit_s, _ = runs[0]
    start = time.perf_counter()
    full = fit_adaptive(space, budget=100, target_relative_error=1e-9)
    full_s = time.perf_counter() - start
    print(row("adaptive, whole budget", full.n_train, full_s, score(full.model, X_test, y_test)))

    raw = Space(TARGET_SPACE, scales=dict.fromkeys(TARGET_SPACE, "linear"))
    baseline, base_s = fixed_design(raw, 100, "latin_hypercube", features="raw", kernel="rbf",
                                    mean="constant", log_target=False, calibrate_variance="none")
    base = score(baseline, X_test, y_test)
    print(row("baseline: LHS, raw inputs, GP on mu", 100, base_s, base))

    if not args.quick:
        ablations = {
            "Sobol, defaults (physics features, linear mean, RBF, log mu)": {},
            "Sobol, features: log scales only (no G/z, tan/cos theta)": {"features": "scaled"},
            "Sobol, features: raw inputs": {"features": "raw"},
            "Sobol, constant mean": {"mean": "constant"},
            "Sobol, Matern 5/2 kernel": {"kernel": "matern52"},
            "Sobol, target mu instead of log mu": {"log_target": False},
            "Sobol, variance calibration: closed-form LOO": {"calibrate_variance": "loo"},
            "Sobol, no variance calibration": {"calibrate_variance": "none"},
        }
        for label, params in ablations.items():
            model, seconds = fixed_design(space, 100, "sobol", **params)
            print(row(label, 100, seconds, score(model, X_test, y_test)))
        model, seconds = fixed_design(space, 100, "latin_hypercube")
        print(row("LHS, defaults", 100, seconds, score(model, X_test, y_test)))

    for seed, (_, _, m) in zip(SEEDS, runs, strict=True):
        print(f"{'' if seed else chr(10)}baseline / adaptive-with-target (seed {seed}) error ratio: "
              f"median {base['median_relative_error'] / m['median_relative_error']:.0f}x, "
              f"p95 {base['p95_relative_error'] / m['p95_relative_error']:.0f}x")

    X_big = design(space, 10_000, "sobol", 7)
    start = time.perf_counter()
    target.model.predict_interval(X_big)
    print(f"predict 10,000 points with interval: {time.perf_counter() - start:.3f} s "
          f"(n_train {target.n_train}); training {fit_s:.1f} s")

    if args.quick:
        return
    for label, bounds in LARGER_SPACES.items():
        big = Space(bounds)
        X_t, y_t = held_out(big)
        print(f"\n{label}: {big}\n")
        print(HEADER)
        for budget in (100, 200):
            start = time.perf_counter()
            fit = fit_adaptive(big, budget=budget, target_relative_error=1e-3)
            seconds = time.perf_counter() - start
            print(row(f"adaptive, budget {budget} (stop: {fit.stop_reason})", fit.n_train, seconds,
                      score(fit.model, X_t, y_t)))
        model, seconds = fixed_design(Space(bounds, scales={n: "linear" for n in bounds}), 200,
                                      "latin_hypercube", features="raw", kernel="rbf", mean="constant",
                                      log_target=False, calibrate_variance="none")
        print(row("baseline: LHS, raw inputs, GP on mu, budget 200", 200, seconds, score(model, X_t, y_t)))


if __name__ == "__main__":
    main()
