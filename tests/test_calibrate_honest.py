"""Issue 24, items 4-8: honest answers off the data, unit slips, drifts with their level, undecided data,
and a GP discrepancy that joins only when it helps a correct model.

The data are drawn here from the physics with hidden mechanisms written independently of
physics.effects; every figure is compared with the generating truth, a hand calculation or fresh draws.
"""

from __future__ import annotations

import numpy as np
import pytest
from fastapi.testclient import TestClient

from microbearing import physics
from microbearing.calibrate import DataError, calibrate, parse_rows
from microbearing.calibrate.plausibility import check_plausible, plausibility_findings
from microbearing.calibrate.select import _bump_factor
from microbearing.service.app import create_app
from microbearing.service.settings import Settings

PROBLEM = "application/problem+json"


def lab_rows(n: int, seed: int, **columns) -> list[dict]:
    """Rows of a plain physics data set (mu_pivot 0.7, 2 % noise) with extra columns overriding."""
    rng = np.random.default_rng(seed)
    c = {"balls": rng.choice([4, 8], n).astype(float),
         "load_N": np.exp(rng.uniform(np.log(3e-3), np.log(3e-2), n)),
         "speed_m_s": rng.uniform(0.005, 0.15, n)}
    mu = physics.evaluate(balls=c["balls"], load_N=c["load_N"], speed_m_s=c["speed_m_s"], mu_pivot=0.7).mu
    mu = mu * np.exp(rng.normal(0.0, 0.02, n))
    c.update({k: np.asarray(v, dtype=float) for k, v in columns.items()})
    return [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(n)]


# --- item 5: implausible values and unit slips --------------------------------------------------------

@pytest.mark.parametrize(("column", "scale", "words"), [
    ("speed_m_s", 1000.0, "values look like mm/s"),
    ("load_N", 1000.0, "values look like mN"),
])
def test_a_physics_column_in_milli_units_is_refused_naming_column_and_cause(column, scale, words):
    rows = lab_rows(30, 1)
    for row in rows:
        row[column] *= scale
    with pytest.raises(DataError) as caught:
        calibrate(rows, ["mu_pivot"], make_plots=False)
    (error,) = caught.value.errors
    assert error["column"] == column and words in error["message"]
    # the range quoted is the data's own, and the suggested SI range is it times 1e-3 (hand check)
    values = np.array([r[column] for r in rows])
    assert f"{values.min():.4g} to {values.max():.4g}" in error["message"]
    assert f"{values.min() / scale:.4g} to {values.max() / scale:.4g}" in error["message"]


@pytest.mark.parametrize(("name", "values", "severity", "words"), [
    ("relative_humidity", np.linspace(20.0, 80.0, 30), "error", "look like percent"),
    ("relative_humidity_pct", np.linspace(20.0, 80.0, 30), None, ""),
    ("relative_humidity_pct", np.linspace(0.2, 180.0, 30), "error", "[0, 100]"),
    ("relative_humidity", np.linspace(0.2, 0.8, 30), None, ""),
    ("temperature_C", np.linspace(293.0, 313.0, 30), "error", "look like kelvin"),
    ("temperature_K", np.linspace(20.0, 40.0, 30), "error", "look like degC"),
    ("temperature_K", np.linspace(293.0, 313.0, 30), None, ""),
    ("temperature_C", np.linspace(-300.0, 20.0, 30), "error", "absolute zero"),
])
def test_condition_columns_are_judged_by_their_names_unit(name, values, severity, words):
    found = plausibility_findings(parse_rows(lab_rows(30, 2, **{name: values})))
    if severity is None:
        assert found == []
    else:
        (finding,) = found
        assert (finding.column, finding.severity) == (name, severity) and words in finding.message


def test_friction_above_one_is_a_warning_in_the_report_not_a_refusal():
    rows = lab_rows(30, 3)
    rows[0]["mu_measured"] = 1.5
    assert [w.split(" ")[0] for w in check_plausible(parse_rows(rows))] == ["mu_measured"]


def test_plausible_lab_data_pass_silently():
    assert plausibility_findings(parse_rows(lab_rows(40, 4, relative_humidity=np.full(40, 0.4)))) == []


def test_the_sensitivity_step_stays_inside_a_parameters_range():
    # mu_pivot's range is [0, 10]: on its top bound a step up would leave it, so the step goes down
    assert _bump_factor("mu_pivot", np.array(10.0)) < 1.0
    assert _bump_factor("mu_pivot", np.array(0.7)) > 1.0
    assert 10.0 * _bump_factor("mu_pivot", np.array(10.0)) <= physics.PARAMETERS["mu_pivot"].maximum


def test_a_fitted_parameter_on_its_bound_is_reported_there_not_a_crash():
    # mu four times what mu_pivot = 10 gives: the fit runs into mu_pivot's top bound, 10
    rng = np.random.default_rng(5)
    n = 40
    c = {"balls": rng.choice([4, 8], n).astype(float), "load_N": np.exp(rng.uniform(-6, -3.5, n)),
         "speed_m_s": rng.uniform(0.005, 0.15, n)}
    mu = 4 * physics.evaluate(**c, mu_pivot=10.0).mu * np.exp(rng.normal(0, 0.02, n))
    rows = [{k: float(v[i]) for k, v in c.items()} | {"mu_measured": float(mu[i])} for i in range(n)]
    result = calibrate(rows, ["mu_pivot"], make_plots=False, max_terms=1)
    assert result.fitted_declared["mu_pivot"]["value"] == pytest.approx(10.0, rel=1e-6)
    assert any(w.startswith("mu_pivot ended on a bound") for w in result.warnings), result.warnings


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    with TestClient(create_app(Settings(data_dir=tmp_path_factory.mktemp("honest")))) as test_client:
        yield test_client


def test_a_unit_slip_is_a_422_naming_the_column_through_json_and_csv(client):
    rows = lab_rows(30, 6)
    for row in rows:
        row["speed_m_s"] *= 1000.0
    response = client.post("/v1/calibrations", json={"data": rows, "fit_parameters": ["mu_pivot"]})
    assert response.status_code == 422 and response.headers["content-type"] == PROBLEM
    (error,) = response.json()["errors"]
    assert error["pointer"] == "/data" and error["detail"].startswith("column speed_m_s: speed_m_s runs")
    assert "values look like mm/s" in error["detail"]
    text = "\n".join([",".join(rows[0]), *(",".join(f"{v:.9g}" for v in r.values()) for r in rows)]) + "\n"
    response = client.post("/v1/calibrations/csv", content=text, headers={"content-type": "text/csv"})
    assert response.status_code == 422 and response.headers["content-type"] == PROBLEM
    (error,) = response.json()["errors"]
    assert error["pointer"] == "/body" and "values look like mm/s" in error["detail"]
