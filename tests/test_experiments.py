"""calibrate.experiments: the next runs for the friction model, rivals, first designs, the plot."""

import numpy as np
import pytest
from labs_helper import kelvin_rows

from microbearing import physics
from microbearing.calibrate import calibrate, parse_rows
from microbearing.calibrate.design import DesignError
from microbearing.calibrate.experiments import (
    ExperimentRequest,
    candidate_points,
    first_experiments,
    next_experiments,
    plan_png,
    rival_models,
)

SPACE = {"balls": {"low": 4, "high": 8}, "load_N": {"low": 3e-3, "high": 3e-2, "spacing": "log"},
         "speed_m_s": {"low": 0.0, "high": 0.15}, "relative_humidity": {"low": 0.2, "high": 0.9}}


@pytest.fixture(scope="module")
def humid():
    dataset = parse_rows(kelvin_rows(3, 150))  # 20-50 % RH, 2 % scatter
    report = calibrate(dataset, ["mu_pivot", "adhesion_energy_J_m2"], make_plots=False)
    return dataset, report


def test_candidates_hold_every_ball_count_and_the_ends_of_every_range():
    points = candidate_points(SPACE)
    assert set(np.unique(points["balls"]).tolist()) == {4.0, 5.0, 6.0, 7.0, 8.0}
    for name in ("load_N", "speed_m_s", "relative_humidity"):
        assert points[name].min() == pytest.approx(SPACE[name]["low"])
        assert points[name].max() == pytest.approx(SPACE[name]["high"])
    assert np.unique(points["relative_humidity"]).size > 5  # the Sobol' set fills between the levels


def test_the_rivals_of_a_kelvin_drift_include_the_linear_law(humid):
    dataset, report = humid
    rivals = rival_models(report.to_dict(), dataset, report.model)
    labels = [label for label, _ in rivals]
    assert any("(linear)" in label for label in labels), labels
    for _, rival in rivals:  # each rival is refitted: it predicts the data about as well as the model
        mu = rival(dataset.columns())
        assert np.sqrt(np.mean(np.log(mu / dataset.mu_measured) ** 2)) < 0.1


def test_discriminate_goes_where_the_rivals_part(humid):
    dataset, report = humid
    rivals = rival_models(report.to_dict(), dataset, report.model)
    proposal = next_experiments(report.model, ExperimentRequest(SPACE, 20, "discriminate"), rivals=rivals,
                                data=dataset.columns())
    result = proposal.to_dict()
    assert len(result["runs"]) == 20
    for run in result["runs"]:
        assert isinstance(run["balls"], int) and 4 <= run["balls"] <= 8
        assert 3e-3 * (1 - 1e-9) <= run["load_N"] <= 3e-2 * (1 + 1e-9)
        assert 0.2 <= run["conditions"]["relative_humidity"] <= 0.9
    humidity = np.array([r["conditions"]["relative_humidity"] for r in result["runs"]])
    assert np.mean(humidity > 0.5) >= 0.5  # beyond the data (20-50 % RH), where the laws part
    assert 0.0 <= result["efficiency_lower_bound"] <= 1.0 and result["efficiency_lower_bound"] > 0.8
    # The expected separation is the rival's weighted least-squares misfit at the runs, recomputed
    # here from its predictions alone (linearized: a rival may shift its parameters).
    for rival in result["rivals"]:
        log_ratio = np.log(np.array(rival["mu_at_runs"]) / np.array(result["mu_reference_at_runs"]))
        unrefitted = float(np.sum((log_ratio / report.model.noise_std_log) ** 2))
        assert 0.0 < rival["expected_chi2_separation"] <= unrefitted * 1.001
    assert result["plot"]["axes"][0] == "relative_humidity"
    png = plan_png(result)
    assert png[:8] == b"\x89PNG\r\n\x1a\n"


def test_parameters_and_predict_shrink_what_they_target(humid):
    _dataset, report = humid
    envelope = {"balls": [6], "load_N": {"low": 0.005, "high": 0.02}, "speed_m_s": [0.05],
                "relative_humidity": {"low": 0.7, "high": 0.85}}
    d = next_experiments(report.model, ExperimentRequest(SPACE, 20, "parameters", envelope=envelope))
    d = d.to_dict()
    for p in d["parameters"]:
        assert p["std_after"] <= p["std_now"] * (1 + 1e-9)
    i = next_experiments(report.model, ExperimentRequest(SPACE, 20, "predict", envelope=envelope)).to_dict()
    assert i["envelope"]["mean_half_width_after"]["mean"] < 0.8 * i["envelope"]["mean_half_width_now"]["mean"]
    # predict's runs narrow the envelope's interval as the service reports it (widened off the data cloud
    # and the inputs' ranges: issue 33, item 8) at least as much as the D-optimal ones, and the parameters'
    # share of it about as much (predict trades a little of it for rows near the envelope).
    after = i["envelope"]["reported_half_width_after"]["mean"]
    assert after <= d["envelope"]["reported_half_width_after"]["mean"] * 1.001
    share = i["envelope"]["mean_half_width_after"]["mean"]
    assert share <= d["envelope"]["mean_half_width_after"]["mean"] * 1.1
    assert not any(r["in_domain"] for r in i["runs"] if r["conditions"]["relative_humidity"] > 0.5 + 1e-9)


def test_a_rival_carries_its_own_scatter_and_the_models_data_cloud(humid):
    # A term the model lacks inflates its scatter; a rival's interval (hedged by predict) uses the rival's
    # own: the RMS of its log residual on the data with n - p degrees of freedom, recomputed here from its
    # predictions, times the small-sample/tail factor the model's interval applies.
    dataset, report = humid
    model = report.model
    factor = model.interval_noise_std_log() / model.noise_std_log
    n = dataset.mu_measured.size
    for _, rival in rival_models(report.to_dict(), dataset, model):
        residual = np.log(rival(dataset.columns()) / dataset.mu_measured)
        p = len(rival.fitted) + sum(len(v) for _, v in rival.terms)
        assert rival.noise_std_log == pytest.approx(np.sqrt(np.sum(residual**2) / (n - p)) * factor, rel=1e-3)
        assert rival.cloud is model.cloud


def test_predict_with_rivals_spreads_its_runs_where_they_part(humid):
    # Issue 33, item 8: the runs hedge against the terms a recalibration may add (the rivals'), at two
    # runs per setting at most (a setting's replicates are held out together), and beyond the data
    # (20-50 % RH) towards the envelope, where the rivals' laws part.
    dataset, report = humid
    envelope = {"balls": [6], "load_N": {"low": 0.005, "high": 0.02}, "speed_m_s": [0.05],
                "relative_humidity": {"low": 0.7, "high": 0.85}}
    rivals = rival_models(report.to_dict(), dataset, report.model)
    result = next_experiments(report.model, ExperimentRequest(SPACE, 12, "predict", envelope=envelope),
                              rivals=rivals, data=dataset.columns()).to_dict()
    settings = [(r["balls"], r["load_N"], r["speed_m_s"], r["conditions"]["relative_humidity"])
                for r in result["runs"]]
    assert len(settings) == 12 and max(settings.count(s) for s in settings) <= 2
    humidity = np.array([s[3] for s in settings])
    assert np.mean(humidity > 0.5) >= 0.5, humidity
    figures = result["envelope"]
    assert figures["reported_half_width_after"]["mean"] < figures["reported_half_width_now"]["mean"]


def test_the_promise_in_mu_spans_where_mu_may_lie_now(humid):
    # Off the data (80 % RH against 20-50 %) the runs may find mu moved, so the half-width after in mu's
    # units is the relative promise times wherever mu turns out to lie: each end of its span is that
    # fraction times the end of today's 95 % interval at the point, or a rival's mu beyond it (a law the
    # data lean to), recomputed here from the models' own predictions.
    dataset, report = humid
    at = {"balls": 6.0, "load_N": 0.01, "speed_m_s": 0.05, "relative_humidity": 0.8}
    rivals = rival_models(report.to_dict(), dataset, report.model)
    figures = next_experiments(report.model, ExperimentRequest(SPACE, 8, "predict",
                                                               envelope={k: [v] for k, v in at.items()}),
                               rivals=rivals, data=dataset.columns()).to_dict()["envelope"]
    now = report.model.predict(at)
    relative = figures["reported_relative_half_width_after"]["mean"]
    span = figures["reported_half_width_after_span"]
    mus = [float(report.model(at)), *(float(rival(at)) for _, rival in rivals)]
    low, high = min(float(now.mu_lower), *mus), max(float(now.mu_upper), *mus)
    assert span["low"] / relative in [pytest.approx(m, rel=1e-9) for m in [low, *mus]]
    assert span["low"] <= relative * low * (1 + 1e-9)
    assert span["high"] / relative in [pytest.approx(m, rel=1e-9) for m in [high, *mus]]
    assert span["high"] >= relative * float(now.mu_upper) * (1 - 1e-9)
    assert span["low"] <= figures["reported_half_width_after"]["mean"] <= span["high"]


def test_first_design_of_one_parameter_puts_every_run_where_it_moves_mu_most():
    # D-optimal for one parameter: all runs where |d log mu / d mu_pivot| is largest, checked by a
    # central difference of the physics at every candidate.
    space = {"balls": {"low": 4, "high": 12}, "load_N": {"low": 1e-3, "high": 3e-2, "spacing": "log"},
             "speed_m_s": {"low": 0.0, "high": 0.15}}
    result = first_experiments(["mu_pivot"], ExperimentRequest(space, 6, "parameters"), noise_std_log=0.03)
    result = result.to_dict()
    points = candidate_points(space)

    def log_mu(value):
        return np.log(physics.evaluate(balls=points["balls"], load_N=points["load_N"],
                                       speed_m_s=points["speed_m_s"], mu_pivot=value).mu)

    sensitivity = np.abs(log_mu(0.5 + 1e-4) - log_mu(0.5 - 1e-4)) / 2e-4
    best = np.argmax(sensitivity)
    for run in result["runs"]:
        assert run["balls"] == int(points["balls"][best])
        assert run["load_N"] == pytest.approx(points["load_N"][best], rel=1e-9)
    std = result["parameters"][0]["std_after"]
    assert std == pytest.approx(0.03 / np.sqrt(6) / sensitivity[best], rel=1e-3)
    assert result["parameters"][0]["std_now"] is None


def test_bad_requests_name_the_field(humid):
    _dataset, report = humid
    with pytest.raises(ValueError, match=r"space\.temperature_C"):
        next_experiments(report.model,
                         ExperimentRequest({**SPACE, "temperature_C": [20, 30]}, 5, "parameters"))
    with pytest.raises(ValueError, match=r"space\.load_N"):
        next_experiments(report.model,
                         ExperimentRequest({**SPACE, "load_N": {"low": -1, "high": 1}}, 5, "parameters"))
    # no rival to tell apart (issue 33, item 8): the runs explore where the data say least, the reason said
    explored = next_experiments(report.model, ExperimentRequest(SPACE, 5, "discriminate")).to_dict()
    assert explored["goal"] == "discriminate" and "no rival model" in explored["warnings"][0]
    with pytest.raises(ValueError, match="relative_humidity"):
        next_experiments(report.model, ExperimentRequest(
            {k: v for k, v in SPACE.items() if k != "relative_humidity"}, 5, "parameters"))
    with pytest.raises(DesignError, match="goal must be parameters or predict"):
        first_experiments(["mu_pivot"], ExperimentRequest(SPACE, 5, "discriminate"))


def test_the_manual_loop_runs_and_prints_what_it_says(tmp_path, monkeypatch, capsys):
    from docs_pages import page

    section = page("how-to/next-experiments.md")
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    printed = section.split("prints\n\n```\n", 1)[1].split("```", 1)[0].strip().splitlines()
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "docs/pages/how-to/next-experiments.md", "exec"), {})
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == len(printed)
    assert lines[0] == printed[0] and lines[3] == printed[3]  # nothing named first; the Kelvin law after
    assert lines[1].startswith(printed[1][:22])  # the bound
    assert lines[-1] == printed[-1]  # the truth
    after = float(lines[-2].split("mu = ")[1].split(",")[0])
    truth = float(printed[-1].split("mu = ")[1])
    assert after == pytest.approx(truth, rel=0.05)
    low, high = (float(x) for x in lines[-2].split("[")[1].split("]")[0].split(","))
    assert low <= truth <= high  # the recalibrated interval holds the truth off the first data
    assert (tmp_path / "next-runs.png").read_bytes()[:4] == b"\x89PNG"


def test_frozen_base_sensitivity_of_a_parameter_fitted_at_its_upper_bound():
    # A recalibration of the bench crashed here: adhesion fitted at its bound 10 J/m^2, bumped up, left
    # its range. The bump now goes down there; the sensitivity matches a one-sided difference made here.
    from microbearing.calibrate.fit import FitResult
    from microbearing.calibrate.search import frozen_base
    from microbearing.calibrate.select import ModelCV

    rows = [{"balls": 4.0, "load_N": load, "speed_m_s": 0.05, "mu_measured": 0.02}
            for load in (0.003, 0.01, 0.03)]
    dataset = parse_rows(rows)
    top = physics.PARAMETERS["adhesion_energy_J_m2"].maximum
    full = FitResult({"adhesion_energy_J_m2": top}, (), [], ["adhesion_energy_J_m2"], np.array([top]),
                     np.eye(1), 0.02, np.zeros(3), ["adhesion_energy_J_m2"], True)
    current = ModelCV((), [], [], [], np.full(3, 0.02), full)
    base = frozen_base(dataset, ["adhesion_energy_J_m2"], current, [], physics.DEFAULT_CONVENTION)

    def mu(gamma):
        return physics.evaluate(balls=4, load_N=np.array([0.003, 0.01, 0.03]), speed_m_s=0.05,
                                adhesion_energy_J_m2=gamma).mu

    expected = np.log(mu(top * (1 - 1e-4)) / mu(top)) / np.log1p(-1e-4)
    assert np.allclose(base.sensitivity["adhesion_energy_J_m2"], expected, rtol=1e-9)
    assert np.all(expected > 0)


def test_a_replicate_count_at_a_corner_of_the_space_stays_inside_the_plot(monkeypatch):
    # four runs at the space's top-right corner and two at its bottom-left: each count ("x4", "x2") is
    # drawn towards the panel's middle, inside the figure (it was cut at the right edge)
    document = {"goal": "parameters", "efficiency_lower_bound": 0.9,
                "plot": {"axes": ["load_N", "speed_m_s"],
                         "runs": {"load_N": [0.03] * 4 + [0.003] * 2, "speed_m_s": [0.15] * 4 + [0.0] * 2}}}
    import matplotlib.figure

    drawn = []
    save = matplotlib.figure.Figure.savefig
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig",
                        lambda self, *a, **k: (drawn.append(self), save(self, *a, **k))[1])
    assert plan_png(document)[:8] == b"\x89PNG\r\n\x1a\n"
    figure = drawn[0]
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = FigureCanvasAgg(figure).get_renderer()  # the closed figure, drawn again as it was saved
    counts = [t for t in figure.axes[0].texts if t.get_text().startswith("x")]
    assert sorted(t.get_text() for t in counts) == ["x2", "x4"]
    for text in counts:
        box, frame = text.get_window_extent(renderer), figure.axes[0].get_window_extent(renderer)
        assert frame.x0 <= box.x0 and box.x1 <= frame.x1 and frame.y0 <= box.y0 and box.y1 <= frame.y1, text
