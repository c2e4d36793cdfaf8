"""Per-stage and per-pair figures on a synthetic study folder built to the layout contracts."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from helpers.layout import assert_fixed_layout
from helpers.synthetic_study import write_synthetic_pair
from lidarfield.errors import ConfigError, InputError
from lidarfield.field.grid import CartesianGrid, SphericalGrid
from lidarfield.plots import plot_pair, plot_settings, plot_stage
from lidarfield.plots.output import SVG_MAX_BYTES
from lidarfield.plots.stage_data import read_vector_field, subsample
from lidarfield.plots.style import (
    FADED_ALPHA,
    magnitude_norm,
    nice_length,
    resolve_magnification,
    vector_colours,
    view_limits,
)
from lidarfield.plots.top_voxels import box_wireframe, spherical_voxel_wireframe, voxel_wireframe

FAST = {"background_points": 3000, "dpi": 60}
# figure size (inches) x dpi -> pixels
EXPECTED_SIZE_IN = {
    "field_top": (9.0, 7.5),
    "field_perspective": (9.0, 7.5),
    "removed_top": (9.0, 7.5),
    "removed_perspective": (9.0, 7.5),
    "top_voxels": (14.0, 6.2),
    "before_after": (16.0, 7.5),
}


def assert_real_image(path, size_in, dpi):
    with Image.open(path) as im:
        im.verify()
    with Image.open(path) as im:
        assert im.size == (round(size_in[0] * dpi), round(size_in[1] * dpi))
        grey = np.asarray(im.convert("L"), dtype=np.float64)
    assert grey.std() > 10.0, f"{path.name} looks blank (pixel std {grey.std():.1f})"


@pytest.fixture(scope="module")
def stages(tmp_path_factory):
    root = tmp_path_factory.mktemp("study")
    return write_synthetic_pair(root / "pair-a", "pair-a", seed=3, levels=3, n=9000)


@pytest.fixture(scope="module")
def plotted(stages):
    """Stage 1 drawn against stage 0 (with SVG and the 3-D view), stage 0 alone."""
    out1 = stages[1] / "figures"
    written1 = plot_stage(stages[1], stages[0], out1, {**FAST, "formats": ["png", "svg"], "magnification": 2.0})
    out0 = stages[0] / "figures"
    written0 = plot_stage(stages[0], None, out0, {**FAST, "interactive": False})
    return written0, written1


def test_every_stage_figure_is_a_real_image_of_its_size(plotted):
    written0, written1 = plotted
    names1 = {p.name for p in written1}
    for stem, size in EXPECTED_SIZE_IN.items():
        assert f"{stem}.png" in names1
        assert_real_image(next(p for p in written1 if p.name == f"{stem}.png"), size, FAST["dpi"])
    assert "field_3d.html" in names1
    # stage 0: it removes nothing and has no previous stage; interactive off, so no 3-D view
    assert {p.name for p in written0} == {"field_top.png", "field_perspective.png", "top_voxels.png"}


def test_only_the_selected_figures_are_drawn(stages, tmp_path):
    written = plot_stage(
        stages[2], stages[1], tmp_path, {**FAST, "figures": ["field_top", "before_after"], "interactive": False}
    )
    assert sorted(p.name for p in written) == ["before_after.png", "field_top.png"]
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_file()) == ["before_after.png", "field_top.png"]
    assert sorted(p.name for p in (tmp_path / "page").iterdir()) == ["before_after.png", "field_top.png"]


def test_page_copy_is_the_figure_file_compacted(stages, tmp_path, monkeypatch):
    """The figure job's page copy, from the pixels it drew, is what a page would make of the
    PNG file; a page uses it unless the file is newer."""
    import os

    import lidarfield.plots.png as png_module
    from lidarfield.plots.png import compact_file, compact_png, page_copy_path

    (png,) = plot_stage(stages[1], stages[0], tmp_path, {**FAST, "figures": ["field_top"], "interactive": False})
    copy = page_copy_path(png)
    assert copy.read_bytes() == compact_png(png.read_bytes())
    with monkeypatch.context() as m:  # as the figure job left them, the copy is read, not made again
        m.setattr(png_module, "compact_png", lambda png: pytest.fail("compacted again"))
        assert compact_file(png) == copy.read_bytes()
    newer = copy.stat().st_mtime_ns + 1_000_000_000
    os.utime(png, ns=(newer, newer))  # the file drawn again by something that left the copy
    assert compact_file(png) == compact_png(png.read_bytes())
    copy.unlink()
    assert compact_file(png) == compact_png(png.read_bytes())


def test_svg_is_written_only_when_small(plotted):
    svgs = [p for p in plotted[1] if p.suffix == ".svg"]
    assert svgs, "field figures should fit an SVG"
    for p in svgs:
        assert p.stat().st_size <= SVG_MAX_BYTES
        assert b"<svg" in p.read_bytes()[:2000]


def test_interactive_view_is_self_contained(plotted):
    html = next(p for p in plotted[1] if p.name == "field_3d.html").read_text()
    assert '<script src="http' not in html  # plotly.js inline: works from file:// offline
    assert "plotly" in html.lower() and len(html) > 1_000_000
    for name in ("cloud 1", "cloud 2", "vectors mean1"):
        assert name in html


def test_no_temporary_files_left(plotted, stages):
    leftovers = [p for p in (stages[1] / "figures").iterdir() if p.name.startswith(".")]
    assert leftovers == []


def test_missing_field_file_is_one_clear_error(tmp_path, stages):
    bad = tmp_path / "stage"
    bad.mkdir()
    (bad / "changes.parquet").write_bytes((stages[0] / "changes.parquet").read_bytes())
    out = tmp_path / "figures"
    with pytest.raises(InputError, match=r"field\.parquet: file not found"):
        plot_stage(bad, None, out, FAST)
    assert not out.exists() or not any(out.iterdir())


def test_settings_are_validated():
    with pytest.raises(ConfigError, match="magnification"):
        plot_settings({"magnification": "big"})
    assert plot_settings({}).top_k == 10
    with pytest.raises(ConfigError, match="magnifcation"):
        plot_settings({"magnifcation": 2})
    with pytest.raises(ConfigError, match="unknown figure"):
        plot_settings({"figures": ["field_top", "histogram"]})
    with pytest.raises(ConfigError, match="formats"):
        plot_settings({"formats": ["jpg"]})


def test_pair_figures(stages, tmp_path):
    import json

    rows = [json.loads((d / "stats.json").read_text()) for d in stages]
    written = plot_pair(rows, tmp_path, {"dpi": 60})
    assert [p.name for p in written] == ["stages.png", "rigid_randomness.png", "tags.png"]
    assert_real_image(written[0], (8.0, 5.0), 60)
    assert_real_image(written[1], (8.0, 6.5), 60)
    assert_real_image(written[2], (8.0, 5.0), 60)


def test_vectors_within_their_noise_are_drawn_faint(stages):
    field = read_vector_field(stages[0] / "field.parquet")
    z = np.abs(field.columns["z"])
    assert field.z_min == 3.0 and 0 < np.count_nonzero(z < 3) < len(z)  # both kinds in this field
    alpha = vector_colours(field, magnitude_norm(field))[:, 3]
    np.testing.assert_array_equal(alpha, np.where(z >= 3, 1.0, FADED_ALPHA))


def test_spherical_wireframe_lies_on_the_voxel_bounds():
    edges = spherical_voxel_wireframe((30.0, 40.0), (-4.0, 4.0), (5.0, 12.0), n_arc=9)
    assert len(edges) == 12
    pts = np.vstack(edges)
    r = np.linalg.norm(pts, axis=1)
    az = np.degrees(np.arctan2(pts[:, 1], pts[:, 0]))
    el = np.degrees(np.arcsin(pts[:, 2] / r))
    assert np.all((r > 5.0 - 1e-9) & (r < 12.0 + 1e-9))
    assert np.all((az > 30.0 - 1e-9) & (az < 40.0 + 1e-9))
    assert np.all((el > -4.0 - 1e-9) & (el < 4.0 + 1e-9))
    # every vertex is on a face: at a bound of range, azimuth or elevation (2 of 3 for edges)
    on_bound = sum(np.isclose(v, b) for v, b in ((r, 5.0), (r, 12.0), (az, 30.0), (az, 40.0), (el, -4.0), (el, 4.0)))
    assert np.all(on_bound >= 2)


def test_voxel_wireframe_encloses_the_voxel_of_its_centre():
    grid = SphericalGrid(36, 5.0, (-20.0, 20.0), 5, (0.0, 10.0, 30.0))
    voxel = int(grid.assign(np.array([[8.0, 12.0, 1.5]]))[0])
    edges = voxel_wireframe(grid, voxel, np.zeros(0, np.int64), np.zeros((0, 3)))
    pts = np.vstack(edges)
    centre = pts.mean(axis=0)  # inside a convex-enough wedge of 10 deg x 8 deg
    assert int(grid.assign(centre[None, :])[0]) == voxel
    r = np.linalg.norm(pts, axis=1)
    assert r.min() == pytest.approx(10.0) and r.max() == pytest.approx(30.0)


def test_voxel_wireframe_without_shells_spans_its_points():
    grid = SphericalGrid(36, 0.0, (-20.0, 20.0), 5)
    points = np.array([[3.0, 0.2, 0.0], [7.0, 0.5, 0.1], [20.0, 40.0, 0.0]])
    ids = grid.assign(points)
    edges = voxel_wireframe(grid, int(ids[0]), ids, points)
    r = np.linalg.norm(np.vstack(edges), axis=1)
    assert r.min() == pytest.approx(np.linalg.norm(points[0]))
    assert r.max() == pytest.approx(np.linalg.norm(points[1]))


def test_cartesian_voxel_is_a_box():
    grid = CartesianGrid(0.5, (1.0, 0.0, 0.0))
    voxel = int(grid.assign(np.array([[1.2, -0.3, 0.7]]))[0])
    edges = voxel_wireframe(grid, voxel, np.zeros(0, np.int64), np.zeros((0, 3)))
    assert len(edges) == 12
    assert all(np.linalg.norm(e[1] - e[0]) == pytest.approx(0.5) for e in edges)
    pts = np.vstack(edges)
    assert pts.min(axis=0) == pytest.approx([1.0, -0.5, 0.5]) and pts.max(axis=0) == pytest.approx([1.5, 0.0, 1.0])
    assert len(box_wireframe(np.zeros(3), np.ones(3))) == 12


def test_subsample_is_deterministic_and_capped():
    xyz = np.random.default_rng(1).normal(size=(1000, 3))
    a, b = subsample(xyz, 100), subsample(xyz, 100)
    assert len(a) == 100 and np.array_equal(a, b)
    assert subsample(xyz, 5000) is xyz


def test_view_limits_ignore_stray_returns_but_keep_vectors():
    rng = np.random.default_rng(0)
    points = np.vstack([rng.uniform(-10, 10, (5000, 3)), [[500.0, 0.0, 0.0]]])
    limits = view_limits(points, np.array([[0.0, 30.0, 0.0]]), pad=0.0)
    assert limits[0, 1] < 20.0  # the one return at 500 m does not shrink the scene
    assert limits[1, 1] == pytest.approx(30.0)  # a drawn vector is never cut off


@pytest.mark.parametrize("x, expected", [(0.37, 0.2), (5.121, 5.0), (1.0, 1.0), (0.012, 0.01), (73.0, 50.0)])
def test_nice_length(x, expected):
    assert nice_length(x) == pytest.approx(expected)


@pytest.mark.parametrize(
    "max_m, span_m, expected",
    [
        (0.162, 26.0, 10.0),  # 26/16/0.162 = 10.03: a 16 cm field on a 26 m scene is drawn x10
        (0.665, 26.0, 2.0),  # 2.44 rounds down to 2
        (44.0, 110.0, 1.0),  # a large field is never shrunk
        (0.0, 26.0, 1.0),  # no vectors
    ],
)
def test_auto_magnification(max_m, span_m, expected):
    assert resolve_magnification("auto", max_m, span_m) == expected
    assert max_m * expected <= span_m / 16 or expected == 1.0  # the largest arrow stays within 1/16
    assert resolve_magnification(3.0, max_m, span_m) == 3.0  # a number is taken as it is


def test_a_3d_view_can_share_one_plotly_js(tmp_path):
    from helpers.synthetic_study import write_synthetic_study
    from lidarfield.plots import plot_stage, write_plotly_js

    dirs = write_synthetic_study(tmp_path, n_pairs=1, levels=1, n=3000)["pair-00"]
    shared = write_plotly_js(tmp_path / "assets" / "plotly.min.js")
    plot_stage(dirs[0], None, dirs[0] / "embedded", {"background_points": 1000, "dpi": 50})
    plot_stage(dirs[0], None, dirs[0] / "shared", {"background_points": 1000, "dpi": 50}, shared)
    embedded = (dirs[0] / "embedded" / "field_3d.html").stat().st_size
    html = (dirs[0] / "shared" / "field_3d.html").read_text()
    src = html.split('<script charset="utf-8" src="', 1)[1].split('"', 1)[0]
    assert (dirs[0] / "shared" / src).resolve() == shared.resolve()
    assert len(html) < embedded - shared.stat().st_size // 2  # the bundle is not in the page


def test_fixed_layout_keeps_axes_legends_and_titles_apart(stages, tmp_path, monkeypatch):
    """The figures use fixed margins (no layout engine): nothing may overlap or be cut off."""
    import matplotlib.pyplot as plt

    figures = []
    monkeypatch.setattr(plt, "close", figures.append)  # keep each figure open after saving
    plot_stage(stages[1], stages[0], tmp_path, {**FAST, "interactive": False})
    plot_pair(
        [
            {
                "pair": "pair-a",
                "stage": "s",
                "level": lv,
                "hypothesis": h,
                "max_magnitude": 1.0 / (lv + 1),
                "rigid_translation_m": [0.1, 0.0, 0.0],
            }
            for lv, h in enumerate(["none", "ego_vehicle"])
        ],
        tmp_path,
    )
    assert len(figures) == 9
    for fig in figures:
        assert_fixed_layout(fig)
    monkeypatch.undo()
    plt.close("all")


def test_top_voxels_whose_edges_all_lie_outside_the_view_are_still_drawn(stages, tmp_path):
    """Found on a drive: every edge of the top voxels clipped away left mplot3d an empty
    collection, and the stage's figure job failed."""
    from lidarfield.plots.settings import plot_settings
    from lidarfield.plots.stage_data import load_stage
    from lidarfield.plots.top_voxels import plot_top_voxels

    stage = load_stage(stages[1])
    far_away = np.array([[1000.0, 1001.0], [1000.0, 1001.0], [1000.0, 1001.0]])
    (written,) = plot_top_voxels(
        stage, far_away, tmp_path, plot_settings({**FAST, "formats": ["png"], "magnification": 2.0})
    )
    assert_real_image(written, EXPECTED_SIZE_IN["top_voxels"], FAST["dpi"])
