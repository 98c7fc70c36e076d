"""Open report.html in headless Chromium: no console errors, every image loaded, a screenshot.

Also: the analyses fold and unfold (<details>), the summary bar stays at the top while
scrolling, and the sample-size warnings sit beside the verdict they qualify.

Needs the Debian packages ``chromium`` and ``chromium-driver`` and selenium. Skips
when they are absent, except under CI (``CI`` set), where their absence fails.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
from pathlib import Path

import pytest

CHROMIUM = ("/usr/bin/chromium", "/usr/bin/chromium-browser", "/usr/bin/google-chrome")
CHROMEDRIVER = ("/usr/bin/chromedriver", "/usr/lib/chromium/chromedriver")
#: Screenshots go to $LIDARQA_SCREENSHOT_DIR when set (e.g. tests/report/_artifacts, kept out of
#: git), else into pytest's temporary folder; the test prints where.
SCREENSHOT_ENV = "LIDARQA_SCREENSHOT_DIR"


def _find(candidates: tuple[str, ...]) -> str | None:
    return next((c for c in candidates if Path(c).is_file() and os.access(c, os.X_OK)), None)


def _need_browser() -> tuple[str, str]:
    browser, driver = _find(CHROMIUM), _find(CHROMEDRIVER)
    try:
        import selenium  # noqa: F401

        has_selenium = True
    except ImportError:
        has_selenium = False
    missing = [
        name
        for name, ok in (
            ("chromium", browser),
            ("chromedriver", driver),
            ("selenium", has_selenium),
        )
        if not ok
    ]
    if missing:
        msg = (
            "browser test needs "
            + ", ".join(missing)
            + " (apt-get install chromium chromium-driver)"
        )
        if os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no"):
            pytest.fail(msg + "; CI is set, so this is a failure, not a skip")
        pytest.skip(msg)
    return browser, driver  # type: ignore[return-value]


@pytest.fixture(scope="module")
def demo_report(demo_run) -> Path:
    assert demo_run["result"].exit_code == 0, demo_run["result"].output
    return demo_run["out"] / "report.html"


@pytest.mark.browser
@pytest.mark.slow  # ~10 s: starts Chromium
def test_report_opens_in_headless_chromium(demo_report: Path, tmp_path_factory) -> None:
    browser, driver_path = _need_browser()
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    profile = tempfile.mkdtemp(prefix="lidarqa-chromium-")
    opts = webdriver.ChromeOptions()
    opts.binary_location = browser
    for arg in (
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-background-networking",
        f"--user-data-dir={profile}",
        "--window-size=1280,2600",
        "--disable-dev-shm-usage",
    ):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    # An explicit Service path: selenium-manager never downloads anything.
    driver = webdriver.Chrome(service=Service(driver_path), options=opts)
    try:
        driver.set_page_load_timeout(60)
        driver.get(demo_report.resolve().as_uri())
        assert driver.title, "page has no title"
        # The summary table comes first.
        first_table = driver.find_element("css selector", "section#summary table")
        assert "Analysis" in first_table.text
        images = driver.execute_script(
            "return Array.from(document.images).map(i => [i.alt, i.complete, i.naturalWidth]);"
        )
        assert images, "the report has no plots"
        broken = [alt for alt, complete, width in images if not complete or width == 0]
        assert not broken, f"images that did not load: {broken}"
        # Nothing was fetched from the network: every resource is inline.
        external = driver.execute_script(
            "return performance.getEntriesByType('resource').map(e => e.name)"
            ".filter(n => !n.startsWith('data:') && !n.startsWith('file:'));"
        )
        assert external == [], external
        severe = [e for e in driver.get_log("browser") if e.get("level") == "SEVERE"]
        assert not severe, f"console errors: {severe}"
        _check_collapsible_sections(driver)
        _check_sticky_summary(driver)
        driver.execute_script("window.scrollTo(0, 0);")
        shots = Path(os.environ.get(SCREENSHOT_ENV) or tmp_path_factory.mktemp("screenshots"))
        shots.mkdir(parents=True, exist_ok=True)
        shot = shots / "report.png"
        driver.save_screenshot(str(shot))
        # A narrow (phone-sized) window must not make the page itself scroll sideways.
        driver.set_window_size(390, 844)
        overflow = driver.execute_script(
            "return document.documentElement.scrollWidth - document.documentElement.clientWidth;"
        )
        driver.save_screenshot(str(shots / "report-phone.png"))
        print(f"screenshots: {shot} and {shots / 'report-phone.png'} ({len(images)} images)")
        assert overflow <= 1, f"page scrolls horizontally by {overflow} px on a phone-sized window"
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def _check_collapsible_sections(driver) -> None:
    """Every analysis is a <details> opened by default; its summary folds and unfolds it."""
    ids = driver.execute_script(
        "return Array.from(document.querySelectorAll('section.analysis')).map(s => s.id);"
    )
    assert len(ids) >= 5, f"expected the demo's analyses as sections, got {ids}"
    for sid in ids:
        is_open = driver.execute_script(
            "const d = document.querySelector(`section#${arguments[0]} > details`);"
            "return d === null ? null : d.open;",
            sid,
        )
        assert is_open is True, f"section {sid} is not an open <details>"
    sid = ids[1]
    height = "return document.getElementById(arguments[0]).getBoundingClientRect().height;"
    toggle = f"section#{sid} > details > summary"
    tall = driver.execute_script(height, sid)
    summary = driver.find_element("css selector", toggle)
    driver.execute_script("arguments[0].scrollIntoView({block: 'center'});", summary)
    summary.click()  # a real click on the section's heading folds it
    folded = driver.execute_script(height, sid)
    assert not driver.execute_script(
        "return document.querySelector(arguments[0]).parentElement.open;", toggle
    )
    assert folded < tall / 3, f"folding {sid} left it {folded:.0f} px tall (was {tall:.0f})"
    # the content is hidden, the heading with its verdict still shows
    assert summary.is_displayed() and "PASS" in summary.text.upper()
    summary.click()
    assert driver.execute_script(height, sid) == pytest.approx(tall, abs=2)
    # Parameters and provenance start folded: the page opens on the results.
    for sid in ("parameters", "provenance"):
        assert driver.execute_script(
            "return document.querySelector(`section#${arguments[0]} > details`).open;", sid
        ) is False


def _check_sticky_summary(driver) -> None:
    """The summary bar stays at the top of the window, with every verdict, while scrolling."""
    bar = driver.find_element("css selector", "#summary-bar")
    verdicts = bar.find_elements("css selector", ".verdict")
    rows = driver.find_elements("css selector", "section#summary table tbody tr")
    assert len(verdicts) == len(rows) > 0
    for y in ("document.body.scrollHeight / 2", "document.body.scrollHeight"):
        driver.execute_script(f"window.scrollTo(0, {y});")
        top = driver.execute_script(
            "return document.getElementById('summary-bar').getBoundingClientRect().top;"
        )
        assert driver.execute_script("return window.scrollY;") > 500
        assert abs(top) <= 1, f"summary bar not at the top of the window (top = {top} px)"
        assert bar.is_displayed()
    # Its links jump to the sections, which are not hidden under the bar.
    link = bar.find_elements("css selector", "a")[-1]
    target = link.get_attribute("href").split("#")[-1]
    driver.execute_script("arguments[0].click();", link)
    bar_bottom = driver.execute_script(
        "return document.getElementById('summary-bar').getBoundingClientRect().bottom;"
    )
    sec_top = driver.execute_script(
        "return document.getElementById(arguments[0]).getBoundingClientRect().top;", target
    )
    assert sec_top >= bar_bottom - 1, f"section {target} starts under the summary bar"
    # The caveats of a verdict sit beside it, in the summary table.
    caveats = driver.find_elements("css selector", "section#summary td.verdict-cell .caveat")
    assert any("check points" in c.text for c in caveats), "sample-size warning not by the verdict"


@pytest.mark.parametrize("ci, outcome", [("", "skip"), ("true", "fail"), ("false", "skip")])
def test_missing_browser_skips_locally_and_fails_under_ci(monkeypatch, ci, outcome):
    monkeypatch.setattr(sys.modules[__name__], "CHROMIUM", ("/nonexistent/chromium",))
    monkeypatch.setenv("CI", ci)
    expected = pytest.skip.Exception if outcome == "skip" else pytest.fail.Exception
    with pytest.raises(expected, match="chromium"):
        _need_browser()
