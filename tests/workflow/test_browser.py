"""Headless Chromium opens the study overview, a pair page and a 3-D view from file://: not blank, no console errors;
at a 1400 px wide window, nothing of the report pages runs off the right edge and the figures are readable."""

from __future__ import annotations

import html
import json
import re
import shutil
import subprocess

import numpy as np
import pytest
from PIL import Image

from helpers.synthetic_study import write_synthetic_study
from lidarfield.plots import plot_stage, write_plotly_js
from lidarfield.report import compare_studies, discover, write_report

pytestmark = pytest.mark.slow

CHROMIUM = shutil.which("chromium")
# A console line that reports a failure (uncaught exceptions, script errors, failed loads);
# driver chatter such as "GL Driver Message ... Performance" is not one.
CONSOLE_ERROR = re.compile(r"Uncaught|[A-Za-z]*Error\b|Failed to load|is not defined|WebGL is not supported")


def chromium(url: str, screenshot, profile, window=(1280, 1000)) -> str:
    """Open ``url`` headless, write a screenshot, return the browser's log (stderr)."""
    cmd = [
        CHROMIUM,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--enable-unsafe-swiftshader",
        "--enable-logging=stderr",
        "--v=0",
        "--virtual-time-budget=8000",
        f"--user-data-dir={profile}",
        f"--screenshot={screenshot}",
        f"--window-size={window[0]},{window[1]}",
        url,
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    assert screenshot.is_file(), f"no screenshot; chromium said:\n{done.stderr[-2000:]}"
    return done.stderr


def console_errors(log: str) -> list[str]:
    return [
        ln for ln in log.splitlines() if ":CONSOLE" in ln and CONSOLE_ERROR.search(ln) and "GL Driver Message" not in ln
    ]


def not_blank(png) -> float:
    with Image.open(png) as im:
        return float(np.asarray(im.convert("L"), dtype=np.float64).std())


@pytest.fixture(scope="module")
def reported_study(tmp_path_factory):
    """A one-pair synthetic study, plotted, with its report: (root, report, the pair's stage folders)."""
    if CHROMIUM is None:
        pytest.skip("chromium not on PATH (Debian: apt-get install chromium chromium-driver)")
    root = tmp_path_factory.mktemp("results")
    pairs = write_synthetic_study(root, n_pairs=1, levels=2, n=6000)
    dirs = pairs["pair-00"]
    shared_js = write_plotly_js(root / "assets" / "plotly.min.js")
    for i, d in enumerate(dirs):
        # the default dpi: the stage figures have the pixel width the page lays out in the real reports;
        # stage 0's 3-D view embeds plotly.js; the last one loads the study's shared copy
        plotly_js = shared_js if i == len(dirs) - 1 else None
        plot_stage(d, dirs[i - 1] if i else None, d / "figures", {"background_points": 4000, "dpi": 120}, plotly_js)
    found, rows = discover(root)
    report = write_report({"grid": {"kind": "spherical"}}, found, rows, root / "report.html")
    return root, report, dirs


@pytest.mark.parametrize("page", ["report.html", "pair-00/report.html"], ids=["overview", "pair-page"])
def test_report_renders(reported_study, tmp_path, page):
    root, _, _ = reported_study
    shot = tmp_path / "report.png"
    log = chromium((root / page).as_uri(), shot, tmp_path / "profile")
    assert not_blank(shot) > 10.0
    assert console_errors(log) == []


@pytest.mark.parametrize("stage", [0, -1], ids=["embedded-plotly", "shared-plotly"])
def test_3d_view_renders_without_console_errors(reported_study, tmp_path, stage):
    _, _, dirs = reported_study
    view = dirs[stage] / "figures" / "field_3d.html"
    shot = tmp_path / "view.png"
    log = chromium(view.as_uri(), shot, tmp_path / "profile")
    assert not_blank(shot) > 10.0
    assert ":CONSOLE" in log or "bytes written" in log  # the log was captured at all
    assert console_errors(log) == [], "\n".join(console_errors(log))


def test_console_error_filter_catches_a_broken_page(tmp_path):
    if CHROMIUM is None:
        pytest.skip("chromium not on PATH")
    page = tmp_path / "broken.html"
    page.write_text("<html><body><h1>x</h1><script>undefinedFunction();</script></body></html>")
    log = chromium(page.as_uri(), tmp_path / "b.png", tmp_path / "profile", window=(400, 300))
    assert console_errors(log), "a page with a script error must be caught"


# Appended to a copy of a page: after load, it writes what the layout test reads into an attribute
# of <html> (an attribute takes no room on the page). An element inside a box that scrolls
# sideways (a table in its scroll box, a <pre>) does not run off the page: its box is measured.
LAYOUT_PROBE = """<script>
addEventListener("load", () => {
  const body = document.body, style = getComputedStyle(body);
  const content = body.clientWidth - parseFloat(style.paddingLeft) - parseFloat(style.paddingRight);
  const scrolls = el => /auto|scroll/.test(getComputedStyle(el).overflowX);
  const clipped = el => {
    for (let a = el.parentElement; a && a !== body; a = a.parentElement) if (scrolls(a)) return true;
    return false;
  };
  let widest = 0, widestTag = "";
  for (const el of body.querySelectorAll("*")) {
    const right = el.getBoundingClientRect().right;
    if (right > widest && !clipped(el)) { widest = right; widestTag = el.tagName.toLowerCase(); }
  }
  const box = t => (scrolls(t.parentElement) ? t.parentElement : t);
  document.documentElement.dataset.layout = JSON.stringify({
    viewport: innerWidth, scrollWidth: document.documentElement.scrollWidth, content, widest, widestTag,
    tables: [...document.querySelectorAll("table")].map(t => box(t).getBoundingClientRect().right),
    tableWidths: [...document.querySelectorAll("table")].map(t => t.getBoundingClientRect().width),
    figures: [...document.querySelectorAll("figure img")].map(i => i.getBoundingClientRect().width / content),
    upscale: [...document.querySelectorAll("figure img")].map(i => i.getBoundingClientRect().width / i.naturalWidth),
  });
});
</script>"""
WIDTH = 1400
FIGURE_SHARE = 0.70  # the narrowest embedded figure, as a share of the page's content width
MAX_UPSCALE = 1.25  # the most a figure is shown above its pixel width


def layout(page, tmp_path, window=(WIDTH, 1000)) -> dict:
    """The probe's measures of ``page`` in a headless window of ``window`` size."""
    probed = tmp_path / "probed.html"
    probed.write_text(page.read_text().replace("</body>", LAYOUT_PROBE + "</body>"))
    cmd = [
        CHROMIUM,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--virtual-time-budget=8000",
        f"--user-data-dir={tmp_path / 'profile'}",
        f"--window-size={window[0]},{window[1]}",
        "--dump-dom",
        probed.as_uri(),
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    found = re.search(r'<html[^>]* data-layout="([^"]*)"', done.stdout)
    assert found, f"the layout probe did not run; chromium said:\n{done.stderr[-2000:]}"
    return json.loads(html.unescape(found.group(1)))


@pytest.fixture(scope="module")
def compare_page(reported_study, tmp_path_factory):
    root, _, _ = reported_study
    return compare_studies(root, root, tmp_path_factory.mktemp("compare") / "compare.html")


@pytest.mark.parametrize(
    "page", ["report.html", "pair-00/report.html", "compare"], ids=["overview", "pair-page", "compare"]
)
def test_nothing_runs_off_a_1400_px_page_and_figures_are_readable(reported_study, compare_page, tmp_path, page):
    """Every table fits the page or scrolls inside its own box; no element reaches past the
    window's right edge; every embedded figure of the overview and a pair page takes at least
    FIGURE_SHARE of the content width (the compare page shows A and B side by side), shown at
    no more than MAX_UPSCALE times its pixel width."""
    root, _, _ = reported_study
    m = layout(compare_page if page == "compare" else root / page, tmp_path)
    assert m["viewport"] == WIDTH and m["tables"]
    assert m["scrollWidth"] <= m["viewport"], m
    assert m["widest"] <= m["viewport"] + 0.5, m
    assert max(m["tables"]) <= m["viewport"] + 0.5, m
    if page != "compare":
        assert m["figures"] and min(m["figures"]) >= FIGURE_SHARE, m
    assert max(m["upscale"]) <= MAX_UPSCALE + 0.01, m
