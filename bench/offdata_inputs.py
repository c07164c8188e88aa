"""Off the data in any physics input (issue 33, item 7, beyond speed): load, balls, speed, groove angle.

Run: ``python bench/offdata_inputs.py --input load 0 1 2`` (seeds); ``--control``: the physics alone (no
departure); ``--amplitude A``: the departure's size where the input's truth has one (load_edge, groove).

Each seed draws 110 rows from the physics (mu_pivot 0.65, 3 % scatter; balls 4/6/8, load 3-30 mN,
speed 50-300 mm/s) with one input drawn in a band only, times a departure in that input, calibrates
``mu_pivot``, and counts how many of 200 fresh measurements (the truth with fresh scatter; the other columns
drawn as the data) fall inside the 95 % interval inside the data and at each point beyond the band, with the
median log half-width and the share flagged ``in_domain`` false:

- ``load``: 2-10 mN, truth x (1 + (1 mN / load)^0.5) (an adhesion-dominated rise), at 0.5 and 30 mN;
- ``load_edge``: 2-10 mN, truth x (1 + A exp(-load / 1 mN) + 0.3 (load / 30 mN)^2) (departures that are
  small inside the band: 6.8 % at 2 mN, 3.3 % at 10 mN with A = 0.5), at 0.5 and 30 mN;
- ``balls``: 4-8 balls, truth x (balls / 6)^0.3, at 3 and 12 balls;
- ``speed_high``: 5-50 mm/s, truth x (1 + 0.3 (speed / 300 mm/s)^1.5) (a hydrodynamic-like rise, +2 % at
  50 mm/s), at 300 mm/s;
- ``groove``: groove angle 50-60 deg, truth x (1 + A ((angle - 55 deg) / 20 deg)^2), at 40 and 70 deg.

The low end of speed is ``bench/offdata_speed.py``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

_REPO = Path(__file__).resolve().parent.parent
if Path(sys.path[0]).resolve() == Path(__file__).resolve().parent:
    sys.path[0] = str(_REPO)

import numpy as np  # noqa: E402

from microbearing import physics  # noqa: E402
from microbearing.calibrate import calibrate  # noqa: E402

# input -> (column, the data's band, the points beyond it, the departure's factor (columns, amplitude))
CASES = {
    "load": ("load_N", (2e-3, 10e-3), (0.5e-3, 30e-3), lambda c, a: 1 + (1e-3 / c["load_N"]) ** 0.5),
    "load_edge": ("load_N", (2e-3, 10e-3), (0.5e-3, 30e-3),
                  lambda c, a: 1 + a * np.exp(-c["load_N"] / 1e-3) + 0.3 * (c["load_N"] / 0.03) ** 2),
    "balls": ("balls", (4, 8), (3, 12), lambda c, a: (c["balls"] / 6.0) ** 0.3),
    "speed_high": ("speed_m_s", (0.005, 0.05), (0.3,), lambda c, a: 1 + 0.3 * (c["speed_m_s"] / 0.3) ** 1.5),
    "groove": ("groove_angle_deg", (50.0, 60.0), (40.0, 70.0),
               lambda c, a: 1 + a * ((c["groove_angle_deg"] - 55.0) / 20.0) ** 2),
}


def draw(rng, n: int, case: str, control: bool, amplitude: float, at: float | None = None):
    """n rows with the case's column in its band (or all at ``at``) and their measured mu."""
    name, band, _, factor = CASES[case]
    c = {"balls": rng.choice([4, 6, 8], n).astype(float),
         "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
         "speed_m_s": rng.uniform(0.05, 0.3, n)}
    if name == "groove_angle_deg":
        c[name] = rng.uniform(*band, n)
    elif name == "balls":
        c[name] = rng.integers(band[0], band[1] + 1, n).astype(float)
    else:
        c[name] = np.exp(rng.uniform(np.log(band[0]), np.log(band[1]), n))
    if at is not None:
        c[name] = np.full(n, float(at))
    truth = physics.evaluate(**c, mu_pivot=0.65).mu * (1.0 if control else factor(c, amplitude))
    return c, truth * np.exp(rng.normal(0.0, 0.03, n))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("seeds", nargs="*", type=int, default=[0])
    parser.add_argument("--input", choices=sorted(CASES), default="load")
    parser.add_argument("--control", action="store_true", help="the physics alone, no departure")
    parser.add_argument("--amplitude", type=float, default=0.5, help="A of load_edge and groove")
    args = parser.parse_args(argv)
    name, _, beyond, _ = CASES[args.input]
    for seed in args.seeds:
        rng = np.random.default_rng(seed)
        c, mu = draw(rng, 110, args.input, args.control, args.amplitude)
        rows = [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])}
                for i in range(mu.size)]
        started = time.perf_counter()
        model = calibrate(rows, ["mu_pivot"], make_plots=False).model
        figures = []
        for at in (None, *beyond):
            points, measured = draw(rng, 200, args.input, args.control, args.amplitude, at)
            p = model.predict(points)
            covered = float(np.mean((p.mu_lower <= measured) & (measured <= p.mu_upper)))
            where = "inside" if at is None else f"at {name} {at:g}"
            figures.append(f"{where}: coverage {covered:.3f}, log half-width "
                           f"{float(np.median(np.log(p.mu_upper / p.mu))):.3f}, flagged "
                           f"{float(np.mean(~p.in_domain)):.2f}")
        terms = ", ".join(f"{t.name}({','.join(getattr(t, 'drivers', ()))})"
                          for t, _ in model.terms) or "none"
        print(f"{args.input}{' control' if args.control else ''} seed {seed} "
              f"({time.perf_counter() - started:.0f} s; terms {terms}; rivals {len(model.rivals)}): "
              + "; ".join(figures), flush=True)


if __name__ == "__main__":
    main()
