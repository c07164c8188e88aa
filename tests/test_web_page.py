"""The lab's page at /ui/: served open with a strict Content-Security-Policy, nothing loaded from outside the
service, every control labelled, and the whole loop walked in the system's Chromium against a live server
with API keys on (upload the README's spreadsheet, read the report, ask, plan and download the next runs,
design over an envelope, delete the model), its figures checked against the API's own answers.

The browser test needs Debian's ``chromium`` and ``chromium-driver`` (``.ci/run`` installs them when
root) and the ``selenium`` package; without them it is skipped with the reason, and it fails instead
when ``CI`` is set and the tests run as root, where the install cannot have been skipped on purpose.
Screenshots at 1280 and 390 px go to ``MICROBEARING_TEST_ARTIFACTS`` (or the test's temporary folder).
"""

from __future__ import annotations

import csv
import io
import json
import os
import re
import shutil
import time
import tomllib
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import urlsplit

import httpx
import pytest
from fastapi.testclient import TestClient
from live_server import Server, wait_for

from microbearing.service.app import create_app
from microbearing.service.routes.web import PAGE_FILES, PAGE_PATHS
from microbearing.service.security import OPEN_PATHS
from microbearing.service.settings import Settings

REPO = Path(__file__).resolve().parent.parent
WEB = REPO / "service" / "web"
KEY = "web-test-key-0123456789"
AUTH = {"Authorization": f"Bearer {KEY}"}


def readme_spreadsheet() -> str:
    """The spreadsheet of the README's calibration quickstart (semicolons, decimal commas, units)."""
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    match = re.search(r"cat > measured\.csv <<'CSV'\n(.*?)\nCSV\n", readme, re.S)
    assert match, "the README's quickstart no longer writes measured.csv"
    return match.group(1) + "\n"


# ---- served, open, strict, self-contained (no browser) -------------------------------------------------

def test_the_page_is_open_with_keys_on_and_the_api_is_not(tmp_path):
    with TestClient(create_app(Settings(data_dir=tmp_path, api_keys=KEY))) as client:
        for name, media_type in PAGE_FILES.items():
            answer = client.get(f"/ui/{name}")
            assert answer.status_code == 200, name
            assert answer.headers["content-type"] == media_type
            policy = answer.headers["content-security-policy"]
            assert "default-src 'none'" in policy and "script-src 'self';" in policy
            assert "connect-src 'self';" in policy and "http" not in policy and "*" not in policy
        page = client.get("/ui/")
        assert page.status_code == 200 and page.text == (WEB / "index.html").read_text(encoding="utf-8")
        assert client.get("/ui", follow_redirects=False).headers["location"] == "/ui/"
        # the bare address, opened in a browser, leads to the page (it answered a 404 problem)
        bare = client.get("/", follow_redirects=False)
        assert bare.status_code == 307 and bare.headers["location"] == "/ui/"
        assert client.get("/v1/calibrations").status_code == 401
        assert client.get("/v1/calibrations", headers=AUTH).status_code == 200
        # Only the page's own files are open: any other name is refused before it reaches the route.
        assert client.get("/ui/secret.txt").status_code == 401
        assert client.get("/ui/secret.txt", headers=AUTH).status_code == 404
        assert client.get("/ui/..%2Fsecurity.py", headers=AUTH).status_code == 404
        assert not [path for path in client.app.openapi()["paths"] if path.startswith("/ui")]
    assert PAGE_PATHS <= OPEN_PATHS


def test_the_package_ships_every_file_of_the_page():
    on_disk = {path.name for path in WEB.iterdir() if path.is_file()}
    assert on_disk == set(PAGE_FILES)
    globs = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"][
        "microbearing.service"]
    assert all(any(Path(f"web/{name}").match(glob) for glob in globs) for name in on_disk), globs


def _code_without_comments(path: Path) -> str:
    text = path.read_text(encoding="utf-8")
    if path.suffix == ".html":
        return re.sub(r"<!--.*?-->", "", text, flags=re.S)
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    if path.suffix == ".js":  # line comments: // not inside a string (the page's strings hold no //)
        text = re.sub(r"(^|\s)//.*$", "", text, flags=re.M)
    if path.suffix == ".svg":  # an XML namespace names the vocabulary; nothing is fetched from it
        text = text.replace('xmlns="http://www.w3.org/2000/svg"', "")
    return text


@pytest.mark.parametrize("name", sorted(PAGE_FILES))
def test_no_file_of_the_page_names_another_host(name):
    code = _code_without_comments(WEB / name)
    assert not re.findall(r"https?://|//[a-z0-9.-]+\.[a-z]{2,}/", code, re.I)
    assert "@import" not in code and "url(" not in code


class _Controls(HTMLParser):
    """Controls, labels, headings and landmarks of an HTML text."""

    def __init__(self) -> None:
        super().__init__()
        self.controls: list[dict[str, str | None]] = []
        self.label_for: set[str] = set()
        self.tags: list[str] = []
        self.images_without_alt = 0

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        attributes = dict(attrs)
        self.tags.append(tag)
        if tag == "label" and attributes.get("for"):
            self.label_for.add(attributes["for"])
        if tag in ("input", "select", "textarea"):
            self.controls.append(attributes)
        if tag == "img" and "alt" not in attributes:
            self.images_without_alt += 1


def test_every_control_of_the_html_is_labelled_and_the_landmarks_are_there():
    parser = _Controls()
    parser.feed((WEB / "index.html").read_text(encoding="utf-8"))
    unlabelled = [c.get("id") for c in parser.controls if c.get("id") not in parser.label_for
                  and not c.get("aria-label") and not c.get("aria-labelledby")]
    assert parser.controls and not unlabelled
    assert parser.tags.count("h1") == 1 and {"header", "nav", "main", "footer"} <= set(parser.tags)
    assert parser.images_without_alt == 0


# ---- the loop in a real browser ------------------------------------------------------------------------

def _browser_or_skip() -> tuple[str, str]:
    """Paths of Chromium and its driver, or a loud skip (a failure under CI as root)."""
    chromium = next(filter(None, (shutil.which(n) for n in ("chromium", "chromium-browser"))), None)
    driver = shutil.which("chromedriver") or next(
        (p for p in ("/usr/bin/chromedriver", "/usr/lib/chromium/chromedriver") if Path(p).exists()), None)
    try:
        import selenium  # noqa: F401
    except ImportError:
        missing = "the selenium package (pip install -e '.[test]')"
    else:
        missing = None if chromium and driver else (
            "Debian's chromium and chromium-driver (apt-get install chromium chromium-driver; .ci/run "
            "does it as root)")
    if missing is None:
        return chromium, driver
    reason = f"THE BROWSER TEST OF THE LAB'S PAGE DID NOT RUN: missing {missing}"
    if os.environ.get("CI") and os.geteuid() == 0:
        pytest.fail(reason + " (CI as root: the install must not be skipped)")
    pytest.skip(reason)


@pytest.fixture
def browser(tmp_path):
    chromium, driver_path = _browser_or_skip()
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = chromium
    for argument in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                     "--host-resolver-rules=MAP * ~NOTFOUND , EXCLUDE 127.0.0.1", "--window-size=1280,900"):
        options.add_argument(argument)
    downloads = tmp_path / "downloads"
    downloads.mkdir()
    options.add_experimental_option("prefs", {"download.default_directory": str(downloads),
                                              "download.prompt_for_download": False})
    driver = webdriver.Chrome(service=Service(driver_path), options=options)
    driver.execute_cdp_cmd("Page.setDownloadBehavior", {"behavior": "allow", "downloadPath": str(downloads)})
    driver.downloads = downloads
    try:
        yield driver
    finally:
        driver.quit()


@pytest.fixture
def keyed_server(tmp_path):
    server = Server(tmp_path / "data", tmp_path / "server.log", api_keys=KEY)
    try:
        yield server
    finally:
        server.stop()


def _wait(driver, condition, timeout_s: float, what: str):
    """Poll ``condition(driver)`` until it is truthy; fail naming ``what`` and any error the page shows."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = condition(driver)
        if value:
            return value
        if time.monotonic() > deadline:
            errors = driver.execute_script(
                "return [...document.querySelectorAll('.problem:not([hidden])')].map(e => e.innerText)")
            pytest.fail(f"the page did not show {what} within {timeout_s} s; errors shown: {errors}")
        time.sleep(0.25)


def _text(driver, element_id: str) -> str:
    found = driver.find_elements("id", element_id)
    return found[0].text if found else ""


def _fill(driver, element_id: str, value: str) -> None:
    field = driver.find_element("id", element_id)
    field.clear()
    field.send_keys(value)


def _click(driver, selector: str, what: str) -> None:
    """Click the element of ``selector`` once it is there (read again if the page re-renders it)."""
    from selenium.common.exceptions import StaleElementReferenceException

    def clicked(d) -> bool:
        try:
            found = d.find_elements("css selector", selector)
            if found:
                found[0].click()
            return bool(found)
        except StaleElementReferenceException:
            return False

    _wait(driver, clicked, 30, what)


def _choose(driver, element_id: str, value: str) -> None:
    from selenium.webdriver.support.ui import Select
    Select(driver.find_element("id", element_id)).select_by_value(value)


def _latest_job_result(server: Server, kind: str) -> dict:
    job = server.client.get("/v1/jobs", params={"kind": kind, "limit": 1}, headers=AUTH).json()["jobs"][0]
    assert job["status"] == "succeeded", job
    return server.client.get(f"/v1/jobs/{job['id']}/result", headers=AUTH).json()


_A11Y = """
const problems = [];
const byId = (id) => document.getElementById(id);
const named = (e) => (e.getAttribute('aria-label') || '').trim()
  || (e.labels && [...e.labels].some(l => l.innerText.trim()))
  || (e.getAttribute('aria-labelledby') || '').split(/\\s+/)
       .some(id => id && byId(id) && byId(id).innerText.trim());
for (const e of document.querySelectorAll('input, select, textarea, progress')) {
  if (!named(e)) problems.push('control without a name: ' + (e.id || e.outerHTML.slice(0, 80)));
}
for (const e of document.querySelectorAll('button, a[href]')) {
  if (!(e.innerText.trim() || (e.getAttribute('aria-label') || '').trim())) {
    problems.push('no text: ' + e.outerHTML.slice(0, 80));
  }
}
for (const e of document.querySelectorAll('img')) if (!e.hasAttribute('alt')) problems.push('no alt');
const h1 = document.querySelectorAll('h1').length;
if (h1 !== 1) problems.push('h1 count ' + h1);
for (const s of ['header', 'nav', 'main', 'footer']) if (!document.querySelector(s)) problems.push('no ' + s);
if (!document.documentElement.lang) problems.push('no lang');
const ids = [...document.querySelectorAll('[id]')].map(e => e.id);
const twice = ids.filter((id, i) => ids.indexOf(id) !== i);
if (twice.length) problems.push('duplicate ids: ' + twice.join(', '));
for (const e of document.querySelectorAll('[aria-labelledby]')) {
  for (const id of e.getAttribute('aria-labelledby').split(/\\s+/)) {
    if (!byId(id)) problems.push('dangling ' + id);
  }
}
return problems;
"""


def _check_accessibility(driver) -> None:
    assert driver.execute_script(_A11Y) == []


def _check_keyboard(driver) -> None:
    """Tab alone reaches every visible, enabled control of the page, in the order of the page."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    count = driver.execute_script(
        "const c = [...document.querySelectorAll('a[href], input, select, textarea, button, summary')]"
        ".filter(e => !e.disabled && e.offsetParent !== null);"
        "c.forEach((e, i) => { e.dataset.k = i; }); return c.length")
    reached = []
    for _ in range(count + 10):
        ActionChains(driver).send_keys(Keys.TAB).perform()
        key = driver.execute_script("return document.activeElement.dataset.k")
        if key is not None:
            reached.append(int(key))
    assert set(range(count)) <= set(reached), sorted(set(range(count)) - set(reached))
    assert reached[reached.index(0):][:count] == list(range(count))  # from the top, in the page's order


def _check_same_origin(driver, origin: str) -> None:
    resources = driver.execute_script(
        "return performance.getEntriesByType('resource').map(e => e.name)"
        ".concat(performance.getEntriesByType('navigation').map(e => e.name))")
    outside = [url for url in resources
               if f"{urlsplit(url.removeprefix('blob:')).scheme}://{urlsplit(url.removeprefix('blob:')).netloc}"
               != origin]
    assert resources and not outside, outside


def _screenshots(driver, folder: Path, stage: str) -> None:
    """Screenshots of the section ``stage`` (an id) at 1280 and 390 px."""
    folder.mkdir(parents=True, exist_ok=True)
    for width in (1280, 390):
        driver.set_window_size(width, 900)
        driver.execute_script("document.getElementById(arguments[0]).scrollIntoView()", stage)
        time.sleep(0.3)
        # readable at the width: the page does not scroll sideways (wide tables scroll in their own box)
        overflow = driver.execute_script("return document.documentElement.scrollWidth - window.innerWidth")
        wide = driver.execute_script(
            "return [...document.querySelectorAll('body *')].filter(e => !e.closest('.scroll, pre')"
            " && (e.getBoundingClientRect().right > window.innerWidth + 1"
            " || e.scrollWidth > e.clientWidth + 1 && getComputedStyle(e).overflowX === 'visible'))"
            ".slice(0, 5).map(e => e.outerHTML.slice(0, 120))")
        assert overflow <= 1, f"the page is {overflow} px wider than the window at {width} px: {wide}"
        driver.save_screenshot(str(folder / f"{stage}-{width}px.png"))
    driver.set_window_size(1280, 900)


def test_the_loop_in_chromium_with_api_keys_on(browser, keyed_server, tmp_path):
    server = keyed_server
    shots = Path(os.environ.get("MICROBEARING_TEST_ARTIFACTS", tmp_path)) / "web-screenshots"
    driver = browser
    driver.get(f"{server.url}/ui/")
    _check_accessibility(driver)
    _check_keyboard(driver)
    _fill(driver, "api-key", KEY)
    driver.find_element("css selector", "#key-form button[type=submit]").click()
    _wait(driver, lambda d: "No stored calibration" in _text(d, "calibration-list"), 30, "the empty list")

    # a surrogate (the README's, 30 evaluations) trains meanwhile, for "my models" at the end
    surrogate_job = server.client.post("/v1/surrogates", headers=AUTH, json={
        "space": {"load_N": [0.001, 0.05], "speed_m_s": [0.001, 0.2]}, "fixed": {"balls": 4}, "budget": 30})
    assert surrogate_job.status_code == 202, surrogate_job.text

    # 1. upload the README's spreadsheet; the page previews it, then follows the job to the report
    sheet = tmp_path / "measured.csv"
    sheet.write_text(readme_spreadsheet(), encoding="utf-8")
    driver.find_element("id", "csv-file").send_keys(str(sheet))
    _fill(driver, "folds", "3")  # the fastest honest calibration: 3 outer folds (README: 5)
    # before any fit, the service's own reading of the file (POST /v1/calibrations/csv/intake)
    _wait(driver, lambda d: "data rows" in _text(d, "preview"), 60, "the file's reading")
    reading = server.client.post("/v1/calibrations/csv/intake", headers={**AUTH, "content-type": "text/csv"},
                                 content=sheet.read_bytes()).json()
    preview = _text(driver, "preview")
    assert f"{reading['rows']} data rows; separator {reading['intake']['separator']}" in preview
    assert all(conversion in preview for conversion in reading["intake"]["conversions"])
    assert server.client.get("/v1/calibrations", headers=AUTH).json()["calibrations"] == []  # nothing fitted
    driver.find_element("id", "upload-start").click()
    _wait(driver, lambda d: _text(d, "report-effect"), 400, "the report")

    # 2. the report in words, checked against the API's JSON of the same calibration
    calibration_id = _text(driver, "report-id")
    report = server.client.get(f"/v1/calibrations/{calibration_id}", headers=AUTH).json()
    assert _text(driver, "report-effect") == report["missing_effect"]["label"]
    for which in ("before", "after"):
        shown = float(_text(driver, f"report-error-{which}"))
        assert shown == pytest.approx(report[f"error_{which}"]["relative_rmse"], rel=5e-4)
    assert report["intake"]["separator"] in _text(driver, "report-intake")
    _wait(driver, lambda d: d.execute_script(
        "const i = [...document.querySelectorAll('#report-body img.plot')];"
        "return i.length === arguments[0] && i.every(e => e.complete && e.naturalWidth > 0)",
        len(report["plots"])), 30, "every plot")
    raw = driver.find_element("css selector", "#report-body details.raw")
    raw.find_element("tag name", "summary").click()  # one click to the raw JSON
    assert json.loads(raw.find_element("tag name", "pre").text)["id"] == calibration_id
    _check_accessibility(driver)
    _screenshots(driver, shots, "report")

    # 3. ask at the point the page proposes (the middle of the data): mu and its interval as the API says
    driver.find_element("css selector", "#ask-form button[type=submit]").click()
    _wait(driver, lambda d: d.find_elements("css selector", "#ask-result table"), 30, "the answer")
    header, values = driver.find_element("id", "ask-table").get_attribute("value").strip().split("\n")
    # the page asks in the upload's headers and units (the spreadsheet's mN, mm/s and %), the middle of
    # the data's range in each: by hand, in SI, the same point
    assert header == "balls,load [mN],speed [mm/s],relative humidity [%]", header
    point = dict(zip(header.split(","), map(float, values.split(",")), strict=True))
    domain = report["model"]["domain"]
    for key, column, factor in (("load [mN]", "load_N", 1e3), ("speed [mm/s]", "speed_m_s", 1e3),
                                ("relative humidity [%]", "relative_humidity", 100.0)):
        assert point[key] == pytest.approx(factor * sum(domain[column]) / 2, rel=5e-3), key
    answer = server.client.post("/v1/friction", headers=AUTH, json={
        "model": report["model_id"], "balls": int(point["balls"]), "load_N": point["load [mN]"] / 1e3,
        "speed_m_s": point["speed [mm/s]"] / 1e3,
        "conditions": {"relative_humidity": point["relative humidity [%]"] / 100}}).json()
    cells = [c.text for c in driver.find_elements("css selector", "#ask-result tbody td")]
    assert float(cells[4]) == pytest.approx(answer["mu"], rel=5e-4)
    low, high = map(float, cells[5].split(" to "))
    assert low == pytest.approx(answer["mu_lower"], rel=5e-4)
    assert high == pytest.approx(answer["mu_upper"], rel=5e-4)
    assert cells[6] == ("inside the data" if answer["in_domain"] else "outside the data: an extrapolation")

    # 4. next runs: plan, download the CSV, and the upload takes it as it is once mu_measured is filled in
    _fill(driver, "next-runs", "16")  # enough rows for a calibration of their own
    _fill(driver, "next-space", "balls: 4 .. 8\nload_N: 0.003 .. 0.03 log\nspeed_m_s: 0 .. 0.15\n"
                                "relative_humidity: 0.2, 0.5, 0.8, 0.9")
    driver.find_element("css selector", "#next-form button[type=submit]").click()
    _wait(driver, lambda d: d.find_elements("id", "next-download"), 120, "the plan")
    plan = _latest_job_result(server, "experiments")
    assert float(_text(driver, "next-efficiency")) == pytest.approx(plan["efficiency_lower_bound"], rel=5e-4)
    driver.find_element("id", "next-download").click()
    downloaded = _wait(driver, lambda d: next(iter(d.downloads.glob("*.csv")), None), 30, "the CSV")
    rows = list(csv.DictReader(io.StringIO(downloaded.read_text(encoding="utf-8"))))
    assert len(rows) == len(plan["runs"]) == 16
    for row, run in zip(rows, plan["runs"], strict=True):
        assert int(row["balls"]) == run["balls"] and row["mu_measured"] == ""
        assert float(row["load_N"]) == run["load_N"] and float(row["speed_m_s"]) == run["speed_m_s"]
        assert float(row["relative_humidity"]) == run["conditions"]["relative_humidity"]
    filled = io.StringIO()
    writer = csv.DictWriter(filled, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows({**row, "mu_measured": str(run["mu"])}  # as the lab fills it in
                     for row, run in zip(rows, plan["runs"], strict=True))
    accepted = server.client.post("/v1/calibrations/csv", params={"fit_parameters": "mu_pivot"}, headers={
        **AUTH, "content-type": "text/csv"}, content=filled.getvalue().encode())
    assert accepted.status_code == 202, accepted.text
    server.client.delete(accepted.headers["location"], headers=AUTH)  # the file was read; no need to fit it

    # an API error is shown with the field it names: mu_upper on the physics, which has no interval
    _choose(driver, "design-model", "physics")
    _choose(driver, "design-objective", "mu_upper")
    driver.find_element("css selector", "#design-form button[type=submit]").click()
    _wait(driver, lambda d: _text(d, "design-error"), 30, "the refusal")
    fields = [e.text for e in driver.find_elements("css selector", "#design-error .field")]
    assert fields == ["/objective"], fields

    # 5. a robust design on the calibration: objective mu_upper over speeds, humidity and an angle tolerance
    _choose(driver, "design-model", report["model_id"])
    for element_id, value in (("design-balls-low", "4"), ("design-balls-high", "4"),
                              ("design-angle-low", "45.5"), ("design-angle-high", "59.5"),
                              ("design-load-low", "0.0044"), ("design-load-high", "0.0132"),
                              ("design-speed-low", "0.01"), ("design-speed-high", "0.1"),
                              ("design-tolerance", "0.5"), ("design-pressure", "7.3e8"),
                              ("design-conditions", "relative_humidity: 0.3 .. 0.7"), ("design-starts", "1")):
        _fill(driver, element_id, value)
    driver.find_element("css selector", "#design-form button[type=submit]").click()
    _wait(driver, lambda d: _text(d, "design-proven"), 300, "the design's proof")
    result = _latest_job_result(server, "optimization")
    assert result["model"] == report["model_id"] and result["objective"] == "mu_upper"
    assert int(_text(driver, "design-balls")) == result["design"]["balls"]
    design = result["design"]
    assert float(_text(driver, "design-angle")) == pytest.approx(design["groove_angle_deg"], rel=5e-4)
    assert float(_text(driver, "design-load")) == pytest.approx(result["design"]["load_N"], rel=5e-4)
    assert float(_text(driver, "design-worst")) == pytest.approx(result["worst_case"]["mu_upper"], rel=5e-4)
    assert _text(driver, "design-proven") == ("yes" if result["proof"]["proven"] else "no")
    _check_accessibility(driver)
    _screenshots(driver, shots, "design-result")
    _screenshots(driver, shots, "next-result")

    # 6. my models: delete the calibration from its row; the API then answers 404
    _check_same_origin(driver, server.url)
    refused = [e["message"] for e in driver.get_log("browser") if "Content Security Policy" in e["message"]]
    assert not refused, refused  # the page needs nothing its policy forbids (no inline script or style)
    _click(driver, f"#calibration-list .delete[data-id='{calibration_id}']", "its delete button")
    driver.switch_to.alert.accept()
    _wait(driver, lambda d: "No stored calibration" in _text(d, "calibration-list"), 30, "the emptied list")
    assert server.client.get(f"/v1/calibrations/{calibration_id}", headers=AUTH).status_code == 404
    assert _text(driver, "report-body") == ""
    # the surrogate: listed, opened, deleted
    surrogate = wait_for(server, surrogate_job.headers["location"], ("succeeded",), headers=AUTH)
    surrogate_id = server.client.get(surrogate["result_url"], headers=AUTH).json()["id"]
    driver.find_element("id", "models-refresh").click()
    _click(driver, f"#surrogate-list .open[data-id='{surrogate_id}']", "the surrogate in the list")
    _wait(driver, lambda d: f"surrogate:{surrogate_id}" in _text(d, "surrogate-view"), 30, "the surrogate")
    _click(driver, f"#surrogate-list .delete[data-id='{surrogate_id}']", "the surrogate's delete button")
    driver.switch_to.alert.accept()
    _wait(driver, lambda d: "No stored surrogate" in _text(d, "surrogate-list"), 30, "the emptied list")
    assert server.client.get(f"/v1/surrogates/{surrogate_id}", headers=AUTH).status_code == 404
    assert _text(driver, "surrogate-view") == ""
    assert httpx.get(f"{server.url}/v1/calibrations/{calibration_id}").status_code == 401

    # progress and cancel: a second upload stopped from the page stores nothing
    driver.execute_script("document.getElementById('upload').scrollIntoView()")
    driver.find_element("id", "upload-start").click()
    _wait(driver, lambda d: d.find_element("id", "upload-cancel").is_enabled()
          and "running" in _text(d, "upload-state"), 60, "the running upload")
    driver.find_element("id", "upload-cancel").click()
    _wait(driver, lambda d: "Cancelled" in _text(d, "upload-error"), 120, "the cancellation")
    jobs = server.client.get("/v1/jobs", params={"kind": "calibration", "limit": 1}, headers=AUTH).json()
    assert jobs["jobs"][0]["status"] == "cancelled"
    assert server.client.get("/v1/calibrations", headers=AUTH).json()["calibrations"] == []
