"""Wall time of a full calibration of 10,000 measured rows (target of issue 6: within 60 s).

Run: ``python bench/calibrate.py [--rows N] [--folds K]``. Builds CSV text of N
synthetic measurements (physics with shifted parameters, a hidden humidity
meniscus effect and 2 % noise), then times parsing and :func:`calibrate.calibrate`
stage by stage (:data:`calibrate.report.PROGRESS_STAGES`, the nested cross-validation
of the effect search included), and, side by side in the same run, one least-squares fit of the
declared model on the same rows, so the ratio calibration / one fit is
comparable across machine loads.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

# Run as a script, this file's folder comes first on sys.path; the repository root must
# come instead so that the packages it measures are found.
_REPO = Path(__file__).resolve().parent.parent
if Path(sys.path[0]).resolve() == Path(__file__).resolve().parent:
    sys.path[0] = str(_REPO)

import numpy as np  # noqa: E402

import physics  # noqa: E402
from calibrate import calibrate, parse_csv  # noqa: E402
from calibrate.fit import fit  # noqa: E402
from calibrate.report import PROGRESS_STAGES  # noqa: E402


def synthetic_csv(n: int, seed: int = 0) -> str:
    """CSV text of n measurements with a hidden humidity effect and 2 % log-normal noise."""
    rng = np.random.default_rng(seed)
    columns = {
        "balls": rng.choice([4, 6, 8, 12], n).astype(float),
        "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
        "speed_m_s": rng.uniform(0.0, 0.15, n),
        "relative_humidity": rng.uniform(0.2, 0.8, n),
        "temperature_C": rng.uniform(20.0, 40.0, n),
        "cycle": rng.integers(0, 5000, n).astype(float),
    }
    mu = physics.evaluate(balls=columns["balls"], load_N=columns["load_N"], speed_m_s=columns["speed_m_s"],
                          mu_pivot=0.7, adhesion_energy_J_m2=0.12).mu
    mu = mu + columns["balls"] * 2e-5 / (columns["load_N"] * np.log(1.0 / columns["relative_humidity"]))
    columns["mu_measured"] = mu * np.exp(rng.normal(0.0, 0.02, n))
    lines = [",".join(columns)]
    lines += [",".join(f"{columns[k][i]:.9g}" for k in columns) for i in range(n)]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=10_000)
    parser.add_argument("--folds", type=int, default=5)
    parser.add_argument("--plots", metavar="DIR", help="also write the residual plots (PNG) into DIR")
    parser.add_argument("--csv", metavar="FILE", help="also write the synthetic data as CSV")
    args = parser.parse_args()
    fit_parameters = ["mu_pivot", "adhesion_energy_J_m2"]
    text = synthetic_csv(args.rows)
    if args.csv:
        Path(args.csv).write_text(text)

    start = time.perf_counter()
    dataset = parse_csv(text)
    parsed = time.perf_counter()
    reports: list[tuple[float, float]] = []

    def progress(fraction: float) -> None:
        reports.append((fraction, time.perf_counter()))

    result = calibrate(dataset, fit_parameters, folds=args.folds, progress=progress)
    done = time.perf_counter()
    fit(dataset, fit_parameters)
    one_fit = time.perf_counter() - done

    total = done - start
    print(f"rows: {args.rows:,}  folds: {args.folds}  fit: {', '.join(fit_parameters)}")
    print(f"parse CSV:            {parsed - start:7.2f} s")
    previous = parsed
    for name, end in PROGRESS_STAGES.items():
        # A stage ends at the first report of its end fraction (the last stage at the return).
        finished = done if end >= 1.0 else next(t for f, t in reports if f >= end - 1e-12)
        print(f"{name + ':':<21} {finished - previous:7.2f} s")
        previous = finished
    print(f"total:                {total:7.2f} s  (target <= 60 s)")
    print(f"one declared fit:     {one_fit:7.2f} s  -> calibration / one fit = {total / one_fit:.0f}")
    print(f"effect found: {result.missing_effect and result.missing_effect['name']} on "
          f"{result.missing_effect and result.missing_effect['drivers']}")
    print(f"stability: {result.effect_stability['summary']}")
    gp = result.discrepancy_gp["errors"]["relative_rmse"]
    print(f"held-out relative RMSE of log mu: before {result.error_before['relative_rmse']:.4f}, "
          f"after (nested CV) {result.error_after['relative_rmse']:.4f}, "
          f"after (same folds as the selection) {result.error_after_selection['relative_rmse']:.4f}, "
          f"GP {gp:.4f}")
    if args.plots:
        Path(args.plots).mkdir(parents=True, exist_ok=True)
        for name, png in result.plots.items():
            (Path(args.plots) / f"{name}.png").write_bytes(png)
            print(f"wrote {Path(args.plots) / f'{name}.png'}")


if __name__ == "__main__":
    main()
