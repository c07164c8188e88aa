"""A lab that states its units in the header reads its problems in those units (issue 32, "units at
every door"): a value out of a physics input's range, and a column a micro bearing's test cannot have,
are said in the unit sent as well as in SI, and no renaming of a column whose header already states
its unit is suggested."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from microbearing.calibrate import DataError, check_request, read_csv, read_rows
from microbearing.service.app import create_app
from microbearing.service.settings import Settings


def csv(header: str, cells: list[str]) -> str:
    return header + "\n" + "".join(f"{c}\n" for c in cells)


def problems(text: str) -> list[str]:
    """The messages of a CSV's problems, at reading or at the plausibility check."""
    with pytest.raises(DataError) as caught:
        dataset, _ = read_csv(text, fixed={"balls": 4})
        check_request(dataset, ["mu_pivot"], 2)
    return [e["message"] for e in caught.value.errors]


def test_an_out_of_range_speed_in_mm_s_is_said_in_mm_s():
    rows = [f"10,{-5 if i == 3 else 20 + i},0.01" for i in range(10)]
    [message] = problems(csv("load [mN],speed [mm/s],mu_measured", rows))
    # By hand: -5 mm/s is -0.005 m/s; the range [0, 1000] m/s is [0, 1e6] mm/s.
    assert "got -0.005" in message and "-5 mm/s" in message and "[0, 1e+06] mm/s" in message
    # JSON rows with a unit in the key: the same words.
    with pytest.raises(DataError) as caught:
        read_rows([{"load_mN": 10, "speed_mm_s": -5, "mu_measured": 0.01}], fixed={"balls": 4})
    assert "-5 mm/s" in caught.value.errors[0]["message"]


def test_implausible_percent_and_degc_columns_are_said_in_their_units_without_renaming_advice():
    rows = [f"0.01,0.02,{150 if i == 4 else 25},0.01" for i in range(10)]
    [message] = problems(csv("load_N,speed_m_s,relative humidity [%],mu_measured", rows))
    # judged in the unit the header states, in the words every door uses (physics.slips.read_slip)
    assert "relative humidity [%] runs 25 to 150 %: it lies in [0, 100]" in message, message
    assert "name the column" not in message and "divide by 100" not in message
    rows = [f"0.01,0.02,{-300 if i == 4 else 25},0.01" for i in range(10)]
    [message] = problems(csv("load_N,speed_m_s,temperature [degC],mu_measured", rows))
    assert "temperature [degC] runs -300 to 25 degC, at or below absolute zero" in message, message
    assert "name the column" not in message
    # A column named without a unit keeps the slip's advice (its name is what to fix).
    rows = [f"0.01,0.02,{40 if i == 4 else 0.3},0.01" for i in range(10)]
    [message] = problems(csv("load_N,speed_m_s,relative_humidity,mu_measured", rows))
    assert "name the column relative_humidity_pct" in message


def test_the_csv_door_says_it_in_the_upload_units(tmp_path):
    rows = [f"4,{10 + i},{5e7 if i == 3 else 20 + i},0.01" for i in range(10)]
    with TestClient(create_app(Settings(data_dir=tmp_path / "data"))) as client:
        answer = client.post("/v1/calibrations/csv?fit_parameters=mu_pivot",
                             headers={"content-type": "text/csv"},
                             content=csv("balls,load [mN],speed [mm/s],mu_measured", rows))
    assert answer.status_code == 422 and answer.headers["content-type"] == "application/problem+json"
    [error] = answer.json()["errors"]
    assert error["pointer"] == "/body"
    assert error["detail"].startswith("line 5, column C (speed [mm/s]): ") and "5e+07 mm/s" in error["detail"]
