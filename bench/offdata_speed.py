"""Off the data in a physics input (issue 33, item 7): coverage at 5 mm/s below data at 50-300 mm/s.

Run: ``python bench/offdata_speed.py 0 1 2`` (seeds).

Each seed draws 120 rows from the physics (mu_pivot 0.65, 3 % scatter) with a low-speed breakaway rise
(physics.effects' Stribeck law, excess 0.009 over 5 mm/s: invisible at 50-300 mm/s, +23 % at 5 mm/s),
calibrates ``mu_pivot``, and counts how many of 400 fresh measurements at 5 mm/s and of 400 inside the data
fall inside the 95 % interval, with its median log half-width.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

_REPO = Path(__file__).resolve().parent.parent
if Path(sys.path[0]).resolve() == Path(__file__).resolve().parent:
    sys.path[0] = str(_REPO)

import numpy as np  # noqa: E402

from microbearing import physics  # noqa: E402
from microbearing.calibrate import calibrate  # noqa: E402
from microbearing.physics.effects import EFFECTS  # noqa: E402

STRIBECK = EFFECTS["stribeck_breakaway"]


def truth(c):
    mu = physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"], mu_pivot=0.65).mu
    return STRIBECK.correct(mu, c["speed_m_s"], c, [0.009, 0.005], {})


def draw(rng, n, speed):
    c = {"balls": rng.choice([4, 6, 8], n).astype(float),
         "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
         "speed_m_s": rng.uniform(*speed, n) if isinstance(speed, tuple) else np.full(n, speed)}
    return c, truth(c) * np.exp(rng.normal(0, 0.03, n))


def main(seeds) -> None:
    for seed in seeds:
        rng = np.random.default_rng(seed)
        c, mu = draw(rng, 120, (0.05, 0.3))
        rows = [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])}
                for i in range(mu.size)]
        started = time.perf_counter()
        model = calibrate(rows, ["mu_pivot"], make_plots=False).model
        figures = []
        for speed in (0.005, (0.05, 0.3)):
            points, measured = draw(rng, 400, speed)
            p = model.predict(points)
            covered = float(np.mean((p.mu_lower <= measured) & (measured <= p.mu_upper)))
            figures.append(f"coverage {covered:.3f}, median log half-width "
                           f"{float(np.median(np.log(p.mu_upper / p.mu))):.3f}, flagged "
                           f"{float(np.mean(~p.in_domain)):.2f}")
        print(f"seed {seed} ({time.perf_counter() - started:.0f} s): at 5 mm/s {figures[0]}; inside "
              f"{figures[1]}", flush=True)


if __name__ == "__main__":
    main([int(s) for s in sys.argv[1:]] or [0])
