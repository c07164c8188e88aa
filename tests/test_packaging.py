"""The install: one import package ``microbearing`` that a package named ``surrogate`` cannot break."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from pathlib import Path

import httpx
from live_server import free_port, terminate, wait_healthy

import microbearing

REPO = Path(__file__).resolve().parent.parent
OLD_IMPORT = re.compile(r"^\s*(?:>>> )?(?:import|from)\s+(?:" + "|".join(microbearing.SUBPACKAGES) + r")\b",
                        re.M)


def _package_folders() -> list[str]:
    names = ["microbearing", "microbearing.docs"]  # docs/: the manual's sources, served at /manual/
    for sub in microbearing.SUBPACKAGES:
        for init in sorted((REPO / sub).rglob("__init__.py")):
            folder = init.parent.relative_to(REPO)
            if "__pycache__" not in folder.parts and folder.as_posix() != "service/root_package":
                names.append("microbearing." + ".".join(folder.parts))
    return names


def test_every_package_folder_is_installed():
    setuptools = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert sorted(setuptools["packages"]) == sorted(_package_folders()), (
        "pyproject.toml's [tool.setuptools] packages differ from the folders with an __init__.py: list "
        "each folder as microbearing.<dotted path>")


def test_nothing_imports_the_old_top_level_names():
    files = [p for p in REPO.rglob("*.py") if not {".venv", "build", ".git"} & set(p.relative_to(REPO).parts)]
    stale = [f"{p.relative_to(REPO)}:{text[:m.start()].count(chr(10)) + 1}" for p in files
             for text in [p.read_text(encoding="utf-8")] for m in OLD_IMPORT.finditer(text)]
    assert not stale, f"imports of the old top-level packages (use `from microbearing import ...`): {stale}"


def test_python_dash_m_microbearing():
    run = subprocess.run([sys.executable, "-m", "microbearing", "--version"], capture_output=True, text=True,
                         timeout=60, cwd=REPO)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == f"microbearing {microbearing.__version__}"


def _stub_surrogate_wheel(folder: Path) -> Path:
    """A wheel of a distribution named ``surrogate`` whose top-level module ``surrogate`` has none of ours."""
    wheel = folder / "surrogate-0.1-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w") as archive:
        archive.writestr("surrogate/__init__.py", '"""Not microbearing\'s surrogate."""\nSTUB = True\n')
        archive.writestr("surrogate-0.1.dist-info/METADATA",
                         "Metadata-Version: 2.1\nName: surrogate\nVersion: 0.1\n")
        archive.writestr("surrogate-0.1.dist-info/WHEEL",
                         "Wheel-Version: 1.0\nGenerator: test\nRoot-Is-Purelib: true\nTag: py3-none-any\n")
        archive.writestr("surrogate-0.1.dist-info/RECORD", "")
    return wheel


def test_wheel_in_a_fresh_venv_beside_a_package_named_surrogate(tmp_path):
    dist = tmp_path / "dist"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(dist), str(REPO)],
                   check=True, capture_output=True, timeout=600)
    wheel = next(dist.glob("microbearing-*.whl"))
    names = zipfile.ZipFile(wheel).namelist()
    assert all(n.startswith(("microbearing/", "microbearing-")) for n in names), sorted(
        {n.split("/")[0] for n in names})
    assert {"microbearing/__main__.py", "microbearing/physics/__init__.py",
            "microbearing/service/routes/__init__.py"} <= set(names)
    assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names)

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    python = venv / "bin" / "python"
    where = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                           check=True, capture_output=True, text=True)
    purelib = Path(where.stdout.strip())
    # The dependencies (numpy, fastapi, ...) from this environment, after the fresh venv's own packages; a
    # path in a .pth file is not a site directory, so this environment's editable install stays inactive.
    (purelib / "dependencies.pth").write_text(sysconfig.get_path("purelib") + "\n")
    subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "-q", "--no-deps",
                    "--no-index", str(wheel), str(_stub_surrogate_wheel(tmp_path))],
                   check=True, capture_output=True, timeout=300)

    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH" and not k.startswith("MICROBEARING_")}
    check = subprocess.run([str(python), "-c", (
        "import importlib.util, surrogate, microbearing, microbearing.service.app\n"
        "from microbearing.surrogate import GaussianProcessSurrogate\n"
        "assert surrogate.STUB and microbearing.__file__.startswith(" + repr(str(venv)) + ")\n"
        "assert importlib.util.find_spec('physics') is None\n"
        "assert importlib.util.find_spec('service') is None\n")],
        capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    assert check.returncode == 0, check.stderr

    port = free_port()
    log = (tmp_path / "server.log").open("wb")
    server = subprocess.Popen([str(python), "-m", "microbearing", "serve", "--port", str(port),
                               "--data-dir", str(tmp_path / "data")],
                              cwd=tmp_path, env=env, stdout=log, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    try:
        wait_healthy(url, server, tmp_path / "server.log")
        point = {"balls": 4, "load_N": 0.01, "speed_m_s": 0.1}
        answer = httpx.post(f"{url}/v1/friction", json=point, timeout=30)
        assert answer.status_code == 200 and answer.json()["mu"] > 0
        assert httpx.get(f"{url}/v1/surrogates", timeout=30).status_code == 200
        assert httpx.get(f"{url}/docs/assets/swagger-ui-bundle.js", timeout=30).status_code == 200
        # the manual, built from the pages the wheel ships
        assert "Tutorial" in httpx.get(f"{url}/manual/", timeout=120).text
    finally:
        terminate(server)
        log.close()
