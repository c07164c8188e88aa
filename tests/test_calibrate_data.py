"""Parsing measured data: every bad cell reported row by row, nothing dropped."""

import numpy as np
import pytest

from microbearing.calibrate import DataError, parse_csv, parse_rows


def _good_row(**overrides):
    row = {"balls": 4, "load_N": 0.009, "speed_m_s": 0.05, "relative_humidity": 0.4, "mu_measured": 0.01}
    row.update(overrides)
    return row


def test_good_csv_keeps_every_row_and_splits_columns():
    text = ("balls,load_N,speed_m_s,balls_touching,relative_humidity,mu_measured,mu_measured_std\n"
            "4,0.009,0.05,false,0.4,0.0105,0.0002\n"
            "6,0.012,0.10,TRUE,0.5,0.0121,0.0002\n"
            "8,0.020,0.15,0,0.6,0.0133,0.0003\n")
    data = parse_csv(text, fixed={"mu_ball": 0.7})
    assert data.n_points == 3
    assert data.physics_columns["balls_touching"].tolist() == [False, True, False]
    assert data.conditions["relative_humidity"].tolist() == [0.4, 0.5, 0.6]
    assert data.mu_measured_std.tolist() == [0.0002, 0.0002, 0.0003]
    assert data.fixed == {"mu_ball": 0.7}
    assert data.inputs()["mu_ball"] == 0.7


def test_bad_json_rows_are_reported_cell_by_cell():
    rows = [
        _good_row(),
        _good_row(load_N=-1.0),                      # row 2: negative load
        _good_row(speed_m_s=float("nan")),           # row 3: NaN
        _good_row(balls="four"),                     # row 4: wrong type
        _good_row(mu_measured=0.0),                  # row 5: mu <= 0
        _good_row(balls=2.5, relative_humidity=True),  # row 6: fractional balls and a boolean condition
        {k: v for k, v in _good_row().items() if k != "relative_humidity"},  # row 7: missing value
    ]
    with pytest.raises(DataError) as caught:
        parse_rows(rows)
    found = {(e["row"], e["column"]) for e in caught.value.errors}
    assert found == {(2, "load_N"), (3, "speed_m_s"), (4, "balls"), (5, "mu_measured"), (6, "balls"),
                     (6, "relative_humidity"), (7, "relative_humidity")}
    messages = {(e["row"], e["column"]): e["message"] for e in caught.value.errors}
    assert "load_N must be in [1e-09, 1e+06] [N]; got -1.0" in messages[(2, "load_N")]
    assert "string" in messages[(4, "balls")]
    assert "row 2, column load_N" in str(caught.value)


def test_csv_wrong_types_extra_cells_and_empty_column():
    text = ("balls,load_N,speed_m_s,notes,mu_measured\n"
            "4,0.009,fast,,0.01\n"
            "4,0.009,0.1,,0.01,7\n"
            "4,abc,0.1,,-0.01\n")
    with pytest.raises(DataError) as caught:
        parse_csv(text)
    found = {(e["row"], e["column"]) for e in caught.value.errors}
    assert found == {(1, "speed_m_s"), (2, None), (3, "load_N"), (3, "mu_measured"), (None, "notes")}


@pytest.mark.parametrize("blank", ["", ",,,", " , ,\t, "])
def test_blank_csv_lines_are_bad_rows_and_keep_the_numbering(blank):
    # Data line 3 is blank and data line 4 has a negative load: both named by their own line.
    lines = ["balls,load_N,speed_m_s,mu_measured", "4,0.009,0.1,0.01", "4,0.009,0.1,0.01", blank,
             "4,-1,0.1,0.01", "4,0.009,0.1,0.01"]
    text = "\n".join(lines) + "\n"
    with pytest.raises(DataError) as caught:
        parse_csv(text)
    assert [(e["row"], e["column"]) for e in caught.value.errors] == [(3, None), (4, "load_N")]
    assert "row 3: is blank" in str(caught.value)
    assert "row 4, column load_N: load_N must be" in str(caught.value)
    # Only the newline that ends the last line is not a row; a blank line after it is.
    good = [line.replace("-1", "0.009") for line in lines if line is not blank]
    assert parse_csv("\n".join(good) + "\n").n_points == 4
    with pytest.raises(DataError) as trailing:
        parse_csv("balls,load_N,speed_m_s,mu_measured\n4,0.009,0.1,0.01\n\n")
    assert [(e["row"], e["column"]) for e in trailing.value.errors] == [(2, None)]


def test_request_problems_are_reported_by_column():
    rows = [{"balls": 4, "speed_m_s": 0.1, "mu_measured": 0.01}]
    with pytest.raises(DataError) as caught:
        parse_rows(rows, fixed={"balls": 6, "gremlins": 1, "mu_pivot": -1})
    columns = {e["column"] for e in caught.value.errors}
    assert columns == {"balls", "gremlins", "mu_pivot", "load_N"}
    assert all(e["row"] is None for e in caught.value.errors)


def test_values_survive_parsing_exactly():
    rng = np.random.default_rng(3)
    loads = rng.uniform(1e-3, 1e-1, 50)
    text = "balls,load_N,speed_m_s,mu_measured\n" + "".join(
        f"4,{float(g)!r},0.1,0.01\n" for g in loads)
    data = parse_csv(text)
    assert data.n_points == 50
    assert data.physics_columns["load_N"].tolist() == loads.tolist()


def test_subset_keeps_the_chosen_rows_of_every_column_in_order():
    text = ("balls,load_N,speed_m_s,balls_touching,relative_humidity,mu_measured,mu_measured_std\n"
            "4,0.009,0.05,false,0.4,0.0105,0.0002\n"
            "6,0.012,0.10,true,0.5,0.0121,0.0002\n"
            "8,0.020,0.15,false,0.6,0.0133,0.0003\n"
            "12,0.030,0.00,true,0.7,0.0150,0.0004\n")
    data = parse_csv(text, fixed={"mu_ball": 0.7})
    part = data.subset(np.array([3, 1]))
    # The same rows parsed on their own, in that order.
    lines = text.splitlines()
    expected = parse_csv("\n".join([lines[0], lines[4], lines[2]]) + "\n", fixed={"mu_ball": 0.7})
    assert part.n_points == 2
    assert set(part.physics_columns) == set(expected.physics_columns)
    for name, values in expected.columns().items():
        assert part.columns()[name].tolist() == values.tolist(), name
    assert part.mu_measured.tolist() == [0.0150, 0.0121]
    assert part.mu_measured_std.tolist() == [0.0004, 0.0002]
    assert part.fixed == {"mu_ball": 0.7}
    # The original is untouched, and a subset shares no array with it.
    assert data.n_points == 4 and data.mu_measured.tolist()[3] == 0.0150
    part.mu_measured[0] = 1.0
    assert data.mu_measured[3] == 0.0150
    without_std = parse_csv("balls,load_N,speed_m_s,mu_measured\n4,0.009,0.05,0.01\n4,0.01,0.1,0.02\n")
    assert without_std.subset(np.array([1])).mu_measured_std is None


def test_calibrate_docstring_examples_run():
    # The project's doctest collection covers physics/ only; the examples of calibrate/ run here.
    import doctest

    import microbearing.calibrate.data
    import microbearing.calibrate.decidability
    import microbearing.calibrate.fit
    import microbearing.calibrate.select  # noqa: F401  (loads the submodule)
    from microbearing import calibrate

    for module in (calibrate.data, calibrate.select, calibrate.fit, calibrate.decidability):
        failures, tried = doctest.testmod(module)
        assert tried > 0 and failures == 0, module.__name__
