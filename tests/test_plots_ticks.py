"""Plots a person reads (issue 28, item 5): numbered ticks on every axis at every data range.

Each plot of a calibration (every term against its driver, the residuals, measured against
predicted) and the Pareto front is drawn from data over a narrow and a wide range; every axis (or
its shared sibling) must show at least two distinct tick labels inside its view, and the panels of
the Pareto front must not draw two quantities on one another.
"""

from __future__ import annotations

import matplotlib
import numpy as np
import pytest

from microbearing import physics
from microbearing.calibrate import calibrate, parse_rows
from microbearing.calibrate.plots import calibration_figures, log_ticks, tick_texts
from microbearing.optimize.pareto import ParetoFront

matplotlib.use("Agg")


def shown_labels(axis) -> list[str]:
    """Texts of the tick labels drawn on an axis, inside its view."""
    low, high = sorted(axis.get_view_interval())
    ticks = axis._update_ticks()  # the ticks matplotlib draws (private, stable since 3.1)
    return [t.label1.get_text() for t in ticks
            if low <= t.get_loc() <= high and t.label1.get_visible() and t.label1.get_text()]


def assert_every_axis_numbered(fig, where: str) -> None:
    fig.canvas.draw()
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        for name in ("x", "y"):
            group = getattr(ax, f"get_shared_{name}_axes")().get_siblings(ax)
            labels = {text for sibling in group for text in shown_labels(getattr(sibling, f"{name}axis"))}
            assert len(labels) >= 2, f"{where}: axes {ax.get_ylabel() or ax.get_title()!r} {name}: {labels}"


def test_log_ticks_always_give_three_numbers_inside_the_range():
    rng = np.random.default_rng(0)
    for _ in range(2000):
        low = 10 ** rng.uniform(-9, 3)
        high = low * 10 ** rng.uniform(0.001, 8)
        ticks = log_ticks(low, high)
        assert len(ticks) >= 3 and all(low <= t <= high for t in ticks), (low, high, ticks)
        assert len(set(tick_texts(ticks))) == len(ticks), (low, high, ticks)  # distinct labels


def rows(seed: int, wide: bool) -> list[dict]:
    """Measurements with menisci growing with humidity: over decades of load (wide) or a sliver (narrow)."""
    rng = np.random.default_rng(seed)
    n = 90
    load = np.exp(rng.uniform(np.log(1e-4), np.log(1e-1), n)) if wide else rng.uniform(8.80e-3, 8.82e-3, n)
    humidity = rng.uniform(0.05, 0.95, n) if wide else rng.uniform(0.500, 0.505, n)
    speed = rng.uniform(0.0, 0.15, n) if wide else rng.uniform(0.0500, 0.0501, n)
    mu = physics.evaluate(balls=4, load_N=load, speed_m_s=speed, mu_pivot=0.7).mu
    mu = (mu + 4 * 2e-5 / (load * np.log(1 / humidity))) * np.exp(rng.normal(0.0, 0.01, n))
    return [{"balls": 4, "load_N": a, "speed_m_s": s, "relative_humidity": h, "mu_measured": m}
            for a, s, h, m in zip(load, speed, humidity, mu, strict=True)]


@pytest.mark.parametrize("wide", [False, True])
def test_every_calibration_plot_is_numbered_on_every_axis(wide):
    dataset = parse_rows(rows(1, wide))
    report = calibrate(dataset, ["mu_pivot"], folds=3)
    measured = dataset.mu_measured
    assert (measured.max() / measured.min() > 100) == wide  # the two ranges are what they claim
    model = report.model
    mu_after = np.asarray(model(dataset.columns()), dtype=float)
    mu_before = np.asarray(physics.evaluate(**dataset.inputs(), mu_pivot=0.7).mu, dtype=float)
    errors = {"before": report.error_before, "after": report.error_after}
    no_outliers = np.zeros(dataset.n_points, bool)
    figures = calibration_figures(dataset, model, mu_before, mu_after, no_outliers, errors,
                                  [e["name"] for e in report.effects])
    assert {"residuals", "measured_vs_predicted"} <= set(figures)
    if wide:
        assert "effect_1" in figures, report.decision
    for name, fig in figures.items():
        assert_every_axis_numbered(fig, f"{name} ({'wide' if wide else 'narrow'})")
        matplotlib.pyplot.close(fig)


def front(objective: str, wide: bool) -> ParetoFront:
    n = 6
    value = np.geomspace(1e6, 1e9, n) if wide else np.linspace(5.00e8, 5.05e8, n)
    if objective == "load_N":
        value = np.geomspace(1e-4, 1e-1, n) if wide else np.linspace(8.80e-3, 8.82e-3, n)
    mu = np.linspace(0.0112, 0.0113, n) if not wide else np.geomspace(0.002, 0.5, n)
    points = [{"level": float(v), "value": float(v), "mu": float(m),
               # the angle constant along the front
               "design": {"balls": 4 + 2 * (k % 2), "groove_angle_deg": 54.7,
                          "load_N": 0.0088 if not wide else float(np.geomspace(1e-4, 1e-1, n)[k])}}
              for k, (v, m) in enumerate(zip(value, mu, strict=True))]
    return ParetoFront(objective, points, 0)


@pytest.mark.parametrize("objective", ["load_N", "max_contact_pressure_Pa"])
@pytest.mark.parametrize("wide", [False, True])
def test_the_pareto_plot_is_numbered_and_draws_each_quantity_in_its_own_panel(objective, wide):
    fig = front(objective, wide).figure()
    assert_every_axis_numbered(fig, f"pareto {objective} ({'wide' if wide else 'narrow'})")
    # one quantity per panel: no twin axes drawing load and angle on top of each other
    lines = [[line for line in ax.get_lines() if len(line.get_xdata()) > 1] for ax in fig.axes]
    assert all(len(panel) <= 1 for panel in lines), [len(p) for p in lines]
    ylabels = [ax.get_ylabel() for ax in fig.axes]
    assert len(set(ylabels)) == len(ylabels) == (2 if objective == "load_N" else 3), ylabels
    assert front(objective, wide).to_png().startswith(b"\x89PNG")


def test_the_plots_speak_the_upload_s_units_and_count_balls_in_whole_numbers():
    from microbearing.calibrate import CalibratedModel, Dataset
    from microbearing.calibrate.candidates import EffectTerm
    from microbearing.calibrate.tabular import read_rows
    from microbearing.physics.effects import EFFECTS

    rng = np.random.default_rng(3)
    n = 60
    si = {"balls": rng.integers(3, 13, n).astype(float),
          "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
          "speed_m_s": rng.uniform(0.01, 0.15, n), "relative_humidity": rng.uniform(0.2, 0.8, n)}
    term = EffectTerm("generic_linear", ("relative_humidity",),
                      EFFECTS["generic_linear"].constants(si, ("relative_humidity",)))
    model = CalibratedModel(fitted={"mu_pivot": 0.7}, terms=[(term, [0.2])],
                            convention=physics.DEFAULT_CONVENTION, covariance=np.eye(2) * 1e-4,
                            noise_std_log=0.02, conditions=["relative_humidity"])
    mu = model(si) * np.exp(rng.normal(0.0, 0.02, n))
    # the lab's upload: mN, mm/s and percent (converted by hand)
    rows = [{"balls": si["balls"][i], "load [mN]": 1e3 * si["load_N"][i],
             "speed_mm_s": 1e3 * si["speed_m_s"][i],
             "relative humidity [%]": 100 * si["relative_humidity"][i], "mu_measured": mu[i]}
            for i in range(n)]
    dataset, _ = read_rows(rows)
    assert dataset.headers == {"load_N": "load [mN]", "speed_m_s": "speed_mm_s",
                               "relative_humidity": "relative humidity [%]"}
    np.testing.assert_allclose(dataset.physics_columns["speed_m_s"], si["speed_m_s"], rtol=1e-12)
    # the one serialization (the job's and the store's) keeps the headers
    again = Dataset.from_columns(dataset.to_columns(), dataset.fixed)
    assert again.headers == dataset.headers
    before = physics.evaluate(**dataset.inputs(), mu_pivot=0.7).mu
    errors = {"before": {"relative_rmse": 0.1}, "after": {"relative_rmse": 0.02}}
    figures = calibration_figures(again, model, before, model(dataset.columns()), np.zeros(n, bool), errors,
                                  [term.label])
    effect = figures["effect_1"].axes[0]
    assert effect.get_xlabel() == "relative humidity [%]"
    # the title names the term by the header as sent too (it said relative_humidity over a % axis)
    title = effect.get_title()
    assert title.startswith("Term 1: generic_linear on relative humidity [%]"), title
    curve = effect.lines[0].get_xydata()
    percent = 100 * si["relative_humidity"]
    assert curve[0, 0] == pytest.approx(percent.min()) and curve[-1, 0] == pytest.approx(percent.max())
    # the drawn term is the model's, read at the fraction: 0.2 (x / 100 - centre) / scale
    np.testing.assert_allclose(curve[:, 1], 0.2 * (curve[:, 0] / 100 - term.constants["centre"])
                               / term.constants["scale"], rtol=1e-9, atol=1e-12)
    drawn = effect.collections[0].get_offsets()[:, 0]
    np.testing.assert_allclose(np.sort(drawn), np.sort(percent), rtol=1e-12)
    # and the residuals' title as the effect's (it said relative_humidity, the column's SI name)
    assert figures["residuals"].get_suptitle().startswith(
        "Residuals after generic_linear on relative humidity [%]\n"), figures["residuals"].get_suptitle()
    panels = {ax.get_xlabel(): ax for ax in figures["residuals"].axes if ax.get_visible()}
    assert set(panels) == {"balls [1]", "load [mN]", "speed_mm_s [mm/s]", "relative humidity [%]"}, panels
    speeds = panels["speed_mm_s [mm/s]"].collections[0].get_offsets()[:, 0]
    np.testing.assert_allclose(np.sort(speeds), np.sort(1e3 * si["speed_m_s"]), rtol=1e-12)
    figures["residuals"].canvas.draw()
    low, high = panels["balls [1]"].get_xlim()
    ticks = [t for t in panels["balls [1]"].get_xticks() if low <= t <= high]
    assert len(ticks) >= 3 and all(t == round(t) for t in ticks), ticks
    for name, fig in figures.items():
        assert_every_axis_numbered(fig, name)
        matplotlib.pyplot.close(fig)
