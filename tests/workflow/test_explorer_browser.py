"""The report's interactive parts in the system's Chromium, driven by Playwright (offline, no
downloaded browser): the pair explorer's slider, hover, cameras and "show all"; every request
stays on the machine. Assertions are on the drawn data (what the viewer hands WebGL, which it
exposes as ``explorer.frame``) and the hover label's text, never on pixels."""

from __future__ import annotations

import base64
import io
import re
import shutil

import numpy as np
import pytest

from helpers.synthetic_study import write_synthetic_study
from lidarfield.io.parquet_table import read_table
from lidarfield.report import compare_studies, discover, write_report
from lidarfield.report.explorer import points_script, rest_script, stage_script
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


def drawn(page, index: int = 0) -> dict:
    """What an explorer drew at its stage: point counts, vector tips, corrections, layers."""
    return page.evaluate(
        """i => { const x = document.querySelectorAll('.explorer')[i].explorer, f = x.frame;
             return {stage: f.stage, kept: f.kept, removed: f.removed, vectors: f.vectors,
                     tips: Array.from(f.tips), moves: f.moves, layers: x.layers,
                     cameras: JSON.parse(JSON.stringify(x.cameras))}; }""",
        index,
    )


def move_slider(page, stage: int) -> None:
    page.eval_on_selector(
        ".stage-slider", "(s, v) => { s.value = v; s.dispatchEvent(new Event('input')); }", str(stage)
    )
    page.wait_for_function(
        "k => document.querySelector('.explorer').explorer.frame.stage === k", arg=stage, timeout=10_000
    )


def drag(page, selector: str, dx: float, dy: float, index: int = 0) -> None:
    """A mouse drag across a view's canvas, from its centre."""
    canvas = page.locator(f"{selector} canvas.gl").nth(index)
    canvas.scroll_into_view_if_needed()
    box = canvas.bounding_box()
    x, y = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(x, y)
    page.mouse.down()
    page.mouse.move(x + dx / 2, y + dy / 2)
    page.mouse.move(x + dx, y + dy)
    page.mouse.up()


def removed_drawn(arrays: dict, c: int, loaded: int) -> int:
    """A stage file's removed points of cloud c among the ``loaded`` first of its draw order."""
    return int(np.count_nonzero(arrays.get(f"removed{c}", np.zeros(0)) < loaded))


def test_the_slider_changes_the_vectors_and_removed_points_and_keeps_the_cameras(study, page):
    root, pairs, _ = study
    dirs = pairs["pair-00"]
    pair_dir = dirs[0].parent.parent
    open_explorer(page, (pair_dir / "report.html").as_uri())
    assert "2,000 of 6,000 points drawn" in page.inner_text(".budget-drawn")  # the budget's cut, stated
    home = drawn(page)["cameras"]
    drag(page, ".explorer-3d", 120, -40)  # orbit the 3-D view
    drag(page, ".explorer-top", 60, 30)  # pan the top view
    page.mouse.wheel(0, -300)  # and zoom it
    cameras = drawn(page)["cameras"]
    assert cameras["3d"]["azimuth"] == pytest.approx(home["3d"]["azimuth"] - 120 * 0.008)
    assert cameras["top"]["centre"] != pytest.approx(home["top"]["centre"])
    assert cameras["top"]["half"] < home["top"]["half"]
    removed_so_far = 0
    for level, d in enumerate(dirs):
        if level:
            move_slider(page, level)
        _, _, data = read_script(stage_script(pair_dir, d.name))
        field, _ = read_table(d / "field.parquet")
        now = drawn(page)
        valid = field["valid"] & np.isfinite(field["magnitude"])
        assert now["vectors"] == int(np.count_nonzero(valid))
        # the tips drawn are the field's tails plus the magnified vectors
        magnification = page.evaluate("document.querySelector('.explorer').explorer.magnification")
        tails = np.column_stack([field[a][valid] for a in ("x1", "y1", "z1")])
        vectors = np.column_stack([field[a][valid] for a in "uvw"])
        assert np.allclose(np.reshape(now["tips"], (-1, 3)), tails + magnification * vectors, atol=1e-3)
        removed_so_far += removed_drawn(data, 1, BUDGET) + removed_drawn(data, 2, BUDGET)
        assert now["removed"] == removed_so_far
        assert sum(now["kept"]) == 2 * BUDGET - removed_so_far
        assert now["cameras"] == cameras  # both views as the analyst left them
    assert removed_so_far > 0
    assert page.evaluate("location.hash") == f"#stage={len(dirs) - 1}"
    # a layer toggled off stays off when the stage changes
    page.uncheck("input.layer[value='removed']")
    move_slider(page, 1)
    assert drawn(page)["layers"]["removed"] is False
    assert page.errors == []


def test_hover_on_a_vector_shows_its_voxels_counts_and_length(study, page):
    root, pairs, _ = study
    d = pairs["pair-01"][1]
    open_explorer(page, f"{(d.parent.parent / 'report.html').as_uri()}#stage=1")
    field, _ = read_table(d / "field.parquet")
    valid = field["valid"] & np.isfinite(field["magnitude"])
    for view in ("top", "3d"):
        # the largest vector's tip, where the view draws it on the page
        best = int(np.argmax(field["magnitude"][valid]))
        page.locator(
            f".explorer-{view} canvas.gl"
        ).first.scroll_into_view_if_needed()  # the mouse moves in the viewport
        x, y = page.evaluate(f"() => document.querySelector('.explorer').explorer.tipOnPage('{view}', {best})")
        page.mouse.move(x, y)
        tooltip = page.wait_for_selector(f".explorer-{view} .explorer-tooltip:not([hidden])", timeout=10_000)
        text = tooltip.inner_text()
        voxel = int(re.search(r"voxel (\d+)", text).group(1))
        row = int(np.flatnonzero(field["voxel"] == voxel)[0])
        assert voxel == field["voxel"][valid][best]
        assert int(re.search(r"n1 (\d+)", text).group(1)) == field["n1"][row]
        assert int(re.search(r"n2 (\d+)", text).group(1)) == field["n2"][row]
        assert float(re.search(r"\|d\| ([0-9.]+) m", text).group(1)) == pytest.approx(field["magnitude"][row], abs=5e-5)
        assert float(re.search(r"se ([0-9.]+) m", text).group(1)) == pytest.approx(field["se"][row], abs=5e-5)
        assert f"az {field['az_bin'][row]}, el {field['el_bin'][row]}, r {field['r_bin'][row]}" in text
        # halfway along the vector: its label too (its line is picked, not only its tip)
        magnification = page.evaluate("document.querySelector('.explorer').explorer.magnification")
        middle = [float(field[t][row] + magnification * field[c][row] / 2) for t, c in zip(("x1", "y1", "z1"), "uvw")]
        hx, hy = page.evaluate(
            "([v, m]) => document.querySelector('.explorer').explorer.onPage(v, ...m)", [view, middle]
        )
        assert np.hypot(hx - x, hy - y) > 10  # away from the tip
        page.mouse.move(hx, hy)
        page.wait_for_function(
            "([view, v]) => { const t = document.querySelector(`.explorer-${view} .explorer-tooltip`);"
            " return !t.hidden && t.textContent.startsWith(`voxel ${v} `); }",
            arg=[view, voxel],
            timeout=10_000,
        )
        page.mouse.move(x, y)  # back on the tip
    # away from every vector: no label
    box = page.locator(".explorer-top canvas.gl").bounding_box()
    page.mouse.move(box["x"] + 3, box["y"] + 3)
    page.wait_for_selector(".explorer-top .explorer-tooltip[hidden]", state="attached", timeout=10_000)
    # clicking selects the voxel; the selection stays when the stage changes
    page.mouse.click(x, y)
    page.wait_for_function("() => document.querySelector('.explorer').explorer.selected !== null")
    move_slider(page, 0)
    assert f"voxel {voxel}" in page.inner_text(".selected-voxel")
    assert page.errors == []


def test_show_all_draws_every_point_and_every_removed_one(study, page):
    root, pairs, _ = study
    dirs = pairs["pair-00"]
    pair_dir = dirs[0].parent.parent
    open_explorer(page, f"{(pair_dir / 'report.html').as_uri()}#stage=2")
    assert not any(url.endswith("/rest.js") for url in page.requests)  # only on demand
    page.click("button.show-all")
    page.wait_for_selector(".explorer[data-all-points='1']", state="attached", timeout=30_000)
    assert "6,000 of 6,000 points drawn" in page.inner_text(".budget-drawn")
    totals = sum(
        c["removed"]["total"] for d in dirs[1:] for c in read_script(stage_script(pair_dir, d.name))[1]["clouds"]
    )
    now = drawn(page)
    assert now["removed"] == totals and sum(now["kept"]) + totals == 12_000
    assert page.locator("button.show-all").is_hidden()
    assert page.errors == []


def test_a_view_exports_what_it_shows_as_png(study, page):
    from PIL import Image

    root, pairs, _ = study
    open_explorer(page, (pairs["pair-00"][0].parent.parent / "report.html").as_uri())
    for view in ("3d", "top"):
        url = page.evaluate(f"() => document.querySelector('.explorer').explorer.png('{view}')")
        assert url.startswith("data:image/png;base64,")
        image = Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("L")
        width = page.eval_on_selector(f".explorer-{view} canvas.gl", "c => c.width")
        assert image.size[0] == width
        # the points and vectors, not a blank canvas (preserveDrawingBuffer keeps the frame)
        assert np.count_nonzero(np.asarray(image) < 200) > 500
    with page.expect_download() as download:
        page.click("button.png-top")
    assert download.value.suggested_filename == f"pair-00-{pairs['pair-00'][0].name}-top.png"
    assert page.errors == []


def test_the_report_requests_nothing_off_the_machine(study, page):
    root, pairs, _ = study
    open_explorer(page, (pairs["pair-00"][0].parent.parent / "report.html").as_uri())
    page.click("button.show-all")
    page.wait_for_selector(".explorer[data-all-points='1']", state="attached", timeout=30_000)
    page.goto((root / "report.html").as_uri())
    page.wait_for_load_state("load")
    assert page.requests and all(url.startswith(("file://", "data:")) for url in page.requests), page.requests
    loaded = {url.rsplit("/", 1)[-1] for url in page.requests}
    assert {"explorer.js", "points.js", "rest.js", "overview.js"} <= loaded
    assert "plotly.min.js" not in loaded  # the explorer draws with WebGL itself
    assert rest_script(pairs["pair-00"][0].parent.parent).is_file()
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
    assert drawn(page)["stage"] == 2
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


def test_compare_shows_a_pair_of_both_studies_with_the_cameras_and_stage_linked(study, page, tmp_path):
    root, _, _ = study
    out = compare_studies(root, root, tmp_path / "compare.html")
    page.goto(out.as_uri())
    page.wait_for_selector(".explorer[data-linked='1']", state="attached", timeout=60_000)
    assert page.locator(".explorer").count() == 4  # two pairs, A beside B
    drag(page, ".explorer-3d", 100, 50, index=0)
    drag(page, ".explorer-top", -40, 20, index=0)
    cameras = [drawn(page, i)["cameras"] for i in range(4)]
    assert cameras[1] == cameras[0]  # B's view of pair-00 as A's
    for view in ("3d", "top"):
        assert cameras[2][view] != cameras[0][view]  # pair-01's views kept theirs
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
    moves = np.array(drawn(page)["moves"], dtype=float)  # a move: before, after
    assert np.allclose(moves[:, 0], points["xyz2"][moved], atol=1e-5)
    assert np.allclose(moves[:, 1], to, atol=1e-5)
    assert "moved 3 of 3" in page.inner_text(".budget-drawn")
    kept2 = page.evaluate(
        "m => { const f = document.querySelector('.explorer').explorer.frame;"
        " return m.map(i => [f.removedBy[1][i], ...Array.from(f.clouds[1].subarray(3 * i, 3 * i + 3))]); }",
        moved.tolist(),
    )
    kept2 = np.array(kept2, dtype=float)
    assert np.all(kept2[:, 0] == 0) and np.allclose(kept2[:, 1:], to, atol=1e-5)  # kept, drawn where moved to
    # the arrows: a shaft and a two-stroke head each
    assert page.evaluate("document.querySelector('.explorer').explorer.frame.arrows.length") == 3 * 3 * 6
    move_slider(page, 1)  # stage 1 moved nothing
    assert drawn(page)["moves"] == []
    assert page.errors == []


def test_the_vectors_take_their_colour_from_the_chosen_scale(study, page):
    """|d|: the largest vector at the scale's top (viridis' last colour, the scale over every
    stage); |z|: the most significant at plasma's; tag: one colour per first tag, named in the legend."""
    root, pairs, _ = study
    d = pairs["pair-00"][0]  # stage 0 holds the largest vector of the stack
    open_explorer(page, (d.parent.parent / "report.html").as_uri())
    field, _ = read_table(d / "field.parquet")
    valid = field["valid"] & np.isfinite(field["magnitude"])

    def colours() -> np.ndarray:
        return np.reshape(
            page.evaluate("Array.from(document.querySelector('.explorer').explorer.frame.colours)"), (-1, 3)
        )

    def choose(mode: str) -> None:
        page.select_option("select.colour-by", mode)
        page.wait_for_function("m => document.querySelector('.explorer').explorer.scale.kind === m", arg=mode)

    top = np.array([0xFD, 0xE7, 0x25]) / 255  # viridis at 1
    drawn = colours()
    assert np.allclose(drawn[np.argmax(field["magnitude"][valid])], top, atol=1e-3)
    assert f"{field['magnitude'][valid].max():.3f}" in page.inner_text(".explorer-legend")
    choose("z")
    assert np.allclose(colours()[np.argmax(np.abs(field["z"][valid]))], np.array([0xF0, 0xF9, 0x21]) / 255, atol=1e-3)
    choose("tag")
    _, header, arrays = read_script(stage_script(d.parent.parent, d.name))
    bits = arrays["tags"]
    first = np.zeros(len(bits), int)  # a vector's first tag, 1-based; 0: none
    for bit in reversed(range(len(header["tags"]))):
        first[(bits >> bit) & 1 == 1] = bit + 1
    drawn = colours()
    for tag in np.unique(first):
        mine = drawn[first == tag]
        assert np.allclose(mine, mine[0])  # one colour a first tag
        others = drawn[first != tag]
        assert not np.any(np.all(np.isclose(others, mine[0]), axis=1))  # and not another's
    legend = page.inner_text(".explorer-legend")
    assert "no tag" in legend and all(name in legend for name in header["tags"])
    assert page.errors == []


def test_a_stage_whose_data_is_not_written_is_said_so(study, page, tmp_path):
    root, pairs, _ = study
    copy = tmp_path / "results"
    shutil.copytree(root, copy)
    stage2 = pairs["pair-00"][2].name
    stage_script(copy / "pair-00", stage2).unlink()
    open_explorer(page, (copy / "pair-00" / "report.html").as_uri())
    assert f"Not written yet: the explorer data of {stage2}" in page.inner_text(".explorer")
    page.eval_on_selector(".stage-slider", "s => { s.value = 2; s.dispatchEvent(new Event('input')); }")
    assert "not written" in page.inner_text(".stage-label")
    assert drawn(page)["stage"] == 0  # the views keep the stage they can draw
    assert page.errors == ["Failed to load resource: net::ERR_FILE_NOT_FOUND"]  # the missing file's, only


def test_a_browser_without_webgl_is_told_so_not_shown_a_blank_view(study, page):
    root, pairs, _ = study
    page.add_init_script(
        "const get = HTMLCanvasElement.prototype.getContext;"
        "HTMLCanvasElement.prototype.getContext = function (kind, o) {"
        " return kind === 'webgl' ? null : get.call(this, kind, o); };"
    )
    page.goto((pairs["pair-00"][0].parent.parent / "report.html").as_uri())
    page.wait_for_selector(".explorer .note:has-text('no WebGL')", timeout=30_000)
    assert page.locator(".explorer canvas").count() == 0
    assert page.errors == []
