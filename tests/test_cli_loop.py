"""The loop a lab runs from a shell (issue 34, item 1), each step a process of the ``microbearing``
command: calibrate a spreadsheet export, predict friction with an interval on the stored model, plan the
next runs, design for the worst case over an operating envelope, delete the model; then the model is gone.

The spreadsheet is generated here from the physics with a known missing effect (capillary menisci
growing with humidity, 2e-5 N per ball) and 2 % scatter, and saved as German Excel writes CSV (semicolon,
decimal comma, units in the header): every number the commands print is checked against that truth.
"""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from microbearing import physics
from microbearing.service.store import Store

MU_PIVOT = 0.6
MENISCUS_N = 2e-5  # per ball, at ln(1/h) = 1


def true_mu(balls, load_N, speed_m_s, humidity, groove_angle_deg):
    """The law the data follow: the physics with mu_pivot 0.6, plus capillary menisci."""
    mu = physics.evaluate(balls=balls, load_N=load_N, speed_m_s=speed_m_s, mu_pivot=MU_PIVOT,
                          groove_angle_deg=groove_angle_deg).mu
    return np.asarray(mu) + balls * MENISCUS_N / (load_N * np.log(1 / humidity))


def spreadsheet(rows: int = 30, seed: int = 11) -> str:
    """Measurements as German Excel saves them: semicolons, decimal commas, units in the header."""
    rng = np.random.default_rng(seed)
    lines = ["balls;groove angle [deg];load [mN];speed [mm/s];relative humidity [%];mu_measured"]
    for _ in range(rows):
        balls, angle, load_mN = int(rng.choice([4, 6, 8])), float(rng.choice([45, 54.7, 60])), float(
            rng.choice([4.4, 8.8, 13.2]))
        speed_mm_s, humidity_pct = rng.uniform(10, 150), rng.uniform(25, 75)
        mu = float(true_mu(balls, load_mN / 1e3, speed_mm_s / 1e3, humidity_pct / 100, angle))
        mu *= math.exp(rng.normal(0, 0.02))
        lines.append(f"{balls};{angle:g};{load_mN:.1f};{speed_mm_s:.1f};{humidity_pct:.0f};{mu:.6f}"
                     .replace(".", ","))
    return "\r\n".join(lines) + "\r\n"


def command() -> list[str]:
    """The installed console script beside this interpreter, else ``python -m microbearing.service.cli``."""
    script = Path(sys.executable).with_name("microbearing")
    return [str(script)] if script.is_file() else [sys.executable, "-m", "microbearing.service.cli"]


@pytest.fixture
def shell(tmp_path):
    """Run ``microbearing ARGS`` in tmp_path as a shell would, on the data folder tmp_path/data."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("MICROBEARING_")}
    env["MICROBEARING_DATA_DIR"] = str(tmp_path / "data")  # --data-dir is given too; this guards a slip

    def run(*args: str, expect: int = 0) -> subprocess.CompletedProcess:
        done = subprocess.run([*command(), *args, "--data-dir", str(tmp_path / "data")], cwd=tmp_path,
                              env=env, capture_output=True, text=True, timeout=600)
        assert done.returncode == expect, (args, done.returncode, done.stderr)
        assert "Traceback" not in done.stderr, done.stderr
        return done

    return run


def test_a_lab_calibrates_predicts_plans_designs_and_deletes_from_the_shell(tmp_path, shell):
    (tmp_path / "lab.csv").write_bytes(spreadsheet().encode())

    # 1. calibrate: the model is stored, its id alone on stdout with --quiet
    done = shell("calibrate", "lab.csv", "--fit", "mu_pivot", "--folds", "3", "--quiet")
    model_id = done.stdout.strip()
    assert re.fullmatch(r"[0-9a-f]{32}", model_id), done.stdout
    assert "separator semicolon (detected), decimal comma (detected)" in done.stderr
    assert "relative humidity [%] read as relative_humidity / 100" in done.stderr
    # stored as POST /v1/calibrations stores one (service.calibrations.store_calibration): the report,
    # the model, the plots and the data, in the store the service reads
    store = Store(tmp_path / "data")
    try:
        stored = store.load_model(model_id)
    finally:
        store.close()
    assert stored.kind == "calibration" and stored.metadata["report"]["n_points"] == 30
    assert [effect["name"] for effect in stored.metadata["report"]["effects"]] == ["humidity_meniscus"]
    assert stored.metadata["report"]["intake"]["separator"] == "semicolon"
    assert stored.metadata["model"]["terms"][0]["name"] == "humidity_meniscus"
    assert len(stored.arrays["data.mu_measured"]) == 30 and "residuals" in stored.arrays

    # 2. friction with its interval on that model, the inputs in the lab's units
    done = shell("evaluate", "--model", model_id, "balls=4", "groove_angle_deg=54.7", "load [mN]=8.8",
                 "speed [mm/s]=50", "relative humidity [%]=50", "--outputs", "mu,mu_lower,mu_upper")
    point = json.loads(done.stdout)
    truth = float(true_mu(4, 0.0088, 0.05, 0.5, 54.7))
    assert point["model"] == f"calibrated:{model_id}" and point["in_domain"] is True
    assert point["mu_lower"] < truth < point["mu_upper"]
    assert point["mu"] == pytest.approx(truth, rel=0.03)
    assert point["mu_upper"] / point["mu_lower"] < 1.2  # 2 % scatter: an interval of about +- 4 %
    assert point["mu_effect"] == pytest.approx(4 * MENISCUS_N / (0.0088 * math.log(2)), rel=0.05)

    # 3. the next experiments for that model
    (tmp_path / "next.json").write_text(json.dumps({
        "runs": 6, "goal": "parameters",
        "space": {"balls": {"values": [4, 8]}, "load_N": {"low": 0.0044, "high": 0.0132},
                  "speed_m_s": {"low": 0.01, "high": 0.15}, "groove_angle_deg": [54.7],
                  "relative_humidity": {"low": 0.25, "high": 0.75}}}))
    plan = json.loads(shell("experiments", "next.json", "--model", model_id).stdout)
    assert plan["calibration_id"] == model_id and len(plan["runs"]) == 6
    for run in plan["runs"]:
        assert run["balls"] in (4, 8) and 0.0044 - 1e-12 <= run["load_N"] <= 0.0132 + 1e-12
        assert 0.01 - 1e-12 <= run["speed_m_s"] <= 0.15 + 1e-12
        assert 0.25 - 1e-12 <= run["conditions"]["relative_humidity"] <= 0.75 + 1e-12
        angle = run["inputs"].get("groove_angle_deg", physics.PARAMETERS["groove_angle_deg"].default)
        expected = float(true_mu(run["balls"], run["load_N"], run["speed_m_s"],
                                 run["conditions"]["relative_humidity"], angle))
        assert run["mu"] == pytest.approx(expected, rel=0.05)
    assert 0 < plan["efficiency_lower_bound"] <= 1

    # 4. a robust design on that model: the lowest 95 % upper bound of mu over 10-100 mm/s and 30-70 % RH
    (tmp_path / "robust.json").write_text(json.dumps({
        "objective": "mu_upper", "speed_m_s": [0.01, 0.1], "conditions": {"relative_humidity": [0.3, 0.7]},
        "bounds": {"balls": [4, 8], "groove_angle_deg": [45, 60], "load_N": [0.0044, 0.0132]},
        "constraints": {"max_contact_pressure_Pa": 7.3e8}}))
    design = json.loads(shell("optimize", "robust.json", "--model", model_id).stdout)
    assert design["model"] == f"calibrated:{model_id}"
    chosen, worst = design["design"], design["worst_case"]
    assert 4 <= chosen["balls"] <= 8 and 45 - 1e-9 <= chosen["groove_angle_deg"] <= 60 + 1e-9
    # friction grows with speed and humidity: the worst case is at their high ends
    assert worst["speed_m_s"] == pytest.approx(0.1)
    assert worst["conditions"]["relative_humidity"] == pytest.approx(0.7)
    at_worst = float(true_mu(chosen["balls"], chosen["load_N"], 0.1, 0.7, chosen["groove_angle_deg"]))
    assert at_worst < worst["mu_upper"] < 1.1 * at_worst  # an upper bound of the truth, and a tight one

    # 5. delete: gone from the list, and refused afterwards in one line with exit code 2
    assert shell("calibrations", "delete", model_id).stdout.startswith(f"deleted calibration {model_id}")
    listed = shell("calibrations", "list").stdout
    assert listed == f"0 calibration(s) in {(tmp_path / 'data').resolve()}\n"
    done = shell("evaluate", "--model", model_id, "balls=4", "load_N=0.0088", "speed_m_s=0.05",
                 "relative_humidity=0.5", expect=2)
    assert done.stdout == "" and len(done.stderr.strip().splitlines()) == 1
    assert f"there is no calibration {model_id}" in done.stderr
