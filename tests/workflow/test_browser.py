"""Headless Chromium opens the study overview, a pair page and a 3-D view from file://: not blank, no console errors."""

from __future__ import annotations

import re
import shutil
import subprocess

import numpy as np
import pytest
from PIL import Image

from lidarfield.plots import plot_stage, write_plotly_js
from lidarfield.plots.synthetic import write_synthetic_study
from lidarfield.report import discover, write_report

pytestmark = pytest.mark.slow

CHROMIUM = shutil.which("chromium")
# A console line that reports a failure (uncaught exceptions, script errors, failed loads);
# driver chatter such as "GL Driver Message ... Performance" is not one.
CONSOLE_ERROR = re.compile(r"Uncaught|[A-Za-z]*Error\b|Failed to load|is not defined|WebGL is not supported")


def chromium(url: str, screenshot, profile, window=(1280, 1000)) -> str:
    """Open ``url`` headless, write a screenshot, return the browser's log (stderr)."""
    cmd = [
        CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync",
        "--enable-unsafe-swiftshader", "--enable-logging=stderr", "--v=0", "--virtual-time-budget=8000",
        f"--user-data-dir={profile}", f"--screenshot={screenshot}", f"--window-size={window[0]},{window[1]}", url,
    ]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    assert screenshot.is_file(), f"no screenshot; chromium said:\n{done.stderr[-2000:]}"
    return done.stderr


def console_errors(log: str) -> list[str]:
    return [ln for ln in log.splitlines() if ":CONSOLE" in ln and CONSOLE_ERROR.search(ln) and "GL Driver Message" not in ln]


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
        # stage 0's 3-D view embeds plotly.js; the last one loads the study's shared copy
        plotly_js = shared_js if i == len(dirs) - 1 else None
        plot_stage(d, dirs[i - 1] if i else None, d / "figures", {"background_points": 4000, "dpi": 60}, plotly_js)
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
