"""Where rivals part, in the column's physical range and with its unit (issue 32, seams).

A rival's scan ran over the data's range and as much again on either side whatever the column: a humidity
measured over 30-80 % was scanned from -20 % to 130 %, and a report could say two models part "at RH
-37.9 %". The scan keeps within the column's physical range, and every place the report names carries its
unit and, when the upload used another, the same under the upload's header in that unit.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from test_seams_integer_columns import N_ROWS, as_rows, columns_with, model_with_term

from microbearing.calibrate import parse_rows
from microbearing.calibrate.prose import located
from microbearing.calibrate.rivals import where_they_part
from microbearing.calibrate.tabular import read_rows


def _humid(low: float, high: float, header: str = "relative_humidity"):
    columns = columns_with("relative_humidity")
    columns["relative_humidity"] = np.linspace(low, high, N_ROWS)
    model = model_with_term(columns, "relative_humidity", "generic_linear", [0.0])
    rival = model_with_term(columns, "relative_humidity", "generic_quadratic", [0.0, 0.8])
    rows = as_rows(columns, np.full(N_ROWS, 0.01))
    if header != "relative_humidity":
        rows = [{(header if k == "relative_humidity" else k): (100 * v if k == "relative_humidity" else v)
                 for k, v in row.items()} for row in rows]
    return model, rival, read_rows(rows)[0]  # read as the upload reads it: headers and units


def test_the_scan_over_a_humidity_stays_between_0_and_1():
    model, rival, dataset = _humid(0.3, 0.8)
    scan = where_they_part(model, rival, dataset, "relative_humidity", 0.02)
    # by hand: the quadratic rival exp(0.8 z^2) parts most far from the data's centre, which the old scan
    # put at -0.2 or 1.3; within [0, 1] it is at an end of the physical range
    assert scan["differ"], scan
    ends = [v for run in scan["differ"] for v in run]
    assert min(ends) >= 0.0 and max(ends) <= 1.0, scan
    assert scan["at"] in (0.0, 1.0), scan


def test_a_temperature_scan_keeps_above_absolute_zero_and_a_count_above_zero():
    for column, data in (("temperature_C", (-250.0, 20.0)), ("cycles", (0.0, 1000.0))):
        columns = columns_with(column)
        columns[column] = np.linspace(*data, N_ROWS)
        model = model_with_term(columns, column, "generic_linear", [0.0])
        rival = model_with_term(columns, column, "generic_linear", [0.5])
        scan = where_they_part(model, rival, parse_rows(as_rows(columns, np.full(N_ROWS, 0.01))), column,
                               0.02)
        ends = [v for run in scan["differ"] for v in run]
        floor = -273.15 if column == "temperature_C" else 0.0
        assert ends and min(ends) >= floor, (column, scan)
        assert column != "temperature_C" or min(ends) > floor, scan  # 0 K itself is no temperature


def test_a_session_s_order_is_scanned_from_the_session_s_start():
    # a step of the reading and a drift parted "at run_index -119 to -77.3" (issue 33's step bench, seed
    # 3): a run number counts from the session's start, so the scan keeps at or above 0 while reaching
    # beyond the session's end, where later runs would tell the two apart
    columns = {**columns_with("balls"), "run_index": np.arange(N_ROWS, dtype=float)}
    model, rival = (replace(model_with_term(columns, "run_index", "generic_linear", [value]),
                            conditions=["run_index"]) for value in (0.0, 0.5))
    scan = where_they_part(model, rival, parse_rows(as_rows(columns, np.full(N_ROWS, 0.01))), "run_index",
                           0.02)
    ends = [v for run in scan["differ"] for v in run]
    assert ends and min(ends) >= 0.0, scan
    assert max(ends) > N_ROWS - 1, scan  # still scanned beyond the session's last run


def test_where_they_part_names_its_unit_and_the_upload_s_header():
    model, rival, dataset = _humid(0.3, 0.8, header="relative humidity [%]")
    part = located(dataset, where_they_part(model, rival, dataset, "relative_humidity", 0.02))
    assert part["unit"] == "1"
    sent = part["as_sent"]
    assert sent["driver"] == "relative humidity [%]" and sent["unit"] == "%"
    assert np.allclose(sent["data_range"], [30.0, 80.0])
    assert np.allclose(np.ravel(sent["differ"]), 100 * np.ravel(part["differ"]))
    assert np.isclose(sent["at"], 100 * part["at"])
    # a column sent in its own unit says so, and has no second reading
    model, rival, own = _humid(0.3, 0.8)
    part = located(own, where_they_part(model, rival, own, "relative_humidity", 0.02))
    assert part["unit"] == "1" and part["as_sent"] is None
