"""The lab's measurement system through the REST API: replicates, drift or a step, a clipping sensor.

Run: ``python bench/measurement_system.py [--seeds N] [--first-seed S] [--part PART]``, PART one of
``all`` (default), ``replicates``, ``drift``, ``saturation``, ``clip_runin``.

Every data set is drawn from the physics (4 balls, mu_pivot 0.65 instead of the default 0.5) with 3 %
log-normal scatter, written here independently of :mod:`calibrate.measurement`, and calibrated through
``POST /v1/calibrations`` (``mu_pivot`` fitted, 5 folds; the job polled until done). The calibrated
model of the answer (``model``, the JSON ``/v1/friction`` reads) then predicts fresh measurements of
the same bearing in the region each case asks about. Per case and seed it prints what the report says
about the measurement system, the terms named, the truth error (RMS of log(predicted / true μ) over
the region, in units of the 3 % noise; the target is at most 0.5) and the coverage of the 95 %
prediction intervals on fresh measurements there (target 0.90-0.98).

Cases:

* ``replicates``: 20 design points (4 loads x 5 speeds, the load read with 0.2 % jitter) measured 5
  times; the report should speak of 20 design points x 5, a pure error near 3 % and a lack of fit that is
  not significant; ``replicates + point offsets``: the same with a 5 % offset per design point that no
  term can follow (the lack-of-fit test should see it);
* ``drift run_index`` / ``drift ISO date``: 120 runs at random loads and speeds, the reading drifting
  +8 % linearly over the session, the order given as a run_index or as ISO 8601 times 4 min apart; the
  report should name a measurement drift near +8 %; coverage at the session's first and last 12 runs;
* ``step run_index``: the same 120 runs, the reading stepping x1.06 from run 60 on (a recalibrated load
  cell); the report should name a step near +6 % at run_index 60 (not a drift); coverage at the first 12
  runs, the middle (runs 50-70, about the step) and the last 12;
* ``run-in cycles``: a physical run-in (friction 1 + 0.4 exp(-cycle / 300) times the physics) with a
  cycle column: it should stay a run-in;
* ``clip``: 120 rows whose reading clips at the 72nd percentile of the true μ (26-31 % of rows
  identical); the report should say so, name no law, and cover fresh (unclipped) measurements in the
  clipped range; ``constant``: 150 identical readings, no term.
* ``clip + run-in`` (part ``clip_runin``): 140 rows with the run-in above (friction
  1 + 0.4 exp(-cycle / 300) times the physics, cycles 0-2000) whose reading clips at the 80th
  percentile of the true μ (17-21 % of rows, most of them the first cycles'); the report should say
  the clip and name the run-in (its amplitude printed against the true 0.4), and cover fresh
  (unclipped) measurements in the clipped range (true μ at or above the clip), the measured range and
  at cycles beyond 1000. The oracle beside it fits the true law (``mu_pivot`` and the run-in) to the
  same rows by the same censored fit (:func:`calibrate.fit.fit` after
  :func:`calibrate.measurement.with_censor_scale`) and prints its truth error in the clipped range and
  the standard deviation of its log μ there from the fit's covariance (what the rows can tell, in
  units of the noise).
"""

from __future__ import annotations

import argparse
import logging
import sys
import tempfile
import time
from datetime import UTC, datetime, timedelta
from pathlib import Path

# Run as a script, this file's folder comes first on sys.path; the repository root must come instead.
_REPO = Path(__file__).resolve().parent.parent
if Path(sys.path[0]).resolve() == Path(__file__).resolve().parent:
    sys.path[0] = str(_REPO)

import numpy as np  # noqa: E402
from fastapi.testclient import TestClient  # noqa: E402

from microbearing import physics  # noqa: E402
from microbearing.calibrate import CalibratedModel, parse_rows  # noqa: E402
from microbearing.calibrate.candidates import EffectTerm  # noqa: E402
from microbearing.calibrate.fit import fit  # noqa: E402
from microbearing.calibrate.measurement import inspect, with_censor_scale  # noqa: E402
from microbearing.service.app import create_app  # noqa: E402
from microbearing.service.settings import Settings  # noqa: E402

PIVOT, NOISE, BALLS = 0.65, 0.03, 4
FRESH = 400


def truth(load_N, speed_m_s) -> np.ndarray:
    """μ of the bearing (no measurement system)."""
    return physics.evaluate(balls=BALLS, load_N=load_N, speed_m_s=speed_m_s, mu_pivot=PIVOT).mu


def as_rows(columns: dict, mu: np.ndarray) -> list[dict]:
    return [{k: (v[i] if isinstance(v[i], str) else float(v[i])) for k, v in columns.items()}
            | {"mu_measured": float(mu[i])} for i in range(mu.size)]


def calibrated(client: TestClient, rows: list[dict]) -> dict:
    """The report of ``POST /v1/calibrations`` once its job is done."""
    response = client.post("/v1/calibrations", json={"data": rows, "fit_parameters": ["mu_pivot"],
                                                     "fixed": {"balls": BALLS}, "folds": 5})
    assert response.status_code == 202, response.text
    location = response.headers["location"]
    deadline = time.monotonic() + 1800
    while True:
        job = client.get(location).json()
        if job["status"] in ("succeeded", "failed", "cancelled"):
            break
        assert time.monotonic() < deadline, f"job {location} not done: {job}"
        time.sleep(1.0)
    assert job["status"] == "succeeded", job
    return client.get(job["result_url"]).json()


def judged(report: dict, points: dict, true_mu: np.ndarray, rng: np.random.Generator) -> tuple[float, float]:
    """Truth error over the points in units of the noise, and the 95 % coverage of one fresh
    measurement at each."""
    model = CalibratedModel.from_json(report["model"])
    prediction = model.predict({"balls": BALLS, **points})
    error = float(np.sqrt(np.mean(np.square(np.log(prediction.mu / true_mu))))) / NOISE
    fresh = true_mu * np.exp(rng.normal(0.0, NOISE, true_mu.size))
    covered = float(np.mean((prediction.mu_lower <= fresh) & (fresh <= prediction.mu_upper)))
    return error, covered


def terms(report: dict) -> str:
    return " + ".join(e["label"] for e in report["effects"] or []) or "none"


def pivot(report: dict) -> str:
    fitted = report["fitted_parameters"]["mu_pivot"]
    return f"mu_pivot {fitted['value']:.3f} +/- {fitted['std']:.3f}"


def replicates(client, seed: int, offsets: bool) -> list[str]:
    rng = np.random.default_rng(seed)
    loads, speeds = np.meshgrid(np.geomspace(3e-3, 3e-2, 4), np.linspace(0.01, 0.15, 5))
    loads, speeds = loads.ravel(), speeds.ravel()
    offset = np.exp(rng.normal(0.0, 0.05, loads.size)) if offsets else np.ones(loads.size)
    load = np.repeat(loads, 5) * (1 + 0.002 * rng.standard_normal(100))
    speed = np.repeat(speeds, 5)
    mu = truth(load, speed) * np.repeat(offset, 5) * np.exp(rng.normal(0.0, NOISE, 100))
    report = calibrated(client, as_rows({"load_N": load, "speed_m_s": speed}, mu))
    system = report["measurement_system"]
    points = {"load_N": np.repeat(loads, FRESH // 20), "speed_m_s": np.repeat(speeds, FRESH // 20)}
    true_mu = truth(points["load_N"], points["speed_m_s"]) * np.repeat(offset, FRESH // 20)
    error, covered = judged(report, points, true_mu, rng)
    lof = system["replicates"]
    words = "no replicates found" if lof is None else (
        f"{lof['points']} points, pure error {100 * lof['pure_error_relative']:.1f} %, lack of fit p = "
        f"{lof['p']:.3g}")
    return [words, f"terms {terms(report)}", pivot(report), f"truth error {error:.2f} x noise",
            f"coverage {covered:.3f}"]


def drifted(run, n: int) -> np.ndarray:
    """The reading's factor of the drift cases: +8 % linearly over the session."""
    return 1.0 + 0.08 * np.asarray(run, dtype=float) / (n - 1)


def stepped(run, n: int) -> np.ndarray:
    """The reading's factor of the step case: x1.06 from the session's middle run on."""
    return np.where(np.asarray(run, dtype=float) >= n // 2, 1.06, 1.0)


def session(client, seed: int, clock: bool, reading=drifted) -> list[str]:
    rng = np.random.default_rng(seed)
    n = 120
    load = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n))
    speed = rng.uniform(0.01, 0.15, n)
    run = np.arange(n, dtype=float)
    mu = truth(load, speed) * reading(run, n) * np.exp(rng.normal(0.0, NOISE, n))
    start = datetime(2026, 11, 28, 9, 0, tzinfo=UTC)
    minutes = 4.0 * run + rng.uniform(0.0, 0.5, n)
    column, values = ("date", [(start + timedelta(minutes=float(m))).isoformat() for m in minutes]) if clock \
        else ("run_index", run)
    report = calibrated(client, as_rows({"load_N": load, "speed_m_s": speed, column: values}, mu))
    out = ["; ".join(report["measurement_system"]["drift"]) or "no drift said", f"terms {terms(report)}",
           pivot(report)]
    regions = [("start", np.arange(12))] + ([("middle", np.arange(50, 71))] if reading is stepped else []) \
        + [("end", np.arange(n - 12, n))]
    for name, runs in regions:
        k = FRESH // runs.size
        at = np.repeat(runs, k).astype(float)
        g = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), at.size))
        v = rng.uniform(0.01, 0.15, at.size)
        where = (minutes[runs].repeat(k) / 60.0) if clock else at  # the model reads hours since the start
        true_mu = truth(g, v) * reading(at, n)
        error, covered = judged(report, {"load_N": g, "speed_m_s": v, column: where}, true_mu, rng)
        out.append(f"{name}: truth error {error:.2f} x noise, coverage {covered:.3f}")
    return out


def run_in(client, seed: int) -> list[str]:
    rng = np.random.default_rng(seed)
    n = 120
    load = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n))
    speed = rng.uniform(0.01, 0.15, n)
    cycle = np.sort(rng.uniform(0.0, 2000.0, n))
    mu = truth(load, speed) * (1 + 0.4 * np.exp(-cycle / 300.0)) * np.exp(rng.normal(0.0, NOISE, n))
    report = calibrated(client, as_rows({"load_N": load, "speed_m_s": speed, "cycle": cycle}, mu))
    g = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), FRESH))
    v = rng.uniform(0.01, 0.15, FRESH)
    c = rng.uniform(0.0, 2000.0, FRESH)
    error, covered = judged(report, {"load_N": g, "speed_m_s": v, "cycle": c},
                            truth(g, v) * (1 + 0.4 * np.exp(-c / 300.0)), rng)
    return [f"terms {terms(report)}", pivot(report), f"truth error {error:.2f} x noise",
            f"coverage {covered:.3f}"]


def clip(client, seed: int) -> list[str]:
    rng = np.random.default_rng(seed)
    n = 120
    load = np.exp(rng.uniform(np.log(1e-3), np.log(3e-2), n))
    speed = rng.uniform(0.01, 0.15, n)
    true_mu = truth(load, speed)
    level = float(np.quantile(true_mu, 0.72))
    mu = np.minimum(true_mu * np.exp(rng.normal(0.0, NOISE, n)), level)
    report = calibrated(client, as_rows({"load_N": load, "speed_m_s": speed}, mu))
    saturation = report["measurement_system"]["saturation"]
    said = "no clip said" if not saturation else (
        f"clip said at {saturation[0]['level']:.4g} ({100 * saturation[0]['share']:.0f} % of rows; true "
        f"{level:.4g}, {100 * np.mean(mu == level):.0f} %)")
    out = [said, f"terms {terms(report)}", pivot(report)]
    g = np.exp(rng.uniform(np.log(1e-3), np.log(3e-2), 4 * FRESH))
    v = rng.uniform(0.01, 0.15, 4 * FRESH)
    t = truth(g, v)
    for name, inside in (("clipped range", t >= level), ("measured range", t < level)):
        error, covered = judged(report, {"load_N": g[inside], "speed_m_s": v[inside]}, t[inside], rng)
        out.append(f"{name}: truth error {error:.2f} x noise, coverage {covered:.3f}")
    return out


def clip_run_in(client, seed: int) -> list[str]:
    rng = np.random.default_rng(seed)
    n = 140
    load = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n))
    speed = rng.uniform(0.01, 0.15, n)
    cycle = np.sort(rng.uniform(0.0, 2000.0, n))
    true_mu = truth(load, speed) * (1 + 0.4 * np.exp(-cycle / 300.0))
    level = float(np.quantile(true_mu, 0.8))
    mu = np.minimum(true_mu * np.exp(rng.normal(0.0, NOISE, n)), level)
    report = calibrated(client, as_rows({"load_N": load, "speed_m_s": speed, "cycle": cycle}, mu))
    saturation = report["measurement_system"]["saturation"]
    said = "no clip said" if not saturation else (
        f"clip said at {saturation[0]['level']:.4g} ({100 * saturation[0]['share']:.0f} % of rows; true "
        f"{level:.4g}, {100 * np.mean(mu == level):.0f} %)")
    run = [e for e in report["effects"] or [] if e["name"] == "run_in"]
    amplitude = "no run_in" if not run else (
        f"run_in amplitude {run[0]['parameters']['run_in_amplitude']:.3f} +/- "
        f"{run[0]['parameter_std']['run_in_amplitude']:.3f} (true 0.4), length "
        f"{run[0]['parameters']['run_in_length']:.0f} cycles (true 300)")
    out = [said, f"terms {terms(report)}", amplitude, pivot(report)]
    g = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), 4 * FRESH))
    v = rng.uniform(0.01, 0.15, 4 * FRESH)
    c = rng.uniform(0.0, 2000.0, 4 * FRESH)
    t = truth(g, v) * (1 + 0.4 * np.exp(-c / 300.0))
    beyond = t >= level
    out.append(oracle(as_rows({"load_N": load, "speed_m_s": speed, "cycle": cycle}, mu),
                      (g[beyond], v[beyond], c[beyond]), t[beyond]))
    for name, inside in (("clipped range", t >= level), ("measured range", t < level),
                         ("cycles > 1000", c > 1000.0)):
        error, covered = judged(report, {"load_N": g[inside], "speed_m_s": v[inside], "cycle": c[inside]},
                                t[inside], rng)
        out.append(f"{name}: truth error {error:.2f} x noise, coverage {covered:.3f}")
    return out


def oracle(rows: list[dict], points: tuple, true_mu: np.ndarray) -> str:
    """The true law (mu_pivot x (1 + a exp(-cycle / L))) fitted to ``rows`` by the calibration's censored
    fit: its amplitude, its truth error at ``points`` (load, speed, cycle) and the standard deviation of
    its log μ there from the fit's covariance (central differences), both in units of the noise."""
    run_in = EffectTerm("run_in", ("cycle",))
    dataset = parse_rows(rows, {"balls": BALLS})
    dataset = with_censor_scale(inspect(dataset, 5).apply(dataset), ["mu_pivot"], physics.DEFAULT_CONVENTION,
                                [run_in])
    result = fit(dataset, ["mu_pivot"], [run_in])
    x = np.array([result.declared["mu_pivot"], *result.term_values[0]])  # the covariance's order
    g, v, c = points

    def log_mu(p: np.ndarray) -> np.ndarray:
        return np.log(physics.evaluate(balls=BALLS, load_N=g, speed_m_s=v, mu_pivot=p[0]).mu
                      * (1 + p[1] * np.exp(-c / p[2])))

    steps = 1e-6 * np.abs(x) * np.eye(x.size)
    gradient = np.array([(log_mu(x + h) - log_mu(x - h)) / (2 * h[k]) for k, h in enumerate(steps)])
    sd = float(np.sqrt(np.mean(np.einsum("ip,ij,jp->p", gradient, result.covariance, gradient)))) / NOISE
    error = float(np.sqrt(np.mean(np.square(log_mu(x) - np.log(true_mu))))) / NOISE
    return (f"oracle: amplitude {x[1]:.3f} +/- {result.std[1]:.3f}, clipped range truth error {error:.2f} x "
            f"noise, its sd there {sd:.2f} x noise")


def constant(client, seed: int) -> list[str]:
    rng = np.random.default_rng(seed)
    n = 150
    load = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n))
    speed = rng.uniform(0.01, 0.15, n)
    report = calibrated(client, as_rows({"load_N": load, "speed_m_s": speed}, np.full(n, 0.012)))
    return [f"constant said: {report['measurement_system']['constant'] is not None}",
            f"terms {terms(report)}"]


CASES = {
    "replicates": [("replicates", lambda c, s: replicates(c, s, False)),
                   ("replicates + point offsets", lambda c, s: replicates(c, s, True))],
    "drift": [("drift run_index", lambda c, s: session(c, s, False)),
              ("drift ISO date", lambda c, s: session(c, s, True)),
              ("step run_index", lambda c, s: session(c, s, False, stepped)),
              ("run-in cycles", run_in)],
    "saturation": [("clip", clip), ("constant", constant)],
    "clip_runin": [("clip + run-in", clip_run_in)],
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3, help="seeds per case")
    parser.add_argument("--first-seed", type=int, default=1)
    parser.add_argument("--part", choices=["all", *CASES], default="all")
    args = parser.parse_args(argv)
    parts = list(CASES) if args.part == "all" else [args.part]
    logging.disable(logging.INFO)  # the service's access log, one line per poll
    with tempfile.TemporaryDirectory() as folder, TestClient(create_app(Settings(data_dir=folder))) as client:
        for part in parts:
            for name, case in CASES[part]:
                for seed in range(args.first_seed, args.first_seed + args.seeds):
                    start = time.perf_counter()
                    figures = case(client, seed)
                    print(f"{name:28s} seed {seed}: " + "; ".join(figures)
                          + f" ({time.perf_counter() - start:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
