"""The report in a real browser (issue 18): Debian's headless Chromium driven by Playwright's
Python package (no browser download: ``executable_path=/usr/bin/chromium``).

Both pages of the demo render without console errors and without any network request, every
figure is there (static: decoded PNGs; interactive: drawn plotly charts), a mouse drag on the
position-error chart zooms its time axis and the matched axes follow, and the map-tiles button
is the only thing that would go online. Screenshots go to ``out/test-artifacts/`` (or
``$INSGNSS_TEST_ARTIFACTS``). Skips outside CI when Chromium or Playwright is missing; fails in
CI (``.ci/run`` installs Chromium with apt when absent).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import pytest
from report_helpers import EXPECTED, REPO, figure_keys, set_outputs

from insgnss.report_data import INTERACTIVE_NAME

CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]


def _chromium() -> str:
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        exe = None
    if exe is None:
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail("Chromium and Playwright are required in CI (.ci/run installs them)")
        pytest.skip("Chromium or Playwright not installed")
    return exe


@pytest.fixture(scope="module")
def pages(tmp_path_factory):
    from insgnss.commands.demo import demo_job_path
    from insgnss.config import load_job
    from insgnss.pipeline import run_job, write_outputs

    exe = _chromium()
    out = tmp_path_factory.mktemp("browser")
    res = run_job(set_outputs(load_job(demo_job_path()), formats=["csv"]), progress=False)
    write_outputs(res, out)
    return exe, out


@pytest.fixture(scope="module")
def browser(pages):
    from playwright.sync_api import sync_playwright

    exe, _ = pages
    with sync_playwright() as p:
        ctx = p.chromium.launch_persistent_context(
            tempfile.mkdtemp(prefix="insgnss-chromium-"), executable_path=exe, headless=True,
            args=CHROMIUM_ARGS, viewport={"width": 1280, "height": 1000})
        yield ctx
        ctx.close()


def _artifacts() -> Path:
    d = Path(os.environ.get("INSGNSS_TEST_ARTIFACTS", REPO / "out" / "test-artifacts"))
    d.mkdir(parents=True, exist_ok=True)
    return d


def _open(browser, path: Path):
    page = browser.new_page()
    problems, requests = [], []
    page.on("console", lambda m: problems.append(f"console {m.type}: {m.text}")
            if m.type == "error" else None)
    page.on("pageerror", lambda e: problems.append(f"page error: {e}"))
    page.on("request", lambda r: requests.append(r.url))
    page.goto(path.as_uri(), wait_until="load")
    return page, problems, requests


def test_static_report_in_chromium(pages, browser):
    _, out = pages
    page, problems, requests = _open(browser, out / "report.html")
    keys = figure_keys((out / "report.html").read_text())
    assert keys == EXPECTED["demo"]
    n = page.evaluate("""() => Array.from(document.querySelectorAll('figure.fig img'))
                           .filter(i => i.complete && i.naturalWidth > 600).length""")
    assert n == len(keys)
    assert page.locator("h2#summary").is_visible()
    assert page.locator("#incomplete").count() == 0
    page.screenshot(path=str(_artifacts() / "report_static.png"), full_page=True)
    assert not problems, problems
    assert all(u.startswith(("file:", "data:")) for u in requests), requests
    page.close()


def test_interactive_report_in_chromium(pages, browser):
    _, out = pages
    page, problems, requests = _open(browser, out / INTERACTIVE_NAME)
    keys = figure_keys((out / INTERACTIVE_NAME).read_text())
    assert keys == EXPECTED["demo"]
    page.wait_for_function(f"document.querySelectorAll('.plot[data-rendered]').length == "
                           f"{len(keys)}", timeout=120_000)
    for key in keys:  # every chart drawn (an SVG with traces)
        assert page.locator(f"#plot-{key} .main-svg").count() >= 1, key
        assert page.locator(f"#plot-{key} .scatterlayer .trace").count() >= 1, key
    # zoom: drag across the first position-error panel; its time axis and the matched ones
    # (the other panels of the figure) narrow to the dragged span
    gd = "document.getElementById('plot-position_errors')"
    before = page.evaluate(f"{gd}._fullLayout.xaxis.range.slice()")
    drag = page.locator("#plot-position_errors .draglayer .xy .nsewdrag").first
    drag.scroll_into_view_if_needed()
    box = drag.bounding_box()
    y = box["y"] + 0.5 * box["height"]
    page.mouse.move(box["x"] + 0.3 * box["width"], y)
    page.mouse.down()
    page.mouse.move(box["x"] + 0.45 * box["width"], y, steps=8)
    page.mouse.move(box["x"] + 0.6 * box["width"], y, steps=8)
    page.mouse.up()
    page.wait_for_timeout(500)
    after = page.evaluate(f"{gd}._fullLayout.xaxis.range.slice()")
    other = page.evaluate(f"{gd}._fullLayout.xaxis4.range.slice()")
    span0, span1 = before[1] - before[0], after[1] - after[0]
    assert 0.2 * span0 < span1 < 0.4 * span0, (before, after)
    assert other == pytest.approx(after)
    page.locator("figure[data-key='position_errors']").screenshot(
        path=str(_artifacts() / "report_interactive_zoomed.png"))
    page.screenshot(path=str(_artifacts() / "report_interactive.png"), full_page=True)
    assert page.locator("#map-tiles").is_visible()  # tiles only on request
    assert not problems, problems
    assert all(u.startswith(("file:", "data:", "blob:")) for u in requests), requests
    page.close()
