"""Issue 32's seams on variants no other test sends (h45's probe): each door reads a column as the others."""

from __future__ import annotations

import json

import pytest

from microbearing.calibrate.plausibility import check_plausible
from microbearing.calibrate.tabular import read_csv
from microbearing.physics.columns import read_name
from microbearing.physics.slips import read_slip


@pytest.mark.parametrize("dash, one", [("RH [-]", "RH [1]"), ("cycles [-]", "cycles [1]"),
                                       ("relative humidity (-)", "relative humidity [1]")])
def test_a_number_s_unit_written_as_a_dash_reads_as_1_for_every_column(dash, one):
    # before: 'RH [-]' and 'cycles [-]' were refused ("whose unit is [%] or [1], not '-'") while 'balls [-]',
    # 'run_index [-]' and 'mu_measured [-]' were read as numbers: one registry, two rules
    read, expected = read_name(dash), read_name(one)
    assert (read.name, read.scale, read.offset, read.reading) == (expected.name, 1.0, 0.0, ""), read
    assert read_name("balls [-]").name == "balls"


def test_an_upload_s_humidity_in_dashes_is_read_as_a_fraction_and_its_slip_refused():
    rows = "balls,load [mN],speed [mm/s],RH [-],mu_measured\n" + "".join(
        f"{4 + i % 3},{5 + i},{20 + 3 * i},{0.2 + 0.05 * i},{0.03 + 0.001 * i}\n" for i in range(8))
    data, _ = read_csv(rows)
    assert list(data.conditions) == ["RH"]
    assert data.conditions["RH"].tolist() == pytest.approx([0.2 + 0.05 * i for i in range(8)])
    # the upload's slip rule judges it as a fraction: 20 to 55 [-] looks like percent
    percent, _ = read_csv("balls,load [mN],speed [mm/s],RH [-],mu_measured\n" + "".join(
        f"{4 + i % 3},{5 + i},{20 + 3 * i},{20 + 5 * i},{0.03 + 0.001 * i}\n" for i in range(8)))
    with pytest.raises(ValueError, match="look like percent"):
        check_plausible(percent)
    # and so does every other door (a key at /v1/friction, batch, UM-Bridge, the CLI): 50 [-] is no fraction
    assert "look like percent" in read_slip(read_name("RH [-]"), [50.0])
    assert read_slip(read_name("RH [-]"), [0.5]) is None


def test_the_cli_reads_a_whole_count_written_with_a_point_as_the_api_does(tmp_path, capsys):
    # before: `microbearing evaluate balls=6.0` was refused ("'6.0' is not a whole number [1]") where
    # /v1/friction and a CSV upload read 6.0 as 6; and 6.5 was refused in other words than the API's
    from fastapi.testclient import TestClient

    from microbearing.service.app import create_app
    from microbearing.service.cli import main
    from microbearing.service.settings import Settings

    out = tmp_path / "point.json"
    assert main(["evaluate", "balls=6.0", "load [gf]=1", "speed [mm/min]=3000", "-o", str(out)]) == 0
    with TestClient(create_app(Settings(data_dir=tmp_path / "data"))) as client:
        point = {"balls": 6.0, "load [gf]": 1, "speed [mm/min]": 3000}
        api = client.post("/v1/friction", json=point)
        assert api.status_code == 200, api.text
        assert json.loads(out.read_text())["mu"] == pytest.approx(api.json()["mu"], rel=1e-12)
        refused = client.post("/v1/friction", json={**point, "balls": 6.5})
    assert refused.status_code == 422
    assert main(["evaluate", "balls=6.5", "load [gf]=1", "speed [mm/min]=3000"]) != 0
    words = "balls must be a whole number in [1, 1e+06] [1]"
    assert words in refused.json()["errors"][0]["detail"] and words in capsys.readouterr().err
    assert main(["evaluate", "balls=six", "load [gf]=1", "speed [mm/min]=3000"]) != 0
    assert "'six' is not a whole number" in capsys.readouterr().err


def test_a_column_sent_under_another_header_in_its_own_unit_is_drawn_and_named_by_that_header():
    # before: 'temperature [K]' (read as temperature_K, unconverted) was drawn as 'temperature_K [K]' and an
    # effect on 'RH [-]' (read as RH) was 'humidity_meniscus on RH': the header dropped where no unit changed
    from microbearing.calibrate.plots import DrawnColumn
    from microbearing.calibrate.prose import in_sent_words, located
    from microbearing.calibrate.tabular import read_rows

    rows = [{"balls": 4 + i % 3, "load [gf]": 1.0 + 0.1 * i, "speed_m_s": 0.05, "RH [-]": 0.2 + 0.05 * i,
             "temperature [K]": 295.0 + i, "mu_measured": 0.03} for i in range(8)]
    data, _ = read_rows(rows)
    assert sorted(data.conditions) == ["RH", "temperature_K"]
    assert DrawnColumn.of(data, "temperature_K").label == "temperature [K]"
    assert DrawnColumn.of(data, "RH").label == "RH [-]"
    assert DrawnColumn.of(data, "load_N").label == "load [gf]"
    assert DrawnColumn.of(data, "speed_m_s").label == "speed_m_s [m/s]"  # sent under its own name
    drawn = DrawnColumn.of(data, "temperature_K")
    assert drawn.shown([300.0]).tolist() == [300.0]  # its own unit: the values as they are
    # a report's ranges under the header, in the unit it says (the column's own: K, 1)
    assert located(data, {"driver": "temperature_K", "range": [295.0, 302.0]})["as_sent"] == {
        "driver": "temperature [K]", "range": [295.0, 302.0], "unit": "K"}
    assert located(data, {"driver": "RH", "range": [0.2, 0.55]})["as_sent"]["unit"] == "1"
    assert located(data, {"driver": "load_N", "range": [0.0098, 0.0098]})["as_sent"]["unit"] == "gf"
    assert in_sent_words(data, "humidity_meniscus on RH; thermal on temperature_K") == (
        "humidity_meniscus on RH [-]; thermal on temperature [K]")


def test_an_experiment_space_refuses_a_fraction_of_a_ball_in_the_words_of_every_other_door(tmp_path):
    # before: "space.balls: ball counts must be whole numbers", where /v1/friction, batch, optimizations,
    # UM-Bridge and the CLI say physics.validate's "balls must be a whole number in [1, 1e+06] [1]"
    from fastapi.testclient import TestClient

    from microbearing.service.app import create_app
    from microbearing.service.settings import Settings

    space = {"balls": {"values": [4, 6.5]}, "load_N": [0.005, 0.02], "speed_m_s": [0.01, 0.05]}
    with TestClient(create_app(Settings(data_dir=tmp_path))) as client:
        refused = client.post("/v1/experiments", json={"runs": 2, "fit_parameters": ["mu_pivot"],
                                                        "space": space})
        friction = client.post("/v1/friction", json={"balls": 6.5, "load_N": 0.01, "speed_m_s": 0.05})
        chosen = client.post("/v1/experiments", json={"runs": 2, "fit_parameters": ["mu_pivot"],
                                                       "space": {**space, "balls": {"values": [4.0, 6.0]}}})
    assert refused.status_code == 422 and friction.status_code == 422
    words = "balls must be a whole number in [1, 1e+06] [1]"
    assert words in friction.json()["errors"][0]["detail"]
    errors = refused.json()["errors"]
    assert errors[0]["pointer"] == "/space/balls" and words in errors[0]["detail"], errors
    assert chosen.status_code in (200, 202), chosen.text  # 6.0 is a whole count


@pytest.mark.parametrize("sweep", [
    {"design": "grid", "fixed": {"load [gf]": 1.0, "balls": 6.0}, "outputs": ["mu"],
     "axes": {"speed [mm/min]": {"start": 1000, "stop": 6000, "num": 3}}},
    {"design": "sobol", "points": 16, "seed": 3, "outputs": ["mu"], "fixed": {"speed [cm/s]": 5},
     "ranges": {"load [gf]": {"low": 0.5, "high": 2}, "balls": [4, 8]}},
], ids=["grid", "sobol"])
def test_a_sweep_answers_in_the_keys_and_units_it_was_sent(tmp_path, sweep):
    # before: the table said speed_m_s 0.0166666666666667 and load_N 0.00980665 for speed [mm/min] 1000 and
    # load [gf] 1, in JSON and CSV alike, where the CLI's evaluate --csv answers a file in its headers
    import csv
    import io

    import numpy as np
    from fastapi.testclient import TestClient
    from pydantic import TypeAdapter

    from microbearing.service.app import create_app
    from microbearing.service.schemas.sweeps import SweepRequest
    from microbearing.service.settings import Settings
    from microbearing.service.store import json_bytes
    from microbearing.service.sweeps import MAX_NUMBER_BYTES, design_columns, result_bytes_bound, run_sweep

    with TestClient(create_app(Settings(data_dir=tmp_path))) as client:
        document = client.post("/v1/sweeps", json=sweep).json()
        table = client.post("/v1/sweeps", json=sweep, headers={"Accept": "text/csv"}).text
    sent = document["as_sent"]
    # by hand: mm/min = 60000 x m/s, gf = N / 0.00980665, cm/s = 100 x m/s
    factor = {"speed [mm/min]": 60000.0, "load [gf]": 1 / 0.00980665, "speed [cm/s]": 100.0}
    for key, part in sent.items():
        assert part["factor"] == pytest.approx(factor[key], rel=1e-12) and part["offset"] == 0, (key, part)
        if part["column"] in document["fixed"]:
            assert part["values"] == pytest.approx(document["fixed"][part["column"]] * factor[key], rel=1e-12)
        else:  # a key map, not a second copy of the column
            assert part.get("values") is None and part["column"] in document["columns"], (key, part)
    if sweep["design"] == "grid":
        assert sent["load [gf]"]["values"] == 1 and sent["speed [mm/min]"]["unit"] == "mm/min", sent
    rows = list(csv.DictReader(io.StringIO(table)))
    assert set(sent) <= set(rows[0]) and not {part["column"] for part in sent.values()} & set(rows[0])
    for key, part in sent.items():
        si = document["columns"].get(part["column"], document["fixed"].get(part["column"]))
        values = np.broadcast_to(np.asarray(si, dtype=float) * factor[key], (len(rows),))
        # the CSV's to the digits each value holds (the SI value's 12), the factor's to a double's
        assert [float(r[key]) for r in rows] == pytest.approx(values.tolist(), rel=1e-10)
    if sweep["design"] == "grid":  # as typed, not their round trip through m/s (999.9999999999)
        assert sorted({r["speed [mm/min]"] for r in rows}) == ["1000.0", "3500.0", "6000.0"], rows
    # the result's size is bounded before a point is computed, exactly but for the digits of the values
    # not known then (an output's, a sampled input's, and their values as sent)
    body = TypeAdapter(SweepRequest).validate_json(json.dumps(sweep))
    result = run_sweep(body, design_columns(body, 10**6))
    unknown = [result["columns"][n] for n in result["columns"]
               if sweep["design"] != "grid" or n not in result["varied"]]
    shortfall = sum(MAX_NUMBER_BYTES - len(json_bytes(v)) for values in unknown
                    for v in np.asarray(values).tolist())
    assert result_bytes_bound(body, result["count"]) - len(json_bytes(result)) == shortfall


def test_a_sweep_job_answers_in_the_keys_sent_as_one_answered_at_once(tmp_path):
    # a sweep past the synchronous limit is a job, rebuilt from its stored request by any process (after a
    # restart too): before, that request was the SI dump, and the rebuilt sweep answered only speed_m_s
    from fastapi.testclient import TestClient
    from jobs_helper import wait_job
    from pydantic import TypeAdapter

    from microbearing.service.app import create_app
    from microbearing.service.schemas.sweeps import SweepRequest
    from microbearing.service.settings import Settings
    from microbearing.service.store import json_bytes
    from microbearing.service.sweeps import design_columns, sent_columns, stored_request

    sweep = {"design": "grid", "fixed": {"load [gf]": 1.0, "balls": 6}, "outputs": ["mu"],
             "axes": {"speed [mm/min]": {"start": 1000, "stop": 6000, "num": 3}}}
    with TestClient(create_app(Settings(data_dir=tmp_path, sweep_sync_max_points=2))) as client:
        job = wait_job(client, client.post("/v1/sweeps", json=sweep), timeout_s=120)
        assert job["status"] == "succeeded", job
        result = client.get(job["result_url"]).json()
        table = client.get(job["result_url"], headers={"Accept": "text/csv"}).text
    assert result["as_sent"]["speed [mm/min]"] == {"column": "speed_m_s", "unit": "mm/min", "factor": 60000.0,
                                                   "offset": 0.0}
    assert result["columns"]["speed_m_s"] == pytest.approx([1 / 60, 3.5 / 60, 0.1], rel=1e-12)
    assert table.splitlines()[0] == "speed [mm/min],balls,load [gf],mu"
    adapter = TypeAdapter(SweepRequest)
    body = adapter.validate_json(json.dumps(sweep))
    rebuilt = adapter.validate_json(json_bytes(stored_request(body)))  # as a job kind rebuilds it
    sent = sent_columns(body, design_columns(body, 100))
    assert sent and sent_columns(rebuilt, design_columns(rebuilt, 100)) == sent
    assert rebuilt.model_dump() == body.model_dump()  # the same sweep


def test_a_large_sweep_in_other_units_is_no_larger_than_in_si_and_its_csv_keeps_the_keys(tmp_path):
    # before: as_sent repeated every varied column under its key: 10^4 Sobol points over speed [mm/s] and
    # load [gf] answered 879012 bytes of JSON against 617936 sent as speed_m_s and load_N (+42 %), and the
    # size bound that answers 413 grew from 750128 to 1250232 bytes (+67 %): a key map now, the CSV the same
    from fastapi.testclient import TestClient
    from pydantic import TypeAdapter

    from microbearing.service.app import create_app
    from microbearing.service.schemas.sweeps import SweepRequest
    from microbearing.service.settings import Settings
    from microbearing.service.sweeps import result_bytes_bound
    from microbearing.service.tables import sweep_table

    def sweep(speed: str, load: str, scale: tuple[float, float]) -> dict:
        return {"design": "sobol", "points": 10_000, "seed": 1, "outputs": ["mu"], "fixed": {"balls": 6},
                "ranges": {speed: {"low": 10 * scale[0], "high": 100 * scale[0]},
                           load: {"low": 0.5 * scale[1], "high": 2 * scale[1]}}}

    sent = sweep("speed [mm/s]", "load [gf]", (1.0, 1.0))
    own = sweep("speed_m_s", "load_N", (1e-3, 0.00980665))  # by hand: 1 mm/s = 1e-3 m/s, 1 gf = 0.00980665 N
    with TestClient(create_app(Settings(data_dir=tmp_path))) as client:
        answers = [client.post("/v1/sweeps", json=body) for body in (sent, own)]
        table = client.post("/v1/sweeps", json=sent, headers={"Accept": "text/csv"}).text
    assert [a.status_code for a in answers] == [200, 200]
    sizes = [len(a.content) for a in answers]
    assert sizes[0] <= sizes[1] + 1000, sizes  # the key map's few hundred bytes, not a second copy
    bounds = [result_bytes_bound(TypeAdapter(SweepRequest).validate_json(json.dumps(body)), 10_000)
              for body in (sent, own)]
    assert bounds[0] <= bounds[1] + 1000, bounds
    document = answers[0].json()
    assert document["as_sent"]["speed [mm/s]"] == {"column": "speed_m_s", "unit": "mm/s", "factor": 1000.0,
                                                   "offset": 0.0}, document["as_sent"]
    lines = table.splitlines()
    assert lines[0] == "load [gf],speed [mm/s],balls,mu" and len(lines) == 10_001, lines[:2]
    speeds = [float(line.split(",")[1]) for line in lines[1:]]
    assert speeds == pytest.approx([1000 * v for v in document["columns"]["speed_m_s"]], rel=1e-10)
    assert 10 <= min(speeds) and max(speeds) <= 100
    # a result stored before, its varied columns repeated under their keys, gives the same CSV columns
    header = lines[0].split(",")
    column = {key: [float(line.split(",")[header.index(key)]) for line in lines[1:]] for key in header}
    old = {**document, "as_sent": {key: {"column": part["column"], "values": column[key]}
                                   for key, part in document["as_sent"].items()}}
    assert list(sweep_table(old)) == list(sweep_table(document)) == header
    assert sweep_table(old)["speed [mm/s]"] == sweep_table(document)["speed [mm/s]"]
