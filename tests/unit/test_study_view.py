"""The overview's interactive parts: the heat map's cells link each pair at each stage with the
summary's numbers, the polar maps' cells carry the voxels table's, where the grid puts them."""

from __future__ import annotations

import html
import re

import numpy as np
import pytest

from helpers.synthetic_study import write_field_study
from lidarfield.report import discover, write_report
from lidarfield.report.polar_svg import SIZE, cell_path, polar_map_parts
from lidarfield.report.study_view import heatmap_grid, removed_shares
from lidarfield.study.tables import compute_study_tables


@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    root = tmp_path_factory.mktemp("study")
    write_field_study(root, 4, levels=3, n=1500)
    pairs, rows = discover(root)
    return compute_study_tables(pairs, rows)


def test_heat_map_cells_link_each_pair_at_each_stage_with_its_numbers(tables):
    grid = heatmap_grid(tables.summary, tables.pairs)
    cells = re.findall(r'<a href="([^"]+)" title="([^"]+)">([^<]+)</a>', grid)
    assert len(cells) == len(tables.summary) == 4 * 3
    rows = {(r["pair"], int(r["level"])): r for r in tables.summary.to_dict("records")}
    for href, title, text in cells:
        pair, level = re.fullmatch(r"(pair-\d+)/report\.html#stage=(\d+)", href).groups()
        r = rows[(pair, int(level))]
        p95 = float(re.search(r"p95_magnitude ([0-9.e-]+) m", html.unescape(title)).group(1))
        assert p95 == pytest.approx(r["p95_magnitude"], rel=1e-3) and float(text) == pytest.approx(p95, rel=5e-3)
    # rows in rank order
    order = re.findall(r'<td class="text">\d+\. (pair-\d+)</td>', grid)
    assert order == list(tables.pairs["pair"])


def test_removed_share_is_what_the_stages_removed_of_both_clouds(tables):
    s = tables.summary
    for pair, share in removed_shares(s).items():
        mine = s[s["pair"] == pair].sort_values("level")
        first, last = mine.iloc[0], mine.iloc[-1]
        assert share == pytest.approx(1 - (last["n1"] + last["n2"]) / (first["n1"] + first["n2"]))


def test_polar_cells_carry_the_voxels_numbers(tables):
    parts = "".join(polar_map_parts(tables.voxels, tables.grid))
    found = re.findall(r'data-level="(\d+)" data-voxel="(\d+)"><title>([^<]+)</title>', parts)
    assert len(found) == 2 * len(tables.voxels)  # the magnitude map and the share map
    rows = {(int(r["level"]), int(r["voxel"])): r for r in tables.voxels.to_dict("records")}
    for level, voxel, title in found:
        r, title = rows[(int(level), int(voxel))], html.unescape(title)
        assert f"(az {r['az_bin']}, el {r['el_bin']})" in title
        median = float(re.search(r"median magnitude ([0-9.e+-]+|nan) m", title).group(1))
        share = float(re.search(r"median ([0-9.e+-]+|nan), valid", title).group(1))
        assert np.isclose(median, r["magnitude_median"], rtol=1e-3, equal_nan=True)
        assert np.isclose(share, r["share_above_pair_median"], rtol=1e-2, equal_nan=True)
        assert f"valid in {r['pairs_valid']} of {r['pairs']} pairs" in title


def test_cells_sit_where_the_png_puts_them():
    """Forward (+x) up, +y left, lowest elevation band inside."""
    grid = {"azimuth_bins": 36, "azimuth_offset_deg": 0.0, "elevation_deg": [-20.0, 20.0], "elevation_bins": 5}

    def first_point(az_bin, el_bin):
        x, y = re.match(r"M([0-9.]+),([0-9.]+)", cell_path(grid, az_bin, el_bin)).groups()
        return float(x) - SIZE / 2, float(y) - SIZE / 2

    x, y = first_point(0, 4)  # azimuth 0: straight up
    assert abs(x) < 1e-6 and y < 0
    x, y = first_point(9, 4)  # azimuth 90 deg (+y): left
    assert x < 0 and abs(y) < 1e-6
    inner, outer = np.hypot(*first_point(0, 0)), np.hypot(*first_point(0, 4))
    assert 0 < inner < outer


def test_a_report_without_an_explorer_writes_its_scripts_only(tmp_path):
    """No pair has figures, so no page has an explorer; the report's own scripts, no library."""
    write_field_study(tmp_path, 2, levels=2, n=1000)
    pairs, rows = discover(tmp_path)
    overview = write_report({}, pairs, rows, tmp_path / "report.html").read_text()
    assert sorted(p.name for p in (tmp_path / "assets").iterdir()) == ["explorer.js", "overview.js"]
    assert '<script src="assets/overview.js"></script>' in overview
    assert 'class="explorer"' not in (tmp_path / "pair-000" / "report.html").read_text()


def test_a_ranked_row_links_its_pair_and_its_last_stage(tables):
    from lidarfield.report.study_view import ranking_table

    table = ranking_table(tables, set(), {})
    for r in tables.pairs.to_dict("records"):
        level = int(r["level"])
        assert f'<a href="{r["pair"]}/report.html">{r["pair"]}</a>' in table
        assert f'<a href="{r["pair"]}/report.html#stage={level}">{level:02d} {r["hypothesis"]}</a>' in table


def study_figure(tables, stem: str):
    from lidarfield.plots.study import study_figures

    figures = study_figures(tables.summary, tables.voxels, tables.hypotheses, tables.pairs, tables.grid)
    return next(f for f in figures if f.stem == stem)


def rendered(f) -> np.ndarray:
    import io

    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(f.png())).convert("RGB")).astype(int)


def test_the_all_pairs_figure_hovers_each_pairs_point_on_its_drawn_marker(tables):
    from lidarfield.report.overview import figure_html

    f = study_figure(tables, "all_pairs")
    spots = f.spots()
    rows = tables.summary.to_dict("records")
    assert len(spots) == len(rows) == 4 * 3
    image = rendered(f)
    height, width, _ = image.shape
    for s in spots:
        pair, level, value = re.fullmatch(r"(pair-\d+) · stage (\d+) \w+: max magnitude ([0-9.e-]+) m", s.text).groups()
        row = next(r for r in rows if r["pair"] == pair and int(r["level"]) == int(level))
        assert float(value) == pytest.approx(row["max_magnitude"], rel=1e-3)
        # the spot's centre is on the pair's marker: coloured pixels (not white, not a grey grid line)
        x, y = (s.box[0] + s.box[2]) / 2 * width, (s.box[1] + s.box[3]) / 2 * height
        patch = image[round(y) - 1 : round(y) + 2, round(x) - 1 : round(x) + 2]
        assert (patch.max(axis=2) - patch.min(axis=2)).min() > 40, s.text
    # on the page: one span a spot over the image, in % of it
    page = figure_html(f, None)
    assert page.count("<span style=") == len(spots) and 'class="hover-spots"' in page


def test_the_hypotheses_figure_hovers_each_box_with_its_quartiles(tables):
    f = study_figure(tables, "hypotheses")
    spots = f.spots()
    levels = sorted(tables.hypotheses["level"].unique())
    assert len(spots) == 3 * len(levels)
    image = rendered(f)
    height, width, _ = image.shape
    for s, level in zip(spots, levels):  # the first panel's: the change of p95
        rows = tables.hypotheses[tables.hypotheses["level"] == level]
        change = (rows["p95_magnitude_after"] - rows["p95_magnitude_before"]).to_numpy(dtype=float)
        median = float(re.search(r"median ([0-9.e-]+),", s.text).group(1))
        assert s.text.startswith(f"{int(level):02d} ") and median == pytest.approx(
            np.median(change), rel=1e-3, abs=1e-9
        )
        # the box's black median line crosses the spot's centre column between its top and bottom
        x = round((s.box[0] + s.box[2]) / 2 * width)
        column = image[round(s.box[1] * height) : round(s.box[3] * height) + 1, x]
        assert (column.max(axis=1) < 60).any(), s.text


def test_beyond_a_dozen_pairs_the_all_pairs_figure_hovers_the_medians(tmp_path):
    write_field_study(tmp_path, 13, levels=2, n=1500)
    pairs, rows = discover(tmp_path)
    tables = compute_study_tables(pairs, rows)
    spots = study_figure(tables, "all_pairs").spots()
    assert len(spots) == 2
    for s, (level, mine) in zip(spots, tables.summary.groupby("level")):
        median = float(re.search(r"median of 13 pairs ([0-9.e-]+) m", s.text).group(1))
        assert median == pytest.approx(mine["max_magnitude"].median(), rel=1e-3)
        top = mine.loc[mine["max_magnitude"].idxmax()]
        assert f"largest {top['pair']} " in s.text
