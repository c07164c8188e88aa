"""Issue 24, items 1-3: factor columns and the spread between groups, scatter that depends on the inputs,
the data cloud and columns that move together. Checked against the generating truth, hand-computed
estimators and brute force."""

from __future__ import annotations

import numpy as np
import pytest
from jobs_helper import finished_job
from scipy import stats

from microbearing import physics
from microbearing.calibrate import DataError, calibrate, parse_csv, parse_rows
from microbearing.calibrate.domain import REPLICATE_JITTER, DataCloud, confounded_pairs
from microbearing.calibrate.groups import fit_group_effect
from microbearing.calibrate.scatter import fit_scatter

TRUE_PIVOT = 0.7


def _columns(rng, n):
    return {"balls": rng.choice([4, 6, 8], n).astype(float),
            "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
            "speed_m_s": rng.uniform(0.005, 0.15, n)}


def _mu(c, **values):
    return physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"],
                            **{"mu_pivot": TRUE_PIVOT, **values}).mu


def builds(seed, groups=8, rows=25, spread=0.15, noise=0.02, coded=False):
    """Rows of several builds, each with its own mu_pivot, and the true levels."""
    rng = np.random.default_rng(seed)
    level = TRUE_PIVOT * np.exp(rng.normal(0.0, spread, groups))
    data = []
    for g in range(groups):
        c = _columns(rng, rows)
        mu = _mu(c, mu_pivot=level[g]) * np.exp(rng.normal(0.0, noise, rows))
        data += [{k: float(v[i]) for k, v in c.items()} | {"specimen": g + 1 if coded else f"S{g + 1}",
                                                          "mu_measured": float(mu[i])} for i in range(rows)]
    return data, level


# ---------------------------------------------------------------------------------------------- parsing


def test_a_column_of_labels_is_a_factor_and_integer_codes_only_when_declared():
    text = ("balls,load_N,speed_m_s,specimen,batch,mu_measured\n"
            "4,0.01,0.05,S1,1,0.011\n4,0.01,0.06,S2,2,0.012\n4,0.01,0.07,S1,2,0.013\n")
    data = parse_csv(text)
    assert list(data.factors) == ["specimen"] and data.factors["specimen"].tolist() == ["S1", "S2", "S1"]
    assert "specimen" not in data.conditions and data.conditions["batch"].tolist() == [1.0, 2.0, 2.0]
    declared = parse_csv(text, factors=["batch"])
    assert declared.factors["batch"].tolist() == ["1", "2", "2"] and "batch" not in declared.conditions
    # JSON rows: numbers and strings of a declared factor give the same labels as CSV text; subsets keep them.
    rows = [{"balls": 4, "load_N": 0.01, "speed_m_s": 0.05, "batch": b, "mu_measured": 0.01}
            for b in (1, 2.0, "2")]
    subset = parse_rows(rows, factors=["batch"]).subset(np.array([2, 0]))
    assert subset.factors["batch"].tolist() == ["2", "1"]


def test_a_condition_column_with_numbers_and_labels_names_each_label_and_the_way_out():
    text = "balls,load_N,speed_m_s,specimen,mu_measured\n4,0.01,0.05,1,0.011\n4,0.01,0.06,S2,0.012\n"
    with pytest.raises(DataError) as caught:
        parse_csv(text)
    assert [(e["row"], e["column"]) for e in caught.value.errors] == [(2, "specimen")]
    assert "declare specimen in factors" in caught.value.errors[0]["message"]
    with pytest.raises(DataError) as unknown:
        parse_csv(text, factors=["operator", "load_N"])
    assert {e["column"] for e in unknown.value.errors} >= {"operator", "load_N"}


# --------------------------------------------------------------------------------------------- groups


def test_the_spread_between_groups_is_the_one_way_anova_estimate_on_balanced_data():
    """REML of a balanced one-way random-effects model is the ANOVA estimator (MSB - MSW) / n when that is
    positive; its within-group variance is MSW. Computed here by hand."""
    rng = np.random.default_rng(5)
    groups, rows = 7, 12
    labels = np.repeat([f"G{g}" for g in range(groups)], rows)
    y = np.repeat(rng.normal(0.0, 0.1, groups), rows) + rng.normal(0.0, 0.03, groups * rows)
    effect = fit_group_effect("specimen", labels, y, {})
    means = y.reshape(groups, rows).mean(axis=1)
    msb = rows * np.sum((means - y.mean()) ** 2) / (groups - 1)
    msw = np.sum((y.reshape(groups, rows) - means[:, None]) ** 2) / (groups * (rows - 1))
    assert effect.parameter == "mu"
    assert effect.spread_log == pytest.approx(np.sqrt((msb - msw) / rows), rel=1e-3)
    assert effect.noise_log == pytest.approx(np.sqrt(msw), rel=1e-3)
    # Each group's level is its mean shrunk toward the overall mean by tau^2 / (tau^2 + sigma^2 / n).
    shrink = effect.spread_log**2 / (effect.spread_log**2 + msw / rows)
    for g, mean in enumerate(means):
        assert effect.levels[f"G{g}"][0] == pytest.approx(shrink * (mean - y.mean()), abs=1e-4)
    lo, hi = effect.spread_interval
    assert lo < effect.spread_log < hi
    # A new group's variance: the wider of tau^2 (1 + 1/G) with Student's t of G - 1 degrees of freedom for
    # z, and the tolerance rule: on balanced data the Q-profile bound is S / chi2_{0.05, G-1} - w (S the sum
    # of squares of the group means about their mean, w = sigma^2 / n), the mean level's variance at it
    # (tau_U^2 + w) / G, on the normal quantile of 90 % content.
    t, z = stats.t.isf(0.025, groups - 1), stats.norm.isf(0.025)
    prediction = effect.spread_log**2 * (1 + 1 / groups) * (t / z) ** 2
    w = effect.noise_log**2 / rows
    upper = np.sum((means - means.mean()) ** 2) / stats.chi2.ppf(0.05, groups - 1) - w
    tolerance = (upper + (upper + w) / groups) * (stats.norm.isf(0.05) / z) ** 2
    assert effect.spread_upper() == pytest.approx(np.sqrt(upper), rel=1e-6)
    assert effect.new_group_variance() == pytest.approx(max(prediction, tolerance), rel=1e-6)
    assert tolerance > prediction  # seven groups: the spread's uncertainty decides
    # Stored and read back it answers the same; stored before the group means were kept, the t rule alone.
    from microbearing.calibrate.groups import GroupEffect

    data = effect.to_json()
    assert GroupEffect.from_json(data).new_group_variance() == pytest.approx(effect.new_group_variance())
    assert GroupEffect.from_json({k: v for k, v in data.items() if k != "group_means"}
                                 ).new_group_variance() == pytest.approx(prediction)
    with pytest.raises(ValueError, match="group mean"):
        GroupEffect.from_json({**data, "group_means": [[0.1, -1.0]] * groups})


def test_the_q_profile_bound_holds_the_true_spread_with_its_confidence_on_uneven_groups():
    """Brute force over the generating truth: five groups of uneven precision; the 95 % upper bound of tau^2
    lies above the true tau^2 in 95 % of draws (and the 80 % bound in 80 %)."""
    from microbearing.calibrate.groups import q_profile_upper

    rng = np.random.default_rng(24)
    w = np.array([1e-4, 4e-4, 1e-3, 3e-3, 2e-4])
    tau2 = 0.004
    held = {0.95: 0, 0.8: 0}
    draws = 3000
    for _ in range(draws):
        m = rng.normal(0.1, np.sqrt(tau2 + w))
        for confidence in held:
            held[confidence] += q_profile_upper(m, w, confidence) >= tau2
    assert abs(held[0.95] / draws - 0.95) < 0.015, held
    assert abs(held[0.8] / draws - 0.8) < 0.025, held


def test_a_new_groups_interval_holds_90_percent_in_almost_every_data_set():
    """Per data set, the exact coverage of a new group's 95 % interval (a new group's log mu is N(0, tau^2 +
    sigma^2) about the truth): below 0.90 in at most a few data sets of six groups (the rule's 5 %), while
    Student's t alone misses it in about one in six; the mean coverage stays at least 95 %."""
    import dataclasses

    rng = np.random.default_rng(2424)
    groups, tau, sigma, z = 6, 0.12, 0.03, stats.norm.isf(0.025)
    now, before = [], []
    for _ in range(50):
        rows = rng.integers(10, 41, groups)
        labels = np.repeat([f"G{g}" for g in range(groups)], rows)
        y = np.repeat(rng.normal(0.0, tau, groups), rows) + rng.normal(0.0, sigma, int(rows.sum()))
        effect = fit_group_effect("specimen", labels, y, {})
        s = np.hypot(tau, sigma)
        for e, out in ((effect, now), (dataclasses.replace(effect, group_means=[]), before)):
            half = z * np.sqrt(e.new_group_variance() + e.noise_log**2)
            out.append(stats.norm.cdf((half - e.offset_log) / s) - stats.norm.cdf((-half - e.offset_log) / s))
    now, before = np.array(now), np.array(before)
    assert np.mean(now < 0.9) <= 0.1 and np.mean(now) >= 0.95, (np.sort(now)[:5], np.mean(now))
    assert np.all(now >= before - 1e-12) and np.mean(before < 0.9) > np.mean(now < 0.9)


@pytest.fixture(scope="module")
def grouped():
    data, level = builds(11)
    return calibrate(data, ["mu_pivot"], make_plots=False, seed=11), level


def test_builds_of_one_bearing_give_their_spread_and_intervals_that_cover_known_and_new_builds(grouped):
    result, level = grouped
    assert result.effects == [], result.decision  # a group is no continuous driver: nothing to add
    (group,) = result.groups
    assert group["factor"] == "specimen" and group["parameter"] in ("mu_pivot", "mu")
    # The spread's interval holds this draw's spread of log mu_pivot between the builds (the truth it saw).
    lo, hi = np.log1p(group["spread_interval_relative"])
    assert lo < np.std(np.log(level), ddof=1) < hi
    assert "varies between the 8 groups of specimen" in group["summary"]
    # Each build's level follows its true mu_pivot.
    shifts = [group["levels"][f"S{g + 1}"]["relative_shift"] for g in range(level.size)]
    assert np.corrcoef(shifts, np.log(level))[0, 1] > 0.95
    rng = np.random.default_rng(111)
    model = result.model
    known = []
    for g in range(level.size):
        c = _columns(rng, 200)
        measured = _mu(c, mu_pivot=level[g]) * np.exp(rng.normal(0.0, 0.02, 200))
        p = model.predict({**c, "specimen": np.full(200, f"S{g + 1}")})
        known.append(np.mean((p.mu_lower <= measured) & (measured <= p.mu_upper)))
    assert 0.9 <= np.mean(known) <= 0.99 and min(known) >= 0.8, known
    # New builds (drawn from the same population): their measurements, with no label or a new one.
    covered, widths = [], []
    for _ in range(60):
        c = _columns(rng, 50)
        pivot = TRUE_PIVOT * np.exp(rng.normal(0.0, 0.15))
        measured = _mu(c, mu_pivot=pivot) * np.exp(rng.normal(0.0, 0.02, 50))
        p = model.predict(c)
        assert np.array_equal(p.mu_upper, model.predict({**c, "specimen": "S99"}).mu_upper)
        covered.append(np.mean((p.mu_lower <= measured) & (measured <= p.mu_upper)))
        widths.append(np.median(np.log(p.mu_upper / p.mu_lower)))
    assert 0.9 <= np.mean(covered) <= 1.0, np.mean(covered)
    # Stored as JSON and read back, the model answers the same.
    import json

    from microbearing.calibrate import CalibratedModel

    again = CalibratedModel.from_json(json.loads(json.dumps(model.to_json())))
    for labels in (np.full(50, "S2"), None):
        points = {**c, **({} if labels is None else {"specimen": labels})}
        for name in ("mu", "mu_lower", "mu_upper", "in_domain"):
            np.testing.assert_array_equal(getattr(again.predict(points), name),
                                          getattr(model.predict(points), name))
    # A known build's interval is far narrower than a new one's: it knows the build's level.
    one = model.predict({**{k: v[:1] for k, v in c.items()}, "specimen": "S1"})
    assert np.log(one.mu_upper / one.mu_lower)[0] < 0.5 * np.median(widths)


# -------------------------------------------------------------------------------------------- scatter


def test_scatter_model_finds_a_step_in_speed_and_stays_constant_on_one_spread():
    rng = np.random.default_rng(3)
    n = 400
    speed = rng.uniform(0.001, 0.15, n)
    other = rng.uniform(0.2, 0.8, n)
    residual = rng.normal(0.0, 1.0, n) * np.where(speed < 0.02, 0.10, 0.015)
    model = fit_scatter({"speed_m_s": speed, "relative_humidity": other}, residual)
    assert model.kind == "step" and model.column == "speed_m_s"
    assert 0.012 <= model.split <= 0.03
    below, above = np.exp(model.coefficients)
    assert below == pytest.approx(0.10, rel=0.3) and above == pytest.approx(0.015, rel=0.15)
    assert model.summary().startswith("scatter ") and "below speed_m_s = " in model.summary()
    # One spread everywhere: a non-constant model is chosen with chance 1 % per data set (the permutation
    # test's level), so at most 2 of 30 (binomial: a 0.3 % chance of 3 or more); the spread is 3 %.
    chosen = 0
    for seed in range(30):
        flat = np.random.default_rng(100 + seed)
        plain = fit_scatter({"speed_m_s": flat.uniform(0.001, 0.15, 200),
                             "relative_humidity": flat.uniform(0.2, 0.8, 200)}, flat.normal(0.0, 0.03, 200),
                            seed=seed)
        chosen += plain.kind != "constant"
        if plain.kind == "constant":
            assert np.exp(plain.coefficients[0]) == pytest.approx(0.03, rel=0.15)
            assert "permutation p = " in plain.summary()
    assert chosen <= 2, chosen


# ---------------------------------------------------------------------------------------- the cloud


def test_the_cloud_threshold_is_the_conformal_quantile_of_leave_one_out_distances():
    rng = np.random.default_rng(8)
    n = 300
    speed = rng.uniform(0.005, 0.15, n)
    temperature = 25 + 50 * (speed - 0.005) / 0.145 + rng.normal(0.0, 1.0, n)
    cloud = DataCloud.from_columns({"speed_m_s": speed, "temperature_C": temperature})
    # Brute force: standardized columns (the speed, positive over more than a decade, by its log), the
    # 5th-nearest other row of every row, and its ceil(0.99 (n + 1))-th smallest (the two columns move
    # together, so alpha = 2 % is shared between the k-NN test and the departure from their line).
    log_speed = np.log(speed)
    x = np.column_stack([(log_speed - log_speed.mean()) / log_speed.std(),
                         (temperature - temperature.mean()) / temperature.std()])
    # Measurement jitter: rows within 0.3 % of each other in every column (of the speed, by its log; of the
    # temperature, of its largest value) are replicates of one design point, which the cloud counts once.
    jitter = np.array([np.log1p(REPLICATE_JITTER) / log_speed.std(),
                       REPLICATE_JITTER * np.abs(temperature).max() / temperature.std()])
    kept: list[int] = []
    for i in range(n):
        if not any(np.all(np.abs(x[i] - x[j]) <= jitter) for j in kept):
            kept.append(i)
    x = x[kept]
    distances = np.sqrt(((x[:, None, :] - x[None, :, :]) ** 2).sum(axis=2))
    own = np.sort(distances, axis=1)[:, 5]
    rank = int(np.ceil(0.99 * (len(kept) + 1))) - 1
    threshold = np.sort(own)[rank]
    # The line of the scaled temperature on the scaled speed, the rows' scatter about it, and the same
    # conformal quantile of the rows' departures.
    slope, intercept = np.polyfit(x[:, 0], x[:, 1], 1)
    spread = np.std(x[:, 1] - intercept - slope * x[:, 0])
    line_threshold = np.sort(np.abs(x[:, 1] - intercept - slope * x[:, 0]) / spread)[rank]

    def by_hand(speed_m_s: float, temperature_c: float) -> float:
        scaled = np.array([(np.log(speed_m_s) - log_speed.mean()) / log_speed.std(),
                           (temperature_c - temperature.mean()) / temperature.std()])
        fifth = np.sort(np.sqrt(((x - scaled) ** 2).sum(axis=1)))[4]
        departure = abs(scaled[1] - intercept - slope * scaled[0]) / spread
        return max(fifth / threshold, departure / line_threshold)

    for at in ((0.08, 52.0), (0.1, 45.0), (0.12, 40.0)):  # on the line, then ever farther off it
        ratio, _ = cloud.score({"speed_m_s": np.array([at[0]]), "temperature_C": np.array([at[1]])}, (1,))
        assert ratio[0] == pytest.approx(by_hand(*at), rel=1e-4)
    off_line, _ = cloud.score({"speed_m_s": np.array([0.12]), "temperature_C": np.array([40.0])}, (1,))
    assert off_line[0] > 1  # 20 degC below the line at 120 mm/s: flagged
    # Points drawn like the data: about 2 % flagged. The corner the data never visited: far outside.
    fresh_speed = rng.uniform(0.005, 0.15, 4000)
    fresh = {"speed_m_s": fresh_speed, "temperature_C": 25 + 50 * (fresh_speed - 0.005) / 0.145
             + rng.normal(0.0, 1.0, 4000)}
    flagged = float(np.mean(cloud.score(fresh, (4000,))[0] > 1))
    assert flagged <= 0.05, flagged
    corner, _ = cloud.score({"speed_m_s": np.array([0.01]), "temperature_C": np.array([70.0])}, (1,))
    assert corner[0] > 3
    pairs = confounded_pairs({"speed_m_s": speed, "temperature_C": temperature,
                              "relative_humidity": rng.uniform(size=n)})
    assert [p["columns"] for p in pairs] == [["speed_m_s", "temperature_C"]]
    # What would separate them: the empty corners, slow and hot, fast and cold.
    assert "cannot be told" in pairs[0]["summary"]
    words = pairs[0]["summary"]
    assert f"speed_m_s near {speed.min():.4g} [m/s] and temperature_C near {temperature.max():.4g}" in words
    assert f"speed_m_s near {speed.max():.4g} [m/s] and temperature_C near {temperature.min():.4g}" in words


# ----------------------------------------------------------------------------------- through the API


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    from fastapi.testclient import TestClient

    from microbearing.service.app import create_app
    from microbearing.service.settings import Settings

    with TestClient(create_app(Settings(data_dir=tmp_path_factory.mktemp("groups")))) as test_client:
        yield test_client


def _finished(client, response) -> dict:
    assert response.status_code == 202, response.text
    location = response.headers["location"]
    # a calibration with groups takes minutes on a busy 2-core host (180 s ran out beside another worker)
    job = finished_job(client, location, timeout_s=600, interval_s=0.2)
    return client.get(job["result_url"]).json()


def test_labels_and_declared_codes_calibrate_through_the_api_and_name_groups_in_predictions(client):
    data, level = builds(21, groups=6, rows=20)
    body = {"data": data, "fit_parameters": ["mu_pivot"], "folds": 3}
    result = _finished(client, client.post("/v1/calibrations", json=body))
    (group,) = result["groups"]
    assert group["factor"] == "specimen" and sorted(group["levels"]) == [f"S{g}" for g in range(1, 7)]
    assert result["model"]["groups"][0]["factor"] == "specimen"
    assert "specimen" not in result["model"]["domain"]
    # The same data as integer codes in CSV, declared a factor: the same groups, labelled 1..6.
    coded, _ = builds(21, groups=6, rows=20, coded=True)
    header = list(coded[0])
    text = "\n".join([",".join(header)] + [",".join(str(row[k]) for k in header) for row in coded]) + "\n"
    csv_result = _finished(client, client.post("/v1/calibrations/csv", content=text,
                                               params=[("fit_parameters", "mu_pivot"), ("folds", "3"),
                                                       ("factors", "specimen")],
                                               headers={"content-type": "text/csv"}))
    assert sorted(csv_result["groups"][0]["levels"]) == [str(g) for g in range(1, 7)]
    assert csv_result["groups"][0]["spread_relative"] == pytest.approx(group["spread_relative"], rel=1e-6)
    # Undeclared, the codes are a number column: no group, a condition.
    plain = _finished(client, client.post("/v1/calibrations/csv", content=text,
                                          params=[("fit_parameters", "mu_pivot"), ("folds", "3")],
                                          headers={"content-type": "text/csv"}))
    assert plain["groups"] == [] and "specimen" in plain["model"]["conditions"]
    hint = "specimen holds the whole numbers 1..6: if they label groups"
    assert any(w.startswith(hint) for w in plain["warnings"])
    assert not any("whole numbers" in w for w in csv_result["warnings"])
    # /v1/friction: the build with the highest mu_pivot is predicted above a new one, its interval narrower.
    model = result["model_id"]
    point = {"balls": 4, "load_N": 0.01, "speed_m_s": 0.05, "model": model}
    top = f"S{int(np.argmax(level)) + 1}"
    known = client.post("/v1/friction", json={**point, "conditions": {"specimen": top}}).json()
    new = client.post("/v1/friction", json=point).json()
    assert known["mu"] > new["mu"] and known["in_domain"] and new["in_domain"]
    assert known["mu_upper"] / known["mu_lower"] < new["mu_upper"] / new["mu_lower"]
    # A new build's interval as the stored model computes it (its groups' own means travel with it), and at
    # least as wide as the spread's upper 95 % bound on the normal quantile of 90 % content gives.
    from microbearing.calibrate import CalibratedModel

    stored = CalibratedModel.from_json(result["model"])
    expected = stored.predict({"balls": 4, "load_N": 0.01, "speed_m_s": 0.05})
    assert new["mu_upper"] == pytest.approx(float(expected.mu_upper), rel=1e-9)
    upper = np.log1p(group["spread_upper_relative"])
    assert upper > np.log1p(group["spread_relative"])
    assert np.log(new["mu_upper"] / new["mu"]) >= stats.norm.isf(0.05) * upper
    # The batch gives the same answers, a label per point (a new label: the new-build answer).
    batch = client.post("/v1/friction/batch", json={
        "points": {"balls": 4, "load_N": [0.01, 0.01], "speed_m_s": 0.05}, "model": model,
        "conditions": {"specimen": [top, "S42"]}, "outputs": ["mu"]}).json()
    assert batch["mu"] == pytest.approx([known["mu"], new["mu"]], rel=1e-12)
    assert batch["mu_upper"] == pytest.approx([known["mu_upper"], new["mu_upper"]], rel=1e-12)
    assert batch["in_domain"] == [True, True]
    assert batch["domain_warnings"] == ["specimen = S42 is not a group of the calibration data: predicted as "
                                        "a new group, whose interval carries the spread between groups"]
    # An optimization with the calibrated model, for the known build and for a new one.
    answers = []
    for conditions in ({"specimen": top}, {}):
        response = client.post("/v1/optimizations", json={
            "bounds": {"balls": [4, 6], "groove_angle_deg": [45, 60], "load_N": [0.005, 0.02]},
            "fixed": {"speed_m_s": 0.05}, "constraints": {"max_contact_pressure_Pa": 1e9}, "model": model,
            "conditions": conditions, "starts": 1})
        answers.append(_finished(client, response))  # a calibrated model's optimization is a job
    spans = [a["mu_upper"] / a["mu_lower"] for a in answers]
    assert spans[0] < spans[1], spans
    # A label given to a number column is a 422 naming it.
    wrong = client.post("/v1/friction", json={**point, "conditions": {"specimen": "S1", "balls_x": "a"}})
    assert wrong.status_code == 422
    assert "/conditions/balls_x" in [e.get("pointer") for e in wrong.json()["errors"]]


def test_a_mixed_label_column_is_a_422_naming_each_label(client):
    data, _ = builds(22, groups=3, rows=8)
    for row in data[:5]:
        row["specimen"] = 7
    response = client.post("/v1/calibrations", json={"data": data})
    assert response.status_code == 422
    pointers = [e["pointer"] for e in response.json()["errors"]]
    assert len(pointers) == len(data) - 5 and pointers[0] == "/data/5/specimen"
    assert "declare specimen in factors" in response.json()["errors"][0]["detail"]


# ------------------------------------------------------------------------ whole calibrations, fresh draws


def _warming_lab(rng, m, speed=None, temperature=None):
    """m rows of a lab that warmed up as it sped up (25 to 75 degC over 5 to 150 mm/s, 1 K scatter; or at a
    fixed speed and temperature) and the film's viscosity falling with temperature (0.01 Pa s at 25 degC,
    26 kJ/mol Arrhenius); measured with 3 % scatter. Returns the columns and mu_measured."""
    c = _columns(rng, m)
    if speed is not None:
        c["speed_m_s"] = np.full(m, speed)
    c["temperature_C"] = (25 + 50 * (c["speed_m_s"] - 0.005) / 0.145 + rng.normal(0.0, 1.0, m)
                          if temperature is None else np.full(m, temperature))
    viscosity = 0.01 * np.exp(26e3 / 8.314 * (1 / (c["temperature_C"] + 273.15) - 1 / 298.15))
    return c, _mu(c, viscosity_Pa_s=viscosity) * np.exp(rng.normal(0.0, 0.03, m))


def _rows(c, measured, n):
    return [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(measured[i])} for i in range(n)]


def test_scatter_ten_percent_below_20_mm_s_gives_intervals_that_cover_each_region():
    rng = np.random.default_rng(2420)
    n, fresh = 200, 3000
    c = {**_columns(rng, n + fresh), "relative_humidity": rng.uniform(0.2, 0.6, n + fresh)}
    c["speed_m_s"] = rng.uniform(0.001, 0.15, n + fresh)
    spread = np.where(c["speed_m_s"] < 0.02, 0.10, 0.015)
    measured = _mu(c) * np.exp(rng.normal(0.0, 1.0, n + fresh) * spread)
    result = calibrate(_rows(c, measured, n), ["mu_pivot"], make_plots=False, seed=1)
    assert result.scatter["kind"] == "step" and result.scatter["column"] == "speed_m_s", result.scatter
    assert 0.01 <= result.scatter["split"] <= 0.03
    # Low-speed rows scatter, they are no gross outliers.
    assert result.outliers["count"] <= 2, result.outliers["summary"]
    p = result.model.predict({k: v[n:] for k, v in c.items()})
    inside = (p.mu_lower <= measured[n:]) & (measured[n:] <= p.mu_upper)
    low = c["speed_m_s"][n:] < 0.02
    assert 0.85 <= inside[low].mean() <= 1.0 and 0.9 <= inside[~low].mean() <= 0.99, (inside[low].mean(),
                                                                                      inside[~low].mean())
    width = np.log(p.mu_upper / p.mu_lower)
    assert np.median(width[low]) > 3 * np.median(width[~low])


def test_speed_and_temperature_that_move_together_are_named_and_the_empty_corner_is_out_of_the_domain():
    rng = np.random.default_rng(2440)

    def draw(m, speed=None, temperature=None):
        return _warming_lab(rng, m, speed, temperature)

    c, measured = draw(200)
    result = calibrate(_rows(c, measured, 200), ["mu_pivot"], make_plots=False, seed=2)
    words = " ".join(result.confounding)
    assert "speed_m_s and temperature_C rise together" in words and "would separate them" in words
    like, _ = draw(2000)
    assert 1 - result.model.predict(like).in_domain.mean() <= 0.05
    corner, _ = draw(50, speed=0.01, temperature=70.0)
    on_data, _ = draw(50, speed=0.01)
    far, near = result.model.predict(corner), result.model.predict(on_data)
    assert not far.in_domain.any() and near.in_domain.mean() > 0.9
    assert any("far from the calibration data's rows" in w for w in far.warnings)
    widths = [np.median(np.log(p.mu_upper / p.mu_lower)) for p in (far, near)]
    assert widths[0] > 1.5 * widths[1], widths


def test_off_the_data_a_term_on_the_column_that_moved_with_speed_holds_the_other_explanation(client):
    """Temperature rose with speed, the film's viscosity (0.01 Pa s at 25 degC, 26 kJ/mol) falls with
    temperature, and no term is strong enough to be chosen. A term on temperature that the data lean to
    but cannot decide is kept as a rival by confounding, and the 95 % interval holds 90 %+ of fresh
    measurements (the generating truth) at two points no row is near and which the bench does not use
    (slow and warm, fast and cool), where the model without it does not; points drawn like the data
    keep their interval (coverage, and width within 15 %). Calibrated through POST /v1/calibrations; the
    far points answered by /v1/friction/batch as the stored model computes them."""
    from dataclasses import replace

    from microbearing.calibrate import CalibratedModel

    rng = np.random.default_rng(91)

    def draw(m, speed=None, temperature=None):
        return _warming_lab(rng, m, speed, temperature)

    c, measured = draw(200)
    result = _finished(client, client.post("/v1/calibrations", json={
        "data": _rows(c, measured, 200), "fit_parameters": ["mu_pivot", "adhesion_energy_J_m2"]}))
    model = CalibratedModel.from_json(result["model"])
    confounded = {r["label"] for r in result["rivals"] if "moves with speed_m_s" in r["statement"]}
    assert confounded and all("temperature_C" in label.split(" instead of ")[0] for label in confounded), \
        result["rivals"]
    alone = replace(model, rivals=[r for r in model.rivals if r.label not in confounded])
    before_all = []
    for speed, temperature in ((0.02, 65.0), (0.13, 30.0)):
        points, truth = draw(400, speed=speed, temperature=temperature)
        p = model.predict(points)
        inside = np.mean((p.mu_lower <= truth) & (truth <= p.mu_upper))
        before = alone.predict(points)
        before_all.append(np.mean((before.mu_lower <= truth) & (truth <= before.mu_upper)))
        assert inside >= 0.9, (speed, temperature, inside, before_all)
        answer = client.post("/v1/friction/batch", json={
            "points": {"balls": points["balls"][:20].astype(int).tolist(),
                       **{k: points[k][:20].tolist() for k in ("load_N", "speed_m_s")}},
            "conditions": {"temperature_C": points["temperature_C"][:20].tolist()},
            "model": result["model_id"], "outputs": ["mu"]})
        assert answer.status_code == 200, answer.text
        np.testing.assert_allclose(answer.json()["mu_upper"], p.mu_upper[:20], rtol=1e-9)
        np.testing.assert_allclose(answer.json()["mu_lower"], p.mu_lower[:20], rtol=1e-9)
    assert min(before_all) < 0.9, before_all  # without those rivals a point is missed
    like, truth = draw(2000)
    p, before = model.predict(like), alone.predict(like)
    assert 1 - p.in_domain.mean() <= 0.05
    assert 0.9 <= np.mean((p.mu_lower <= truth) & (truth <= p.mu_upper)) <= 0.995
    widths = [np.median(np.log(q.mu_upper / q.mu_lower)) for q in (p, before)]
    assert widths[0] <= 1.15 * widths[1], widths


def test_a_label_per_row_is_reported_and_not_fitted():
    from microbearing.calibrate.groups import why_not_fitted

    assert why_not_fitted(np.array(["a", "a", "b", "b"])) is None
    assert "fewer than two rows a group" in why_not_fitted(np.array(["a", "b", "c", "c"]))
    assert "one group only" in why_not_fitted(np.array(["a", "a"]))
    assert "more than 500" in why_not_fitted(np.arange(1200).astype(str).repeat(2))


def test_off_line_difference_is_the_log_ratio_on_the_rows_with_the_rivals_driver_reflected():
    """By hand: a rival that only adds exp(c1 (T - centre) / scale) to the model's own fit differs from it,
    on a row whose temperature is reflected to lo + hi - T, by |c1 (lo + hi - T - centre) / scale|; the
    figure is the 0.9 quantile of that over the rows (the speed each row was measured at is kept)."""
    from types import SimpleNamespace

    from microbearing.calibrate.candidates import EffectTerm
    from microbearing.calibrate.rivals import off_line_difference

    rng = np.random.default_rng(5)
    c = _columns(rng, 40)
    temperature = 25 + 50 * (c["speed_m_s"] - 0.005) / 0.145
    data = parse_rows([{**{k: float(v[i]) for k, v in c.items()}, "temperature_C": float(temperature[i]),
                        "mu_measured": 0.01} for i in range(40)])
    term = EffectTerm("generic_linear", ("temperature_C",), {"centre": 40.0, "scale": 12.0})
    final = SimpleNamespace(declared={"mu_pivot": 0.6}, term_values=[])
    rival = SimpleNamespace(term=term, fit=SimpleNamespace(declared={"mu_pivot": 0.6}, term_values=[[0.3]]))
    reflected = temperature.min() + temperature.max() - temperature
    expected = np.quantile(np.abs(0.3 * (reflected - 40.0) / 12.0), 0.9)
    assert off_line_difference(data, final, [], rival, "speed_m_s") == pytest.approx(expected, rel=1e-9)
    # A rival that agrees with the model everywhere parts from it nowhere.
    same = SimpleNamespace(term=term, fit=SimpleNamespace(declared={"mu_pivot": 0.6}, term_values=[[0.0]]))
    assert off_line_difference(data, final, [], same, "speed_m_s") == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("seed", [61, 62, 63])
def test_a_law_the_score_held_back_on_the_column_that_moved_with_speed_is_kept_where_the_columns_part(seed):
    """Temperature rose with speed and the film's viscosity (0.01 Pa s at 25 degC, 26 kJ/mol) falls with it;
    no term on temperature scores better than the model once its parameter is paid for, so a rule that
    kept only terms the data lean to kept none in these three data sets (coverage 0.72, 0.51 and 0.72 of
    the generating truth at 140 mm/s and 27 degC). Every term on temperature the data cannot reject is a
    candidate rival and the ones that part most from the model where speed and temperature part are kept:
    the generating law is among them, and the 95 % interval holds 90 %+ of fresh measurements at the two
    empty corners and between them, while points drawn like the data keep their coverage and width."""
    from dataclasses import replace

    rng = np.random.default_rng(seed)

    def draw(m, speed=None, temperature=None):
        return _warming_lab(rng, m, speed, temperature)

    c, measured = draw(200)
    result = calibrate(_rows(c, measured, 200), ["mu_pivot", "adhesion_energy_J_m2"], make_plots=False,
                       seed=seed)
    labels = [r.label for r in result.model.rivals]
    assert "viscosity_Pa_s drifts with temperature_C (arrhenius) added" in labels, labels
    for speed, temperature in ((0.14, 27.0), (0.01, 70.0), (0.08, 30.0)):
        points, truth = draw(300, speed=speed, temperature=temperature)
        p = result.model.predict(points)
        inside = np.mean((p.mu_lower <= truth) & (truth <= p.mu_upper))
        assert inside >= 0.9, (speed, temperature, inside)
    alone = replace(result.model, rivals=[r for r in result.model.rivals if "temperature_C" not in r.label])
    like, truth = draw(1000)
    p, before = result.model.predict(like), alone.predict(like)
    assert 0.9 <= np.mean((p.mu_lower <= truth) & (truth <= p.mu_upper)) <= 0.99
    widths = [np.median(np.log(q.mu_upper / q.mu_lower)) for q in (p, before)]
    assert widths[0] <= 1.15 * widths[1], widths


@pytest.mark.parametrize("seed", [463, 464])
def test_a_gp_on_what_the_terms_leave_does_not_learn_the_specimens_levels(seed):
    # 4 specimens x 8 design points x 5 runs (the runs' cycle differs, so they are no replicates), the
    # physics alone times each specimen's level (8 % spread) with 3 % scatter. Before, the GP on what the
    # terms leave was trained on the residual with the levels in it: the five rows of a point share their
    # specimen's level, the GP learned it as a bump at each point and joined the model beside the
    # specimens' own levels (probe /work/exp76/h46/probe.py d: 8 of 9 data sets, truth error at S1 median
    # 1.01 x the noise, 0.47 with the levels taken out first)
    rng = np.random.default_rng(seed)
    specimens, points, runs = 4, 8, 5
    n = specimens * points * runs
    design = {"load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), specimens * points)),
              "speed_m_s": rng.uniform(0.005, 0.15, specimens * points),
              "relative_humidity": rng.uniform(0.2, 0.8, specimens * points)}
    c = {k: np.repeat(v, runs) for k, v in design.items()}
    c["cycle"] = rng.uniform(0.0, 2000.0, n)
    label = np.repeat([f"S{g + 1}" for g in range(specimens)], points * runs)
    level = np.repeat(rng.normal(0.0, 0.08, specimens), points * runs)
    true_mu = physics.evaluate(balls=4, load_N=c["load_N"], speed_m_s=c["speed_m_s"], mu_pivot=0.65).mu
    measured = true_mu * np.exp(level + rng.normal(0.0, 0.03, n))
    rows = [{k: float(v[i]) for k, v in c.items()}
            | {"specimen": str(label[i]), "mu_measured": float(measured[i])} for i in range(n)]
    result = calibrate(parse_rows(rows, fixed={"balls": 4}), ["mu_pivot"], make_plots=False, max_terms=0)
    assert result.model.discrepancy is None
    assert result.groups and result.groups[0]["groups"] == specimens
