"""A new group's 95 % interval, data set by data set: how its coverage spreads over many draws.

Run: ``python bench/group_coverage.py [--draws 40] [--groups 4,6,10] [--spreads 0.03,0.05,0.1,0.15,0.25]``.

The calibration's lab suite measures a new build's coverage on a handful of draws, each a whole
calibration. This check works one level down, on what :func:`calibrate.groups.fit_group_effect` sees:
``log(mu_measured / mu_model)`` of G groups, each shifted by its own level ``b_g ~ N(0, spread^2)``, with
10-40 rows a group (uneven) and 3 % scatter within a group. Per draw it fits the spread (REML, as a
calibration does) and computes the coverage of a new group's 95 % interval exactly: a new group's
measurement is ``N(0, spread^2 + 0.03^2)`` about the truth, the interval is centred on the fitted mean
level with half-width ``z sqrt(new-group variance + within-group scatter^2)``, so its coverage in this
draw is ``Phi((h - d) / s) - Phi((-h - d) / s)`` (``d`` the fitted mean's error, ``s`` the new
measurement's standard deviation). Both rules run on the same fits, side by side: the prediction rule
alone (Student's t of G - 1 degrees of freedom, the rule before issue 24's coverage round) and the rule
in use (the wider of it and the Q-profile tolerance rule, :meth:`GroupEffect.new_group_variance`).

Reported per number of groups and spread: the share of draws whose coverage lies in [0.90, 0.98], the
share below 0.90, the mean and median coverage, and the median width of the interval in use over the
prediction rule's.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

_REPO = Path(__file__).resolve().parent.parent
if Path(sys.path[0]).resolve() == Path(__file__).resolve().parent:
    sys.path[0] = str(_REPO)

import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

from microbearing.calibrate.groups import fit_group_effect  # noqa: E402

NOISE = 0.03
Z = float(stats.norm.isf(0.025))


def draw(rng: np.random.Generator, groups: int, spread: float):
    """Labels and log residuals of one data set, and its true mean level (0)."""
    rows = rng.integers(10, 41, groups)
    level = rng.normal(0.0, spread, groups)
    labels = np.repeat([f"G{g}" for g in range(groups)], rows)
    y = np.repeat(level, rows) + rng.normal(0.0, NOISE, int(rows.sum()))
    return labels, y


def coverage(effect, spread: float) -> tuple[float, float]:
    """This draw's coverage of a new group's measurements by the 95 % interval, and its half-width (log)."""
    half = Z * np.sqrt(effect.new_group_variance(0.95) + effect.noise_log**2)
    s = np.sqrt(spread**2 + NOISE**2)
    d = effect.offset_log  # the truth's mean level is 0
    return float(stats.norm.cdf((half - d) / s) - stats.norm.cdf((-half - d) / s)), float(half)


def best_window(groups: int, n: int = 200_000, seed: int = 0) -> float:
    """Largest share of draws in [0.90, 0.98] over every interval ``k * (fitted spread)`` of G groups
    (within-group scatter neglected: the fitted variance is ``spread^2 chi2_{G-1} / (G - 1)``, the fitted
    mean's error ``N(0, spread^2 / G)``, independent)."""
    rng = np.random.default_rng(seed)
    fitted = np.sqrt(rng.chisquare(groups - 1, n) / (groups - 1))
    d = rng.normal(0.0, np.sqrt(1.0 / groups), n)
    best = 0.0
    for k in np.linspace(0.5, 5.0, 181):
        h = k * fitted
        c = stats.norm.cdf(h - d) - stats.norm.cdf(-h - d)
        best = max(best, float(np.mean((c >= 0.9) & (c <= 0.98))))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--draws", type=int, default=40)
    parser.add_argument("--groups", default="4,6,10")
    parser.add_argument("--spreads", default="0.03,0.05,0.1,0.15,0.25")
    parser.add_argument("--seed", type=int, default=5000)
    args = parser.parse_args()
    groups = [int(g) for g in args.groups.split(",")]
    spreads = [float(s) for s in args.spreads.split(",")]
    print(f"new group's 95 % interval per draw: {args.draws} draws per cell, 10-40 rows a group, "
          f"{100 * NOISE:.0f} % within a group; seeds from {args.seed}")
    print(f"{'groups':>6} {'spread':>6} | {'prediction rule (t_{G-1}) alone':^44} | "
          f"{'in use (wider of t and tolerance)':^44} | width")
    print(f"{'':>6} {'':>6} | {'in [.90,.98]':>12} {'< .90':>6} {'mean':>6} {'median':>6} {'min':>6}  "
          f"| {'in [.90,.98]':>12} {'< .90':>6} {'mean':>6} {'median':>6} {'min':>6}  | ratio")
    start = time.perf_counter()
    totals = {"before": [], "after": []}
    for gi, g in enumerate(groups):
        for si, spread in enumerate(spreads):
            rng = np.random.default_rng(args.seed + 1000 * gi + 100 * si)
            before, after, ratio = [], [], []
            for _ in range(args.draws):
                labels, y = draw(rng, g, spread)
                effect = fit_group_effect("specimen", labels, y, {})
                old = dataclasses.replace(effect, group_means=[])  # the prediction rule alone
                c_old, h_old = coverage(old, spread)
                c_new, h_new = coverage(effect, spread)
                before.append(c_old)
                after.append(c_new)
                ratio.append(h_new / h_old)
            totals["before"] += before
            totals["after"] += after

            def cells(c):
                c = np.asarray(c)
                window = np.mean((c >= 0.9) & (c <= 0.98))
                return (f"{window:>12.2f} {np.mean(c < 0.9):>6.2f} {c.mean():>6.3f} "
                        f"{np.median(c):>6.3f} {c.min():>6.3f}")

            print(f"{g:>6} {spread:>6.2f} | {cells(before)}  | {cells(after)}  | x{np.median(ratio):.2f}",
                  flush=True)
    for name, c in totals.items():
        c = np.asarray(c)
        print(f"all {c.size} draws, {name}: in [0.90, 0.98] {np.mean((c >= 0.9) & (c <= 0.98)):.3f}, "
              f"below 0.90 {np.mean(c < 0.9):.3f}, below 0.85 {np.mean(c < 0.85):.3f}, mean {c.mean():.3f}")
    print("the most any rule that scales with the fitted spread can put in [0.90, 0.98] (the spread's "
          "estimate is chi-square distributed; 200,000 draws of the balanced model, the best scale factor):")
    for g in groups:
        print(f"  {g} groups: {best_window(g):.2f}")
    print(f"{time.perf_counter() - start:.1f} s")


if __name__ == "__main__":
    main()
