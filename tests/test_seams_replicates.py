"""Replicated designs (several measurements at each design point) predict with finite intervals.

Issue 32: with six measurements at each of 20 design points every row's 5th neighbour was its own twin
(distance 0), the data cloud's threshold was clamped to 1e-12 and its stored rows were rounded, so a
design point missed its own row by ~1e-7 and every interval overflowed (422 "mu_upper is not finite").
The cloud now holds one row per design point at full precision, replicates whose conditions differ by
measurement jitter (0.05 and 0.05003 m/s) counted as one.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from fastapi.testclient import TestClient
from jobs_helper import job_result

from microbearing import physics
from microbearing.calibrate.domain import DataCloud

N_DESIGN = 20
MENISCUS_FORCE_N = 2e-5


def design(seed: int = 0) -> dict[str, np.ndarray]:
    """20 design points: ball count, load, speed and relative humidity."""
    rng = np.random.default_rng(seed)
    return {"balls": rng.choice([4, 8, 12], N_DESIGN).astype(float),
            "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), N_DESIGN)),
            "speed_m_s": rng.uniform(0.01, 0.15, N_DESIGN),
            "relative_humidity": rng.uniform(0.2, 0.8, N_DESIGN)}


def truth(points: dict[str, np.ndarray]) -> np.ndarray:
    """mu of the physics with mu_pivot 0.7 plus menisci growing with humidity (noise-free)."""
    mu = physics.evaluate(balls=points["balls"], load_N=points["load_N"], speed_m_s=points["speed_m_s"],
                          mu_pivot=0.7).mu
    meniscus = points["balls"] * MENISCUS_FORCE_N / points["load_N"]
    return mu + meniscus / np.log(1 / points["relative_humidity"])


def replicated_rows(replicates: int, seed: int = 0, jitter: bool = False) -> list[dict]:
    """Every design point measured ``replicates`` times with 2 % log-normal noise (with ``jitter``, its
    conditions read within 0.1 % of the set point each time, :func:`jittered`)."""
    points = design(seed)
    read = (jittered(points, replicates) if jitter
            else {k: np.repeat(v, replicates) for k, v in points.items()})
    mu = np.repeat(truth(points), replicates)
    rng = np.random.default_rng(100 + replicates)
    return [{k: float(v[i]) for k, v in read.items()}
            | {"mu_measured": float(mu[i] * np.exp(rng.normal(0, 0.02)))}
            for i in range(N_DESIGN * replicates)]


# ------------------------------------------------------------------------------------------ the cloud


def scaled_design(points: dict[str, np.ndarray]) -> np.ndarray:
    """The design standardized by hand as the cloud does (load spans a decade: by its log)."""
    columns = []
    for v in points.values():
        t = np.log(v) if np.all(v > 0) and v.max() > 10 * v.min() else v
        columns.append((t - t.mean()) / t.std())
    return np.column_stack(columns)


@pytest.mark.parametrize("replicates", [1, 2, 5, 6, 10])
def test_replicates_do_not_change_the_cloud(replicates):
    points = design()
    cloud = DataCloud.from_columns({k: np.repeat(v, replicates) for k, v in points.items()})
    x = scaled_design(points)  # replication leaves means and standard deviations as they are
    np.testing.assert_allclose(cloud.rows, x, rtol=1e-12, atol=1e-12)
    # Brute force over the 20 distinct points: each one's 5th-nearest other point, and the
    # ceil(0.98 * 21) = 21st smallest of 20, i.e. the largest (no two columns move together here).
    distances = np.sqrt(((x[:, None, :] - x[None, :, :]) ** 2).sum(axis=2))
    own = np.sort(distances, axis=1)[:, 5]
    threshold = own.max()
    assert threshold > 0.1
    ratio, given = cloud.score(points, (N_DESIGN,))
    assert given == list(points)
    # At a design point its own row is at distance 0, so the score is its 4th other neighbour over the
    # threshold: at most 1, every one inside the cloud.
    by_hand = np.sort(distances, axis=1)[:, 4] / threshold
    np.testing.assert_allclose(ratio, by_hand, rtol=1e-9)
    assert np.all(ratio <= 1.0)
    # Through JSON: the same scores to the last bit.
    again = DataCloud.from_json(cloud.to_json())
    np.testing.assert_array_equal(again.score(points, (N_DESIGN,))[0], ratio)


def test_a_cloud_stored_with_rounded_replicated_rows_still_scores_finitely():
    # The form earlier versions stored: every replicate's row, rounded to 6 decimals.
    points = design()
    x = scaled_design(points)
    stored = {"columns": list(points), "transforms": ["linear", "log", "linear", "linear"],
              "centre": [float(np.mean(np.log(v) if k == "load_N" else v)) for k, v in points.items()],
              "scale": [float(np.std(np.log(v) if k == "load_N" else v)) for k, v in points.items()],
              "rows": np.round(np.repeat(x, 6, axis=0), 6).tolist(), "alpha": 0.02}
    cloud = DataCloud.from_json(stored)
    ratio, _ = cloud.score(points, (N_DESIGN,))
    assert np.all(np.isfinite(ratio)) and np.all(ratio <= 1.0 + 1e-5), ratio


def jittered(points: dict[str, np.ndarray], replicates: int, seed: int = 1) -> dict[str, np.ndarray]:
    """Each design point measured ``replicates`` times, every reading of a condition within 0.1 % of its set
    point (speed 0.05 read as 0.05003); ball counts exact."""
    rng = np.random.default_rng(seed)
    return {k: np.repeat(v, replicates) if k == "balls"
            else np.repeat(v, replicates) * (1.0 + rng.uniform(-1e-3, 1e-3, v.size * replicates))
            for k, v in points.items()}


def test_replicates_differing_by_jitter_are_one_design_point():
    points = design()
    exact = DataCloud.from_columns({k: np.repeat(v, 6) for k, v in points.items()})
    cloud = DataCloud.from_columns(jittered(points, 6))
    assert cloud.rows.shape == exact.rows.shape == (N_DESIGN, 4)
    # each kept row is the first reading of its design point: within the jitter of the exact row
    assert np.max(np.abs(cloud.rows - exact.rows)) < 0.02
    threshold = cloud.space(list(points)).threshold
    assert threshold == pytest.approx(exact.space(list(points)).threshold, rel=0.02)
    ratio, _ = cloud.score(points, (N_DESIGN,))
    assert np.all(np.isfinite(ratio)) and np.all(ratio <= 1.0 + 0.02), ratio
    # through JSON the tolerance is kept: a subspace also finds 20 design points
    again = DataCloud.from_json(cloud.to_json())
    assert again.space(["load_N", "speed_m_s"]).threshold == cloud.space(["load_N", "speed_m_s"]).threshold
    assert again.space(["load_N", "speed_m_s"]).threshold > 0.1
    # design points 1 % apart are not replicates
    apart = {k: np.concatenate([v, v if k == "balls" else v * 1.01]) for k, v in points.items()}
    assert DataCloud.from_columns(apart).rows.shape[0] == 2 * N_DESIGN


@pytest.mark.parametrize("first", [0.0, 1.0])
def test_a_column_counted_from_zero_puts_zero_next_to_the_data(first):
    # a run-in measured at cycles first, 10, 100, ..., 1e5 at four loads each: log-spread counts
    cycles = np.repeat(np.concatenate([[first], 10.0 ** np.arange(1, 6)]), 4)
    load = np.tile([0.003, 0.006, 0.012, 0.024], 6)
    cloud = DataCloud.from_columns({"cycles": cycles, "load_N": load})
    i = cloud.columns.index("cycles")
    assert cloud.transforms[i] == "log"
    shift = 10.0 if first == 0.0 else 1.0  # the least positive count
    assert cloud.shift[i] == shift
    # by hand: log(cycles + shift), standardized
    t = np.log(cycles + shift)
    np.testing.assert_allclose(cloud.scaled("cycles", cycles), (t - t.mean()) / t.std(), rtol=1e-12)
    # cycles 0 at a measured load lies next to the data: its score is that of the least count's rows
    # (0 and 1 are the same point here, 0 is log 2 below 1 when the counts start at 1), not infinite
    at_zero = cloud.score({"cycles": 0.0, "load_N": 0.006}, ())[0]
    at_first = cloud.score({"cycles": first, "load_N": 0.006}, ())[0]
    assert np.isfinite(at_zero) and at_zero <= max(at_first, 1.0) + 0.5, (at_zero, at_first)
    assert float(cloud.scaled("cycles", 0.0)) >= float(cloud.rows[:, i].min()) - np.log(2) / t.std() - 1e-12
    # a speed spanning decades is scaled by its plain log, as before
    other = DataCloud.from_columns({"speed_m_s": np.repeat([0.001, 0.003, 0.01, 0.03, 0.1, 1.0], 4),
                                    "load_N": load})
    assert other.transforms == ["log", "linear"] and other.shift == [0.0, 0.0]


def test_too_few_distinct_design_points_make_no_cloud():
    # 11 design points measured 10 times: 110 rows, but fewer than 2k + 2 = 12 places.
    points = {k: np.repeat(v[:11], 10) for k, v in design().items()}
    assert DataCloud.from_columns(points) is None


# ---------------------------------------------------------------------------------- through the API


def finished_result(client: TestClient, response) -> dict:
    return job_result(client, response, timeout_s=600, interval_s=0.1)


@pytest.mark.parametrize(("replicates", "jitter"), [(2, False), (5, False), (6, False), (10, False),
                                                    (6, True)])
def test_a_replicated_design_predicts_with_intervals_that_cover_the_truth(client, replicates, jitter):
    body = {"data": replicated_rows(replicates, jitter=jitter), "fit_parameters": ["mu_pivot"], "folds": 3}
    result = finished_result(client, client.post("/v1/calibrations", json=body))
    assert result["n_points"] == N_DESIGN * replicates
    model = result["model_id"]
    points = design()
    physics_points = {k: v.tolist() for k, v in points.items() if k != "relative_humidity"}
    request = {"points": physics_points, "model": model,
               "conditions": {"relative_humidity": points["relative_humidity"].tolist()}}
    response = client.post("/v1/friction/batch", json=request)
    assert response.status_code == 200, response.text
    batch = response.json()
    lower, upper = np.array(batch["mu_lower"]), np.array(batch["mu_upper"])
    assert np.all(np.isfinite(lower)) and np.all(np.isfinite(upper)) and np.all(lower > 0)
    # The noise-free truth at every design point lies inside its 95 % interval of a new measurement, and
    # the interval is not vacuous: about +-2 sigma of the 2 % noise and the fit's uncertainty.
    mu_true = truth(points)
    assert np.all((lower <= mu_true) & (mu_true <= upper)), (lower / mu_true, upper / mu_true)
    assert np.all(batch["in_domain"])
    assert np.max(np.log(upper / lower)) < 4 * 0.1  # the band is under +-20 % (the noise is 2 %)
    # One point through /v1/friction answers the same.
    single = client.post("/v1/friction", json={**{k: v[0] for k, v in physics_points.items()}, "model": model,
                                               "conditions": {"relative_humidity": request["conditions"][
                                                   "relative_humidity"][0]}})
    assert single.status_code == 200, single.text
    assert math.isclose(single.json()["mu_upper"], upper[0], rel_tol=1e-12)
    # Between design points (halfway from each to the next, ball counts kept) the data are near: with
    # jittered replicates too, the cloud's threshold is the design points' spacing, not the jitter's.
    halfway = {k: (v[:-1] + v[1:]) / 2 for k, v in points.items()}
    halfway["balls"] = points["balls"][:-1]
    between = client.post("/v1/friction/batch", json={
        "points": {k: v.tolist() for k, v in halfway.items() if k != "relative_humidity"}, "model": model,
        "conditions": {"relative_humidity": halfway["relative_humidity"].tolist()}})
    assert between.status_code == 200, between.text
    assert all(between.json()["in_domain"])
    assert np.max(np.log(np.divide(between.json()["mu_upper"], between.json()["mu_lower"]))) < 4 * 0.1
    # Off the data (every column inside its range, but in a corner no design point is near) the interval
    # is flagged and wider than at any design point.
    corner = {"balls": 12, "load_N": float(points["load_N"].max()),
              "speed_m_s": float(points["speed_m_s"].min())}
    far = client.post("/v1/friction", json={**corner, "model": model, "conditions": {
        "relative_humidity": float(points["relative_humidity"].min())}})
    assert far.status_code == 200, far.text
    far = far.json()
    assert far["in_domain"] is False
    assert np.log(far["mu_upper"] / far["mu_lower"]) > np.max(np.log(upper / lower))
