"""Throughput of physics.evaluate against one numpy.power pass, measured side by side.

Run: ``python bench/physics.py [--points N] [--repeats R]``. Prints points per
second and the ratio of the evaluation time to one ``numpy.power`` pass over
arrays of the same size (best of R runs each, interleaved so that both see the
same machine load), for ``physics.evaluate`` returning all 21 outputs and
returning μ alone (``outputs=["mu"]``: the same arithmetic, one array stored),
each on the threads a large call uses by default (the usable CPUs) and on one
thread (``MICROBEARING_PHYSICS_THREADS=1``). Target of issue 2: ratio <= 15,
goal <= 10.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

# Run as a script, this file's folder comes first on sys.path and its name would
# shadow the package it measures.
if Path(sys.path[0]).resolve() == Path(__file__).resolve().parent:
    sys.path.pop(0)

import numpy as np

import physics

THREADS = physics.bearing.THREADS_VARIABLE


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
    cases = {(outputs, threads): [] for outputs in ("all 21 outputs", "mu only") for threads in ("", "1")}
    t_pow = []
    for _ in range(args.repeats):
        for (outputs, threads), times in cases.items():
            os.environ[THREADS] = threads
            start = time.perf_counter()
            physics.evaluate(outputs=["mu"] if outputs == "mu only" else None, **points)
            times.append(time.perf_counter() - start)
        start = time.perf_counter()
        np.power(base, 0.47)
        t_pow.append(time.perf_counter() - start)
    os.environ.pop(THREADS)
    best_pow = min(t_pow)
    print(f"points: {args.points:,}  (7 of 16 inputs varied per point, the rest at defaults); "
          f"{physics.bearing._threads()} usable CPUs")
    print(f"numpy.power pass:                                   {best_pow * 1e3:8.1f} ms")
    for (outputs, threads), times in cases.items():
        label = f"{outputs}, {'one thread' if threads else 'default threads'}"
        best = min(times)
        print(f"physics.evaluate, {label:32s} {best * 1e3:8.1f} ms  -> {args.points / best:12,.0f} points/s"
              f"  ratio {best / best_pow:5.1f}")
    print("target: ratio <= 15, goal <= 10")


if __name__ == "__main__":
    main()
