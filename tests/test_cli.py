"""The ``microbearing`` command line: evaluate, sweep and optimize, their outputs and exit codes."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest

from microbearing import physics
from microbearing.service.cli import EXIT_FILE, EXIT_INFEASIBLE, EXIT_INVALID, main
from microbearing.service.routes.meta import package_version
from microbearing.service.schemas.optimizations import OptimizationResult
from microbearing.service.schemas.sweeps import SweepResult

PROBLEM = {"bounds": {"balls": [4, 8], "groove_angle_deg": [35, 70], "load_N": [0.001, 0.05]},
           "fixed": {"speed_m_s": 0.05, "mu_pivot": 1.0}, "constraints": {"max_contact_pressure_Pa": 1e9}}


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0 and capsys.readouterr().out.strip() == f"microbearing {package_version()}"


@pytest.mark.parametrize("command", ["evaluate", "sweep", "optimize"])
def test_help_shows_examples(capsys, command):
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = capsys.readouterr().out
    assert "examples:" in text and f"\n  microbearing {command} " in text.split("examples:")[1]


def test_evaluate_one_point_is_the_physics(capsys):
    code, out, _ = run(capsys, "evaluate", "balls=4", "load_N=0.008826", "speed_m_s=0.05", "mu_pivot=1",
                       "--outputs", "mu,max_contact_pressure_Pa")
    exact = physics.evaluate(balls=4, load_N=0.008826, speed_m_s=0.05, mu_pivot=1.0)
    assert code == 0 and json.loads(out) == {"convention": "olaru2005", "mu": float(exact.mu),
                                             "max_contact_pressure_Pa": float(exact.max_contact_pressure_Pa)}


def test_evaluate_a_csv_of_points(capsys, tmp_path):
    points = tmp_path / "points.csv"
    points.write_text("load_N,speed_m_s,balls\n0.001,0.05,4\n0.01,0.1,6\n0.02,0,18\n")
    code, _, _ = run(capsys, "evaluate", "--csv", str(points), "mu_pivot=0.8", "--outputs", "mu",
                     "-o", str(tmp_path / "out.csv"))
    rows = list(csv.reader(io.StringIO((tmp_path / "out.csv").read_text())))
    exact = physics.evaluate(load_N=np.array([0.001, 0.01, 0.02]), speed_m_s=np.array([0.05, 0.1, 0.0]),
                             balls=np.array([4, 6, 18]), mu_pivot=0.8).mu
    # the fixed mu_pivot is a column too (issue 28: outputs carry their inputs)
    assert code == 0 and rows[0] == ["load_N", "speed_m_s", "balls", "mu_pivot", "mu"]
    assert [r[2] for r in rows[1:]] == ["4", "6", "18"] and {r[3] for r in rows[1:]} == {"0.8"}
    assert [float(r[4]) for r in rows[1:]] == exact.tolist()
    # its answer read back as points: the output column is left out, said, and computed again
    again = tmp_path / "again.csv"
    code, _, err = run(capsys, "evaluate", "--csv", str(tmp_path / "out.csv"), "--outputs", "mu",
                       "-o", str(again))
    assert code == 0 and "column(s) mu are outputs, not inputs: left out" in err, err
    assert again.read_text() == (tmp_path / "out.csv").read_text()
    # a cell that is no number, named under its key as sent and in that key's unit (not the SI name's)
    typed = tmp_path / "typed.csv"
    typed.write_text("balls,load [mN],speed [mm/s]\n4,,50\n")
    code, _, err = run(capsys, "evaluate", "--csv", str(typed))
    assert code == EXIT_INVALID and err.rstrip().endswith("column load [mN]: '' is not a number"), err


@pytest.mark.parametrize(("argv", "code", "message"), [
    (["evaluate", "balls=4", "load_N=-1", "speed_m_s=0.1"], EXIT_INVALID, "load_N"),
    (["evaluate", "balls=4", "speed_m_s=0.1"], EXIT_INVALID, "load_N=VALUE"),
    (["evaluate", "balls=four", "load_N=1", "speed_m_s=0.1"], EXIT_INVALID, "balls"),
    (["evaluate", "bogus=1"], EXIT_INVALID, "bogus"),
    (["evaluate", "--csv", "/no/such/file.csv"], EXIT_FILE, "cannot read"),
    (["sweep", "/no/such/request.json"], EXIT_FILE, "cannot read"),
])
def test_errors_have_meaningful_exit_codes(capsys, argv, code, message):
    got, _, err = run(capsys, *argv)
    assert got == code and message in err, err


def test_sweep_writes_the_api_table(capsys, tmp_path):
    request = {"design": "grid", "fixed": {"load_N": 0.0088}, "outputs": ["mu"],
               "axes": {"balls": {"start": 4, "stop": 12, "num": 3},
                        "speed_m_s": {"start": 0, "stop": 0.15, "num": 4}}}
    (tmp_path / "grid.json").write_text(json.dumps(request))
    code, out, _ = run(capsys, "sweep", str(tmp_path / "grid.json"))
    result = SweepResult.model_validate_json(out)  # the schema of POST /v1/sweeps
    assert code == 0 and result.count == 12
    assert run(capsys, "sweep", str(tmp_path / "grid.json"), "-o", str(tmp_path / "grid.csv"))[0] == 0
    rows = list(csv.reader(io.StringIO((tmp_path / "grid.csv").read_text())))
    assert rows[0] == ["balls", "speed_m_s", "load_N", "mu"]  # the fixed load too (issue 28)
    assert {r[2] for r in rows[1:]} == {"0.0088"}
    assert [r[:2] for r in rows[1:5]] == [["4", "0.0"], ["4", "0.05"], ["4", "0.1"], ["4", "0.15"]]
    bad = {**request, "axes": {"balls": {"start": 4, "stop": 12, "num": 0}}}
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    code, _, err = run(capsys, "sweep", str(tmp_path / "bad.json"))
    assert code == EXIT_INVALID and "/axes/balls/num" in err


def test_optimize_reads_and_writes_the_api_schemas(capsys, tmp_path):
    (tmp_path / "problem.json").write_text(json.dumps(PROBLEM))
    code, out, _ = run(capsys, "optimize", str(tmp_path / "problem.json"))
    result = OptimizationResult.model_validate_json(out)
    design = result.design
    exact = physics.evaluate(balls=design.balls, groove_angle_deg=design.groove_angle_deg,
                             load_N=design.load_N, speed_m_s=0.05, mu_pivot=1.0)
    assert code == 0 and result.mu == float(exact.mu)
    assert float(exact.max_contact_pressure_Pa) <= 1e9 * (1 + 1e-9)


def test_optimize_infeasible_and_pareto_plot(capsys, tmp_path):
    infeasible = {**PROBLEM, "constraints": {"max_contact_pressure_Pa": 1e6}}
    (tmp_path / "infeasible.json").write_text(json.dumps(infeasible))
    code, _, err = run(capsys, "optimize", str(tmp_path / "infeasible.json"))
    assert code == EXIT_INFEASIBLE and "/constraints/max_contact_pressure_Pa" in err
    front = {**PROBLEM, "pareto": {"objective": "max_contact_pressure_Pa", "points": 3}}
    (tmp_path / "front.json").write_text(json.dumps(front))
    code, out, _ = run(capsys, "optimize", str(tmp_path / "front.json"),
                       "--plot", str(tmp_path / "front.png"))
    assert code == 0 and len(json.loads(out)["pareto"]["points"]) >= 2
    assert (tmp_path / "front.png").read_bytes().startswith(b"\x89PNG")


def test_evaluate_csv_reads_a_spreadsheet_export_as_calibrate_does(capsys, tmp_path):
    clean = tmp_path / "clean.csv"
    clean.write_text("balls,load_N,speed_m_s\n4,0.0088,0.05\n6,0.0132,0.1\n")
    excel = tmp_path / "excel.csv"  # semicolons, decimal commas, units in the header, CRLF, a BOM
    excel.write_bytes("\ufeffballs;load [mN];speed [mm/s]\r\n4;8,8;50\r\n6;13,2;100\r\n".encode())
    code, _, _ = run(capsys, "evaluate", "--csv", str(clean), "--outputs", "mu", "-o", str(tmp_path / "a"))
    assert code == 0
    code, _, err = run(capsys, "evaluate", "--csv", str(excel), "--outputs", "mu", "-o", str(tmp_path / "b"))
    assert code == 0 and "separator semicolon (detected), decimal comma (detected)" in err
    a = list(csv.reader(io.StringIO((tmp_path / "a").read_text())))
    b = list(csv.reader(io.StringIO((tmp_path / "b").read_text())))
    # each answer speaks its file's headers and units: the export's mN and mm/s as typed (8,8 is 8.8)
    assert a[0] == ["balls", "load_N", "speed_m_s", "mu"]
    assert b[0] == ["balls", "load [mN]", "speed [mm/s]", "mu"]
    assert [[float(c) for c in r[1:3]] for r in b[1:]] == [[8.8, 50.0], [13.2, 100.0]]
    exact = physics.evaluate(balls=np.array([4, 6]), load_N=np.array([0.0088, 0.0132]),
                             speed_m_s=np.array([0.05, 0.1])).mu
    for rows in (a, b):
        np.testing.assert_allclose([float(r[3]) for r in rows[1:]], exact, rtol=1e-12)


def test_evaluate_csv_warns_of_a_unit_slip_in_the_words_calibrate_refuses_it_with(capsys, tmp_path):
    from microbearing.calibrate import DataError, calibrate, read_csv

    points = tmp_path / "points.csv"
    points.write_text("balls,load_N,speed_m_s\n4,0.0088,50\n")
    code, _, err = run(capsys, "evaluate", "--csv", str(points), "--outputs", "mu")
    assert code == 0 and "speed_m_s runs 50 to 50 m/s" in err and "look like mm/s" in err
    rows = "".join(f"4,0.0088,{v},0.01\n" for v in [50] * 12)
    dataset, _ = read_csv("balls,load_N,speed_m_s,mu_measured\n" + rows)
    with pytest.raises(DataError, match="look like mm/s"):
        calibrate(dataset, ["mu_pivot"])
    # a column that is not a physics input is a condition: read by a calibrated model only
    points.write_text("balls,load_N,speed_m_s,rh\n4,0.0088,0.05,0.3\n")
    code, _, err = run(capsys, "evaluate", "--csv", str(points))
    error = err.strip().splitlines()[-1]  # after the line saying how the file was read
    assert code == EXIT_INVALID and error.startswith("microbearing evaluate: ") and "'rh'" in error
    assert error.endswith("a condition column is read by a calibrated model only (--model ID)")


def test_evaluate_csv_names_a_bad_cell_by_its_file_line_and_value_as_typed(capsys, tmp_path):
    points = tmp_path / "points.csv"
    points.write_text("balls,load [mN],speed_m_s\n4,10,0.05\n4,-5,0.05\n")
    code, _, err = run(capsys, "evaluate", "--csv", str(points))
    error = err.strip().splitlines()[-1]
    assert code == EXIT_INVALID and "line 3, column load [mN]" in error, error
    assert "(sent as load [mN]: -5, read as load_N: -0.005)" in error, error
    # text among a condition's numbers is named at its line (hand: line 3 is the second data row)
    points.write_text("balls,load_N,speed_m_s,cycles [kcycles]\n4,0.01,0.05,5\n4,0.01,0.05,abc\n")
    code, _, err = run(capsys, "evaluate", "--csv", str(points))
    error = err.strip().splitlines()[-1]
    assert code == EXIT_INVALID and "line 3, column cycles [kcycles]: 'abc' is not a number" in error, error


def test_every_command_that_reads_or_writes_the_store_takes_data_dir():
    from microbearing.service.cli import build_parser

    parser = build_parser()
    for argv in (["evaluate"], ["optimize", "r.json"], ["experiments", "r.json"], ["calibrate", "d.csv"],
                 ["calibrations", "list"], ["calibrations", "delete", "x"], ["surrogate", "list"],
                 ["surrogate", "train", "r.json"], ["surrogate", "predict", "x", "a=1"],
                 ["surrogate", "delete", "x"]):
        assert parser.parse_args([*argv, "--data-dir", "/tmp/d"]).data_dir is not None, argv


def test_surrogate_delete_removes_it_and_a_second_delete_is_refused(capsys, tmp_path):
    request = tmp_path / "request.json"
    request.write_text(json.dumps({"space": {"load_N": [0.002, 0.03]}, "budget": 12, "adaptive": False,
                                   "fixed": {"balls": 4, "speed_m_s": 0.05}, "validation_points": 0}))
    data = tmp_path / "data"
    code, out, err = run(capsys, "surrogate", "train", str(request), "--data-dir", str(data))
    assert code == 0, err
    surrogate_id = json.loads(out)["id"]
    code, out, _ = run(capsys, "surrogate", "list", "--data-dir", str(data))
    assert out.splitlines()[1].endswith("12 evaluations  load_N [0.002, 0.03]"), out  # of the physics
    code, out, err = run(capsys, "surrogate", "delete", surrogate_id, "--data-dir", str(data))
    assert code == 0 and out.startswith(f"deleted surrogate {surrogate_id}"), err
    code, out, _ = run(capsys, "surrogate", "list", "--data-dir", str(data))
    assert out.startswith("0 surrogate(s)")
    code, _, err = run(capsys, "surrogate", "delete", f"surrogate:{surrogate_id}", "--data-dir", str(data))
    assert code == EXIT_INVALID and "no surrogate" in err and surrogate_id in err and str(data) in err
    code, _, err = run(capsys, "calibrations", "delete", "not-an-id", "--data-dir", str(data))
    assert code == EXIT_INVALID and "id: expected an id (32 hexadecimal digits)" in err
    assert "--model" not in err  # the command has no such option: its argument is named


def test_a_calibration_not_stored_leaves_no_data_folder(capsys, tmp_path):
    data = tmp_path / "data"
    bad = tmp_path / "bad.csv"
    bad.write_text("balls,load_N,speed_m_s,mu_measured\n4,-1,0.1,0.01\n4,0.01,0.1,x\n")
    code, _, err = run(capsys, "calibrate", str(bad), "--data-dir", str(data))
    assert code == EXIT_INVALID and "row 1, column load_N" in err and len(err.strip().splitlines()) == 1
    assert not data.exists()  # refused before the store was opened
