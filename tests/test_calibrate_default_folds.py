"""Eight rows, the fewest a calibration takes, are answered at every door when the caller leaves the
folds to the service (issue 33, item 5): the default is 5 folds, or half the rows when there are fewer
than 10 (5 folds of 8 rows would hold fewer than two rows each: refused when asked for explicitly)."""

from __future__ import annotations

import json

import pytest
from fastapi.testclient import TestClient
from jobs_helper import job_result

from microbearing.calibrate import default_folds
from microbearing.service.app import create_app
from microbearing.service.cli import EXIT_INVALID, main
from microbearing.service.schemas import examples
from microbearing.service.settings import Settings

#: 8 rows of the spec's calibration example (4, 8 and 12 balls; 3-24 mN; 10 and 100 mm/s).
ROWS = examples.CALIBRATION["data"][::3]
CSV = "balls,load_N,speed_m_s,mu_measured\n" + "".join(
    f"{r['balls']},{r['load_N']},{r['speed_m_s']},{r['mu_measured']}\n" for r in ROWS)


def test_the_default_is_five_folds_or_half_the_rows():
    # By hand: a fold holds at least two rows, and never more folds than 5.
    assert [default_folds(n) for n in (8, 9, 10, 11, 200)] == [4, 4, 5, 5, 5]


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    with TestClient(create_app(Settings(data_dir=tmp_path_factory.mktemp("data")))) as c:
        yield c


def test_eight_json_rows_without_folds_calibrate_with_four(client):
    assert len(ROWS) == 8
    answer = client.post("/v1/calibrations", json={"data": ROWS, "fit_parameters": ["mu_pivot"]})
    assert answer.status_code == 202, answer.text
    assert job_result(client, answer)["folds"] == 4
    # Asked for explicitly, five folds of eight rows are still a problem naming the field.
    refused = client.post("/v1/calibrations", json={"data": ROWS, "fit_parameters": ["mu_pivot"], "folds": 5})
    assert refused.status_code == 422
    assert refused.json()["errors"][0]["pointer"] == "/folds", refused.text


def test_eight_csv_rows_without_folds_calibrate_with_four(client):
    answer = client.post("/v1/calibrations/csv?fit_parameters=mu_pivot", content=CSV,
                         headers={"content-type": "text/csv"})
    assert answer.status_code == 202, answer.text
    assert job_result(client, answer)["folds"] == 4
    refused = client.post("/v1/calibrations/csv?fit_parameters=mu_pivot&folds=5", content=CSV,
                          headers={"content-type": "text/csv"})
    assert refused.status_code == 422 and "folds" in refused.text


def test_eight_rows_calibrate_from_the_command_line(tmp_path, capsys):
    data, report = tmp_path / "eight.csv", tmp_path / "report.json"
    data.write_text(CSV)
    assert main(["calibrate", str(data), "--fit", "mu_pivot", "--no-store", "--json", str(report)]) == 0
    assert json.loads(report.read_text())["folds"] == 4
    capsys.readouterr()
    code = main(["calibrate", str(data), "--fit", "mu_pivot", "--no-store", "--folds", "5"])
    assert code == EXIT_INVALID and "folds must be in [2, 4]" in capsys.readouterr().err


def test_eight_rows_calibrate_in_the_library_with_the_same_default():
    # The library's own default is the doors' (calibrate(folds=None) -> default_folds(n)).
    from microbearing.calibrate import calibrate

    report = calibrate(ROWS, ["mu_pivot"], make_plots=False)
    assert report.folds == 4
    with pytest.raises(ValueError, match=r"folds must be in \[2, 4\]"):
        calibrate(ROWS, ["mu_pivot"], folds=5, make_plots=False)
