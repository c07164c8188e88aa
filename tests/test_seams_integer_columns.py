"""A term on any column completes with its plots; a whole-number column (balls) gets whole-number grids.

Issue 32: data with a ball-count effect failed the calibration job at 90 % ("balls must be a whole number;
got 4.067"): the effect plot fed fractional ball counts to the physics. The rivals' scan over a driver
skipped every fractional ball count, so it looked at the two ends of its range alone.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from fastapi.testclient import TestClient
from jobs_helper import job_result

from microbearing import physics
from microbearing.calibrate import CalibratedModel, parse_rows
from microbearing.calibrate.candidates import EffectTerm
from microbearing.calibrate.domain import DataCloud
from microbearing.calibrate.plots import calibration_figures
from microbearing.calibrate.rivals import where_they_part
from microbearing.physics.effects import EFFECTS
from microbearing.service.app import create_app
from microbearing.service.cli import main
from microbearing.service.settings import Settings

N_ROWS = 80
BASE = ("balls", "load_N", "speed_m_s")
# Every column a term can be put on: each numeric physics input a data column may hold, and conditions.
CONDITIONS = {"relative_humidity": (0.2, 0.8), "temperature_C": (20.0, 40.0), "cycles": (0.0, 1000.0)}
COLUMNS = [name for name, p in physics.PARAMETERS.items() if p.kind != "bool"] + list(CONDITIONS)


def columns_with(column: str, seed: int = 0) -> dict[str, np.ndarray]:
    """Ball counts 3..12, loads, speeds, and ``column`` varying inside its declared range."""
    rng = np.random.default_rng(seed)
    c = {"balls": rng.integers(3, 13, N_ROWS).astype(float),
         "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), N_ROWS)),
         "speed_m_s": rng.uniform(0.01, 0.15, N_ROWS)}
    if column in CONDITIONS:
        low, high = CONDITIONS[column]
        c[column] = rng.uniform(low, high, N_ROWS)
        if column == "cycles":
            c[column] = np.round(c[column])
    elif column not in c:
        spec = physics.PARAMETERS[column]
        c[column] = np.clip(spec.default * np.exp(rng.uniform(-0.3, 0.3, N_ROWS)), *spec.closed_range)
    return c


def as_rows(columns: dict[str, np.ndarray], mu: np.ndarray) -> list[dict]:
    return [{k: float(v[i]) for k, v in columns.items()} | {"mu_measured": float(mu[i])}
            for i in range(mu.size)]


def fitted_for(column: str) -> dict[str, float]:
    """The fitted declared parameter: mu_pivot, unless the data give it as a column."""
    return {"mu_ball": 0.5} if column == "mu_pivot" else {"mu_pivot": 0.7}


def model_with_term(columns: dict[str, np.ndarray], column: str, effect: str, values: list[float]):
    term = EffectTerm(effect, (column,), EFFECTS[effect].constants(columns, (column,)))
    conditions = [c for c in columns if c in CONDITIONS]
    varying = {k: v for k, v in columns.items() if np.unique(v).size > 1}
    size = 1 + len(values)
    domain = {name: [float(np.min(v)), float(np.max(v))] for name, v in columns.items()}
    return CalibratedModel(fitted=fitted_for(column), terms=[(term, list(values))],
                           convention=physics.DEFAULT_CONVENTION, covariance=np.eye(size) * 1e-4,
                           noise_std_log=0.02, domain=domain, conditions=conditions,
                           cloud=DataCloud.from_columns(varying), domain_rows=N_ROWS)


def whole_ticks(ax) -> np.ndarray:
    low, high = ax.get_xlim()
    ticks = np.asarray(ax.get_xticks(), dtype=float)
    return ticks[(ticks >= low) & (ticks <= high)]


@pytest.mark.parametrize("column", COLUMNS)
def test_a_term_on_any_column_draws_its_plots(column):
    columns = columns_with(column)
    model = model_with_term(columns, column, "generic_linear", [0.2])
    rng = np.random.default_rng(1)
    mu = model(columns) * np.exp(rng.normal(0.0, 0.02, N_ROWS))
    dataset = parse_rows(as_rows(columns, mu))
    before = physics.evaluate(**{**fitted_for(column), **dataset.inputs()}).mu
    errors = {"before": {"relative_rmse": 0.1}, "after": {"relative_rmse": 0.02}}
    figures = calibration_figures(dataset, model, before, model(columns), np.zeros(N_ROWS, bool), errors,
                                  [model.terms[0][0].label])
    assert sorted(figures) == ["effect_1", "measured_vs_predicted", "residuals"]
    effect_axes = figures["effect_1"].axes[0]
    curve = effect_axes.lines[0].get_xydata()
    assert np.all(np.isfinite(curve))
    # The drawn term is the model's log(mu / mu without it) = c1 (x - centre) / scale, by hand.
    constants = model.terms[0][0].constants
    np.testing.assert_allclose(curve[:, 1], 0.2 * (curve[:, 0] - constants["centre"]) / constants["scale"],
                               rtol=1e-9, atol=1e-12)
    x = columns[column]
    assert curve[0, 0] == pytest.approx(x.min()) and curve[-1, 0] == pytest.approx(x.max())
    whole = physics.PARAMETERS.get(column) is not None and physics.PARAMETERS[column].kind == "int"
    if whole:
        # Every whole number of the data's range, once, and whole-number ticks.
        np.testing.assert_array_equal(curve[:, 0], np.arange(x.min(), x.max() + 1))
        ticks = whole_ticks(effect_axes)
        assert ticks.size >= 3 and np.all(ticks == np.round(ticks)), ticks
    residual_axes = [ax for ax in figures["residuals"].axes if ax.get_xlabel().startswith("balls ")]
    assert len(residual_axes) == 1  # balls vary in every data set here
    ticks = whole_ticks(residual_axes[0])
    assert ticks.size >= 3 and np.all(ticks == np.round(ticks)), ticks
    import matplotlib.pyplot as plt

    for fig in figures.values():
        plt.close(fig)


def test_the_rivals_scan_over_balls_visits_every_whole_ball_count():
    columns = columns_with("balls")
    model = model_with_term(columns, "balls", "generic_power", [0.25])
    rival = model_with_term(columns, "balls", "generic_quadratic", [0.6, 0.1])
    dataset = parse_rows(as_rows(columns, np.full(N_ROWS, 0.01)))
    scan = where_they_part(model, rival, dataset, "balls", 0.02)
    # By hand: the data span 3..12 balls; the scan reaches as far again on either side, every whole ball
    # count from 1 (the physics' least) to 21, the median over the rows of |log(rival / model)| at each.
    largest, at, differ = 0.0, None, []
    for z in range(1, 22):
        points = {**columns, "balls": np.full(N_ROWS, float(z))}
        difference = float(np.median(np.abs(np.log(rival(points) / model(points)))))
        if difference > largest:
            largest, at = difference, float(z)
        if difference > 2 * 0.02:  # apart by more than two noise standard deviations: runs of them
            if differ and differ[-1][1] == z - 1:
                differ[-1][1] = float(z)
            else:
                differ.append([float(z), float(z)])
    assert scan["largest_difference_log"] == pytest.approx(largest, rel=1e-12)
    assert scan["at"] == at
    assert scan["differ"] == differ and differ[0][0] < 21  # (was: [[21, 21]], the one whole value scanned)


# ------------------------------------------------------------------------------- through the API, CLI


def ball_rows() -> list[dict]:
    """The issue's case: truth x (balls / 8)^0.25 over 3..12 balls, 2 % noise."""
    columns = columns_with("balls", seed=3)
    rng = np.random.default_rng(4)
    mu = physics.evaluate(**columns, mu_pivot=0.7).mu * (columns["balls"] / 8) ** 0.25
    mu = mu * np.exp(rng.normal(0.0, 0.02, N_ROWS))
    return as_rows(columns, mu)


def test_a_ball_count_effect_calibrates_with_its_plots_through_the_api(tmp_path):
    with TestClient(create_app(Settings(data_dir=tmp_path))) as client:
        response = client.post("/v1/calibrations", json={"data": ball_rows(), "fit_parameters": ["mu_pivot"],
                                                         "folds": 3})
        result = job_result(client, response, timeout_s=600, interval_s=0.1)
        assert result["effects"][0]["drivers"] == ["balls"], result["decision"]
        assert sorted(result["plots"]) == ["effect_1", "measured_vs_predicted", "residuals"]
        for url in result["plots"].values():
            png = client.get(url)
            assert png.status_code == 200 and png.content.startswith(b"\x89PNG")


def test_a_ball_count_effect_calibrates_with_its_plots_through_the_cli(tmp_path, capsys):
    data = tmp_path / "data.csv"
    rows = ball_rows()
    data.write_text(",".join(rows[0]) + "\n" + "\n".join(",".join(str(v) for v in r.values()) for r in rows))
    code = main(["calibrate", str(data), "--fit", "mu_pivot", "--folds", "3", "--no-store",
                 "--plots", str(tmp_path / "plots"), "--json", str(tmp_path / "report.json")])
    assert code == 0, capsys.readouterr().err
    assert sorted(p.name for p in (tmp_path / "plots").iterdir()) == [
        "effect_1.png", "measured_vs_predicted.png", "residuals.png"]
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["model"]["terms"][0]["drivers"] == ["balls"]
