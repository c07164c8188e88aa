"""The first hour of a user (issue 28, items 6-8): the command line, UM-Bridge out of the box, and
tables that carry their inputs.

* CLI: ``microbearing surrogate`` trains, predicts and lists; every command's ``--help`` has
  examples; a read names the data folder when something is not found and creates no database.
* UM-Bridge: the physics differentiates with its default inputs (the ball count held), and a
  client without a key gets the protocol's 401 error at Evaluate (the stock client shows it).
* Sweep and evaluate tables include the inputs the request fixed.
"""

from __future__ import annotations

import argparse
import csv
import io
import json

import numpy as np
import pytest
import umbridge
from fastapi.testclient import TestClient
from live_server import Server

from microbearing import physics
from microbearing.service.app import create_app
from microbearing.service.cli import build_parser, main
from microbearing.service.settings import Settings
from microbearing.service.store import DATABASE_NAME

KEY = "first-hour-key-0123"


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def commands(parser: argparse.ArgumentParser, prefix: tuple[str, ...] = ()):
    """Every command and subcommand path of the parser, e.g. ("surrogate", "train")."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield (*prefix, name)
                yield from commands(sub, (*prefix, name))


def test_every_command_help_shows_examples_of_itself(capsys):
    found = list(commands(build_parser()))
    assert {("surrogate", "train"), ("surrogate", "predict"), ("surrogate", "list"), ("paper",), ("serve",),
            ("calibrate",)} <= set(found)
    for path in found:
        with pytest.raises(SystemExit):
            main([*path, "--help"])
        text = capsys.readouterr().out
        assert "examples:" in text, path
        assert f"\n  microbearing {' '.join(path)}" in text.split("examples:")[1], path


def test_surrogate_train_predict_list_round_trip(tmp_path, capsys):
    request = tmp_path / "request.json"
    request.write_text(json.dumps({"space": {"load_N": [0.002, 0.03], "speed_m_s": [0.01, 0.15]},
                                   "fixed": {"balls": 4}, "budget": 20, "adaptive": False,
                                   "validation_points": 0}))
    data = tmp_path / "data"
    code, out, err = run(capsys, "surrogate", "train", str(request), "--data-dir", str(data))
    assert code == 0, err
    trained = json.loads(out)
    assert f"stored {trained['model_id']} in {data.resolve()}" in err
    code, out, err = run(capsys, "surrogate", "predict", trained["model_id"], "load_N=0.005,0.02",
                         "speed_m_s=0.05", "--data-dir", str(data))
    assert code == 0, err
    predicted = json.loads(out)
    exact = physics.evaluate(balls=4, load_N=[0.005, 0.02], speed_m_s=0.05).mu
    np.testing.assert_allclose(predicted["mu"], exact, rtol=0.02)
    assert all(lo <= mu <= hi for lo, mu, hi in zip(predicted["mu_lower"], predicted["mu"],
                                                    predicted["mu_upper"], strict=True))
    code, out, _ = run(capsys, "surrogate", "list", "--data-dir", str(data))
    assert code == 0 and out.splitlines()[0] == f"1 surrogate(s) in {data.resolve()}"
    assert trained["model_id"] in out.splitlines()[1] and "load_N [0.002, 0.03]" in out
    code, out, _ = run(capsys, "surrogate", "list", "--json", "--data-dir", str(data))
    assert [s["id"] for s in json.loads(out)["surrogates"]] == [trained["id"]]
    # not found: the data folder is named
    code, _, err = run(capsys, "surrogate", "predict", "0" * 32, "load_N=0.01", "speed_m_s=0.05",
                       "--data-dir", str(data))
    assert code == 2 and str(data.resolve()) in err and "0" * 32 in err


@pytest.mark.parametrize("argv", [
    ["surrogate", "list"],
    ["surrogate", "predict", "surrogate:" + "1" * 32, "load_N=0.01"],
])
def test_a_read_of_a_missing_data_folder_names_it_and_creates_nothing(tmp_path, capsys, argv):
    folder = tmp_path / "nowhere"
    code, _, err = run(capsys, *argv, "--data-dir", str(folder))
    assert code == 2 and str(folder) in err and DATABASE_NAME in err
    assert not folder.exists()


def test_optimize_with_a_stored_model_names_the_data_folder_and_creates_no_database(tmp_path, capsys,
                                                                                    monkeypatch):
    problem = tmp_path / "problem.json"
    problem.write_text(json.dumps({"model": "surrogate:" + "2" * 32,
                                   "bounds": {"balls": [4, 6], "groove_angle_deg": [40, 60],
                                              "load_N": [0.002, 0.03]},
                                   "fixed": {"speed_m_s": 0.05}}))
    folder = tmp_path / "server-data"
    monkeypatch.setenv("MICROBEARING_DATA_DIR", str(folder))
    code, _, err = run(capsys, "optimize", str(problem))
    assert code == 2 and str(folder) in err and not folder.exists()
    # an existing data folder without that surrogate: 404 naming the folder
    main(["surrogate", "list", "--data-dir", str(folder)])  # still nothing created by a read
    assert not folder.exists()
    from microbearing.service.store import Store

    Store(folder).close()
    capsys.readouterr()
    code, _, err = run(capsys, "optimize", str(problem))
    assert code == 2 and "2" * 32 in err and f"looked in the data folder {folder}" in err


def test_evaluate_csv_carries_the_fixed_inputs(tmp_path, capsys):
    points = tmp_path / "points.csv"
    points.write_text("load_N,speed_m_s\n0.01,0.05\n0.02,0.1\n")
    code, out, err = run(capsys, "evaluate", "--csv", str(points), "balls=6", "mu_pivot=0.8",
                         "--outputs", "mu")
    assert code == 0, err
    rows = list(csv.DictReader(io.StringIO(out)))
    assert list(rows[0]) == ["load_N", "speed_m_s", "balls", "mu_pivot", "mu"]
    assert [r["balls"] for r in rows] == ["6", "6"] and [r["mu_pivot"] for r in rows] == ["0.8", "0.8"]
    exact = physics.evaluate(balls=6, mu_pivot=0.8, load_N=[0.01, 0.02], speed_m_s=[0.05, 0.1]).mu
    np.testing.assert_allclose([float(r["mu"]) for r in rows], exact, rtol=1e-12)


def test_calibrate_cli_reads_a_spreadsheet_export_and_says_how(tmp_path, capsys):
    rng = np.random.default_rng(3)
    lines = ["balls;load [mN];speed [mm/s];mu_measured;"]
    for _ in range(60):
        load_mN, speed_mm_s = rng.uniform(3, 30), rng.uniform(1, 150)
        mu = physics.evaluate(balls=4, load_N=load_mN / 1e3, speed_m_s=speed_mm_s / 1e3, mu_pivot=0.7).mu
        mu = float(mu) * np.exp(rng.normal(0, 0.02))
        cells = [f"{v:.6g}".replace(".", ",") for v in (load_mN, speed_mm_s, mu)]
        lines.append(";".join(["4", *cells]) + ";")
    export = tmp_path / "export.csv"
    export.write_bytes(("\ufeff" + "\r\n".join(lines) + "\r\n").encode())
    code, _, err = run(capsys, "calibrate", str(export), "--fit", "mu_pivot", "--folds", "3", "--no-store",
                         "--json", str(tmp_path / "report.json"))
    assert code == 0, err
    assert "separator semicolon (detected), decimal comma (detected)" in err
    assert "speed [mm/s] read as speed_m_s / 1000" in err
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["fitted_parameters"]["mu_pivot"]["value"] == pytest.approx(0.7, rel=0.05)
    assert report["intake"]["conversions"][0] == "load [mN] read as load_N / 1000"


# --- sweeps carry their fixed inputs (API) -------------------------------------------------------


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    settings = Settings(data_dir=tmp_path_factory.mktemp("first-hour"), api_keys=KEY)
    with TestClient(create_app(settings), headers={"Authorization": f"Bearer {KEY}"}) as test_client:
        yield test_client


def test_a_sweep_table_carries_its_fixed_inputs(client):
    body = {"design": "grid", "fixed": {"load_N": 0.008826, "balls": 4}, "outputs": ["mu"],
            "axes": {"speed_m_s": {"start": 0.0, "stop": 0.15, "num": 4}}}
    table = client.post("/v1/sweeps", json=body, headers={"Accept": "text/csv"})
    assert table.status_code == 200, table.text
    rows = list(csv.DictReader(io.StringIO(table.text)))
    assert list(rows[0]) == ["speed_m_s", "balls", "load_N", "mu"]  # varied, fixed (table order), outputs
    assert {r["load_N"] for r in rows} == {"0.008826"} and {r["balls"] for r in rows} == {"4"}
    exact = physics.evaluate(balls=4, load_N=0.008826, speed_m_s=np.linspace(0, 0.15, 4)).mu
    np.testing.assert_allclose([float(r["mu"]) for r in rows], exact, rtol=1e-12)
    document = client.post("/v1/sweeps", json=body).json()
    assert document["fixed"] == {"load_N": 0.008826, "balls": 4}
    assert list(document["columns"]) == ["speed_m_s", "mu"]  # JSON keeps them once, in fixed


# --- UM-Bridge out of the box ------------------------------------------------------------------------


def central(f, x: float, h: float) -> float:
    return (f(x + h) - f(x - h)) / (2 * h)


def test_the_default_physics_gradient_holds_the_ball_count(client):
    point = [4, 0.008826, 0.05]
    response = client.post("/umbridge/Gradient", json={"name": "physics", "input": [point], "outWrt": 0,
                                                       "inWrt": 0, "sens": [1.0]})
    assert response.status_code == 200, response.text
    d_balls, d_load, d_speed = response.json()["output"]
    assert d_balls == 0.0  # a count: held, as documented
    mu = lambda load, speed: float(physics.evaluate(balls=4, load_N=load, speed_m_s=speed).mu)  # noqa: E731
    assert d_load == pytest.approx(central(lambda v: mu(v, 0.05), 0.008826, 1e-6), rel=1e-5)
    assert d_speed == pytest.approx(central(lambda v: mu(0.008826, v), 0.05, 1e-5), rel=1e-5)
    applied = client.post("/umbridge/ApplyJacobian", json={"name": "physics", "input": [point], "outWrt": 0,
                                                           "inWrt": 0, "vec": [1.0, 0.0, 0.0]})
    assert applied.json() == {"output": [0.0]}


def test_without_a_key_the_metadata_shows_the_physics_and_evaluate_is_a_protocol_401(client):
    bare = {"Authorization": ""}
    listed = client.get("/umbridge/Info", headers=bare).json()
    assert listed == {"protocolVersion": 1.0, "models": ["physics"]}
    assert client.post("/umbridge/ModelInfo", json={"name": "physics"}, headers=bare).status_code == 200
    sizes = client.post("/umbridge/InputSizes", json={"name": "physics"}, headers=bare).json()
    assert sizes == {"inputSizes": [3]}
    stored = client.post("/umbridge/ModelInfo", json={"name": "calibrated:" + "3" * 32}, headers=bare)
    assert stored.status_code == 401 and stored.json()["error"]["type"] == "Unauthorized"
    for route, body in (("Evaluate", {"name": "physics", "input": [[4, 0.01, 0.05]]}),
                        ("Gradient", {"name": "physics", "input": [[4, 0.01, 0.05]], "outWrt": 0, "inWrt": 0,
                                      "sens": [1.0]})):
        refused = client.post(f"/umbridge/{route}", json=body, headers=bare)
        assert refused.status_code == 401
        assert refused.json()["error"]["type"] == "Unauthorized"
        assert "umbridge:<key>@" in refused.json()["error"]["message"]
    # the REST API is unchanged: no key, no answer
    assert client.get("/v1/jobs", headers=bare).status_code == 401


def test_the_stock_client_without_a_key_shows_the_refusal_and_the_server_log_names_its_folder(tmp_path):
    data = tmp_path / "served"
    server = Server(data, tmp_path / "server.log", api_keys=KEY)
    try:
        url = server.url + "/umbridge"
        model = umbridge.HTTPModel(url, "physics")  # lists and describes the physics without a key
        with pytest.raises(Exception, match="Unauthorized: This API needs a key: put it in the URL"):
            model([[4, 0.008826, 0.05]])
        keyed = umbridge.HTTPModel(url.replace("http://", f"http://umbridge:{KEY}@"), "physics")
        gradient = keyed.gradient(0, 0, [[4, 0.008826, 0.05]], [1.0])
        assert gradient[0] == 0.0 and gradient[1] < 0 and gradient[2] > 0
    finally:
        server.stop()
    log = (tmp_path / "server.log").read_text()
    assert f"data folder {data}" in log and DATABASE_NAME in log
