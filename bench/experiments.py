"""Next experiments: do the proposed runs teach a calibration more than random or space-filling ones?

Run: ``python bench/experiments.py --seeds 4 --runs 20`` for the simulation, ``python bench/experiments.py
--timing`` for the time of proposals of 100 runs over a 5-column space (target of issue 26: <= 10 s).

The simulation hides a truth of its own (written here, independently of physics.effects) in the
physics: adhesion drifting with humidity by a Kelvin law, the same by a linear law, or water menisci
growing as 1/ln(1/h). A lab first measures a poor data set (40 rows at 20-40 % RH, 3 % noise) and
calibrates (``mu_pivot`` and ``adhesion_energy_J_m2`` fitted); then it takes N more runs, measured
from the truth with the same noise, and calibrates again on all rows. The N runs are:

* ``discriminate``: proposed by :func:`calibrate.experiments.next_experiments` to tell the rivals apart
  (``parameters`` when the first calibration left no rival; counted in the table);
* ``predict``: proposed to shrink the 95 % interval over the envelope (6 balls, 5-20 mN, 0.05 m/s,
  70-85 % RH: where the lab will use the model, outside the first data);
* ``predict+rivals``: the same, model-robust: the envelope variance of the model and of its rivals;
* ``random``: uniform over the same space (ball counts uniform among the whole counts);
* ``space-filling``: a scrambled Sobol' design over the same space.

Per strategy: how often the recalibration names the hidden mechanism exactly (effect and driver, or
drifting parameter, driver and law), the truth error over the envelope (RMS of log(mu / mu_true) on
200 envelope points) and the mean half-width of the 95 % prediction interval there relative to mu.
Ratios to ``random`` are geometric means over the cases and seeds.

The figures are of one noise draw of the new runs' measurements, and a data set's truth error can move several
times over between draws. ``--draws K`` measures the same proposed runs under K independent draws (draw 0 the
default's; the others seeded from the data set's seed and the draw) and gives the figures over data sets x
draws, each draw's figure and the standard error of their mean; ``--strategies`` recalibrates only some
strategies (``predict+rivals,random``: a third of the time) and ``--json`` keeps every figure, e.g. to compare
two versions of the library draw by draw (the same data sets, runs and noise where the plans agree).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

_REPO = Path(__file__).resolve().parent.parent
if Path(sys.path[0]).resolve() == Path(__file__).resolve().parent:
    sys.path[0] = str(_REPO)

import numpy as np  # noqa: E402
from scipy.stats import qmc  # noqa: E402

from microbearing import physics  # noqa: E402
from microbearing.calibrate import calibrate, parse_rows  # noqa: E402
from microbearing.calibrate.experiments import ExperimentRequest, next_experiments, rival_models  # noqa: E402

FIT = ["mu_pivot", "adhesion_energy_J_m2"]
NOISE = 0.03
FIRST_ROWS = 40
# The first data's humidity range (fraction): narrow, as a lab's first campaign at room conditions.
FIRST_HUMIDITY = (0.2, 0.4)
SPACE = {"balls": {"low": 4, "high": 8}, "load_N": {"low": 3e-3, "high": 3e-2, "spacing": "log"},
         "speed_m_s": {"low": 0.0, "high": 0.15}, "relative_humidity": {"low": 0.2, "high": 0.9}}
ENVELOPE = {"balls": [6], "load_N": {"low": 5e-3, "high": 2e-2}, "speed_m_s": [0.05],
            "relative_humidity": {"low": 0.7, "high": 0.85}}


def _mu(c, **values):
    return physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"],
                            **{"mu_pivot": 0.7, "adhesion_energy_J_m2": 0.12, **values}).mu


# truth -> (the label a calibration must name, mu of the columns)
TRUTHS = {
    "adhesion, Kelvin law in humidity": (
        "adhesion_energy_J_m2 drifts with relative_humidity (kelvin)",
        lambda c: _mu(c, adhesion_energy_J_m2=0.05 * (1 + 1.5 / np.log(1 / c["relative_humidity"])))),
    "adhesion, linear law in humidity": (
        "adhesion_energy_J_m2 drifts with relative_humidity (linear)",
        lambda c: _mu(c, adhesion_energy_J_m2=0.04 + 0.25 * c["relative_humidity"])),
    "water menisci, 1/ln(1/h)": (
        "humidity_meniscus on relative_humidity",
        lambda c: _mu(c) + c["balls"] * 2e-5 / (c["load_N"] * np.log(1 / c["relative_humidity"]))),
}


def first_data(rng, n):
    return {"balls": rng.choice([4, 6, 8], n).astype(float),
            "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
            "speed_m_s": rng.uniform(0.0, 0.15, n), "relative_humidity": rng.uniform(*FIRST_HUMIDITY, n)}


def _scaled(unit: np.ndarray) -> dict[str, np.ndarray]:
    """Points of SPACE from points of the unit cube (columns in SPACE's order)."""
    out = {}
    for j, (name, spec) in enumerate(SPACE.items()):
        low, high = spec["low"], spec["high"]
        if name == "balls":
            out[name] = np.floor(low + unit[:, j] * (high - low + 1)).clip(low, high)
        elif spec.get("spacing") == "log":
            out[name] = np.exp(np.log(low) + unit[:, j] * (np.log(high) - np.log(low)))
        else:
            out[name] = low + unit[:, j] * (high - low)
    return out


def random_runs(rng, n):
    return _scaled(rng.random((n, len(SPACE))))


def space_filling_runs(seed, n):
    """The first n points of a scrambled Sobol' sequence (n need not be a power of two)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return _scaled(qmc.Sobol(len(SPACE), scramble=True, seed=seed).random(n))


def measure(truth, columns, rng):
    mu = truth(columns) * np.exp(rng.normal(0.0, NOISE, columns["balls"].size))
    return [{k: float(v[i]) for k, v in columns.items()} | {"mu_measured": float(mu[i])}
            for i in range(mu.size)]


def envelope_points(rng, n=200):
    return {"balls": np.full(n, 6.0), "load_N": rng.uniform(5e-3, 2e-2, n), "speed_m_s": np.full(n, 0.05),
            "relative_humidity": rng.uniform(0.7, 0.85, n)}


def judge(report, truth_label, truth, points):
    prediction = report.model.predict(points)
    error = float(np.sqrt(np.mean(np.log(prediction.mu / truth(points)) ** 2)))
    width = float(np.mean((prediction.mu_upper - prediction.mu_lower) / 2 / prediction.mu))
    named = [e["label"] for e in report.effects]
    return {"right": named == [truth_label], "error": error, "width": width, "named": named}


def measure_rng(seed, draw):
    """The noise of the new runs' measurements: draw 0 is the bench's single draw, the others fresh."""
    return np.random.default_rng(30_000 + seed if draw == 0 else [30_000 + seed, draw])


def run_case(name, seed, runs, draws=1, recalibrated=None):
    """The first calibration's and each strategy's records; ``records["draws"][d]`` holds each strategy's
    records under noise draw d (the same proposed runs, fresh noise), draw 0 also at ``records[strategy]``.
    Strategies outside ``recalibrated`` (None: all) are measured (their noise stays drawn in order, so the
    others' noise does not depend on the choice) but not recalibrated, and have no records."""
    truth_label, truth = TRUTHS[name]
    rng = np.random.default_rng(seed)
    rows = measure(truth, first_data(rng, FIRST_ROWS), rng)
    dataset = parse_rows(rows)
    first = calibrate(dataset, FIT, make_plots=False, seed=seed)
    points = envelope_points(np.random.default_rng(10_000 + seed))
    records = {"first": judge(first, truth_label, truth, points)}
    rivals = rival_models(first.to_dict(), dataset, first.model)
    strategies = {}
    goal = "discriminate" if rivals else "parameters"
    strategies["discriminate"] = next_experiments(
        first.model, ExperimentRequest(SPACE, runs, goal, envelope=ENVELOPE, seed=seed), rivals=rivals)
    strategies["predict"] = next_experiments(
        first.model, ExperimentRequest(SPACE, runs, "predict", envelope=ENVELOPE, seed=seed))
    new = {k: {c: np.array([_flat(r)[c] for r in plan.to_dict()["runs"]], dtype=float) for c in SPACE}
           for k, plan in strategies.items()}
    new["random"] = random_runs(np.random.default_rng(20_000 + seed), runs)
    new["space-filling"] = space_filling_runs(seed, runs)
    # Last, so that the noise drawn for the strategies above does not depend on it.
    robust = next_experiments(
        first.model, ExperimentRequest(SPACE, runs, "predict", envelope=ENVELOPE, seed=seed), rivals=rivals)
    new["predict+rivals"] = {c: np.array([_flat(r)[c] for r in robust.to_dict()["runs"]], dtype=float)
                             for c in SPACE}
    records["draws"] = []
    for draw in range(draws):
        rng_draw, judged = measure_rng(seed, draw), {}
        for strategy, columns in new.items():
            measured = measure(truth, columns, rng_draw)
            if recalibrated is None or strategy in recalibrated:
                again = calibrate(parse_rows(rows + measured), FIT, make_plots=False, seed=seed)
                judged[strategy] = judge(again, truth_label, truth, points)
        records["draws"].append(judged)
    records |= records["draws"][0]
    records["goal"] = goal
    records["first"]["rivals"] = [label for label, _ in rivals]
    return records


def _flat(run):
    return {"balls": run["balls"], "load_N": run["load_N"], "speed_m_s": run["speed_m_s"],
            **run["conditions"]}


STRATEGIES = ["discriminate", "predict", "predict+rivals", "random", "space-filling"]


def simulation(seeds: int, runs: int, draws: int = 1, chosen: list[str] | None = None,
               json_path: str | None = None) -> None:
    strategies = ["first"] + (chosen or STRATEGIES)
    table = {s: [] for s in strategies}  # per strategy: records over data sets x draws (first: data sets)
    per_draw = {s: [[] for _ in range(draws)] for s in strategies}
    rows = []
    no_rival = 0
    start = time.perf_counter()
    for name in TRUTHS:
        for seed in range(seeds):
            records = run_case(name, seed, runs, draws, None if chosen is None else set(chosen))
            no_rival += records["goal"] != "discriminate"
            for draw, judged in enumerate(records["draws"]):
                judged = {"first": records["first"]} | judged
                for s in strategies:
                    if s != "first" or draw == 0:
                        table[s].append(judged[s])
                    per_draw[s][draw].append(judged[s])
                    rows.append({"truth": name, "seed": seed, "draw": draw, "strategy": s} | judged[s])
                where = f"{name}, seed {seed}" + (f", draw {draw}" if draws > 1 else "")
                print(f"{where}: " + "; ".join(
                    f"{s} {'right' if judged[s]['right'] else 'wrong'} err {judged[s]['error']:.4f} "
                    f"hw {judged[s]['width']:.4f}" for s in strategies), flush=True)
    if json_path:
        Path(json_path).write_text(json.dumps(rows, indent=1))
    low, high = FIRST_HUMIDITY
    print(f"\n{len(table['first'])} data sets ({len(TRUTHS)} truths x {seeds} seeds), {runs} new runs each, "
          f"{FIRST_ROWS} first rows at {low:.0%}-{high:.0%} RH, noise {NOISE:.0%}; {no_rival} first "
          f"calibration(s) left no rival (discriminate fell back to parameters); "
          f"{time.perf_counter() - start:.0f} s")
    if draws > 1:
        print(f"{draws} noise draws of the new runs' measurements per data set (the same runs, fresh noise): "
              f"figures over data sets x draws; 'per draw' the figure of each draw over the data sets, "
              f"'se' the standard error of the figure from their spread (relative, geometric)")
    print(f"{'strategy':<16}{'right mechanism':>17}{'truth error (RMS log)':>23}{'ratio to random':>17}"
          f"{'95 % half-width':>17}{'ratio to random':>17}"
          + (f"  {'truth error per draw, se':<{7 * draws + 5}}  half-width per draw, se" * (draws > 1)))
    for s in strategies:
        errors = np.array([r["error"] for r in table[s]])
        widths = np.array([r["width"] for r in table[s]])
        right = sum(r["right"] for r in table[s])
        ratios = "".join(f"{_ratio(per_draw[s], per_draw['random'], key):>17.2f}" if "random" in table
                         else f"{'-':>17}" for key in ("error", "width"))
        line = (f"{s:<16}{right:>11}/{len(errors):<5}{_geomean(errors):>23.4f}{ratios[:17]}"
                f"{_geomean(widths):>17.4f}{ratios[17:]}")
        if draws > 1:
            line += "  " + "  ".join(_spread([[r[key] for r in d] for d in per_draw[s]], draws)
                                     for key in ("error", "width"))
        print(line)


def _geomean(values) -> float:
    return float(np.exp(np.mean(np.log(values))))


def _ratio(per_draw, random_per_draw, key) -> float:
    """Geometric mean of the ratios to random's figure on the same data set and draw."""
    return _geomean([r[key] / q[key] for rs, qs in zip(per_draw, random_per_draw, strict=True)
                     for r, q in zip(rs, qs, strict=True)])


def _spread(values_per_draw, draws) -> str:
    """Each draw's geometric mean over the data sets, and the relative standard error of their mean."""
    figures = np.array([_geomean(v) for v in values_per_draw])
    se = float(np.std(np.log(figures), ddof=1) / np.sqrt(draws))
    return f"{' '.join(f'{f:.4f}' for f in figures)}, {np.expm1(se):>4.0%}"


def timing() -> None:
    name = "adhesion, Kelvin law in humidity"
    rng = np.random.default_rng(0)
    rows = measure(TRUTHS[name][1], first_data(rng, 150), rng)
    dataset = parse_rows(rows)
    report = calibrate(dataset, FIT, make_plots=False)
    space = {**SPACE, "balls": {"low": 4, "high": 12}, "groove_angle_deg": {"low": 45.0, "high": 65.0}}
    envelope = {**ENVELOPE, "groove_angle_deg": [54.7]}
    start = time.perf_counter()
    rivals = rival_models(report.to_dict(), dataset, report.model)
    print(f"rivals refitted: {len(rivals)} in {time.perf_counter() - start:.2f} s")
    for goal in ("discriminate", "parameters", "predict"):
        start = time.perf_counter()
        request = ExperimentRequest(space, 100, goal, envelope=envelope)
        plan = next_experiments(report.model, request, rivals=rivals)
        seconds = time.perf_counter() - start
        d = plan.to_dict()
        print(f"{goal:<13} 100 runs over 5 columns: {seconds:.2f} s, efficiency >= "
              f"{d['efficiency_lower_bound']:.4f} (continuous {d['continuous_efficiency_lower_bound']:.4f}), "
              f"{d['support_points']} settings")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--draws", type=int, default=1,
                        help="noise draws of the new runs' measurements per data set (the same runs, fresh "
                             "noise; draw 0 is the single draw of the default)")
    parser.add_argument("--strategies", default=",".join(STRATEGIES),
                        help="comma-separated strategies to recalibrate (the others' runs are still proposed "
                             "and measured, so the noise of those kept does not change)")
    parser.add_argument("--json", help="write every data set's, draw's and strategy's figures to this file")
    parser.add_argument("--timing", action="store_true")
    args = parser.parse_args()
    chosen = [s for s in args.strategies.split(",") if s]
    if unknown := set(chosen) - set(STRATEGIES):
        parser.error(f"unknown strategies {sorted(unknown)}; choose among {STRATEGIES}")
    if args.timing:
        timing()
    else:
        simulation(args.seeds, args.runs, args.draws, None if chosen == STRATEGIES else chosen, args.json)


if __name__ == "__main__":
    main()
