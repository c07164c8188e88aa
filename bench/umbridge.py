"""Points per second through the UM-Bridge protocol against the REST API, side by side in one run.

Run: ``.venv/bin/python -m bench.umbridge`` (about a minute; ``--quick`` for less). Run it as a module:
as a script, ``bench/physics.py`` would shadow the ``physics`` package.

Starts ``microbearing serve`` on a free loopback port (:func:`bench.api.start_server`), then measures,
request by request alternating the routes compared so that both see the same load:

* one point per request: ``POST /umbridge/Evaluate`` (the physics, default config: balls, load and
  speed in, mu out) against ``POST /v1/friction`` (every output) on one keep-alive client, and the
  stock ``umbridge.HTTPModel`` client (``requests``, a new connection per call) on the same point;
* many points per request (``config.points``, one input vector per point, mu out) against
  ``POST /v1/friction/batch`` with the same points as columns and ``outputs: ["mu"]``.

Request bodies are encoded once, so client-side encoding is not counted; answers are received but
not decoded (except by the stock client, which decodes as a user's code would).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time

import httpx
import numpy as np
import umbridge

from bench.api import JSON, POINT, start_server


def _rate(client: httpx.Client, path: str, body: bytes, points: int) -> float:
    start = time.perf_counter()
    client.post(path, content=body, headers=JSON).raise_for_status()
    return points / (time.perf_counter() - start)


def single_point(client: httpx.Client, url: str, rounds: int, per_round: int) -> dict[str, float]:
    """Median points per second of one-point requests per route, over ``rounds`` alternating rounds."""
    vector = list(POINT.values())
    bodies = {"/umbridge/Evaluate": json.dumps({"name": "physics", "input": [vector]}).encode(),
              "/v1/friction": json.dumps(POINT).encode()}
    model = umbridge.HTTPModel(f"{url}/umbridge", "physics")
    rates: dict[str, list[float]] = {"/umbridge/Evaluate": [], "/v1/friction": [], "umbridge.HTTPModel": []}
    for round_index in range(rounds + 1):  # the first round warms up
        spent = dict.fromkeys(rates, 0.0)
        for _ in range(per_round):
            for path, body in bodies.items():
                start = time.perf_counter()
                client.post(path, content=body, headers=JSON).raise_for_status()
                spent[path] += time.perf_counter() - start
            start = time.perf_counter()
            model([vector])
            spent["umbridge.HTTPModel"] += time.perf_counter() - start
        if round_index:
            for name, seconds in spent.items():
                rates[name].append(per_round / seconds)
    return {name: float(np.median(values)) for name, values in rates.items()}


def many_points(client: httpx.Client, points: int, repeats: int) -> tuple[float, float]:
    """Median points per second of /umbridge/Evaluate and /v1/friction/batch on the same points (mu only)."""
    rng = np.random.default_rng(0)
    loads, speeds = rng.uniform(1e-3, 1e-2, points).tolist(), rng.uniform(0.0, 0.15, points).tolist()
    vectors = [[4.0, a, b] for a, b in zip(loads, speeds, strict=True)]
    protocol = json.dumps({"name": "physics", "input": vectors, "config": {"points": points}}).encode()
    columns = {"balls": 4, "load_N": loads, "speed_m_s": speeds}
    batch = json.dumps({"points": columns, "outputs": ["mu"]}).encode()
    evaluate, batched = [], []
    for _ in range(repeats):
        evaluate.append(_rate(client, "/umbridge/Evaluate", protocol, points))
        batched.append(_rate(client, "/v1/friction/batch", batch, points))
    return float(np.median(evaluate)), float(np.median(batched))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer rounds")
    args = parser.parse_args()
    rounds, per_round, repeats = (3, 50, 2) if args.quick else (7, 200, 5)
    with tempfile.TemporaryDirectory(prefix="microbearing-bench-") as data_dir:
        process, url = start_server(data_dir)
        try:
            with httpx.Client(base_url=url, timeout=300) as client:
                rates = single_point(client, url, rounds, per_round)
                print(f"one point per request, the routes alternating request by request, median of {rounds} "
                      f"rounds x {per_round}")
                for name, how in (("/umbridge/Evaluate", "keep-alive"), ("/v1/friction", "keep-alive"),
                                  ("umbridge.HTTPModel", "new connection each")):
                    print(f"  {name:20s} ({how:19s}) {rates[name]:8.0f} points/s")
                ratio = rates["/umbridge/Evaluate"] / rates["/v1/friction"]
                print(f"  ratio /umbridge/Evaluate / /v1/friction: {ratio:.2f}")
                print(f"many points per request (mu only), the routes alternating, median of {repeats}")
                for points in (1_000, 100_000):
                    evaluate, batch = many_points(client, points, repeats)
                    print(f"  {points:>7,} points  /umbridge/Evaluate {evaluate:12,.0f} points/s   "
                          f"/v1/friction/batch {batch:12,.0f} points/s   ratio {evaluate / batch:.2f}")
        finally:
            process.terminate()
            process.wait(timeout=30)


if __name__ == "__main__":
    main()
