"""Trust in a calibration's numbers (issue 33 items 4, 5, 6, 9), through the REST API, several seeds each.

Run: ``python bench/calibration_trust.py [--seeds 5] [--part small,heavy,groups,plausible,clean]``
(``--part small-effect`` too).

Every data set is the physics with mu_pivot 0.65 and 3 % log-normal scatter (Student t of 3 degrees of
freedom for ``heavy``), posted to ``POST /v1/calibrations`` of an in-process app; the returned model
(``CalibratedModel.from_json`` of the result's ``model``) predicts 400 fresh rows drawn like the data,
whose share inside the 95 % interval is the coverage (target 0.90-0.98).

* ``small``: 8, 12 and 15 rows, nothing to find: answered or refused, scatter estimated, coverage;
* ``heavy``: 200 rows, Student-t (3 dof) scatter of scale 3 %, nothing to find: coverage;
* ``groups``: 6 specimens x 30 rows, each specimen's mu offset (8 % between them), a humidity meniscus and
  a viscosity falling with temperature (Arrhenius): the terms named with and without the ``specimen``
  column, the within-specimen scatter;
* ``plausible``: adhesion drifting with humidity (Kelvin) plus a run-in over cycles: what carries the
  humidity effect, whether it is plausible, its standard deviation, coverage at RH 0.85;
* ``clean``: 200 rows, nothing to find: no term named (false discoveries);
* ``speedscatter`` (not in the default parts; issue 33 case d): a humidity meniscus and a run-in over
  ``cycle`` on 4 specimens (``specimen``, log-normal levels of 6 %), 8 design points per specimen x 5 runs
  each, every run at its own cycle (no replicates), log-normal scatter growing linearly with speed from 2 %
  at 5 mm/s to 6 % at 150 mm/s: per seed the named terms, the scatter model, err at specimen S1 (RMS
  log(predicted / true mu) over 400 fresh S1 points inside, in units of 3 %) and the coverage of 400
  fresh S1 measurements per region (inside; the lowest and highest tenth of load, speed, RH, cycle),
  predicted by ``POST /v1/friction/batch`` with the calibrated model;
* ``small-effect`` (not in the default parts): 8 and 10 rows over RH 0.2-0.8 of the physics x
  (1 + 0.1 RH^4 / load_N), friction up to 14x the physics at high humidity and low load, which so few rows
  cannot decide: coverage of 2000 fresh rows drawn like the data, over the whole range and at RH 0.7-0.8,
  and the interval's mean half-width in log mu there.
"""

from __future__ import annotations

import argparse
import logging
import sys
import tempfile
import time
from pathlib import Path

_REPO = Path(__file__).resolve().parent.parent
if Path(sys.path[0]).resolve() == Path(__file__).resolve().parent:
    sys.path[0] = str(_REPO)
sys.path.insert(0, str(_REPO / "tests"))

import numpy as np  # noqa: E402
from fastapi.testclient import TestClient  # noqa: E402
from jobs_helper import finished_job  # noqa: E402

from microbearing import physics  # noqa: E402
from microbearing.calibrate import CalibratedModel  # noqa: E402
from microbearing.service.app import create_app  # noqa: E402
from microbearing.service.settings import Settings  # noqa: E402

MU_PIVOT = 0.65
NOISE = 0.03
GAS_CONSTANT = 8.314462618


def columns(rng: np.random.Generator, n: int, rh=(0.2, 0.6)) -> dict[str, np.ndarray]:
    """Lab-like inputs and conditions of n rows."""
    return {
        "balls": rng.choice([4.0, 6.0, 8.0], n),
        "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
        "speed_m_s": rng.uniform(0.005, 0.15, n),
        "relative_humidity": rng.uniform(*rh, n),
        "temperature_C": rng.uniform(20.0, 40.0, n),
    }


def mu_of(c, **values) -> np.ndarray:
    """μ of the physics (mu_pivot 0.65 unless overridden) at the rows of c."""
    return physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"],
                            **{"mu_pivot": MU_PIVOT, **values}).mu


def viscosity(temperature_C, activation_J_mol=26e3, reference_C=25.0, level=0.01):
    kelvin = np.asarray(temperature_C) + 273.15
    return level * np.exp(activation_J_mol / GAS_CONSTANT * (1.0 / kelvin - 1.0 / (reference_C + 273.15)))


def as_rows(c, measured, extra=None) -> list[dict]:
    extra = extra or {}
    return [{k: float(v[i]) for k, v in c.items()} | {k: v[i] for k, v in extra.items()}
            | {"mu_measured": float(measured[i])} for i in range(measured.size)]


def post(client: TestClient, body: dict) -> tuple[int, dict]:
    """A calibration through the API: (status of the POST, the result or the problem)."""
    response = client.post("/v1/calibrations", json=body)
    if response.status_code != 202:
        return response.status_code, response.json()
    job = finished_job(client, response.headers["location"], timeout_s=3600, interval_s=0.5)
    return 202, client.get(job["result_url"]).json()


def coverage(result: dict, points: dict, measured: np.ndarray) -> float:
    p = CalibratedModel.from_json(result["model"]).predict(points)
    return float(np.mean((p.mu_lower <= measured) & (measured <= p.mu_upper)))


def small(client, seed: int, n: int) -> dict:
    rng = np.random.default_rng(seed)
    c = columns(rng, n + 400)
    mu = mu_of(c) * np.exp(rng.normal(0.0, NOISE, n + 400))
    status, result = post(client, {"data": as_rows({k: v[:n] for k, v in c.items()}, mu[:n]),
                                   "fit_parameters": ["mu_pivot"], "folds": min(5, n // 2)})
    if status != 202:
        return {"status": status, "detail": str(result.get("detail", result))[:90]}
    model = result["model"]
    return {"status": status, "terms": [e["label"] for e in result["effects"]],
            "scatter": model["noise_std_log"],
            "cover": coverage(result, {k: v[n:] for k, v in c.items()}, mu[n:]),
            "undecided": [u["kind"] for u in result["undecided"]]}


def small_effect(client, seed: int, n: int, fresh: int = 2000) -> dict:
    rng = np.random.default_rng(seed)
    c = columns(rng, n + fresh, rh=(0.2, 0.8))
    mu = mu_of(c) * (1.0 + 0.1 * c["relative_humidity"] ** 4 / c["load_N"]) * np.exp(
        rng.normal(0.0, NOISE, n + fresh))
    status, result = post(client, {"data": as_rows({k: v[:n] for k, v in c.items()}, mu[:n]),
                                   "fit_parameters": ["mu_pivot"], "folds": min(5, n // 2)})
    if status != 202:
        return {"status": status, "detail": str(result.get("detail", result))[:90]}
    p = CalibratedModel.from_json(result["model"]).predict({k: v[n:] for k, v in c.items()})
    inside = (p.mu_lower <= mu[n:]) & (mu[n:] <= p.mu_upper)
    high = c["relative_humidity"][n:] >= 0.7
    half = 0.5 * np.log(p.mu_upper / p.mu_lower)
    return {"cover": round(float(inside.mean()), 4), "cover_rh70": round(float(inside[high].mean()), 4),
            "half_log": round(float(half.mean()), 3), "half_log_rh70": round(float(half[high].mean()), 3),
            "terms": [e["label"] for e in result["effects"]],
            "undecided": [u["kind"] for u in result["undecided"]],
            "rivals": [r["label"] for r in result["model"].get("rivals") or []]}


def heavy(client, seed: int, n: int = 200) -> dict:
    rng = np.random.default_rng(seed)
    c = columns(rng, n + 2000)
    mu = mu_of(c) * np.exp(NOISE * rng.standard_t(3, n + 2000))
    _, result = post(client, {"data": as_rows({k: v[:n] for k, v in c.items()}, mu[:n]),
                                   "fit_parameters": ["mu_pivot"]})
    return {"terms": [e["label"] for e in result["effects"]],
            "cover": coverage(result, {k: v[n:] for k, v in c.items()}, mu[n:])}


def group_data(seed: int, specimens: int = 6, rows: int = 30, spread: float = 0.08):
    rng = np.random.default_rng(seed)
    n = specimens * rows
    c = columns(rng, n, rh=(0.2, 0.8))
    label = np.repeat([f"S{g + 1}" for g in range(specimens)], rows)
    offset = np.repeat(rng.normal(0.0, spread, specimens), rows)
    mu = mu_of(c, viscosity_Pa_s=viscosity(c["temperature_C"]))
    mu = mu + c["balls"] * 2e-5 / (c["load_N"] * np.log(1 / c["relative_humidity"]))
    return c, mu * np.exp(offset + rng.normal(0.0, NOISE, n)), label


def groups(client, seed: int) -> dict:
    c, measured, label = group_data(seed)
    out = {}
    for name, extra in (("with", {"specimen": list(label)}), ("without", {})):
        _, result = post(client, {"data": as_rows(c, measured, extra),
                                       "fit_parameters": ["mu_pivot"]})
        g = result["groups"][0] if result["groups"] else {}
        out[name] = {"terms": [e["label"] for e in result["effects"]],
                     "within": g.get("within_group_scatter_relative")}
    return out


def plausible_data(seed: int, n: int = 200):
    rng = np.random.default_rng(seed)
    c = columns(rng, n + 400, rh=(0.2, 0.6))
    c["relative_humidity"][n:] = 0.85
    c["cycle"] = np.concatenate([rng.integers(0, 5000, n), rng.integers(2000, 5000, 400)]).astype(float)
    adhesion = 0.05 * (1 + 1.5 / np.log(1 / c["relative_humidity"]))
    mu = mu_of(c, adhesion_energy_J_m2=adhesion) * (1 + np.exp(-c["cycle"] / 800))
    return c, mu * np.exp(rng.normal(0.0, NOISE, mu.size)), n


def plausible(client, seed: int) -> dict:
    c, measured, n = plausible_data(seed)
    _, result = post(client, {"data": as_rows({k: v[:n] for k, v in c.items()}, measured[:n]),
                                   "fit_parameters": ["mu_pivot", "adhesion_energy_J_m2"]})
    effects = [(e["label"], e.get("plausible", {}).get("plausible") if isinstance(e.get("plausible"), dict)
                else None) for e in result["effects"]]
    modulus = [e for e in result["effects"] if e.get("parameter") == "youngs_modulus_Pa"]
    fresh = {k: v[n:] for k, v in c.items()}
    return {"effects": effects, "cover_rh85": coverage(result, fresh, measured[n:]),
            "modulus": [(e["parameters"], e["parameter_std"]) for e in modulus],
            "implausible": result.get("implausible", [])}


def clean(client, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    c = columns(rng, 600)
    mu = mu_of(c) * np.exp(rng.normal(0.0, NOISE, 600))
    _, result = post(client, {"data": as_rows({k: v[:200] for k, v in c.items()}, mu[:200]),
                                   "fit_parameters": ["mu_pivot"]})
    return {"terms": [e["label"] for e in result["effects"]],
            "cover": coverage(result, {k: v[200:] for k, v in c.items()}, mu[200:])}


SPEED_RANGE = (0.005, 0.15)
CYCLES = 5000.0


def scatter_at(speed_m_s) -> np.ndarray:
    """Case d's log-normal scatter: 2 % at 5 mm/s to 6 % at 150 mm/s, linear in speed. [1]"""
    lo, hi = SPEED_RANGE
    return 0.02 + 0.04 * (np.asarray(speed_m_s) - lo) / (hi - lo)


def meniscus_run_in(c) -> np.ndarray:
    """The true μ of case d: the physics, a humidity meniscus (``bench/calibrate.py``'s) and a run-in over
    ``cycle`` (x2 at the start, 1/e over 800 cycles)."""
    meniscus = c["balls"] * 2e-5 / (c["load_N"] * np.log(1 / c["relative_humidity"]))
    return (mu_of(c) + meniscus) * (1 + np.exp(-c["cycle"] / 800.0))


def speedscatter_data(seed: int, specimens: int = 4, points: int = 8, runs: int = 5, spread: float = 0.06):
    """Case d's rows: (columns, measured μ, specimen labels, each specimen's log level)."""
    rng = np.random.default_rng(seed)
    design = columns(rng, specimens * points)
    c = {k: np.repeat(v, runs) for k, v in design.items()}
    n = specimens * points * runs
    c["cycle"] = rng.uniform(0.0, CYCLES, n)
    levels = rng.normal(0.0, spread, specimens)
    group = np.repeat(np.arange(specimens), points * runs)
    measured = meniscus_run_in(c) * np.exp(levels[group] + rng.normal(0.0, scatter_at(c["speed_m_s"])))
    return c, measured, np.array([f"S{g + 1}" for g in group]), levels


def _region(rng, c, name: str, size: int) -> dict[str, np.ndarray]:
    """Fresh points drawn as the data, the named column (``column:low|high``) in its lowest or highest
    tenth of the data's range."""
    fresh = columns(rng, size)
    fresh["cycle"] = rng.uniform(0.0, CYCLES, size)
    if name != "inside":
        column, end = name.split(":")
        lo, hi = float(np.min(c[column])), float(np.max(c[column]))
        tenth = (np.log(lo), np.log(hi)) if column == "load_N" else (lo, hi)
        a, b = tenth
        edge = (a, a + 0.1 * (b - a)) if end == "low" else (b - 0.1 * (b - a), b)
        values = rng.uniform(*edge, size)
        fresh[column] = np.exp(values) if column == "load_N" else values
    return fresh


SPEEDSCATTER_REGIONS = ["inside"] + [f"{c}:{end}" for c in ("load_N", "speed_m_s", "relative_humidity",
                                                             "cycle") for end in ("low", "high")]


def speedscatter(client, seed: int, fresh: int = 400) -> dict:
    c, measured, label, levels = speedscatter_data(seed)
    _, result = post(client, {"data": as_rows(c, measured, {"specimen": list(label)}),
                              "fit_parameters": ["mu_pivot"]})
    rng = np.random.default_rng(10_000 + seed)
    cover, err = {}, None
    for name in SPEEDSCATTER_REGIONS:
        points = _region(rng, c, name, fresh)
        true = meniscus_run_in(points) * np.exp(levels[0])
        seen = true * np.exp(rng.normal(0.0, scatter_at(points["speed_m_s"])))
        physics_columns = ("balls", "load_N", "speed_m_s")
        answer = client.post("/v1/friction/batch", json={
            "model": result["model_id"], "outputs": ["mu"],
            "points": {k: points[k].tolist() for k in physics_columns},
            "conditions": {**{k: v.tolist() for k, v in points.items() if k not in physics_columns},
                           "specimen": "S1"}}).json()
        mu, lower, upper = (np.asarray(answer[k]) for k in ("mu", "mu_lower", "mu_upper"))
        cover[name] = round(float(np.mean((lower <= seen) & (seen <= upper))), 3)
        if name == "inside":
            err = round(float(np.sqrt(np.mean(np.log(mu / true) ** 2)) / NOISE), 2)
    scatter = result["model"].get("scatter") or {}
    return {"terms": [e["label"] for e in result["effects"]], "err_S1": err,
            "least": min(cover.values()), "cover": cover,
            "scatter": scatter.get("kind"), "scatter_column": scatter.get("column"),
            "p": round(float(scatter.get("cv", {}).get("p_value", float("nan"))), 4),
            "noise": round(float(result["model"]["noise_std_log"]), 4)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--part", default="small,heavy,groups,plausible,clean",
                        help="comma-separated parts; also speedscatter and small-effect (not by default)")
    args = parser.parse_args()
    logging.disable(logging.INFO)
    parts = args.part.split(",")
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    with tempfile.TemporaryDirectory() as tmp, TestClient(create_app(Settings(data_dir=tmp))) as client:
        for part in parts:
            start = time.perf_counter()
            if part == "small":
                for n in (8, 12, 15):
                    for seed in seeds:
                        print(f"small n={n} seed={seed}: {small(client, seed, n)}", flush=True)
            elif part == "small-effect":
                for n in (8, 10):
                    got = [small_effect(client, seed, n) for seed in seeds]
                    for seed, item in zip(seeds, got, strict=True):
                        print(f"small-effect n={n} seed={seed}: {item}", flush=True)
                    print(f"small-effect n={n}: " + "; ".join(
                        f"{key} mean {np.mean([g[key] for g in got if key in g]):.3f} "
                        f"least {np.min([g[key] for g in got if key in g]):.3f}"
                        for key in ("cover", "cover_rh70", "half_log", "half_log_rh70")), flush=True)
            else:
                fn = {"heavy": heavy, "groups": groups, "plausible": plausible, "clean": clean,
                      "speedscatter": speedscatter}[part]
                for seed in seeds:
                    print(f"{part} seed={seed}: {fn(client, seed)}", flush=True)
            print(f"{part}: {time.perf_counter() - start:.0f} s", flush=True)


if __name__ == "__main__":
    main()
