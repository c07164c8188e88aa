"""/docs and /redoc work offline: their assets come from the package, and a headless browser with every
host but the loopback unresolvable renders every operation of the spec."""

from __future__ import annotations

import json
import re
import shutil
import subprocess

import pytest
from fastapi.testclient import TestClient
from test_service_live import server  # noqa: F401  (the live server fixture)

from microbearing.service.app import create_app
from microbearing.service.openapi import SPEC_PATH
from microbearing.service.security import OPEN_PATHS

SPEC = json.loads(SPEC_PATH.read_text(encoding="utf-8"))
CHROMIUM = next((shutil.which(name) for name in ("chromium", "chromium-browser") if shutil.which(name)), None)


@pytest.mark.parametrize("page", ["/docs", "/redoc"])
def test_doc_pages_load_only_local_assets(page):
    with TestClient(create_app()) as client:
        html = client.get(page).text
        assets = re.findall(r'(?:src|href)="([^"]+)"', html)
        assert assets and all(a.startswith("/docs/assets/") for a in assets), assets
        assert "cdn" not in html.lower() and "fonts.googleapis" not in html
        for asset in assets:
            assert asset in OPEN_PATHS  # readable without an API key, like the page itself
            response = client.get(asset)
            assert response.status_code == 200 and len(response.content) > 0, asset


def _rendered(url: str) -> str:
    """The DOM of ``url`` after its scripts ran, in headless Chromium that can resolve only 127.0.0.1."""
    run = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                          "--host-resolver-rules=MAP * ~NOTFOUND , EXCLUDE 127.0.0.1",
                          "--virtual-time-budget=20000", "--dump-dom", url],
                         capture_output=True, text=True, timeout=180)
    assert run.returncode == 0, run.stderr[-2000:]
    return run.stdout


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (Debian: apt-get install chromium)")
def test_swagger_ui_and_redoc_render_every_operation_without_network(server):  # noqa: F811
    swagger = _rendered(f"{server}/docs")
    shown = set(re.findall(r'opblock-summary-path" data-path="([^"]+)"', swagger))
    assert shown == set(SPEC["paths"]), set(SPEC["paths"]) ^ shown
    redoc = _rendered(f"{server}/redoc")
    operations = {op["operationId"] for item in SPEC["paths"].values() for op in item.values()}
    shown = set(re.findall(r'operation/(\w+)"', redoc))
    assert operations <= shown, operations - shown
