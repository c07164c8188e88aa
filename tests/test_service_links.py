"""No dead links (issue 28, item 4): every path the README, the manual and the API's texts name is served.

The README, the manual's pages (docs/pages), every description and example of the OpenAPI spec, and the
messages that name paths (the CSV schema's text, the /v1/parameters table) are read; every path under
``/v1`` or ``/umbridge`` they name, and the fixed paths (``/healthz``, ``/docs``, ...), must match a route of
the app, with ``{id}``-style placeholders matched as any segment.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from starlette.routing import Match

from microbearing.service.app import create_app
from microbearing.service.settings import Settings

ROOT = Path(__file__).resolve().parents[1]
_PATH = re.compile(r"(?<![A-Za-z_.$/])/(?:v1|umbridge)(?:/[A-Za-z0-9_{}<>.:-]+)*"
                   r"|(?<![A-Za-z_.$/])/(?:healthz|readyz|metrics|docs|redoc|openapi\.json|manual|ui)\b")


def named_paths(text: str) -> set[str]:
    """Paths named in a text, trailing punctuation and query strings dropped.

    >>> sorted(named_paths("see /v1/jobs/{id}. or /v1/parameters, http://h:8000/umbridge/Info and $JOB/x"))
    ['/umbridge/Info', '/v1/jobs/{id}', '/v1/parameters']
    """
    text = text.replace("127.0.0.1:$PORT/", "127.0.0.1:8000/")  # the examples' port variable
    return {match.rstrip(".,:;") for match in _PATH.findall(text)}


def concrete(path: str) -> str:
    """A path a request could take: each placeholder ({id}, <id>) one segment."""
    return re.sub(r"\{[^}]*\}|<[^>]*>", "x", path)


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    return create_app(Settings(data_dir=tmp_path_factory.mktemp("links")))


def served(app, path: str) -> bool:
    """Whether a route of the app takes the path (with any method), as the router matches requests."""
    scope = {"type": "http", "path": concrete(path), "method": "GET", "root_path": "", "headers": []}
    return any(route.matches(scope)[0] != Match.NONE for route in app.routes)


def _strings(node) -> list[str]:
    if isinstance(node, dict):
        return [s for v in node.values() for s in _strings(v)]
    if isinstance(node, list):
        return [s for v in node for s in _strings(v)]
    return [node] if isinstance(node, str) else []


def test_the_pattern_finds_paths_and_rejects_dead_ones(app):
    assert served(app, "/v1/jobs/{id}/result") and served(app, "/umbridge/Info")
    assert not served(app, "/v1/meta")  # the dead link of issue 28


#: Base URLs the README gives to clients, which append their own paths (checked through one of them).
BASE_URLS = {"/umbridge": "/umbridge/Info"}


#: The documents whose paths are checked, with paths each surely names (the reader works).
DOCUMENTS = {"README.md": {"/v1/friction", "/manual", "/docs"},
             **{p.relative_to(ROOT).as_posix(): set() for p in (ROOT / "docs" / "pages").rglob("*.md")}}
DOCUMENTS["docs/pages/reference/rest-api.md"] = {"/v1/friction", "/v1/calibrations", "/v1/jobs/{id}"}
DOCUMENTS["docs/pages/reference/umbridge.md"] = {"/umbridge/Info"}


@pytest.mark.parametrize("document", sorted(DOCUMENTS))
def test_every_path_the_readme_and_the_manual_name_is_served(app, document):
    paths = named_paths((ROOT / document).read_text(encoding="utf-8"))
    paths = {BASE_URLS.get(p, p) for p in paths}
    assert DOCUMENTS[document] <= paths, DOCUMENTS[document] - paths  # the reader works
    dead = sorted(p for p in paths if not served(app, p))
    assert not dead, f"{document} names paths the app does not serve: {dead}"


def test_every_path_the_api_texts_name_is_served(app):
    spec = app.openapi()
    texts = [s for s in _strings(spec) if not s.startswith(("#/components", "http"))]
    paths = set().union(*(named_paths(t) for t in texts))
    assert "/v1/parameters" in paths  # the schemas point at the parameter table
    dead = sorted(p for p in paths if not served(app, p))
    assert not dead, f"the OpenAPI descriptions name paths the app does not serve: {dead}"
    committed = json.loads((ROOT / "openapi" / "openapi.json").read_text(encoding="utf-8"))
    assert set(committed["paths"]) == set(spec["paths"])
