"""The study level: its Parquet tables against the per-pair fields and summary they summarise
(recomputed here with pandas), its figures, and the report of a study of hundreds of pairs."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from helpers.layout import assert_fixed_layout
from helpers.synthetic_study import write_field_study
from lidarfield.cli import main
from lidarfield.errors import ConfigError, InputError
from lidarfield.plots import plot_pair
from lidarfield.plots.study import _polar_cells, plot_study
from lidarfield.study.config import AUTO_PLOT_PAIRS, AUTO_SUGGEST_PAIRS, selected_pairs, validate_config
from lidarfield.study.tables import group_medians, read_study_tables, write_study_tables, write_study_voxels


@pytest.fixture(scope="module")
def field_study(tmp_path_factory):
    """12 pairs x 3 stages of fields (a ring at the lowest elevations, shrinking stage by stage)
    and their study tables, as the workflow's jobs write them."""
    root = tmp_path_factory.mktemp("results")
    pairs = write_field_study(root, n_pairs=12, levels=3, n=4000)
    fields = sorted(root.glob("*/stages/*/field.parquet"))
    write_study_voxels(fields, root / "study" / "voxels.parquet")
    write_study_tables(
        root / "summary.parquet", root / "study" / "hypotheses.parquet", root / "study" / "pairs.parquet"
    )
    return root, pairs


def all_fields(root: Path) -> pd.DataFrame:
    """Every field file of the study, one frame, with its pair and level from the path."""
    frames = []
    for path in sorted(root.glob("*/stages/*/field.parquet")):
        df = pd.read_parquet(path)
        df["pair"] = path.parents[2].name
        df["level"] = int(path.parent.name[:2])
        frames.append(df)
    return pd.concat(frames, ignore_index=True)


def test_group_medians_match_numpy_per_group():
    rng = np.random.default_rng(1)
    keys = rng.integers(0, 7, 500)
    values = rng.normal(size=500)
    unique, medians = group_medians(keys, values)
    assert list(unique) == sorted(set(keys))
    assert medians == pytest.approx([np.median(values[keys == k]) for k in unique], abs=1e-12)


def test_voxels_table_agrees_with_the_fields(field_study):
    root, pairs = field_study
    got = pd.read_parquet(root / "study" / "voxels.parquet").set_index(["level", "voxel"]).sort_index()
    fields = all_fields(root)
    valid = fields[fields["valid"]].copy()
    pair_median = valid.groupby(["level", "pair"])["magnitude"].median().rename("pair_median")
    valid = valid.join(pair_median, on=["level", "pair"])
    valid["above"] = valid["magnitude"] > valid["pair_median"]
    by_voxel = valid.groupby(["level", "voxel"])
    expected = pd.DataFrame(
        {
            "pairs_valid": by_voxel.size(),
            "u_median": by_voxel["u"].median(),
            "v_median": by_voxel["v"].median(),
            "w_median": by_voxel["w"].median(),
            "magnitude_median": by_voxel["magnitude"].median(),
            "share_above_pair_median": by_voxel["above"].mean(),
        }
    )
    present = fields.groupby(["level", "voxel"])["pair"].nunique()
    assert list(got.index) == list(present.index)  # every voxel holding points in any pair
    assert (got["pairs_with_points"] == present).all() and (got["pairs"] == len(pairs)).all()
    assert (got.loc[expected.index, "pairs_valid"] == expected["pairs_valid"]).all()
    assert (got.drop(expected.index)["pairs_valid"] == 0).all() and got.drop(expected.index)["u_median"].isna().all()
    for column in ("u_median", "v_median", "w_median", "magnitude_median", "share_above_pair_median"):
        np.testing.assert_allclose(got.loc[expected.index, column], expected[column], rtol=1e-12, atol=1e-12)
    # the grid's bins come with the voxel ids: voxel = az + 36 * el on the synthetic 36 x 5 grid
    assert (got.index.get_level_values("voxel") == got["az_bin"] + 36 * got["el_bin"]).all()
    # the ring the fields carry: the lowest band is above its pair's median in most pairs at stage 0
    ring = got.loc[0]
    assert ring.loc[ring["el_bin"] == 0, "share_above_pair_median"].mean() > 0.9
    assert ring.loc[ring["el_bin"] > 0, "share_above_pair_median"].mean() < 0.5


def test_hypotheses_and_pairs_tables_agree_with_the_summary(field_study):
    root, pairs = field_study
    summary = pd.read_parquet(root / "summary.parquet")
    hypotheses = pd.read_parquet(root / "study" / "hypotheses.parquet")
    assert len(hypotheses) == len(pairs) * 2 and set(hypotheses["level"]) == {1, 2}
    after = summary.set_index(["pair", "level"])
    for r in hypotheses.itertuples():
        before_row, after_row = after.loc[(r.pair, r.level - 1)], after.loc[(r.pair, r.level)]
        assert r.stage == after_row["stage"] and r.hypothesis == after_row["hypothesis"]
        for metric in ("max", "p95", "rms"):
            assert getattr(r, f"{metric}_magnitude_before") == before_row[f"{metric}_magnitude"]
            assert getattr(r, f"{metric}_magnitude_after") == after_row[f"{metric}_magnitude"]
        assert (r.removed1, r.removed2) == (after_row["removed1"], after_row["removed2"])
        assert r.removed_share == pytest.approx((r.removed1 + r.removed2) / (before_row["n1"] + before_row["n2"]))
    ranked = pd.read_parquet(root / "study" / "pairs.parquet")
    last = summary[summary["level"] == 2].sort_values("p95_magnitude", ascending=False)
    assert list(ranked["pair"]) == list(last["pair"]) and list(ranked["rank"]) == list(range(1, len(pairs) + 1))
    assert list(ranked["p95_magnitude"]) == list(last["p95_magnitude"])
    first = summary[summary["level"] == 0].set_index("pair")["p95_magnitude"]
    assert list(ranked["p95_magnitude_stage0"]) == list(first.loc[ranked["pair"]])


def test_study_voxels_refuses_a_file_outside_the_layout(tmp_path, field_study):
    root, _ = field_study
    stray = tmp_path / "field.parquet"
    stray.write_bytes(next(root.glob("*/stages/*/field.parquet")).read_bytes())
    with pytest.raises(InputError, match="not a field of the study layout"):
        write_study_voxels([stray], tmp_path / "voxels.parquet")
    assert not (tmp_path / "voxels.parquet").exists()


def test_polar_cells_put_each_voxel_at_its_azimuth_and_elevation(field_study):
    root, _ = field_study
    tables = read_study_tables(root / "summary.parquet", root / "study")
    rows = tables.voxels[tables.voxels["level"] == 0]
    cells = _polar_cells(rows, tables.grid, "magnitude_median")
    assert cells.shape == (5, 36)
    for r in rows.sample(20, random_state=0).itertuples():
        expected = r.magnitude_median if r.pairs_valid > 0 else np.nan
        np.testing.assert_equal(cells[r.el_bin, r.az_bin], expected)


def test_study_figures_are_written_one_per_stage_level_plus_three_and_keep_their_layout(
    field_study, tmp_path, monkeypatch
):
    import matplotlib.pyplot as plt

    root, _ = field_study
    t = read_study_tables(root / "summary.parquet", root / "study")
    figures = []
    monkeypatch.setattr(plt, "close", figures.append)  # keep each figure open after saving
    written = plot_study(t.summary, t.voxels, t.hypotheses, t.pairs, t.grid, tmp_path / "figures")
    assert sorted(p.name for p in written) == [
        "all_pairs.png",
        "heatmap.png",
        "hypotheses.png",
        "voxels_00.png",
        "voxels_01.png",
        "voxels_02.png",
    ]
    for fig in figures:
        assert_fixed_layout(fig)
    monkeypatch.undo()
    plt.close("all")


def plot_pairs(setting, names):
    return selected_pairs(setting, names, AUTO_PLOT_PAIRS, "plots.pairs")


def test_plots_pairs_chooses_the_pairs_that_get_stage_figures():
    few = [f"p{i:02d}" for i in range(AUTO_PLOT_PAIRS)]
    assert plot_pairs("auto", few) == few
    drive = [f"drive-{i:03d}" for i in range(100)]
    picked = plot_pairs("auto", drive)
    assert len(picked) == AUTO_PLOT_PAIRS and picked[0] == "drive-000" and picked[-1] == "drive-099"
    gaps = np.diff([int(p[-3:]) for p in picked])
    assert gaps.min() >= 8 and gaps.max() <= 10  # evenly spaced along the drive
    assert plot_pairs("all", drive) == drive and plot_pairs("none", drive) == []
    assert plot_pairs(["drive-042", "drive-007"], drive) == ["drive-007", "drive-042"]
    with pytest.raises(ConfigError, match=r"plots.pairs: unknown pair\(s\) \['drive-777'\]"):
        plot_pairs(["drive-777"], drive)


def test_suggest_pairs_spreads_the_last_stages_suggestions_over_a_long_drive():
    def study(frames: int, **settings) -> object:
        circle = {"center_xy": [0, 0], "radius_m": 2, "start_angle_rad": 0, "speed_mps": 1, "frames": frames}
        drive = {"scene": "paper-intersection", "sensor": "paper-sim-80", "trajectory": circle}
        return validate_config({"sequences": {"drive": {"simulate": drive}}, **settings})

    short = study(AUTO_SUGGEST_PAIRS + 1)  # frames: one pair fewer
    assert short.suggest_pairs == sorted(short.pairs)
    long = study(250)
    names = sorted(long.pairs)
    assert len(long.suggest_pairs) == AUTO_SUGGEST_PAIRS
    assert set(long.plot_pairs) <= set(long.suggest_pairs)  # the plotted pairs' every stage
    assert long.suggest_pairs[0] == names[0] and long.suggest_pairs[-1] == names[-1]
    gaps = np.diff([names.index(p) for p in long.suggest_pairs])
    assert gaps.min() >= 2 and gaps.max() <= 3
    chosen = study(250, suggest_pairs=["drive-007"], plots={"pairs": ["drive-100"]})
    assert chosen.suggest_pairs == ["drive-007", "drive-100"]
    assert study(250, suggest_pairs="none", plots={"pairs": "none"}).suggest_pairs == []
    with pytest.raises(ConfigError, match=r"suggest_pairs: unknown pair\(s\) \['drive-777'\]"):
        study(250, suggest_pairs=["drive-777"])


@pytest.mark.slow
def test_report_of_300_pairs_is_under_10_mb_and_links_a_page_for_every_pair(tmp_path):
    root = tmp_path / "results"
    pairs = write_field_study(root, n_pairs=300, levels=3, n=3000)
    # pair-000's stage-by-stage figures, drawn once, stand in for every pair's (as plot_pair
    # writes them in a study): the report would otherwise draw 600 figures
    first = plot_pair(
        [json.loads((d / "stats.json").read_text()) for d in pairs["pair-000"]],
        root / "pair-000" / "figures",
        {"dpi": 60},
    )
    for name in pairs:
        for png in first:
            (root / name / "figures").mkdir(exist_ok=True)
            if not (root / name / "figures" / png.name).exists():
                shutil.copy(png, root / name / "figures" / png.name)
    out = root / "report.html"
    assert main(["report", str(root), "--out", str(out)]) == 0
    html = out.read_text()
    assert out.stat().st_size < 10e6
    links = re.findall(r'<a href="([^"]+/report\.html)">', html)
    assert len(links) == 300 and len(set(links)) == 300
    assert all((root / link).is_file() for link in links)
    assert {Path(link).parent.name for link in links} == set(pairs)
    # the study level comes first, the config last and folded
    assert html.index("The study level") < html.index("Pairs ranked") < html.index("<details><summary>the config")
    page = (root / links[0]).read_text()
    assert 'href="../report.html"' in page and Path(links[0]).parent.name in page
