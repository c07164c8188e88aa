"""A factor column of two labels (two chambers, two specimens): the spread between groups has no upper 95 %
end, which JSON cannot hold as a number; the calibration is stored, reported and predicts (it failed at its
last step with "Out of range float values are not JSON compliant"); a label no group of the data has is
predicted as a new group and said so."""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient
from jobs_helper import finished_job

from microbearing import physics
from microbearing.service.app import create_app
from microbearing.service.settings import Settings


def _rows(n: int = 60, seed: int = 5) -> list[dict]:
    rng = np.random.default_rng(seed)
    design = {"balls": rng.choice([4.0, 6.0, 8.0], n),
              "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
              "speed_m_s": rng.uniform(0.02, 0.15, n)}
    chamber = rng.choice(["A", "B"], n)
    mu = (physics.evaluate(outputs=["mu"], mu_pivot=0.65, **design).mu * np.where(chamber == "B", 1.08, 1.0)
          * np.exp(rng.normal(0.0, 0.03, n)))
    return [{k: float(v[i]) for k, v in design.items()}
            | {"chamber": str(chamber[i]), "mu_measured": float(mu[i])} for i in range(n)]


def test_a_factor_of_two_labels_is_calibrated_stored_and_predicts(tmp_path):
    with TestClient(create_app(Settings(data_dir=tmp_path))) as client:
        response = client.post("/v1/calibrations", json={"data": _rows(), "fit_parameters": ["mu_pivot"],
                                                         "factors": ["chamber"], "folds": 3})
        assert response.status_code == 202, response.text
        result = client.get(finished_job(client, response, timeout_s=300)["result_url"]).json()
        groups = result["groups"]
        assert len(groups) == 1 and groups[0]["groups"] == 2, groups
        low, high = groups[0]["spread_interval_relative"]
        assert low >= 0 and high is None  # two groups leave the spread's upper end open
        model = result["model_id"]
        point = {"balls": 6, "load_N": 0.01, "speed_m_s": 0.05, "model": model}
        known = client.post("/v1/friction", json={**point, "conditions": {"chamber": "B"}})
        new = client.post("/v1/friction", json={**point, "conditions": {"chamber": "C"}})
        assert known.status_code == new.status_code == 200, (known.text, new.text)
        for answer in (known.json(), new.json()):
            assert 0 < answer["mu_lower"] < answer["mu"] < answer["mu_upper"] < np.inf
        # a new chamber carries the spread between the two: a wider interval than a known one's
        width = [a.json()["mu_upper"] / a.json()["mu_lower"] for a in (new, known)]
        assert width[0] > width[1], width
        # a new group is said (its interval is the spread's), and a number where the data hold text labels
        # is a label too: no group of the data, said so
        assert any("chamber = C is not a group" in w for w in new.json()["domain_warnings"]), new.text
        assert known.json()["domain_warnings"] == [], known.text
        numeric = client.post("/v1/friction", json={**point, "conditions": {"chamber": 2}})
        assert numeric.status_code == 200, numeric.text
        assert any("chamber = 2 is not a group" in w for w in numeric.json()["domain_warnings"]), numeric.text
        assert numeric.json()["mu_upper"] == pytest.approx(new.json()["mu_upper"], rel=1e-12)
        # UM-Bridge takes a group label in config.fixed, known or new, and answers as /v1/friction
        for label, answer in (("B", known), ("C", new)):
            bridged = client.post("/umbridge/Evaluate", json={
                "name": model, "input": [[6, 0.01]], "config": {
                    "inputs": ["balls", "load_N"], "fixed": {"speed_m_s": 0.05, "chamber": label},
                    "outputs": ["mu", "mu_upper"]}})
            assert bridged.status_code == 200, bridged.text
            assert bridged.json()["output"][0] == pytest.approx(
                [answer.json()["mu"], answer.json()["mu_upper"]], rel=1e-12)
        stored = client.get(f"/v1/calibrations/{model.split(':')[1]}")
        assert stored.status_code == 200, stored.text


@pytest.mark.parametrize("interval", [(0.02, float("inf")), (0.0, 0.3)])
def test_a_group_effect_s_interval_round_trips_through_json(interval):
    import json

    from microbearing.calibrate.groups import GroupEffect

    levels = {"A": [0.01, 1e-4, 30.0], "B": [-0.01, 1e-4, 30.0]}
    means = [[0.01, 1e-4], [-0.01, 1e-4]]
    effect = GroupEffect("chamber", "mu", 0.05, interval, 0.0, levels, 0.03, {}, means)
    back = GroupEffect.from_json(json.loads(json.dumps(effect.to_json(), allow_nan=False)))
    assert back.spread_interval == interval
