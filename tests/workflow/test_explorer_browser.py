"""The report's interactive parts in the system's Chromium, driven by Playwright (offline, no
downloaded browser): the pair explorer's slider, hover and camera; every request stays on the
machine. Assertions are on the drawn data (Plotly's traces) and the hover label's text, never
on pixels."""

from __future__ import annotations

import re
import shutil

import numpy as np
import pytest

from helpers.synthetic_study import write_synthetic_study
from lidarfield.io.parquet_table import read_table
from lidarfield.report import compare_studies, discover, write_report
from lidarfield.report.explorer import points_script, stage_script
from lidarfield.report.explorer_data import encode, read_script, wrap_script

pytestmark = pytest.mark.slow

CHROMIUM = shutil.which("chromium")
BUDGET = 2000  # points drawn of each cloud: fewer than the pair has, so the page states a cut
# No static figure: a pair counts as plotted (and gets its explorer) by its stages' figures folders.
STUDY = {"grid": {"kind": "spherical"}, "plots": {"figures": [], "interactive": False}}
STUDY["report"] = {"explorer_points": BUDGET}


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """A two-pair, three-stage synthetic study with its report: (root, {pair: stage folders})."""
    if CHROMIUM is None:
        pytest.skip("chromium not on PATH (Debian: apt-get install chromium)")
    sync_api = pytest.importorskip("playwright.sync_api")
    root = tmp_path_factory.mktemp("results")
    pairs = write_synthetic_study(root, n_pairs=2, levels=3, n=6000)
    for dirs in pairs.values():
        for d in dirs:
            (d / "figures").mkdir()
    found, rows = discover(root)
    write_report(STUDY, found, rows, root / "report.html")
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=["--enable-unsafe-swiftshader"])
        yield root, pairs, browser
        browser.close()


@pytest.fixture
def page(study):
    """A page of the study's browser that records every request and every script error."""
    _, _, browser = study
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    tab = context.new_page()
    tab.requests, tab.errors = [], []
    tab.on("request", lambda r: tab.requests.append(r.url))
    tab.on("pageerror", lambda e: tab.errors.append(str(e)))
    tab.on("console", lambda m: tab.errors.append(m.text) if m.type == "error" else None)
    yield tab
    context.close()


def open_explorer(page, url: str) -> None:
    page.goto(url)
    page.wait_for_selector(".explorer[data-ready='1']", state="attached", timeout=60_000)


def traces(page, view: str = "3d") -> dict:
    """The drawn traces of a view by name: their point counts and (vector tips) coordinates."""
    return page.evaluate(
        """view => Object.fromEntries(document.querySelector(`.explorer-${view}`).data.map(t =>
             [t.name, {n: (t.x || []).length, x: Array.from(t.x || []), y: Array.from(t.y || []),
                       visible: t.visible}]))""",
        view,
    )


def move_slider(page, stage: int) -> None:
    page.eval_on_selector(
        ".stage-slider", "(s, v) => { s.value = v; s.dispatchEvent(new Event('input')); }", str(stage)
    )
    page.wait_for_function("k => document.querySelector('.explorer').explorer.stage === k", arg=stage, timeout=10_000)
    page.wait_for_timeout(300)  # Plotly.react resolves after the redraw


def test_the_slider_changes_the_vectors_and_removed_points_and_keeps_the_camera(study, page):
    root, pairs, _ = study
    dirs = pairs["pair-00"]
    pair_dir = dirs[0].parent.parent
    open_explorer(page, (pair_dir / "report.html").as_uri())
    assert "2,000 of 6,000 points drawn" in page.inner_text(".budget-drawn")  # the budget's cut, stated
    page.evaluate(
        "() => Plotly.relayout(document.querySelector('.explorer-3d'), {'scene.camera.eye': {x: 0.3, y: -2.1, z: 0.9}})"
    )
    removed_so_far = 0
    for level, d in enumerate(dirs):
        if level:
            move_slider(page, level)
        _, _, data = read_script(stage_script(pair_dir, d.name))
        field, _ = read_table(d / "field.parquet")
        drawn = traces(page)
        assert drawn["vector tips"]["n"] == int(np.count_nonzero(field["valid"]))
        removed_so_far += len(data.get("removed1", [])) + len(data.get("removed2", []))
        assert drawn["removed points"]["n"] == removed_so_far
        assert drawn["cloud 1 (kept)"]["n"] + drawn["cloud 2 (kept)"]["n"] == 2 * BUDGET - removed_so_far
        # the same vectors in the top view
        assert traces(page, "top")["vector tips"]["n"] == drawn["vector tips"]["n"]
        eye = page.evaluate("() => document.querySelector('.explorer-3d')._fullLayout.scene.camera.eye")
        assert eye == pytest.approx({"x": 0.3, "y": -2.1, "z": 0.9})
    assert removed_so_far > 0
    assert page.evaluate("location.hash") == f"#stage={len(dirs) - 1}"
    # a layer toggled off is drawn invisible, and stays so when the stage changes
    page.uncheck("input.layer[value='removed']")
    move_slider(page, 1)
    assert traces(page)["removed points"]["visible"] is False
    assert page.errors == []


def test_hover_on_a_vector_shows_its_voxels_counts_and_length(study, page):
    root, pairs, _ = study
    d = pairs["pair-01"][1]
    open_explorer(page, f"{(d.parent.parent / 'report.html').as_uri()}#stage=1")
    field, _ = read_table(d / "field.parquet")
    # the largest vector's tip in the top view, in the page's pixels
    box = page.evaluate(
        """() => {
          const gd = document.querySelector('.explorer-top'), L = gd._fullLayout;
          const tips = gd.data.find(t => t.name === 'vector tips'), r = gd.getBoundingClientRect();
          const mags = tips.hovertext.map(h => parseFloat(/\\|d\\| ([0-9.]+)/.exec(h)[1]));
          const best = mags.indexOf(Math.max(...mags));
          return {x: r.left + L._size.l + L.xaxis.l2p(tips.x[best]), y: r.top + L._size.t + L.yaxis.l2p(tips.y[best]),
                  voxel: tips.customdata[best]};
        }"""
    )
    page.mouse.move(box["x"], box["y"])
    label = page.wait_for_selector(".explorer-top .hoverlayer .hovertext", state="attached", timeout=10_000)
    # the label's lines (SVG tspans), one per line
    text = label.evaluate("g => [...g.querySelectorAll('tspan.line')].map(t => t.textContent).join('\\n')")
    voxel = int(re.search(r"voxel (\d+)", text).group(1))
    assert voxel == box["voxel"]
    row = int(np.flatnonzero(field["voxel"] == voxel)[0])
    assert int(re.search(r"n1 (\d+)", text).group(1)) == field["n1"][row]
    assert int(re.search(r"n2 (\d+)", text).group(1)) == field["n2"][row]
    assert float(re.search(r"\|d\| ([0-9.]+) m", text).group(1)) == pytest.approx(field["magnitude"][row], abs=5e-5)
    assert f"az {field['az_bin'][row]}, el {field['el_bin'][row]}" in text
    # the 3-D view's tips carry the same hover texts as the top view's
    hovers = page.evaluate(
        "() => ['3d', 'top'].map(v => document.querySelector(`.explorer-${v}`).data.find(t => t.name === 'vector tips')"
        ".hovertext)"
    )
    assert hovers[0] == hovers[1] and len(hovers[0]) == int(np.count_nonzero(field["valid"]))
    # clicking selects the voxel; the selection stays when the stage changes
    page.mouse.click(box["x"], box["y"])
    page.wait_for_function("() => document.querySelector('.explorer').explorer.selected !== null")
    move_slider(page, 0)
    assert f"voxel {voxel}" in page.inner_text(".selected-voxel")
    assert page.errors == []


def test_the_report_requests_nothing_off_the_machine(study, page):
    root, pairs, _ = study
    open_explorer(page, (pairs["pair-00"][0].parent.parent / "report.html").as_uri())
    page.goto((root / "report.html").as_uri())
    page.wait_for_load_state("load")
    assert page.requests and all(url.startswith(("file://", "data:")) for url in page.requests), page.requests
    loaded = {url.rsplit("/", 1)[-1] for url in page.requests}
    assert {"plotly.min.js", "explorer.js", "points.js"} <= loaded
    assert points_script(pairs["pair-00"][0].parent.parent).is_file()
    assert page.errors == []


def test_a_heat_map_cell_opens_that_pair_at_that_stage(study, page):
    root, pairs, _ = study
    page.goto((root / "report.html").as_uri())
    cell = page.locator("table.heatmap a[href='pair-01/report.html#stage=2']")
    title = cell.get_attribute("title")
    assert title.startswith("pair-01 · stage 02 field_of_view: p95_magnitude ")
    cell.click()
    page.wait_for_selector(".explorer[data-ready='1']", state="attached", timeout=60_000)
    assert page.url.endswith("/pair-01/report.html#stage=2")
    assert page.evaluate("document.querySelector('.stage-slider').value") == "2"
    assert page.inner_text(".stage-label") == "02 field_of_view"
    assert page.errors == []


def test_the_ranked_table_sorts_and_filters(study, page):
    root, _, _ = study
    page.goto((root / "report.html").as_uri())
    page.wait_for_selector("html[data-overview-ready='1']", state="attached")
    table = "table.sortable"

    def column(name: str) -> list[str]:
        return page.eval_on_selector(
            table,
            """(t, name) => { const i = [...t.tHead.rows[0].cells].findIndex(c => c.textContent === name);
                 return [...t.tBodies[0].rows].filter(r => !r.hidden).map(r => r.cells[i].textContent); }""",
            name,
        )

    ranked = column("pair")
    assert sorted(ranked) == ["pair-00", "pair-01"]
    page.click(f"{table} th:text-is('p95 (m)')")  # ascending: the ranking reversed
    assert column("pair") == ranked[::-1]
    p95 = [float(v) for v in column("p95 (m)")]
    assert p95 == sorted(p95) and p95[0] < p95[1]
    page.click(f"{table} th:text-is('p95 (m)')")  # again: descending
    assert column("pair") == ranked
    page.fill(".table-filter input", ranked[1])
    assert column("pair") == [ranked[1]]
    assert page.inner_text(".filter-count") == "1 of 2 pairs shown"
    page.fill(".table-filter input", "")
    assert column("pair") == ranked
    assert page.errors == []


def test_compare_shows_a_pair_of_both_studies_with_the_camera_and_stage_linked(study, page, tmp_path):
    root, _, _ = study
    out = compare_studies(root, root, tmp_path / "compare.html")
    page.goto(out.as_uri())
    page.wait_for_selector(".explorer[data-linked='1']", state="attached", timeout=60_000)
    assert page.locator(".explorer").count() == 4  # two pairs, A beside B
    eye = {"x": 0.2, "y": -1.9, "z": 1.1}
    page.evaluate(
        "eye => Plotly.relayout(document.querySelectorAll('.explorer-3d')[0], {'scene.camera.eye': eye})", eye
    )
    page.wait_for_timeout(500)
    cameras = page.evaluate(
        "() => [...document.querySelectorAll('.explorer-3d')].map(v => v._fullLayout.scene.camera.eye)"
    )
    assert cameras[1] == pytest.approx(eye) and cameras[2] != pytest.approx(eye)  # B's view of pair-00 only
    move_slider(page, 2)  # the first explorer's slider moves its partner's
    stages = page.evaluate("() => [...document.querySelectorAll('.explorer')].map(e => e.explorer.stage)")
    assert stages == [2, 2, 0, 0]
    assert page.errors == []


def test_a_correcting_stage_draws_its_moves_from_before_to_after(study, page, tmp_path):
    """Stage 2's file of a copy of the study gains moves of three sampled points of cloud 2: the
    corrections layer draws each from where stage 1 left it to where stage 2 put it, and the
    kept points are drawn where they were moved to."""
    root, pairs, _ = study
    copy = tmp_path / "results"
    shutil.copytree(root, copy)
    pair_dir = copy / "pair-00"
    stage2 = stage_script(pair_dir, pairs["pair-00"][2].name)
    key, header, arrays = read_script(stage2)
    _, _, points = read_script(points_script(pair_dir))
    by_stage1 = read_script(stage_script(pair_dir, pairs["pair-00"][1].name))[2]["removed2"]
    kept = np.setdiff1d(np.arange(BUDGET), np.concatenate([arrays["removed2"], by_stage1]))  # cloud 2's at stage 2
    moved = kept[:3].astype(np.uint32)
    to = points["xyz2"][moved] + np.float32([0.5, -0.25, 1.0])
    arrays = {**arrays, "moved2": moved, "moved2_xyz": to.astype(np.float32)}
    header["clouds"][1]["moved"] = {"total": 3, "drawn": 3}
    stage2.write_text(wrap_script(key, encode(header, arrays)))
    open_explorer(page, f"{(pair_dir / 'report.html').as_uri()}#stage=2")
    segments = page.evaluate(
        "() => { const t = document.querySelector('.explorer-3d').data.find(t => t.name === 'corrections');"
        " return [Array.from(t.x), Array.from(t.y), Array.from(t.z)]; }"
    )
    drawn = np.array(segments, dtype=float).T.reshape(3, 3, 3)  # a segment: before, after, NaN
    assert np.allclose(drawn[:, 0], points["xyz2"][moved], atol=1e-5)
    assert np.allclose(drawn[:, 1], to, atol=1e-5)
    assert "moved 3 of 3" in page.inner_text(".budget-drawn")
    kept2 = page.evaluate(
        "() => { const t = document.querySelector('.explorer-3d').data.find(t => t.name === 'cloud 2 (kept)');"
        " return [Array.from(t.x), Array.from(t.y), Array.from(t.z)]; }"
    )
    kept2 = np.array(kept2, dtype=float).T
    assert all(np.min(np.linalg.norm(kept2 - p, axis=1)) < 1e-5 for p in to)  # drawn where they were moved to
    move_slider(page, 1)  # stage 1 moved nothing
    assert traces(page)["corrections"]["n"] == 0
    assert page.errors == []
