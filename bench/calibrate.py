"""Calibration: a synthetic suite of hidden effects (discovery, error, coverage) and a 10,000-row timing.

Run: ``python bench/calibrate.py --suite [--seeds N] [--clean-seeds M] [--distinct-clean-seeds]`` for
the suite, ``python bench/calibrate.py --suite --part lab [--seeds N] [--cases 0:2] [--first-seed S]`` for
the lab structures of issue 24 (several builds, scatter that depends on the speed, conditions that move
together),
``python bench/calibrate.py --suite --part null [--null-seeds K]`` for the family-wise error
of one selection step on data with nothing to find, and ``python bench/calibrate.py --rows 10000`` for
the timing (target of issue 6: within 60 s).

The suite draws measurements from the physics (mu_pivot 0.7, adhesion 0.12 J/m^2 instead of the
defaults 0.5 and 0.18) with the hidden effects of each case, written here independently of
physics.effects, and log-normal noise; every data set carries the same condition columns
(humidity, temperature, cycle, vibration, a 0/1 coating flag) whatever is hidden in it. Per case
and seed it calibrates (``mu_pivot`` and ``adhesion_energy_J_m2`` fitted) and records: whether
the terms added are the hidden ones (by effect name and driver, or drifting parameter and driver),
the nested after-error over the noise floor (outlier rows left out when there are outliers),
the coverage of the 95 % prediction intervals on 400 fresh measurements of the same bearing (no
outliers), and the run time. Clean cases count false discoveries (any term added).

The timing builds CSV text of N measurements with a hidden humidity meniscus and 2 % noise and
times parsing and :func:`calibrate.calibrate` stage by stage (:data:`calibrate.report.PROGRESS_STAGES`),
and, side by side in the same run, one least-squares fit of the declared model on the same rows.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

# Run as a script, this file's folder comes first on sys.path; the repository root must
# come instead so that the packages it measures are found.
_REPO = Path(__file__).resolve().parent.parent
if Path(sys.path[0]).resolve() == Path(__file__).resolve().parent:
    sys.path[0] = str(_REPO)

import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

from microbearing import physics  # noqa: E402
from microbearing.calibrate import calibrate, parse_csv, parse_rows  # noqa: E402
from microbearing.calibrate.fit import fit  # noqa: E402
from microbearing.calibrate.report import PROGRESS_STAGES  # noqa: E402
from microbearing.calibrate.select import FAMILY_ALPHA, SearchOptions, forward_select  # noqa: E402

FIT = ["mu_pivot", "adhesion_energy_J_m2"]
TRUE = {"mu_pivot": 0.7, "adhesion_energy_J_m2": 0.12}


def _columns(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    return {
        "balls": rng.choice([4, 6, 8, 12], n).astype(float),
        "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
        "speed_m_s": rng.uniform(0.0, 0.15, n),
        "relative_humidity": rng.uniform(0.2, 0.8, n),
        "temperature_C": rng.uniform(20.0, 40.0, n),
        "cycle": rng.integers(0, 5000, n).astype(float),
        "vibration_um": rng.uniform(0.0, 10.0, n),
        "coated": rng.integers(0, 2, n).astype(float),
    }


def _physics(c, **overrides):
    values = {**TRUE, **overrides}
    return physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"], **values).mu


# Hidden mechanisms: (what a calibration must name, mu of the columns). A named effect is
# ("effect", name, driver); a drift ("drift", parameter, driver).
MECHANISMS = {
    "meniscus": (
        ("effect", "humidity_meniscus", "relative_humidity"),
        lambda c, mu: mu + c["balls"] * 2e-5 / (c["load_N"] * np.log(1 / c["relative_humidity"])),
    ),
    "constant_drag": (("effect", "constant_drag", "load_N"), lambda c, mu: mu + 2e-4 / c["load_N"]),
    "run_in": (("effect", "run_in", "cycle"), lambda c, mu: mu * (1 + np.exp(-c["cycle"] / 800))),
    "breakaway": (
        ("effect", "stribeck_breakaway", "speed_m_s"),
        lambda c, mu: mu + 0.01 * np.exp(-c["speed_m_s"] / 0.01),
    ),
    "coating_mu_pivot": (
        ("drift", "mu_pivot", "coated"),
        lambda c, mu: _physics(c, mu_pivot=TRUE["mu_pivot"] * np.where(c["coated"] == 1, 0.6, 1.0)),
    ),
    "humid_adhesion": (
        ("drift", "adhesion_energy_J_m2", "relative_humidity"),
        lambda c, mu: _physics(c, adhesion_energy_J_m2=0.05 * (1 + 1.5 / np.log(1 / c["relative_humidity"]))),
    ),
}

# case -> (mechanisms, noise log std, (outlier fraction, factor on mu), declared relative std or None)
CASES = {
    "one effect: meniscus": (["meniscus"], 0.02, (0.0, 1.0), None),
    "one effect: constant drag": (["constant_drag"], 0.02, (0.0, 1.0), None),
    "one effect: run-in": (["run_in"], 0.02, (0.0, 1.0), None),
    "one effect: Stribeck breakaway": (["breakaway"], 0.02, (0.0, 1.0), None),
    "two effects: meniscus + constant drag": (["meniscus", "constant_drag"], 0.02, (0.0, 1.0), None),
    "drift: mu_pivot with coating": (["coating_mu_pivot"], 0.02, (0.0, 1.0), None),
    "drift: adhesion with humidity (Kelvin)": (["humid_adhesion"], 0.02, (0.0, 1.0), None),
    "5 % outliers (x5): meniscus": (["meniscus"], 0.02, (0.05, 5.0), None),
    "10 % outliers (x5): meniscus": (["meniscus"], 0.02, (0.10, 5.0), None),
    "scatter 11 % over 3 % declared": ([], 0.11, (0.0, 1.0), 0.03),
    # Outlier cases the selection was not tuned on: another effect, a milder factor, low outliers.
    "8 % outliers (x3): constant drag": (["constant_drag"], 0.02, (0.08, 3.0), None),
    "10 % outliers (x0.3): run-in": (["run_in"], 0.02, (0.10, 0.3), None),
    "7 % outliers (x5): meniscus + drag": (["meniscus", "constant_drag"], 0.02, (0.07, 5.0), None),
}
CLEAN = {"clean, 1 % noise": 0.01, "clean, 3 % noise": 0.03}
# Data with nothing to find for the family-wise error of one selection step: name -> (noise log std,
# (outlier fraction, factor on mu)); seeds from 1000 (the suite's clean cases use 100-139).
NULL = {"null, 2 % noise": (0.02, (0.0, 1.0)), "null, 2 % noise, 5 % outliers (x5)": (0.02, (0.05, 5.0))}
# The selection's least paired z (forward_select's default), below the family-wise thresholds.
Z_THRESHOLD = 3.0


def measurements(mechanisms, noise, outliers, declared, seed, n=200):
    """Rows of measurements and the true mu, and a fresh set of 400 clean ones for the intervals."""
    rng = np.random.default_rng(seed)
    c = _columns(rng, n + 400)
    mu = _physics(c)
    for name in mechanisms:
        mu = MECHANISMS[name][1](c, mu)
    measured = mu * np.exp(rng.normal(0.0, noise, mu.size))
    fit_rows = np.arange(n)
    fraction, factor = outliers
    bad = rng.choice(n, round(fraction * n), replace=False)
    measured[bad] *= factor
    rows = [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(measured[i])} for i in fit_rows]
    if declared is not None:
        for row in rows:
            row["mu_measured_std"] = declared * row["mu_measured"]
    fresh = {k: v[n:] for k, v in c.items()}
    return rows, fresh, measured[n:]


def named_right(result, mechanisms) -> bool:
    """Whether the terms added are the hidden mechanisms (effect and driver, or parameter and driver)."""
    found = set()
    for e in result.effects:
        if e["kind"] == "drift":
            found.add(("drift", e["parameter"], e["drivers"][0]))
        else:
            found.add(("effect", e["name"], e["drivers"][0]))
    return found == {MECHANISMS[m][0] for m in mechanisms}


def run_case(mechanisms, noise, outliers, declared, seed, folds):
    rows, fresh, fresh_measured = measurements(mechanisms, noise, outliers, declared, seed)
    start = time.perf_counter()
    result = calibrate(rows, FIT, folds=folds, make_plots=False, seed=seed)
    seconds = time.perf_counter() - start
    prediction = result.model.predict({k: v for k, v in fresh.items()})
    coverage = float(
        np.mean((prediction.mu_lower <= fresh_measured) & (fresh_measured <= prediction.mu_upper))
    )
    after = result.robust_errors["after"] if outliers[0] else result.error_after
    return {
        "right": named_right(result, mechanisms),
        "terms": [e["label"] for e in result.effects],
        "after_over_noise": after["relative_rmse"] / noise,
        "coverage": coverage,
        "seconds": seconds,
        "outliers": result.outliers["count"],
        "noise": result.noise,
    }


def suite(
    seeds: int,
    clean_seeds: int,
    folds: int,
    part: str,
    cases: slice = slice(None),
    distinct_clean: bool = False,
) -> None:
    print(
        f"synthetic suite: 200 rows, {folds}-fold nested CV, fit {', '.join(FIT)}; coverage on 400 fresh rows"
    )
    print(
        f"{'case':42s} {'runs':>4s} {'named right':>11s} {'after/noise mean (max)':>22s} "
        f"{'95 % coverage mean [min, max]':>29s} {'time s':>7s}"
    )

    def line(name, records, extra=""):
        ratio = [r["after_over_noise"] for r in records]
        cover = [r["coverage"] for r in records]
        right = sum(r["right"] for r in records)
        print(
            f"{name:42s} {len(records):4d} {right:7d}/{len(records):<3d} {np.mean(ratio):13.2f} "
            f"({max(ratio):.2f}) {np.mean(cover):16.3f} [{min(cover):.3f}, {max(cover):.3f}] "
            f"{np.mean([r['seconds'] for r in records]):7.1f}"
            f"{extra}",
            flush=True,
        )

    chosen = list(CASES.items())[cases] if part != "clean" else []
    for name, (mechanisms, noise, outliers, declared) in chosen:
        records = [run_case(mechanisms, noise, outliers, declared, seed, folds) for seed in range(seeds)]
        extra = ""
        wrong = [r["terms"] for r in records if not r["right"]]
        if wrong:
            extra += f"  wrong: {wrong}"
        if outliers[0]:
            extra += f"  outliers flagged: {[r['outliers'] for r in records]}"
        if declared is not None:
            p_values = ", ".join(f"{r['noise']['chi2_p_value']:.2g}" for r in records)
            extra += f"  chi-square p: [{p_values}]; {records[0]['noise']['statement']}"
        line(name, records, extra)
    if part == "effects":
        return
    false = 0
    for level, (name, noise) in list(enumerate(CLEAN.items()))[cases]:
        # By default every noise level draws the same seeds (the same data, the noise scaled); distinct
        # seeds make the levels independent data sets.
        first = 100 + (level * clean_seeds if distinct_clean else 0)
        records = [run_case([], noise, (0.0, 1.0), None, first + seed, folds) for seed in range(clean_seeds)]
        found = [r["terms"] for r in records if r["terms"]]
        false += len(found)
        line(name, records, f"  false discoveries: {len(found)}{' ' + str(found) if found else ''}")
    runs = clean_seeds * len(list(CLEAN)[cases])
    print(f"false discoveries on clean data: {false} in {runs} runs (target 0)")


def family_error(null_seeds: int, folds: int) -> None:
    """First selection step on data with nothing to find: its best held-out paired z against the
    max-T threshold it used and against the Bonferroni bound over the same candidates."""
    print(f"family-wise error: first selection step on 200 rows, {folds} folds, fit {', '.join(FIT)}")
    print(f"{'case':36s} {'runs':>4s} {'z > max-T':>9s} {'z > Bonferroni':>14s} "
          f"{'best z 50/90/99 % (max)':>25s} {'max-T mean [min, max]':>22s} {'Bonferroni':>10s}")
    for level, (name, (noise, outliers)) in enumerate(NULL.items()):
        best, needed, bonferroni = [], [], []
        for seed in range(1000 * (level + 1), 1000 * (level + 1) + null_seeds):
            rows, _, _ = measurements([], noise, outliers, None, seed)
            options = SearchOptions(Z_THRESHOLD, max_terms=1)
            step = forward_select(parse_rows(rows), FIT, folds, seed, options).steps[0]
            best.append(max(c.z for c in step.ranked if c.joint))
            needed.append(step.z_needed)
            bonferroni.append(max(Z_THRESHOLD, float(stats.norm.isf(FAMILY_ALPHA / len(step.ranked)))))
        best, needed, bonferroni = map(np.asarray, (best, needed, bonferroni))
        quantiles = "/".join(f"{q:.2f}" for q in np.quantile(best, [0.5, 0.9, 0.99]))
        passed = int(np.sum(best > needed))
        passed_bonferroni = int(np.sum(best > bonferroni))
        print(f"{name:36s} {len(best):4d} {passed:9d} {passed_bonferroni:14d} {quantiles:>18s} "
              f"({best.max():.2f}) {needed.mean():9.2f} [{needed.min():.2f}, {needed.max():.2f}] "
              f"{bonferroni.mean():10.2f}", flush=True)


# ---------------------------------------------------------------------------------------------------------
# Lab structures (issue 24, items 1-3): several builds, scatter that depends on the speed, conditions that
# move together. Seeds from 2400 (the generators below are this script's own, written from the physics).

LAB_CASES = ["groups: 6 specimens (labels)", "groups: 6 specimens (integer codes declared)",
             "scatter: 10 % below 20 mm/s, 1.5 % above", "scatter: the same, mu_measured_std declared",
             "confounded: temperature with speed, viscosity drifts",
             # Cases added after the method was settled, not used to tune it:
             "groups (not tuned on): 10 batches of 12 rows, adhesion 25 % spread",
             "scatter (not tuned on): 1 % at 3 mN growing to 8 % at 30 mN"]
GAS_CONSTANT = 8.314


def _lab_columns(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    return {
        "balls": rng.choice([4, 6, 8], n).astype(float),
        "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
        "speed_m_s": rng.uniform(0.005, 0.15, n),
        "relative_humidity": rng.uniform(0.2, 0.6, n),
    }


def _mu(c, **values):
    return physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"],
                            **{**TRUE, **values}).mu


def _inside(prediction, measured) -> np.ndarray:
    return (prediction.mu_lower <= measured) & (measured <= prediction.mu_upper)


def lab_groups(seed: int, coded: bool, builds: int = 6, rows: int = 30, spread: float = 0.12,
               noise: float = 0.03, parameter: str = "mu_pivot") -> dict:
    """Builds with their own value of `parameter` (log-normal, `spread` between builds): the spread found,
    coverage of a known build's fresh measurements and of new builds'."""
    rng = np.random.default_rng(seed)
    level = TRUE[parameter] * np.exp(rng.normal(0.0, spread, builds))
    data = []
    for g in range(builds):
        c = _lab_columns(rng, rows)
        mu = _mu(c, **{parameter: level[g]}) * np.exp(rng.normal(0.0, noise, rows))
        label = g + 1 if coded else f"S{g + 1}"
        data += [{k: float(v[i]) for k, v in c.items()} | {"specimen": label, "mu_measured": float(mu[i])}
                 for i in range(rows)]
    dataset = parse_rows(data, factors=["specimen"] if coded else ())
    start = time.perf_counter()
    result = calibrate(dataset, FIT, make_plots=False, seed=seed)
    seconds = time.perf_counter() - start
    known = []
    for g in range(builds):
        c = _lab_columns(rng, 100)
        measured = _mu(c, **{parameter: level[g]}) * np.exp(rng.normal(0.0, noise, 100))
        label = str(g + 1) if coded else f"S{g + 1}"
        known.append(_inside(result.model.predict({**c, "specimen": np.full(100, label)}), measured).mean())
    new = []
    for _ in range(40):
        c = _lab_columns(rng, 50)
        fresh_level = TRUE[parameter] * np.exp(rng.normal(0.0, spread))
        measured = _mu(c, **{parameter: fresh_level}) * np.exp(rng.normal(0.0, noise, 50))
        new.append(_inside(result.model.predict(c), measured).mean())
    group = result.groups[0] if result.groups else None
    return {"terms": [e["label"] for e in result.effects], "seconds": seconds,
            "spread": None if group is None else (group["parameter"], np.log1p(group["spread_relative"]),
                                                  np.log1p(group["spread_interval_relative"])),
            "sample_spread": float(np.std(np.log(level), ddof=1)), "known": float(np.mean(known)),
            "new": float(np.mean(new)), "new_per_build": new,
            "summary": None if group is None else group["summary"]}


def _scatter_noise(c) -> np.ndarray:
    return np.where(c["speed_m_s"] < 0.02, 0.10, 0.015)


def _load_noise(c) -> np.ndarray:
    return 0.01 * (c["load_N"] / 3e-3) ** (np.log(8.0) / np.log(10.0))


def lab_scatter(seed: int, declared: bool, n: int = 200, noise=_scatter_noise,
                region=("speed_m_s", 0.02)) -> dict:
    """A meniscus with scatter 10 % below 20 mm/s and 1.5 % above (or `noise` of the columns): right effect,
    outliers among real rows, coverage below and above the `region` split on fresh measurements."""
    rng = np.random.default_rng(seed)
    c = {**_lab_columns(rng, n + 2000), "temperature_C": rng.uniform(20.0, 40.0, n + 2000)}
    c["speed_m_s"] = rng.uniform(0.001, 0.15, n + 2000)
    mu = MECHANISMS["meniscus"][1](c, _physics(c))
    measured = mu * np.exp(rng.normal(0.0, 1.0, mu.size) * noise(c))
    rows = [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(measured[i])} for i in range(n)]
    if declared:
        for i, row in enumerate(rows):
            row["mu_measured_std"] = float(noise(c)[i] * measured[i])
    start = time.perf_counter()
    result = calibrate(rows, FIT, make_plots=False, seed=seed)
    seconds = time.perf_counter() - start
    fresh = {k: v[n:] for k, v in c.items()}
    prediction = result.model.predict(fresh)
    inside = _inside(prediction, measured[n:])
    low = fresh[region[0]] < region[1]
    # Median log width of the 95 % intervals per region, and the generating truth's (2 x 1.96 x its scatter).
    width = np.log(prediction.mu_upper / prediction.mu_lower)
    truth = 2.0 * float(stats.norm.isf(0.025)) * noise(fresh)
    # Coverage in each third of the fresh points ordered by the region's column.
    thirds = np.array_split(np.argsort(fresh[region[0]]), 3)
    return {"right": named_right(result, ["meniscus"]), "terms": [e["label"] for e in result.effects],
            "seconds": seconds, "outliers": result.outliers["count"],
            "low": float(inside[low].mean()), "high": float(inside[~low].mean()),
            "widths": [float(np.median(width[low])), float(np.median(width[~low]))],
            "truth_widths": [float(np.median(truth[low])), float(np.median(truth[~low]))],
            "thirds": [float(inside[t].mean()) for t in thirds],
            "summary": result.scatter["summary"]}


def _viscosity(temperature_C, activation_J_mol=26e3, reference_C=25.0, level=0.01):
    kelvin = np.asarray(temperature_C) + 273.15
    return level * np.exp(activation_J_mol / GAS_CONSTANT * (1.0 / kelvin - 1.0 / (reference_C + 273.15)))


def lab_confounded(seed: int, n: int = 200) -> dict:
    """Temperature rising with speed (r ~ 0.998) and a viscosity falling with temperature: the words, the
    share of ordinary points (drawn like the data) flagged, and a point far from every row (10 mm/s,
    70 degC)."""
    rng = np.random.default_rng(seed)

    def draw(m, speed=None, temperature=None):
        c = _lab_columns(rng, m)
        if speed is not None:
            c["speed_m_s"] = np.full(m, speed)
        c["temperature_C"] = (25.0 + 50.0 * (c["speed_m_s"] - 0.005) / 0.145 + rng.normal(0.0, 1.0, m)
                              if temperature is None else np.full(m, temperature))
        mu = _mu(c, viscosity_Pa_s=_viscosity(c["temperature_C"]))
        return c, mu * np.exp(rng.normal(0.0, 0.03, m))

    c, measured = draw(n)
    rho = float(np.corrcoef(c["speed_m_s"], c["temperature_C"])[0, 1])
    rows = [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(measured[i])} for i in range(n)]
    start = time.perf_counter()
    result = calibrate(rows, FIT, make_plots=False, seed=seed)
    seconds = time.perf_counter() - start
    like, like_measured = draw(2000)
    ordinary = result.model.predict(like)
    far_c, far_measured = draw(400, speed=0.01, temperature=70.0)
    far = result.model.predict(far_c)
    near_c, near_measured = draw(400, speed=0.01, temperature=None)
    near = result.model.predict(near_c)
    # Points not tuned on: the other empty corner (fast and cool), and one between the data and the far point.
    others = {name: draw(400, speed=v, temperature=t) for name, v, t in
              (("140 mm/s, 27 degC", 0.14, 27.0), ("40 mm/s, 60 degC", 0.04, 60.0))}
    # Side by side: the same model without its rivals by confounding (the interval before them).
    confounded = {r["label"] for r in result.rivals if "moves with" in r["statement"]}
    alone = replace(result.model, rivals=[r for r in result.model.rivals if r.label not in confounded])

    def width(p):
        return float(np.median(np.log(p.mu_upper / p.mu_lower)))

    def figures(model):
        ordinary_ = model.predict(like)
        out = {"ordinary": (float(_inside(ordinary_, like_measured).mean()), width(ordinary_)),
               "10 mm/s, 70 degC": (float(_inside(model.predict(far_c), far_measured).mean()),
                                    width(model.predict(far_c)))}
        for name, (c_, m_) in others.items():
            p = model.predict(c_)
            out[name] = (float(_inside(p, m_).mean()), width(p))
        return out

    words = " | ".join(result.confounding)
    return {"terms": [e["label"] for e in result.effects], "seconds": seconds, "r": rho,
            "named_both": "speed_m_s" in words and "temperature_C" in words,
            "ordinary_flagged": float(1 - ordinary.in_domain.mean()),
            "ordinary_coverage": float(_inside(ordinary, like_measured).mean()),
            "far_flagged": float(1 - far.in_domain.mean()),
            "far_coverage": float(_inside(far, far_measured).mean()),
            "near_coverage": float(_inside(near, near_measured).mean()),
            "width_ratio": float(np.median(np.log(far.mu_upper / far.mu_lower))
                                 / np.median(np.log(near.mu_upper / near.mu_lower))),
            "others_flagged": {k: float(1 - result.model.predict(c_).in_domain.mean()) for k, (c_, _) in
                               others.items()},
            "rivals": [r.label for r in result.model.rivals],
            "with": figures(result.model), "without": figures(alone),
            "summary": result.confounding[0] if result.confounding else "(nothing said)"}


def lab_suite(seeds: int, cases: slice, first_seed: int | None = None) -> None:
    """The lab-structure cases, several seeds each: figures per seed, then the range over seeds. Case k's
    seeds start at 2400 + 10 k, or at ``first_seed`` for every case."""
    print(f"lab structures (issue 24, items 1-3): fit {', '.join(FIT)}; seeds from "
          f"{2400 if first_seed is None else first_seed}")
    for index, name in list(enumerate(LAB_CASES))[cases]:
        print(f"\n{name}", flush=True)
        start = 2400 + 10 * index if first_seed is None else first_seed
        for seed in range(start, start + seeds):
            if index in (0, 1, 5):
                r = (lab_groups(seed, coded=index == 1) if index != 5 else
                     lab_groups(seed, False, builds=10, rows=12, spread=0.25,
                                parameter="adhesion_energy_J_m2"))
                parameter, spread, (lo, hi) = r["spread"] if r["spread"] else ("-", np.nan, (np.nan, np.nan))
                print(f"  seed {seed}: terms {r['terms']}; spread of log {parameter} {spread:.3f} "
                      f"[{lo:.3f}, {hi:.3f}] "
                      f"(true {0.25 if index == 5 else 0.12}, this draw's builds {r['sample_spread']:.3f}); "
                      f"coverage known build "
                      f"{r['known']:.3f}, new build {r['new']:.3f} (per build {min(r['new_per_build']):.2f}-"
                      f"{max(r['new_per_build']):.2f}); {r['seconds']:.1f} s", flush=True)
                if seed == start:
                    print(f"    said: {r['summary']}")
            elif index in (2, 3, 6):
                r = (lab_scatter(seed, declared=index == 3) if index != 6 else
                     lab_scatter(seed, False, noise=_load_noise, region=("load_N", 0.01)))
                where = "10 mN" if index == 6 else "20 mm/s"
                print(f"  seed {seed}: named right {r['right']} {r['terms']}; outliers {r['outliers']}; "
                      f"coverage below {where} {r['low']:.3f}, above {r['high']:.3f}; median log width "
                      f"{r['widths'][0]:.4f}, {r['widths'][1]:.4f} (the truth's {r['truth_widths'][0]:.4f}, "
                      f"{r['truth_widths'][1]:.4f}); by thirds of {'load_N' if index == 6 else 'speed_m_s'} "
                      f"{', '.join(f'{v:.3f}' for v in r['thirds'])}; {r['seconds']:.1f} s", flush=True)
                print(f"    said: {r['summary']}")
            else:
                r = lab_confounded(seed)
                print(f"  seed {seed}: r = {r['r']:.4f}; terms {r['terms']}; named both {r['named_both']}; "
                      f"ordinary points flagged {r['ordinary_flagged']:.3f} (coverage "
                      f"{r['ordinary_coverage']:.3f}); at 10 mm/s, 70 degC flagged {r['far_flagged']:.2f}, "
                      f"coverage {r['far_coverage']:.3f}, width x{r['width_ratio']:.2f} of 10 mm/s on the "
                      f"data (coverage there {r['near_coverage']:.3f}); "
                      f"{r['seconds']:.1f} s", flush=True)
                print(f"    rivals {r['rivals']}; flagged " + ", ".join(
                    f"{k} {v:.2f}" for k, v in r["others_flagged"].items()))
                for name in r["with"]:
                    (c1, w1), (c0, w0) = r["with"][name], r["without"][name]
                    print(f"    {name:>18}: coverage {c1:.3f} (without the rivals by confounding {c0:.3f}), "
                          f"width {w1:.3f} ({w0:.3f}) log")
                if seed == start:
                    print(f"    said: {r['summary']}")


# ---------------------------------------------------------------------------------------------------------
# The selection weighted by the scatter (issue 24, item 2's "weight the fit by it" in the search): forward
# selection alone, unweighted (scatter_rounds=1) and weighted, on data whose scatter grows 40-fold with the
# load (0.5 % at 3 mN to 20 % at 30 mN): a small constant drag (4 uN: 2 % of mu at 3 mN) that acts where the
# scatter is smallest, and the same data with nothing to find. Seeds from 2500.

def _weighted_rows(seed: int, drag_N: float, n: int = 200):
    rng = np.random.default_rng(seed)
    c = {**_lab_columns(rng, n), "temperature_C": rng.uniform(20.0, 40.0, n)}
    mu = _physics(c) + drag_N / c["load_N"]
    spread = 0.005 * (c["load_N"] / 3e-3) ** np.log10(40.0)
    measured = mu * np.exp(rng.normal(0.0, 1.0, n) * spread)
    return parse_rows([{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(measured[i])}
                       for i in range(n)])


def weighted_suite(seeds: int) -> None:
    print("selection weighted by the scatter: 200 rows, scatter 0.5 % at 3 mN to 20 % at 30 mN; forward "
          f"selection of terms on {', '.join(FIT)}; seeds from 2500")
    for name, drag in (("constant drag 4 uN (truth: constant_drag on load_N)", 4e-6),
                       ("nothing to find", 0.0)):
        print(f"\n{name}")
        tally = {"unweighted": 0, "weighted": 0}
        for seed in range(2500, 2500 + seeds):
            data = _weighted_rows(seed, drag)
            line = []
            for label, rounds in (("unweighted", 1), ("weighted", None)):
                start = time.perf_counter()
                options = SearchOptions(scatter_rounds=rounds) if rounds else None
                selection = forward_select(data, FIT, seed=seed, options=options)
                terms = [t.label for t in selection.terms]
                right = terms == (["constant_drag on load_N"] if drag else [])
                tally[label] += right
                weights = "" if rounds else (f" (weights: {selection.scatter.summary().split(' (')[0]})"
                                             if selection.scatter is not None else " (weights: none)")
                line.append(f"{label} {terms}{weights} {time.perf_counter() - start:.1f} s")
            print(f"  seed {seed}: " + "; ".join(line), flush=True)
        print(f"  right: unweighted {tally['unweighted']}/{seeds}, weighted {tally['weighted']}/{seeds}")


def confounded_selection(seeds: int) -> None:
    """Lab case 4's data (temperature rising with speed, viscosity falling with temperature by Arrhenius'
    law) at the case's viscosity (0.01 Pa s at 25 degC) and five times it: what the selection names, and
    what a close call names (forward selection and calibrate.decidability.undecided only)."""
    from microbearing.calibrate.decidability import undecided

    print(f"confounded drivers: lab case 4's generator, forward selection on {', '.join(FIT)}; "
          f"seeds from 2440")
    for level in (0.01, 0.05):
        print(f"\nviscosity {level} Pa s at 25 degC")
        for seed in range(2440, 2440 + seeds):
            rng = np.random.default_rng(seed)
            c = _lab_columns(rng, 200)
            c["temperature_C"] = 25.0 + 50.0 * (c["speed_m_s"] - 0.005) / 0.145 + rng.normal(0.0, 1.0, 200)
            mu = _mu(c, viscosity_Pa_s=_viscosity(c["temperature_C"], level=level))
            measured = mu * np.exp(rng.normal(0.0, 0.03, 200))
            data = parse_rows([{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(measured[i])}
                               for i in range(200)])
            selection = forward_select(data, FIT, seed=seed)
            close = [u for u in undecided(data, selection, None, (), FIT, 0.03)
                     if u["kind"] == "near_threshold"]
            said = (f"close call on {' | '.join(close[0]['terms'])} (z = {close[0]['z']:.2f}, "
                    f"{close[0]['z_needed']:.2f} needed)" if close else "no close call")
            print(f"  seed {seed}: chose {[t.label for t in selection.terms]}; {said}", flush=True)


def synthetic_csv(n: int, seed: int = 0, groups: int = 0, load_scatter: bool = False) -> str:
    """CSV text of n measurements with a hidden humidity effect and 2 % log-normal noise; with ``groups``, a
    factor column ``specimen`` of that many labels drawn at random (no effect of its own); with
    ``load_scatter``, noise added where lab case 6's scatter (1 % at 3 mN to 8 % at 30 mN) exceeds the 2 %:
    2 % up to about 7 mN, growing to 8 % at 30 mN."""
    rows, _, _ = measurements(["meniscus"], 0.02, (0.0, 1.0), None, seed, n)
    if load_scatter:
        rng = np.random.default_rng(seed + 2)
        for row in rows:
            # A fresh log-normal factor of the spread the load's scatter has beyond the 2 % already drawn.
            extra = np.sqrt(max(_load_noise(row)**2 - 0.02**2, 0.0))
            row["mu_measured"] *= float(np.exp(rng.normal(0.0, extra))) if extra > 0 else 1.0
    lines = [",".join(rows[0]) + (",specimen" if groups else "")]
    labels = np.random.default_rng(seed + 1).integers(1, groups + 1, n) if groups else None
    lines += [",".join(f"{v:.9g}" for v in row.values()) + (f",B{labels[i]}" if groups else "")
              for i, row in enumerate(rows)]
    return "\n".join(lines) + "\n"


def _timed_parts() -> dict[str, float]:
    """Wrap the parts of the last stage that issue 24 added (scatter model, groups, data cloud, confounded
    columns) with timers; the dict fills as they run."""
    from microbearing.calibrate import report

    spent: dict[str, float] = {}

    def timed(name, fn):
        def wrapper(*args, **kwargs):
            start = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                spent[name] = spent.get(name, 0.0) + time.perf_counter() - start
        return wrapper

    report.fit_scatter = timed("scatter model", report.fit_scatter)
    report._group_effects = timed("groups", report._group_effects)
    report.DataCloud.from_columns = timed("data cloud", report.DataCloud.from_columns)
    report.confounded_pairs = timed("confounded columns", report.confounded_pairs)
    return spent


def timing(n_rows: int, folds: int, plots: str | None, groups: int = 0, load_scatter: bool = False,
           unweighted_beside: bool = False) -> None:
    text = synthetic_csv(n_rows, groups=groups, load_scatter=load_scatter)
    if unweighted_beside:
        # The procedure before the weighted selection, timed first in the same run so that the machine's
        # load touches both alike: one unweighted search (scatter_rounds=1) and the ranking fits' former
        # tolerance (1e-4; calibrate/fit.py's private _TOLERANCE, restored after).
        from microbearing.calibrate import fit as fit_module

        dataset = parse_csv(text)
        tolerance = fit_module._TOLERANCE[False]
        fit_module._TOLERANCE[False] = 1e-4
        try:
            begin = time.perf_counter()
            plain = calibrate(dataset, FIT, folds=folds, scatter_rounds=1)
            seconds = time.perf_counter() - begin
            print(f"before (unweighted selection, ranking fits at 1e-4): {seconds:7.2f} s; "
                  f"terms {[e['label'] for e in plain.effects]}")
        finally:
            fit_module._TOLERANCE[False] = tolerance
    spent = _timed_parts()
    start = time.perf_counter()
    dataset = parse_csv(text)
    parsed = time.perf_counter()
    reports: list[tuple[float, float]] = []
    result = calibrate(dataset, FIT, folds=folds, progress=lambda f: reports.append((f, time.perf_counter())))
    done = time.perf_counter()
    fit(dataset, FIT)
    one_fit = time.perf_counter() - done
    total = done - start
    print(f"rows: {n_rows:,}  folds: {folds}  fit: {', '.join(FIT)}"
          + (f"  factor: specimen, {groups} labels" if groups else "")
          + ("  scatter 2 % up to 7 mN, 8 % at 30 mN" if load_scatter else ""))
    print(f"parse CSV:                    {parsed - start:7.2f} s")
    previous = parsed
    for name, end in PROGRESS_STAGES.items():
        # A stage ends at the first report of its end fraction (the last stage at the return).
        finished = done if end >= 1.0 else next(t for f, t in reports if f >= end - 1e-12)
        print(f"{name + ':':<29} {finished - previous:7.2f} s")
        previous = finished
    print(f"total:                        {total:7.2f} s  (target <= 60 s; issue 24: <= 30 s)")
    print("  of the last stage, issue 24's parts: "
          + ", ".join(f"{name} {seconds:.2f} s" for name, seconds in spent.items())
          + f" (sum {sum(spent.values()):.2f} s)")
    print(f"one declared fit:             {one_fit:7.2f} s  -> calibration / one fit = {total / one_fit:.0f}")
    print(f"terms: {[e['label'] for e in result.effects]}")
    print(f"stability: {result.effect_stability['summary']}")
    print(f"selection: {result.decision}")
    print(f"scatter: {result.scatter['summary']}")
    for group in result.groups:
        print(f"groups: {group['summary']}")
    print(
        f"held-out relative RMSE of log mu: before {result.error_before['relative_rmse']:.4f}, "
        f"after (nested CV) {result.error_after['relative_rmse']:.4f}, "
        f"after (same folds as the selection) {result.error_after_selection['relative_rmse']:.4f}, "
        f"GP {result.discrepancy_gp['errors']['relative_rmse']:.4f}"
    )
    if plots:
        Path(plots).mkdir(parents=True, exist_ok=True)
        for name, png in result.plots.items():
            (Path(plots) / f"{name}.png").write_bytes(png)
            print(f"wrote {Path(plots) / f'{name}.png'}")


# --- issue 24, items 4-8: honest answers off the data, unit slips, drift levels, undecided data, GP ------

GAS_CONSTANT = 8.314462618


def _kelvin_adhesion(h):
    return 0.05 * (1 + 1.5 / np.log(1 / h))


def humidity_law_data(law: str, seed: int, n: int = 200, rh=(0.2, 0.5), fresh_rh: float = 0.8):
    """Adhesion drifting with humidity by the Kelvin law, or by the linear law through the same values at
    20 and 50 % RH; data at 20-50 % RH, 3 % noise; 400 fresh rows at ``fresh_rh`` and 400 inside."""
    rng = np.random.default_rng(seed)
    c = _columns(rng, n + 800)
    c["relative_humidity"] = np.concatenate([rng.uniform(*rh, n), np.full(400, fresh_rh),
                                             rng.uniform(*rh, 400)])
    h = c["relative_humidity"]
    if law == "kelvin":
        adhesion = _kelvin_adhesion(h)
    else:
        low, high = _kelvin_adhesion(rh[0]), _kelvin_adhesion(rh[1])
        adhesion = low + (high - low) * (h - rh[0]) / (rh[1] - rh[0])
    mu = _physics(c, adhesion_energy_J_m2=adhesion) * np.exp(rng.normal(0.0, 0.03, h.size))
    rows = [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(n)]
    outside = {k: v[n:n + 400] for k, v in c.items()}
    inside = {k: v[n + 400:] for k, v in c.items()}
    return rows, (outside, mu[n:n + 400]), (inside, mu[n + 400:])


def _coverage(prediction, measured) -> float:
    return float(np.mean((prediction.mu_lower <= measured) & (measured <= prediction.mu_upper)))


def honest_extrapolation(seeds: int) -> None:
    """Item 4: coverage of 95 % intervals at 80 % RH (data 20-50 %) whichever law is true, with and
    without the rivals, and the width inside the data."""
    import dataclasses

    print("extrapolated condition: adhesion drifting with humidity, data 20-50 % RH (200 rows, 3 % noise), "
          "400 fresh rows at 80 % RH and 400 inside; fit mu_pivot, adhesion")
    print(f"{'true law':10s} {'seed':>4s} {'named':>8s} {'rivals':>6s} {'cover 80 %':>10s} {'(alone)':>8s} "
          f"{'cover inside':>12s} {'width inside / alone':>20s} {'time s':>6s}")
    for law in ("kelvin", "linear"):
        cover, alone_cover, inside_cover, ratios = [], [], [], []
        for seed in range(seeds):
            rows, (outside, m_out), (inside, m_in) = humidity_law_data(law, 300 + seed)
            start = time.perf_counter()
            result = calibrate(rows, FIT, make_plots=False, seed=seed)
            seconds = time.perf_counter() - start
            alone = dataclasses.replace(result.model, rivals=[])
            p_in, a_in = result.model.predict(inside), alone.predict(inside)
            cover.append(_coverage(result.model.predict(outside), m_out))
            alone_cover.append(_coverage(alone.predict(outside), m_out))
            inside_cover.append(_coverage(p_in, m_in))
            ratios.append(float(np.median(np.log(p_in.mu_upper / p_in.mu_lower)
                                          / np.log(a_in.mu_upper / a_in.mu_lower))))
            named = ",".join(e.get("law", e["name"]) for e in result.effects) or "none"
            print(f"{law:10s} {seed:4d} {named:>8s} {len(result.rivals):6d} {cover[-1]:10.3f} "
                  f"{alone_cover[-1]:8.3f} {inside_cover[-1]:12.3f} {ratios[-1]:20.3f} {seconds:6.1f}",
                  flush=True)
        print(f"{law:10s} mean {'':8s} {'':6s} {np.mean(cover):10.3f} {np.mean(alone_cover):8.3f} "
              f"{np.mean(inside_cover):12.3f} {np.mean(ratios):20.3f}  (cover 80 % min {min(cover):.3f})")


def honest_unit_slips(seeds: int) -> None:
    """Item 5: unit slips refused before any fitting, naming the column; a fitted parameter on its bound."""
    from microbearing.calibrate import DataError

    slips = {"speed in mm/s": ("speed_m_s", 1e3), "load in mN": ("load_N", 1e3),
             "humidity in percent": ("relative_humidity", 1e2),
             "temperature in K under _C": ("temperature_C", None)}
    print("unit slips (200 rows of the suite's clean data with one column in the wrong unit):")
    for name, (column, factor) in slips.items():
        refused, named = 0, 0
        for seed in range(seeds):
            rows, _, _ = measurements([], 0.02, (0.0, 1.0), None, 700 + seed)
            for row in rows:
                row[column] = row[column] + 273.15 if factor is None else row[column] * factor
            try:
                calibrate(rows, FIT, make_plots=False, max_terms=0)
            except DataError as exc:
                refused += 1
                named += any(e["column"] == column for e in exc.errors)
                message = exc.errors[0]["message"]
        print(f"  {name:28s} refused {refused}/{seeds}, column named {named}/{seeds}: {message}")
    finished, on_bound = 0, 0
    for seed in range(seeds):
        rng = np.random.default_rng(800 + seed)
        c = _columns(rng, 60)
        mu = 4 * _physics(c, mu_pivot=10.0) * np.exp(rng.normal(0.0, 0.02, 60))
        rows = [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(60)]
        result = calibrate(rows, ["mu_pivot"], make_plots=False, seed=seed)
        finished += 1
        on_bound += any(w.startswith("mu_pivot ended on a bound") for w in result.warnings)
    print(f"  mu 4x what mu_pivot = 10 gives (60 rows): {finished}/{seeds} calibrations finished, "
          f"{on_bound}/{seeds} report mu_pivot on its bound")


def honest_drift_level(seeds: int) -> None:
    """Item 6: viscosity ten times the default thinning with temperature (26 kJ/mol), mu_pivot fitted."""
    print("drift with its level: viscosity 1e-2 Pa s at 40 degC, Arrhenius 26 kJ/mol, 20-60 degC, 200 rows, "
          "2 % noise, fit mu_pivot only")
    print(f"{'seed':>4s} {'terms':60s} {'E_a kJ/mol (std)':>18s} {'level/true':>10s} {'after/noise':>11s} "
          f"{'truth err/noise':>15s}")
    for seed in range(seeds):
        rng = np.random.default_rng(900 + seed)
        c = _columns(rng, 600)
        c["temperature_C"] = rng.uniform(20.0, 60.0, 600)
        eta = 1e-2 * np.exp(26e3 / GAS_CONSTANT * (1 / (c["temperature_C"] + 273.15) - 1 / 313.15))
        true_mu = physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"],
                                   mu_pivot=0.7, viscosity_Pa_s=eta).mu
        mu = true_mu * np.exp(rng.normal(0.0, 0.02, 600))
        rows = [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(200)]
        result = calibrate(rows, ["mu_pivot"], make_plots=False, seed=seed)
        fresh = {k: v[200:] for k, v in c.items()}
        truth_error = float(np.sqrt(np.mean(np.log(result.model(fresh) / true_mu[200:]) ** 2)))
        drift = [e for e in result.effects if e["name"] == "viscosity_Pa_s~arrhenius"]
        if drift:
            e = drift[0]
            t_ref = e["constants"]["reference"]
            level = 1e-2 * np.exp(26e3 / GAS_CONSTANT * (1 / t_ref - 1 / 313.15))
            ea = (f"{e['parameters']['activation_energy_J_mol'] / 1e3:.1f} "
                  f"({e['parameter_std']['activation_energy_J_mol'] / 1e3:.1f})")
            ratio = f"{e['parameters'].get('viscosity_Pa_s_ref', float('nan')) / level:.3f}"
        else:
            ea, ratio = "-", "-"
        print(f"{seed:4d} {' + '.join(x['label'] for x in result.effects):60s} {ea:>18s} {ratio:>10s} "
              f"{result.error_after['relative_rmse'] / 0.02:11.2f} {truth_error / 0.02:15.2f}", flush=True)


def run_in_rows(seed: int, n: int):
    rng = np.random.default_rng(seed)
    c = _columns(rng, n)
    mu = MECHANISMS["run_in"][1](c, _physics(c)) * np.exp(rng.normal(0.0, 0.02, n))
    return [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(n)]


def honest_undecided(seeds: int, clean_seeds: int) -> None:
    """Item 7: a run-in in 24 rows (found, said undecided with where, or silent); clean data (false alarms);
    item 8: the GP in the model."""
    print("undecided: run-in (x2 at the start, 1/e over 800 cycles) in 24 rows, 2 % noise, fit mu_pivot, "
          "adhesion")
    found = said = silent = 0
    for seed in range(seeds):
        result = calibrate(run_in_rows(1000 + seed, 24), FIT, make_plots=False, seed=seed)
        named = [e["name"] for e in result.effects]
        near = [u for u in result.undecided
                if u["kind"] == "near_threshold" and "run_in on cycle" in u["terms"]]
        if "run_in" in named:
            found += 1
            barely = any(u["kind"] == "barely_chosen" for u in result.undecided)
            what = "found" + (" (barely: said)" if barely else "")
        elif near:
            said += 1
            u = near[0]
            what = (f"said: z {u['z']:.2f} < {u['z_needed']:.2f}, ~{u['rows_to_settle']} rows, "
                    f"where {u['where']['range']}")
        else:
            silent += 1
            what = f"silent; terms {named}"
        print(f"  seed {seed}: {what}", flush=True)
    print(f"  run-in found {found}/{seeds}, not found but said undecided {said}/{seeds}, "
          f"silent {silent}/{seeds}")
    alarms, gp_in = [], 0
    for seed in range(clean_seeds):
        rows, _, _ = measurements([], 0.02, (0.0, 1.0), None, 1100 + seed)
        result = calibrate(rows, FIT, make_plots=False, seed=seed)
        alarms += [(seed, u["kind"], u["terms"]) for u in result.undecided]
        gp_in += bool(result.discrepancy_gp["in_model"])
        if result.effects:
            alarms.append((seed, "false discovery", [e["label"] for e in result.effects]))
    print(f"  clean data (200 rows, 2 % noise): {len(alarms)} undecided item(s) or terms in {clean_seeds} "
          f"runs {alarms}; GP in the model {gp_in}/{clean_seeds}")


def honest(seeds: int, clean_seeds: int, which: str) -> None:
    parts = {"extrapolation": lambda: honest_extrapolation(seeds), "slips": lambda: honest_unit_slips(seeds),
             "level": lambda: honest_drift_level(seeds),
             "undecided": lambda: honest_undecided(seeds, clean_seeds)}
    for name, run in parts.items():
        if which in ("all", name):
            run()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--suite", action="store_true", help="run the synthetic suite instead of the timing")
    parser.add_argument("--seeds", type=int, default=5, help="seeds per case of the suite")
    parser.add_argument("--clean-seeds", type=int, default=20, help="seeds per clean case (two cases)")
    parser.add_argument("--distinct-clean-seeds", action="store_true",
                        help="give each clean noise level its own seeds (independent data sets)")
    parser.add_argument("--honest", choices=["all", "extrapolation", "slips", "level", "undecided"],
                        help="issue 24 items 4-8 instead (--seeds per case, --clean-seeds clean runs)")
    parser.add_argument("--part",
                        choices=["all", "effects", "clean", "null", "lab", "weighted", "confounded"],
                        default="all",
                        help="run only the cases with effects, or only the clean ones; or (null) the "
                             "family-wise error of one selection step on data with nothing to find; or "
                             "(weighted) the selection unweighted and weighted on load-dependent scatter; "
                             "or (confounded) what the selection names on lab case 4's confounded drivers")
    parser.add_argument("--null-seeds", type=int, default=100, help="data sets per null case (--part null)")
    parser.add_argument("--cases", default=":", help="a Python slice of the part's cases, e.g. 0:5")
    parser.add_argument("--first-seed", type=int,
                        help="lab part: every case's seeds start here (default: 2400 + 10 x the case)")
    parser.add_argument("--rows", type=int, default=10_000)
    parser.add_argument("--folds", type=int, default=5)
    parser.add_argument("--plots", metavar="DIR", help="also write the timing run's plots (PNG) into DIR")
    parser.add_argument("--groups", type=int, default=0,
                        help="timing: add a factor column of this many labels (its spread is fitted)")
    parser.add_argument("--load-scatter", action="store_true",
                        help="timing: noise growing with the load (2 %% to 8 %%), the selection weighted")
    parser.add_argument("--unweighted-beside", action="store_true",
                        help="timing: first time the same calibration as before the weighted selection")
    args = parser.parse_args()
    if args.honest:
        honest(args.seeds, args.clean_seeds, args.honest)
    elif args.suite and args.part == "null":
        family_error(args.null_seeds, args.folds)
    elif args.suite and args.part == "confounded":
        confounded_selection(args.seeds)
    elif args.suite and args.part == "weighted":
        weighted_suite(args.seeds)
    elif args.suite and args.part == "lab":
        start, _, stop = args.cases.partition(":")
        lab_suite(args.seeds, slice(int(start) if start else None, int(stop) if stop else None),
                  args.first_seed)
    elif args.suite:
        start, _, stop = args.cases.partition(":")
        suite(args.seeds, args.clean_seeds, args.folds, args.part,
              slice(int(start) if start else None, int(stop) if stop else None), args.distinct_clean_seeds)
    else:
        timing(args.rows, args.folds, args.plots, args.groups, args.load_scatter, args.unweighted_beside)


if __name__ == "__main__":
    main()
