"""Plans keep their promise (issue 33, item 8): do the runs proposed for ``predict`` shrink the interval the
service reports over the envelope, as much as the proposal says, and more than as many random runs?

Run: ``python bench/plans_promise.py --seeds 4 --runs 16 --labs humidity,temperature``.

Each simulated lab hides an effect of one condition in the physics (written here, independently of
physics.effects): ``humidity``, adhesion growing with the Kelvin radius, first data at 20-40 % RH, the
envelope at 70-85 % RH (``mu_pivot`` and ``adhesion_energy_J_m2`` fitted); ``temperature`` (not tuned on),
the pivot friction rising 1.5 %/degC, first data at 20-35 degC, the envelope at 55-70 degC (``mu_pivot``
fitted). A lab measures 40 first rows (3 % noise), calibrates through the REST API
(``POST /v1/calibrations``), then asks
``POST /v1/calibrations/{id}/next-experiments`` for ``predict`` over the envelope (6 balls, 5-20 mN,
0.05 m/s, the condition beyond the first data), measures the proposed runs from the truth, or as many random
runs over the same space, and calibrates again on all rows. Over 200 envelope points it asks
``POST /v1/friction/batch`` of each recalibration for the 95 % interval and reports:

* the mean half-width the service reports, (mu_upper - mu_lower) / 2 [1], after the proposed and after the
  random runs, and the proposal's ``reported_half_width_after`` (its promise) with the ratio of the two;
* the truth error over the envelope, RMS of log(mu / mu_true);
* the coverage of fresh measurements there.

One draw of the runs' noise decides much of a lab's comparison: after 56 rows the scatter makes up over
90 % of the variance of the reported interval on the temperature labs, and the scatter each recalibration
estimates from its rows moves by about 10 % with the draw, while the runs' places move the parameters'
share of a few per cent. ``--noise-replicates R`` measures each arm's runs R times (the same R draws for
both arms, common random numbers) and reports the means over the draws (R times the recalibrations).
"""

from __future__ import annotations

import argparse
import logging
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

_REPO = Path(__file__).resolve().parent.parent
if Path(sys.path[0]).resolve() == Path(__file__).resolve().parent:
    sys.path[0] = str(_REPO)
sys.path.insert(0, str(_REPO / "tests"))

import numpy as np  # noqa: E402
from fastapi.testclient import TestClient  # noqa: E402
from jobs_helper import finished_job  # noqa: E402

from microbearing import physics  # noqa: E402
from microbearing.service.app import create_app  # noqa: E402
from microbearing.service.settings import Settings  # noqa: E402

NOISE = 0.03
FIRST_ROWS = 40


@dataclass(frozen=True)
class Lab:
    """A simulated lab: the truth hidden in the physics, one condition column, the first data's range of
    it, what the lab can set (``space``) and where the model will be used (``envelope``), beyond the data."""

    name: str
    condition: str
    first: tuple[float, float]
    space: tuple[float, float]
    envelope: tuple[float, float]
    fit: tuple[str, ...]
    truth_parameters: Callable[[np.ndarray], dict[str, np.ndarray]]

    def truth(self, c) -> np.ndarray:
        return physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"],
                                **self.truth_parameters(np.asarray(c[self.condition], dtype=float))).mu

    def space_body(self) -> dict:
        return {"balls": {"low": 4, "high": 8}, "load_N": {"low": 3e-3, "high": 3e-2, "spacing": "log"},
                "speed_m_s": {"low": 0.0, "high": 0.15}, self.condition: {"low": self.space[0],
                                                                         "high": self.space[1]}}

    def envelope_body(self) -> dict:
        return {"balls": [6], "load_N": {"low": 5e-3, "high": 2e-2}, "speed_m_s": [0.05],
                self.condition: {"low": self.envelope[0], "high": self.envelope[1]}}


def kelvin_adhesion(h: np.ndarray) -> dict[str, np.ndarray]:
    """Adhesion growing with the Kelvin radius, 1/ln(1/h), in the physics (mu_pivot 0.7)."""
    return {"mu_pivot": 0.7, "adhesion_energy_J_m2": 0.05 * (1 + 1.5 / np.log(1 / h))}


def warm_pivot(t: np.ndarray) -> dict[str, np.ndarray]:
    """The pivot friction rising 1.5 % per degree Celsius from 0.7 at 25 degC (a softening lubricant
    film); the adhesion at its default."""
    return {"mu_pivot": 0.7 * (1 + 0.015 * (t - 25.0))}


LABS = {
    "humidity": Lab("humidity", "relative_humidity", (0.2, 0.4), (0.2, 0.9), (0.7, 0.85),
                    ("mu_pivot", "adhesion_energy_J_m2"), kelvin_adhesion),
    # not tuned on: a temperature effect on the pivot friction, the envelope at 55-70 degC
    "temperature": Lab("temperature", "temperature_C", (20.0, 35.0), (20.0, 80.0), (55.0, 70.0),
                       ("mu_pivot",), warm_pivot),
}


def first_data(lab: Lab, rng, n: int) -> dict[str, np.ndarray]:
    return {"balls": rng.choice([4, 6, 8], n).astype(float),
            "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
            "speed_m_s": rng.uniform(0.0, 0.15, n), lab.condition: rng.uniform(*lab.first, n)}


def random_runs(lab: Lab, rng, n: int) -> dict[str, np.ndarray]:
    return {"balls": rng.integers(4, 9, n).astype(float),
            "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
            "speed_m_s": rng.uniform(0.0, 0.15, n), lab.condition: rng.uniform(*lab.space, n)}


def envelope_points(lab: Lab, rng, n: int = 200) -> dict[str, np.ndarray]:
    return {"balls": np.full(n, 6.0), "load_N": rng.uniform(5e-3, 2e-2, n), "speed_m_s": np.full(n, 0.05),
            lab.condition: rng.uniform(*lab.envelope, n)}


def measure(lab: Lab, columns, rng) -> list[dict]:
    mu = lab.truth(columns) * np.exp(rng.normal(0.0, NOISE, columns["balls"].size))
    return [{k: float(v[i]) for k, v in columns.items()} | {"mu_measured": float(mu[i])}
            for i in range(mu.size)]


def calibrate(client, lab: Lab, rows) -> str:
    response = client.post("/v1/calibrations", json={"data": rows, "fit_parameters": list(lab.fit)})
    assert response.status_code == 202, response.text
    job = finished_job(client, response.headers["location"], timeout_s=900, interval_s=0.5)
    return client.get(job["result_url"]).json()["model_id"]


def propose(client, model_id: str, body: dict) -> dict:
    calibration = model_id.split(":", 1)[-1]
    response = client.post(f"/v1/calibrations/{calibration}/next-experiments", json=body)
    assert response.status_code == 202, response.text
    job = finished_job(client, response.headers["location"], timeout_s=900, interval_s=0.5)
    return client.get(job["result_url"]).json()


def judge(client, lab: Lab, model_id: str, points, rng) -> dict[str, float]:
    response = client.post("/v1/friction/batch", json={
        "points": {k: v.tolist() for k, v in points.items() if k != lab.condition},
        "conditions": {lab.condition: points[lab.condition].tolist()},
        "model": model_id, "outputs": ["mu"]})
    assert response.status_code == 200, response.text
    body = response.json()
    mu, lower, upper = (np.asarray(body[k], dtype=float) for k in ("mu", "mu_lower", "mu_upper"))
    fresh = lab.truth(points) * np.exp(rng.normal(0.0, NOISE, mu.size))
    return {"half_width": float(np.mean((upper - lower) / 2)),
            "error": float(np.sqrt(np.mean(np.log(mu / lab.truth(points)) ** 2))),
            "coverage": float(np.mean((lower <= fresh) & (fresh <= upper)))}


def columns_of(lab: Lab, runs: list[dict]) -> dict[str, np.ndarray]:
    flat = [{"balls": r["balls"], "load_N": r["load_N"], "speed_m_s": r["speed_m_s"], **r["conditions"]}
            for r in runs]
    return {k: np.array([f[k] for f in flat], dtype=float) for k in lab.space_body()}


def lab_run(client, lab: Lab, seed: int, runs: int, replicates: int = 1) -> dict:
    """One lab: its first calibration and proposal, and each arm's recalibrations judged over the envelope
    (``replicates`` > 1: the mean over that many noise draws of the runs, the same draws for both arms)."""
    rng = np.random.default_rng(seed)
    rows = measure(lab, first_data(lab, rng, FIRST_ROWS), rng)
    first = calibrate(client, lab, rows)
    points = envelope_points(lab, np.random.default_rng(10_000 + seed))
    started = time.perf_counter()
    proposal = propose(client, first, {"runs": runs, "goal": "predict", "space": lab.space_body(),
                                       "envelope": lab.envelope_body(), "seed": seed})
    seconds = time.perf_counter() - started
    measured = np.random.default_rng(30_000 + seed)
    out = {"first": judge(client, lab, first, points, np.random.default_rng(40_000 + seed)),
           "promise": proposal["envelope"]["reported_half_width_after"]["mean"],
           "now": proposal["envelope"]["reported_half_width_now"]["mean"], "seconds": seconds,
           "support": proposal["support_points"]}
    for name, columns in (("proposed", columns_of(lab, proposal["runs"])),
                          ("random", random_runs(lab, np.random.default_rng(20_000 + seed), runs))):
        judged = []
        for k in range(replicates):
            # one draw: the arms draw in turn from one generator (the recorded figures); several: draw k of
            # both arms from one seed (common random numbers), so that they differ by where the runs sit
            noise = measured if replicates == 1 else np.random.default_rng([30_000 + seed, k])
            again = calibrate(client, lab, rows + measure(lab, columns, noise))
            judged.append(judge(client, lab, again, points, np.random.default_rng(40_000 + seed)))
        out[name] = {key: float(np.mean([j[key] for j in judged])) for key in judged[0]}
        out[name]["half_widths"] = [j["half_width"] for j in judged]
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--first-seed", type=int, default=0,
                        help="the first lab's seed (then first-seed + 1, ...)")
    parser.add_argument("--runs", type=int, default=16)
    parser.add_argument("--noise-replicates", type=int, default=1,
                        help="noise draws of each arm's runs (> 1: the same for both arms; means reported)")
    parser.add_argument("--labs", default="humidity,temperature", help="comma-separated: " + ", ".join(LABS))
    args = parser.parse_args(argv)
    logging.disable(logging.INFO)  # the service's access log of every poll
    records = []
    with (tempfile.TemporaryDirectory() as data_dir,
          TestClient(create_app(Settings(data_dir=data_dir))) as client):
        seeds = range(args.first_seed, args.first_seed + args.seeds)
        for name, seed in ((n, k) for n in args.labs.split(",") for k in seeds):
            r = lab_run(client, LABS[name], seed, args.runs, args.noise_replicates)
            records.append(r)
            print(f"{name} lab {seed}: first hw {r['first']['half_width']:.5f} | proposed ({r['support']} "
                  f"points, {r['seconds']:.0f} s) hw {r['proposed']['half_width']:.5f} (promised "
                  f"{r['promise']:.5f}, ratio {r['proposed']['half_width'] / r['promise']:.2f}) err "
                  f"{r['proposed']['error']:.4f} cov {r['proposed']['coverage']:.2f} | random hw "
                  f"{r['random']['half_width']:.5f} err {r['random']['error']:.4f} cov "
                  f"{r['random']['coverage']:.2f}" + ("" if args.noise_replicates == 1 else (
                      " | hw proposed / random per draw " + ", ".join(
                          f"{a / b:.2f}" for a, b in zip(r["proposed"]["half_widths"],
                                                         r["random"]["half_widths"], strict=True)))),
                  flush=True)
    ratio_hw = np.array([r["proposed"]["half_width"] / r["random"]["half_width"] for r in records])
    ratio_err = np.array([r["proposed"]["error"] / r["random"]["error"] for r in records])
    promise = np.array([r["proposed"]["half_width"] / r["promise"] for r in records])
    print(f"\n{len(records)} labs, {args.runs} runs each: reported half-width proposed / random "
          f"{', '.join(f'{x:.2f}' for x in ratio_hw)} (geometric mean "
          f"{np.exp(np.mean(np.log(ratio_hw))):.2f}); "
          f"truth error proposed / random {', '.join(f'{x:.2f}' for x in ratio_err)} (geometric mean "
          f"{np.exp(np.mean(np.log(ratio_err))):.2f}); reported after / promised "
          f"{', '.join(f'{x:.2f}' for x in promise)}")


if __name__ == "__main__":
    main()
