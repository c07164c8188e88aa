"""Speed of /v1/friction/batch on a calibrated model, side by side with the physics and point by point.

Run: ``.venv/bin/python -m bench.calibrated_batch`` (about a minute; ``--points`` to change the batch).

In process (FastAPI's TestClient, a temporary data folder): calibrates a model on 60 synthetic
measurements (physics with mu_pivot 0.7 and menisci growing with relative humidity, 2 % noise,
mu_pivot fitted; tests/test_service_calibrated_batch.py uses the same model), then times, in one
run and alternating over the repeats,

* ``POST /v1/friction/batch`` of N points (load, speed and humidity as lists) on the physics and on
  the calibrated model, with ``mu`` only (the calibrated answer adds mu_effect, mu_lower, mu_upper,
  in_domain) and with every output;
* the same N points as N single-point ``POST /v1/friction`` requests on the calibrated model,
  extrapolated from the first 200, and as N calls of ``CalibratedPhysicsModel.evaluate`` on one
  point each (the Python loop a batch avoids), extrapolated likewise;
* single-point requests on the calibrated model by an app that keeps its rebuilt model
  (``MICROBEARING_MODEL_CACHE_SIZE``, default 16) and by one that keeps none (0, a reload and
  rebuild per request, as before the setting), alternating in blocks on the same data folder;
* how many times ``physics.evaluate`` runs for one calibrated batch.

Times are medians over the repeats [s]; the machine's CPU count and load average are printed.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

import numpy as np
from fastapi.testclient import TestClient

from microbearing import physics
from microbearing.service.app import create_app
from microbearing.service.calibrations import load_mu_model
from microbearing.service.deps import get_runtime
from microbearing.service.settings import Settings

N_ROWS = 60
LOOP_SAMPLE = 200


def measurements(seed: int) -> list[dict]:
    """Synthetic tribometer rows: mu_pivot 0.7, a humidity meniscus term, 2 % log-normal noise, and a
    temperature column no term reads."""
    rng = np.random.default_rng(seed)
    c = {"balls": rng.choice([4, 8], N_ROWS).astype(float),
         "load_N": np.exp(rng.uniform(np.log(5e-3), np.log(3e-2), N_ROWS)),
         "speed_m_s": rng.uniform(0.01, 0.15, N_ROWS),
         "relative_humidity": rng.uniform(0.2, 0.8, N_ROWS),
         "temperature_C": rng.uniform(20.0, 40.0, N_ROWS)}
    mu = physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"], mu_pivot=0.7).mu
    mu = (mu + c["balls"] * 2e-5 / (c["load_N"] * np.log(1 / c["relative_humidity"]))) * np.exp(
        rng.normal(0.0, 0.02, N_ROWS))
    return [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(N_ROWS)]


def calibration(client: TestClient, timeout_s: float = 300.0) -> dict:
    """The result of calibrating mu_pivot on :func:`measurements` (seed 3, 3 folds) through the API."""
    response = client.post("/v1/calibrations", json={"data": measurements(3), "fit_parameters": ["mu_pivot"],
                                                     "folds": 3})
    assert response.status_code == 202, response.text
    deadline = time.monotonic() + timeout_s
    while (job := client.get(response.headers["location"]).json())["status"] in ("queued", "running"):
        assert time.monotonic() < deadline, job
        time.sleep(0.1)
    assert job["status"] == "succeeded", job
    return client.get(job["result_url"]).json()


def timed(call) -> float:
    start = time.perf_counter()
    call()
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--points", type=int, default=10_000, help="points per batch [1]")
    parser.add_argument("--repeats", type=int, default=7, help="timed repeats of each batch [1]")
    args = parser.parse_args()
    n = args.points
    print(f"cpus {os.cpu_count()}, load average {os.getloadavg()}")
    rng = np.random.default_rng(1)
    load_N = np.exp(rng.uniform(np.log(5e-3), np.log(3e-2), n)).tolist()
    speed_m_s = rng.uniform(0.01, 0.15, n).tolist()
    humidity = rng.uniform(0.2, 0.8, n).tolist()
    with tempfile.TemporaryDirectory() as folder, TestClient(create_app(Settings(data_dir=folder))) as client:
        model = calibration(client)["model_id"]
        points = {"balls": 4, "load_N": load_N, "speed_m_s": speed_m_s}
        requests = {
            "physics, mu": {"points": points, "outputs": ["mu"]},
            "calibrated, mu + interval + domain": {"points": points, "outputs": ["mu"], "model": model,
                                                   "conditions": {"relative_humidity": humidity}},
            "physics, every output": {"points": points},
            "calibrated, every output": {"points": points, "model": model,
                                         "conditions": {"relative_humidity": humidity}},
        }
        times: dict[str, list[float]] = {name: [] for name in requests}
        for _ in range(args.repeats):
            for name, body in requests.items():
                def post(body=body):
                    response = client.post("/v1/friction/batch", json=body)
                    assert response.status_code == 200, response.text
                times[name].append(timed(post))
        calls = []
        evaluate = physics.evaluate

        def counted(*a, **k):
            calls.append(1)
            return evaluate(*a, **k)

        physics.evaluate = counted
        try:
            client.post("/v1/friction/batch", json=requests["calibrated, mu + interval + domain"])
        finally:
            physics.evaluate = evaluate

        def singles(app_client: TestClient = client):
            for i in range(LOOP_SAMPLE):
                point = {"balls": 4, "load_N": load_N[i], "speed_m_s": speed_m_s[i]}
                response = app_client.post("/v1/friction", json={
                    **point, "model": model, "conditions": {"relative_humidity": humidity[i]}})
                assert response.status_code == 200, response.text

        mu_model = load_mu_model(get_runtime(client.app).store, model)

        def loop():
            for i in range(LOOP_SAMPLE):
                mu_model.evaluate({"balls": 4, "load_N": load_N[i], "speed_m_s": speed_m_s[i],
                                   "relative_humidity": humidity[i]}, ["mu", "mu_lower", "mu_upper"])

        per_single = timed(singles) / LOOP_SAMPLE
        per_loop = timed(loop) / LOOP_SAMPLE
        with TestClient(create_app(Settings(data_dir=folder, model_cache_size=0))) as rebuilding:
            kept, rebuilt = [], []
            for _ in range(args.repeats):
                kept.append(timed(singles) / LOOP_SAMPLE)
                rebuilt.append(timed(lambda: singles(rebuilding)) / LOOP_SAMPLE)
    print(f"\n{n} points per batch, median of {args.repeats} [s]:")
    for name, values in times.items():
        print(f"  POST /v1/friction/batch, {name:<36} {statistics.median(values):8.3f}")
    base = statistics.median(times["physics, mu"])
    calibrated = statistics.median(times["calibrated, mu + interval + domain"])
    print(f"  calibrated / physics (mu only): {calibrated / base:.2f}")
    print(f"  physics.evaluate calls in one calibrated batch: {len(calls)}")
    print(f"  {n} single POST /v1/friction (calibrated), from {LOOP_SAMPLE}: {per_single * n:8.3f}"
          f"  ({per_single * n / calibrated:.0f}x the batch)")
    print(f"  {n} CalibratedPhysicsModel.evaluate calls of one point, from {LOOP_SAMPLE}: {per_loop * n:8.3f}"
          f"  ({per_loop * n / calibrated:.0f}x the batch)")
    print(f"one calibrated POST /v1/friction, median of {args.repeats} blocks of {LOOP_SAMPLE} [ms]: "
          f"model kept "
          f"{statistics.median(kept) * 1e3:.2f}, rebuilt per request {statistics.median(rebuilt) * 1e3:.2f} "
          f"(ratio {statistics.median(rebuilt) / statistics.median(kept):.1f})")
    print(f"load average {os.getloadavg()}")


if __name__ == "__main__":
    main()
