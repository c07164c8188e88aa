"""Flood: far more job submissions than the server takes, while /healthz is watched and RSS sampled.

Starts ``microbearing serve`` (one process) on a free loopback port with a temporary data folder
and the default limits, then ``--clients`` concurrent clients submit ``--jobs`` sweeps of
``--points`` points each as fast as the server answers. Meanwhile one client asks ``/healthz``
every 0.25 s and the server's resident memory is read from ``/proc`` every 0.1 s. Once every
submission is answered, the accepted jobs are awaited. Reports how many submissions were
accepted (202), refused (429 / 503, each with ``Retry-After``) or failed otherwise, how the
accepted jobs ended, whether ``/healthz`` answered every time, and the server's peak RSS
(``VmHWM``, Linux)::

    .venv/bin/python bench/flood.py --jobs 1000 --points 1000000 --clients 16

With ``--calibration-rows N`` it instead uploads one calibration CSV of N rows (the physics with
``mu_pivot`` 0.7 and 2 % noise, as the calibration tests) and reports the server's RSS before and its
peak while the calibration job runs, and the job's duration: the memory of the largest accepted
calibration (``MICROBEARING_MAX_CALIBRATION_ROWS``, 20,000)::

    .venv/bin/python bench/flood.py --calibration-rows 20000
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import httpx
from load import start_server, stop_server


def rss_mib(pid: int, field: str = "VmRSS") -> float:
    """A memory figure of process ``pid`` from /proc/<pid>/status [MiB] (VmRSS now, VmHWM the peak)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) / 1024
    raise RuntimeError(f"{field} not found for pid {pid}")


def sweep(points: int, index: int) -> dict:
    """A Sobol sweep of ``points`` points (mu over load and speed); ``index`` varies the seed."""
    return {"design": "sobol", "points": points, "seed": index, "outputs": ["mu"],
            "ranges": {"load_N": {"low": 1e-3, "high": 0.05}, "speed_m_s": {"low": 0.0, "high": 0.2}},
            "fixed": {"balls": 4}}


async def flood(url: str, pid: int, jobs: int, points: int, clients: int) -> dict:
    """Submit, watch, sample; returns the counts and figures."""
    statuses: Counter[int] = Counter()
    missing_retry_after = 0
    locations: list[str] = []
    health = {"asked": 0, "answered": 0, "slowest_s": 0.0}
    peak_sampled = rss_mib(pid)
    queue: asyncio.Queue[int] = asyncio.Queue()
    for index in range(jobs):
        queue.put_nowait(index)
    done = asyncio.Event()

    async def submitter() -> None:
        nonlocal missing_retry_after
        async with httpx.AsyncClient(base_url=url, timeout=120.0) as client:
            while not queue.empty():
                index = queue.get_nowait()
                try:
                    response = await client.post("/v1/sweeps", json=sweep(points, index))
                except httpx.HTTPError:
                    statuses[-1] += 1
                    continue
                statuses[response.status_code] += 1
                if response.status_code == 202:
                    locations.append(response.headers["location"])
                elif response.status_code in (429, 503) and "retry-after" not in response.headers:
                    missing_retry_after += 1

    async def watch_health() -> None:
        async with httpx.AsyncClient(base_url=url, timeout=10.0) as client:
            while not done.is_set():
                health["asked"] += 1
                started = time.perf_counter()
                try:
                    if (await client.get("/healthz")).status_code == 200:
                        health["answered"] += 1
                except httpx.HTTPError:
                    pass
                health["slowest_s"] = max(health["slowest_s"], time.perf_counter() - started)
                await asyncio.sleep(0.25)

    async def sample_memory() -> None:
        nonlocal peak_sampled
        while not done.is_set():
            peak_sampled = max(peak_sampled, rss_mib(pid))
            await asyncio.sleep(0.1)

    watchers = [asyncio.create_task(watch_health()), asyncio.create_task(sample_memory())]
    started = time.perf_counter()
    await asyncio.gather(*(submitter() for _ in range(clients)))
    submitted_s = time.perf_counter() - started
    rss_after_submissions = rss_mib(pid)
    endings: Counter[str] = Counter()
    async with httpx.AsyncClient(base_url=url, timeout=120.0) as client:
        for location in locations:
            while (job := (await client.get(location)).json())["status"] in ("queued", "running"):
                await asyncio.sleep(0.2)
            endings[job["status"]] += 1
            if job["status"] == "succeeded":
                await client.delete(location)  # keep the data folder small
    done.set()
    await asyncio.gather(*watchers)
    return {"statuses": statuses, "missing_retry_after": missing_retry_after, "endings": endings,
            "health": health, "peak_sampled_mib": peak_sampled, "submitted_s": submitted_s,
            "rss_after_submissions_mib": rss_after_submissions, "elapsed_s": time.perf_counter() - started}


def calibration_csv(url: str, rows: int) -> bytes:
    """Measurements of ``rows`` bearings: the physics (asked of the server, /v1/friction/batch) with
    mu_pivot 0.7 and 2 % log-normal noise. (This script cannot import ``physics``: run as a script,
    ``bench/physics.py`` shadows the package.)"""
    import numpy as np

    rng = np.random.default_rng(0)
    balls = rng.choice([4, 8, 12], rows).astype(float)
    load = np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), rows))
    speed = rng.uniform(0.0, 0.15, rows)
    humidity = rng.uniform(0.2, 0.8, rows)
    batch = {"points": {"balls": balls.astype(int).tolist(), "load_N": load.tolist(),
                        "speed_m_s": speed.tolist(), "mu_pivot": 0.7}, "outputs": ["mu"]}
    response = httpx.post(f"{url}/v1/friction/batch", json=batch, timeout=600.0)
    response.raise_for_status()
    mu = np.asarray(response.json()["mu"]) * np.exp(rng.normal(0.0, 0.02, rows))
    lines = ["balls,load_N,speed_m_s,relative_humidity,mu_measured"]
    lines += [f"{b:g},{x!r},{v!r},{h!r},{m!r}" for b, x, v, h, m in
              zip(balls.tolist(), load.tolist(), speed.tolist(), humidity.tolist(), mu.tolist(), strict=True)]
    return ("\n".join(lines) + "\n").encode()


def calibration_memory(url: str, pid: int, rows: int) -> int:
    """Run one calibration of ``rows`` rows; print the RSS figures and the duration."""
    body = calibration_csv(url, rows)
    before = rss_mib(pid)
    started = time.perf_counter()
    response = httpx.post(f"{url}/v1/calibrations/csv", params={"fit_parameters": "mu_pivot"}, content=body,
                          headers={"content-type": "text/csv"}, timeout=600.0)
    if response.status_code != 202:
        print(f"refused: {response.status_code} {response.text[:300]}")
        return 1
    location = response.headers["location"]
    while (job := httpx.get(url + location, timeout=60.0).json())["status"] in ("queued", "running"):
        time.sleep(0.5)
    print(f"one calibration of {rows} rows ({len(body)} bytes of CSV): {job['status']} after "
          f"{time.perf_counter() - started:.0f} s")
    print(f"server RSS [MiB]      before {before:.0f}, peak {rss_mib(pid, 'VmHWM'):.0f} (VmHWM)")
    return 0 if job["status"] == "succeeded" else 1


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--jobs", type=int, default=1000, help="sweep submissions (default: %(default)s)")
    parser.add_argument("--points", type=int, default=1_000_000,
                        help="points per sweep (default: %(default)s)")
    parser.add_argument("--clients", type=int, default=16,
                        help="concurrent submitters (default: %(default)s)")
    parser.add_argument("--calibration-rows", type=int,
                        help="instead, measure the memory of one calibration of this many rows")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="microbearing-flood-") as data_dir:
        process, url = start_server(1, data_dir)
        if args.calibration_rows:
            try:
                return calibration_memory(url, process.pid, args.calibration_rows)
            finally:
                stop_server(process)
        try:
            baseline = rss_mib(process.pid)
            figures = asyncio.run(flood(url, process.pid, args.jobs, args.points, args.clients))
            peak = rss_mib(process.pid, "VmHWM")
        finally:
            stop_server(process)
    statuses, health = figures["statuses"], figures["health"]
    refused = statuses[429] + statuses[503]
    other = sum(count for status, count in statuses.items() if status not in (202, 429, 503))
    print(f"{args.jobs} sweep submissions of {args.points} points from {args.clients} clients, 1 server "
          "process, default limits")
    print(f"accepted (202)        {statuses[202]}")
    print(f"refused (429 / 503)   {refused} ({statuses[429]} / {statuses[503]}), without Retry-After: "
          f"{figures['missing_retry_after']}")
    others = {status: count for status, count in statuses.items() if status not in (202, 429, 503)}
    print(f"other answers/errors  {other} {others}")
    print(f"accepted jobs ended   {dict(figures['endings'])}")
    print(f"/healthz answered     {health['answered']} of {health['asked']}, slowest "
          f"{health['slowest_s']:.2f} s")
    print(f"server RSS [MiB]      at start {baseline:.0f}, after the submissions "
          f"{figures['rss_after_submissions_mib']:.0f}, peak {peak:.0f} (VmHWM; sampled peak "
          f"{figures['peak_sampled_mib']:.0f})")
    print(f"time [s]              submissions answered in {figures['submitted_s']:.1f}, all jobs done after "
          f"{figures['elapsed_s']:.1f}")
    ok = other == 0 and health["answered"] == health["asked"] and figures["missing_retry_after"] == 0
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
