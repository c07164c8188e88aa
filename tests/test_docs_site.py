"""The manual (issue 34, item 5): the docs site builds offline in strict mode, loads nothing from elsewhere,
and the service serves it at /manual/ to anyone, keys or not, every link of it answered.

The code blocks of its pages are run by the tests of what they show (tests/docs_pages.py names them).
"""

from __future__ import annotations

import re
import subprocess
import sys
import time
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import urljoin, urlsplit

import pytest
from fastapi.testclient import TestClient
from test_web_page import browser, keyed_server  # noqa: F401  (fixtures: Chromium; a live server with a key)

from microbearing.service.app import create_app
from microbearing.service.routes import manual
from microbearing.service.settings import Settings

REPO = Path(__file__).resolve().parent.parent
KEY = "manual-test-key-0123456789"


def _mkdocs_build(config: Path, site: Path) -> subprocess.CompletedProcess:
    command = [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(config), "-d", str(site)]
    return subprocess.run(command, cwd=REPO, capture_output=True, text=True, timeout=300)


def test_the_site_builds_in_strict_mode_without_a_warning(tmp_path):
    # Strict: a broken link between pages, a missing anchor or a page left out of the navigation fails.
    # The root mkdocs.yml inherits docs/mkdocs.yml: `mkdocs build --strict` from a checkout.
    run = _mkdocs_build(REPO / "mkdocs.yml", tmp_path / "site")
    assert run.returncode == 0, run.stderr
    assert "WARNING" not in run.stderr, run.stderr
    pages = sorted(p.relative_to(tmp_path).as_posix() for p in (tmp_path / "site").rglob("index.html"))
    sources = sorted((REPO / "docs" / "pages").rglob("*.md"))
    assert len(pages) == len(sources) >= 15, (pages, sources)


def test_the_package_sources_are_the_repository_docs():
    # The service builds what the repository holds (an editable install maps microbearing.docs to docs/).
    assert manual.sources() == (REPO / "docs").resolve()


class _Links(HTMLParser):
    """Every src and href of a page, and the bodies of its inline scripts."""

    def __init__(self) -> None:
        super().__init__()
        self.links: list[str] = []
        self.inline_scripts: list[str] = []
        self._in_inline_script = False

    def handle_starttag(self, tag, attrs):
        attributes = dict(attrs)
        self.links += [attributes[name] for name in ("src", "href") if attributes.get(name)]
        self._in_inline_script = tag == "script" and not attributes.get("src")

    def handle_endtag(self, tag):
        self._in_inline_script = False

    def handle_data(self, data):
        if self._in_inline_script and data.strip():
            self.inline_scripts.append(data)


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    settings = Settings(data_dir=tmp_path_factory.mktemp("manual"), api_keys=KEY)
    with TestClient(create_app(settings)) as client:
        yield client


def test_the_service_serves_every_page_without_a_key_and_every_link_answers(client):
    assert client.get("/v1/calibrations").status_code == 401  # keys are on
    redirect = client.get("/manual", follow_redirects=False)
    assert redirect.status_code == 308 and redirect.headers["location"] == "/manual/"
    seen, queue, pages = set(), ["/manual/"], 0
    while queue:
        url = queue.pop()
        if url in seen:
            continue
        seen.add(url)
        answer = client.get(url)
        assert answer.status_code == 200, url
        assert "'self'" in answer.headers["content-security-policy"]
        if not answer.headers["content-type"].startswith("text/html"):
            continue
        pages += 1
        parser = _Links()
        parser.feed(answer.text)
        # The policy admits scripts of this origin only: none inline, none from elsewhere (no CDN).
        assert not parser.inline_scripts, (url, parser.inline_scripts)
        for link in parser.links:
            target = urlsplit(urljoin("http://testserver" + url, link))
            if target.netloc == "testserver":
                assert target.path.startswith("/manual/"), (url, link)
                queue.append(target.path)
            else:  # a page may link elsewhere (the pint docs), but loads nothing from there
                assert not re.search(rf'<(script|img|link)[^>]*(src|href)="{re.escape(link)}"', answer.text)
    assert pages >= 15, pages
    assert {"/manual/tutorial/", "/manual/reference/settings/", "/manual/js/settings.js",
            "/manual/search/main.js"} <= seen
    # The search starts its worker and reads its index from this origin (worker-src, connect-src 'self').
    assert "importScripts" in client.get("/manual/search/worker.js").text
    assert client.get("/manual/search/search_index.json").json()["docs"]


def test_only_files_of_the_site_are_served(client):
    for path in ("/manual/nothing-here", "/manual/%2e%2e/%2e%2e/pyproject.toml",
                 "/manual/..%2f..%2fREADME.md"):
        answer = client.get(path)
        assert answer.status_code == 404, path
        assert answer.headers["content-type"] == "application/problem+json"
    folder = client.get("/manual/tutorial", follow_redirects=False)
    assert folder.status_code == 308 and folder.headers["location"] == "/manual/tutorial/"


def test_a_changed_source_builds_a_new_site(tmp_path):
    # The site is keyed by the digest of its sources: an edited page is never served from an old build.
    source = tmp_path / "docs"
    (source / "pages").mkdir(parents=True)
    (source / "mkdocs.yml").write_text("site_name: t\ndocs_dir: pages\n")
    (source / "pages" / "index.md").write_text("# One\n")
    first = manual.source_digest(source, "1.6.1")
    (source / "pages" / "index.md").write_text("# Two\n")
    assert manual.source_digest(source, "1.6.1") != first
    assert manual.source_digest(source, "1.6.2") != manual.source_digest(source, "1.6.1")
    manual.build_site(source, tmp_path / "site", strict=True)
    assert "Two" in (tmp_path / "site" / "index.html").read_text()


def test_a_data_folder_that_cannot_hold_the_site_is_a_503_problem(tmp_path):
    (tmp_path / "manual").write_text("a file where the site's folder goes")
    with TestClient(create_app(Settings(data_dir=tmp_path))) as client:
        answer = client.get("/manual/")
    assert answer.status_code == 503, answer.text
    assert answer.headers["content-type"] == "application/problem+json"
    assert str(tmp_path / "manual") in answer.json()["detail"]


def test_the_readme_is_a_landing_page_whose_links_resolve():
    # Issue 34: under 200 lines, the manual one link away (GitHub renders the pages' Markdown too).
    text = (REPO / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) < 200
    targets = [t for t in re.findall(r"\]\(([^)#\s]+)\)", text) if not t.startswith(("http://", "https://"))]
    assert "docs/pages/tutorial.md" in targets
    assert all((REPO / target).is_file() for target in targets), targets


def test_the_manual_runs_its_scripts_and_searches_in_a_browser(browser, keyed_server):  # noqa: F811
    # Under its Content-Security-Policy, with a key configured and none given: the theme's settings come
    # from js/settings.js (base_url), and the search's worker builds its index and answers.
    browser.get(f"{keyed_server.url}/manual/reference/settings/")
    deadline = time.monotonic() + 120
    while browser.execute_script("return typeof base_url") != "string":
        assert time.monotonic() < deadline, "js/settings.js did not run"
        time.sleep(0.25)
    assert browser.execute_script("return base_url") == f"{keyed_server.url}/manual"
    results = []
    while not results:
        assert time.monotonic() < deadline, "the search found nothing for Arrhenius"
        browser.execute_script("const box = document.getElementById('mkdocs-search-query'); box.value = "
                               "'Arrhenius'; box.dispatchEvent(new KeyboardEvent('keyup'));")
        time.sleep(0.5)
        results = browser.find_elements("css selector", "#mkdocs-search-results article a")
    assert any("/manual/science/" in r.get_attribute("href") for r in results)
