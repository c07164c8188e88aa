"""Throughput of physics.evaluate against one numpy.power pass, measured side by side.

Run: ``python bench/physics.py [--points N] [--repeats R]``. Prints points per
second and the ratio of the evaluation time to one ``numpy.power`` pass over
arrays of the same size (best of R runs each, interleaved so that both see the
same machine load), for ``physics.evaluate`` returning all 21 outputs and
returning μ alone (``outputs=["mu"]``: the same arithmetic, one array stored).
Target of issue 2: ratio <= 15, goal <= 10.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

# Run as a script, this file's folder comes first on sys.path and its name would
# shadow the package it measures.
if Path(sys.path[0]).resolve() == Path(__file__).resolve().parent:
    sys.path.pop(0)

import numpy as np

import physics


def random_design_points(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """Random designs over a broad domain: every design and operating input varies."""
    rng = np.random.default_rng(seed)
    return {
        "balls": rng.integers(3, 41, n).astype(float),
        "groove_angle_deg": rng.uniform(30.0, 75.0, n),
        "load_N": 10 ** rng.uniform(-3, np.log10(0.05), n),
        "speed_m_s": rng.uniform(0.0, 0.2, n),
        "balls_touching": rng.random(n) < 0.5,
        "mu_pivot": rng.uniform(0.1, 1.0, n),
        "adhesion_energy_J_m2": rng.uniform(0.0, 0.3, n),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--points", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()

    points = random_design_points(args.points)
    base = points["load_N"]
    physics.evaluate(**points)  # warm up
    t_all, t_mu, t_pow = [], [], []
    for _ in range(args.repeats):
        start = time.perf_counter()
        physics.evaluate(**points)
        t_all.append(time.perf_counter() - start)
        start = time.perf_counter()
        physics.evaluate(outputs=["mu"], **points)
        t_mu.append(time.perf_counter() - start)
        start = time.perf_counter()
        np.power(base, 0.47)
        t_pow.append(time.perf_counter() - start)
    best_all, best_mu, best_pow = min(t_all), min(t_mu), min(t_pow)
    print(f"points: {args.points:,}  (7 of 16 inputs varied per point, the rest at defaults)")
    print(f"numpy.power pass:                   {best_pow * 1e3:8.1f} ms")
    for label, best in (("all 21 outputs", best_all), ("mu only (outputs=['mu'])", best_mu)):
        print(f"physics.evaluate, {label:24s} {best * 1e3:8.1f} ms  -> {args.points / best:,.0f} points/s"
              f"  ratio {best / best_pow:.1f}")
    print("target: ratio <= 15, goal <= 10")

if __name__ == "__main__":
    main()
