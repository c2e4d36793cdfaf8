"""Open-to-interactive time and bytes of the report's interactive pages in Chromium (issue 39).

Each page is opened from file:// in the system's Chromium (headless, software WebGL, driven by
Playwright) in a fresh tab; "open to interactive" is the page's own clock (performance.now(),
from the navigation's start) when its script has drawn and wired everything: the explorer's
first draw of both views, the overview's table handlers. Bytes: every file the page loaded.

- the default study (``config/config.yaml``, run with Snakemake in a temporary folder): its
  overview and its plotted pair's page;
- synthetic studies of 100 and 1,000 pairs (fields and summary rows only): their overviews;
- one pair of 2 x 120,000 points and 4 stages: its page with the explorer's default budget
  (50,000 points a cloud), then its "draw all" button (the rest of the points loaded and
  drawn), and its page with every point;
- the viewers considered, on the same 2 x 120,000 points: plotly.js (scatter3d, as the explorer
  drew before its own viewer) and a bare WebGL point renderer (the floor for any viewer).

Run: python bench/explorer.py [--runs 3] [--no-default-study | --default-results RESULTS]
"""

from __future__ import annotations

import argparse
import base64
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from urllib.parse import unquote, urlparse

import numpy as np
from playwright.sync_api import sync_playwright

from lidarfield.plots.interactive import write_plotly_js
from lidarfield.report import discover, write_pair_page, write_report
from lidarfield.report.explorer import write_assets, write_explorer_data
from lidarfield.report.explorer_data import encode
from timing import machine  # bench/timing.py

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the tests' synthetic studies
from helpers.synthetic_study import write_field_study, write_synthetic_pair  # noqa: E402
from helpers.workflow import workflow_command  # noqa: E402 (the workflow's command, as the tests run it)

EXPLORER_READY = ".explorer[data-ready='1']"
OVERVIEW_READY = "html[data-overview-ready='1']"
CANDIDATE_READY = "html[data-ready-ms]"


def open_page(browser, path: Path, ready: str) -> tuple[float, int]:
    """Milliseconds from navigation to interactive, and the bytes of every file the page loaded."""
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    page = context.new_page()
    files = []
    page.on("request", lambda r: files.append(r.url))
    page.goto(path.as_uri(), wait_until="commit")
    page.wait_for_selector(ready, state="attached", timeout=180_000)
    ms = float(page.eval_on_selector(ready, "e => e.dataset.readyMs"))
    context.close()
    local = {Path(unquote(urlparse(url).path)) for url in files if url.startswith("file://")}
    return ms, sum(p.stat().st_size for p in local if p.is_file())


def show_all(browser, path: Path) -> tuple[float, int]:
    """Milliseconds from a click on the explorer's "draw all" to every point drawn, and the bytes
    of the files it loaded."""
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    page = context.new_page()
    page.goto(path.as_uri())
    page.wait_for_selector(EXPLORER_READY, state="attached", timeout=180_000)
    files = []
    page.on("request", lambda r: files.append(r.url))
    start = page.evaluate("() => { document.querySelector('button.show-all').click(); return performance.now(); }")
    page.wait_for_selector(".explorer[data-all-points='1']", state="attached", timeout=180_000)
    ms = page.evaluate("() => performance.now()") - start
    context.close()
    local = {Path(unquote(urlparse(url).path)) for url in files if url.startswith("file://")}
    return ms, sum(p.stat().st_size for p in local if p.is_file())


def measure(browser, label: str, path: Path, ready: str, runs: int) -> dict:
    times, size = [], 0
    for _ in range(runs):
        ms, size = open_page(browser, path, ready)
        times.append(ms)
    row = {"case": label, "median_s": statistics.median(times) / 1000, "runs_s": [t / 1000 for t in times]}
    row["MB"] = size / 1e6
    print(f"{label}: {row['median_s']:.2f} s (runs {', '.join(f'{t:.2f}' for t in row['runs_s'])}), {row['MB']:.2f} MB")
    return row


def default_study(work: Path) -> Path:
    """The default study's results folder, run with Snakemake in ``work``."""
    cmd = [*workflow_command(work, ROOT / "config" / "config.yaml"), "--cores", "2", "--quiet"]
    subprocess.run(cmd, check=True, capture_output=True)
    return work / "results"


def synthetic_overview(work: Path, n_pairs: int) -> Path:
    root = work / f"study-{n_pairs}"
    write_field_study(root, n_pairs, levels=4, n=2000)
    found, rows = discover(root)
    return write_report({"grid": {"kind": "spherical"}}, found, rows, root / "report.html")


def big_pair(work: Path, budget: int) -> Path:
    """A pair of 2 x 120,000 points and 4 stages, its page with the explorer at ``budget``."""
    pair_dir = work / f"big-{budget}" / "big"
    dirs = write_synthetic_pair(pair_dir, "big", levels=4, n=120_000)
    write_assets(pair_dir.parent / "assets")
    write_explorer_data(pair_dir, dirs, budget)
    rows = [json.loads((d / "stats.json").read_text()) for d in dirs]
    plots = {"figures": [], "interactive": False}
    return write_pair_page("big", dirs, rows, pair_dir / "report.html", plots, overview_href="../report.html")


# The candidates: the same 2 x 120,000 points in the explorer's data format, drawn once.
PLOTLY_PAGE = """<!DOCTYPE html><html><body><div id="v" style="width:1380px;height:900px"></div>
<script src="plotly.min.js"></script><script src="explorer.js"></script><script src="points.js"></script>
<script>
const {arrays} = lidarfieldExplorer.decode(window.points);
const traces = ["xyz1", "xyz2"].map(k => { const a = arrays[k].data, n = a.length / 3;
  const x = new Float32Array(n), y = new Float32Array(n), z = new Float32Array(n);
  for (let i = 0; i < n; i++) { x[i] = a[3*i]; y[i] = a[3*i+1]; z[i] = a[3*i+2]; }
  return {type: "scatter3d", mode: "markers", x, y, z, marker: {size: 1.5}}; });
Plotly.newPlot("v", traces, {scene: {aspectmode: "data"}}).then(() =>
  requestAnimationFrame(() => { document.documentElement.dataset.readyMs = performance.now().toFixed(0); }));
</script></body></html>"""
WEBGL_PAGE = """<!DOCTYPE html><html><body><canvas id="c" width="1380" height="900"></canvas>
<script src="explorer.js"></script><script src="points.js"></script>
<script>
const {arrays} = lidarfieldExplorer.decode(window.points);
const gl = document.getElementById("c").getContext("webgl");
const shader = (type, src) => {
  const s = gl.createShader(type); gl.shaderSource(s, src); gl.compileShader(s); return s; };
const prog = gl.createProgram();
gl.attachShader(prog, shader(gl.VERTEX_SHADER, "attribute vec3 p; uniform float s; void main() {" +
  " gl_Position = vec4(p.x * s, p.y * s, p.z * s * 0.5, 1.0); gl_PointSize = 2.0; }"));
gl.attachShader(prog, shader(gl.FRAGMENT_SHADER, "precision mediump float; uniform vec3 c;" +
  " void main() { gl_FragColor = vec4(c, 1.0); }"));
gl.linkProgram(prog); gl.useProgram(prog);
gl.uniform1f(gl.getUniformLocation(prog, "s"), 1 / 25);
const at = gl.getAttribLocation(prog, "p");
gl.clearColor(1, 1, 1, 1); gl.clear(gl.COLOR_BUFFER_BIT);
for (const [k, colour] of [["xyz1", [0.6, 0.6, 0.6]], ["xyz2", [0.3, 0.4, 0.6]]]) {
  gl.bindBuffer(gl.ARRAY_BUFFER, gl.createBuffer());
  gl.bufferData(gl.ARRAY_BUFFER, arrays[k].data, gl.STATIC_DRAW);
  gl.enableVertexAttribArray(at); gl.vertexAttribPointer(at, 3, gl.FLOAT, false, 0, 0);
  gl.uniform3fv(gl.getUniformLocation(prog, "c"), colour);
  gl.drawArrays(gl.POINTS, 0, arrays[k].data.length / 3);
}
gl.finish();
requestAnimationFrame(() => { document.documentElement.dataset.readyMs = performance.now().toFixed(0); });
</script></body></html>"""


def candidates(work: Path, big: Path) -> dict[str, Path]:
    """The candidate pages beside a copy of the big pair's points (every one of them)."""
    folder = work / "candidates"
    folder.mkdir()
    write_plotly_js(folder / "plotly.min.js")
    shutil.copy(big.parent.parent / "assets" / "explorer.js", folder)
    rng = np.random.default_rng(0)
    xyz = [rng.normal(0, 10, (120_000, 3)).astype(np.float32) for _ in range(2)]
    blob = encode({"kind": "points"}, {"xyz1": xyz[0], "xyz2": xyz[1]})
    # the candidates take the blob (base64, as the explorer's files hold it) as a global
    (folder / "points.js").write_text(f'window.points = "{base64.b64encode(blob).decode("ascii")}";\n')
    pages = {"plotly.js scatter3d": PLOTLY_PAGE, "bare WebGL points": WEBGL_PAGE}
    paths = {}
    for name, html in pages.items():
        paths[name] = folder / f"{name.split()[0].replace('.', '_')}.html"
        paths[name].write_text(html)
    return paths


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--no-default-study", action="store_true")
    parser.add_argument("--default-results", type=Path, help="the default study's results folder, already run")
    parser.add_argument("--overviews-only", action="store_true", help="only the overviews")
    args = parser.parse_args()
    print(machine())
    results = []
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as p:
        work = Path(tmp)
        browser = p.chromium.launch(executable_path=shutil.which("chromium"), args=["--enable-unsafe-swiftshader"])
        if not args.no_default_study:
            results_dir = args.default_results or default_study(work / "default")
            results.append(
                measure(browser, "default study: overview", results_dir / "report.html", OVERVIEW_READY, args.runs)
            )
            results.append(
                measure(
                    browser,
                    "default study: paper-sim's page",
                    results_dir / "paper-sim" / "report.html",
                    EXPLORER_READY,
                    args.runs,
                )
            )
        for n in (100, 1000):
            results.append(
                measure(browser, f"{n}-pair overview", synthetic_overview(work, n), OVERVIEW_READY, args.runs)
            )
        if args.overviews_only:
            print(json.dumps(results, indent=1))
            return
        for budget, label in ((50_000, "default budget, 50,000 a cloud drawn"), (0, "every point drawn")):
            page = big_pair(work, budget)
            results.append(measure(browser, f"2 x 120,000 points, 4 stages, {label}", page, EXPLORER_READY, args.runs))
            if budget:
                clicks = [show_all(browser, page) for _ in range(args.runs)]
                row = {"case": "2 x 120,000 points: 'draw all' clicked, the other 2 x 70,000 loaded and drawn"}
                row |= {"median_s": statistics.median(c[0] for c in clicks) / 1000, "MB": clicks[0][1] / 1e6}
                print(f"{row['case']}: {row['median_s']:.2f} s, {row['MB']:.2f} MB")
                results.append(row)
        for name, page in candidates(work, page).items():
            results.append(
                measure(browser, f"viewer candidate, 2 x 120,000 points: {name}", page, CANDIDATE_READY, args.runs)
            )
        browser.close()
    print(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
