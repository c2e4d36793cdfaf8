"""Rematching: every stage registered again from seeded offsets about the reference pose."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import yaml

from lidarfield.analysis.rematch import perturbed, read_rematch, rematch, start_offsets, summary_columns
from lidarfield.cli import main
from lidarfield.errors import ConfigError
from lidarfield.io import write_scan
from lidarfield.pair import RegisteredPair
from lidarfield.poses import apply_pose, invert_pose, pose_error, pose_from_xyzrpy, relative_pose
from lidarfield.sensors.models import sensor_model
from lidarfield.simulation.raycast import simulate_scan
from lidarfield.simulation.scene import load_scene
from lidarfield.study.config import validate_config
from lidarfield.study.stack import apply_stack
from lidarfield.study.summary import read_stats

# 32 channels over the paper sensor's span, 0.4 deg steps: 29k rays a scan, fast to match.
SENSOR = {"name": "test-32", "elevation_deg": np.linspace(-22, 9.6, 32).tolist(), "azimuth_resolution_deg": 0.4}
POSE1, POSE2 = [0, 0, 3, 0, 0, 0], [1, 1, 3, 0, 0, 0.05]
# The truck body of the ego-truck scene, in the sensor frame, with a margin.
TRUCK_BOX = [-5.4, -0.2, -1.2, 1.2, -2.9, 0.5]


def settings(**changes) -> dict:
    config = {"pairs": {}, "rematch": changes}
    return validate_config(config, require_pairs=False).rematch


def simulated(scene: str):
    """Both scans of the paper's pair poses in ``scene``, and the true pose of sensor 2 in frame 1."""
    sensor = sensor_model(SENSOR)
    scans = [simulate_scan(load_scene(scene), sensor, pose_from_xyzrpy(p)) for p in (POSE1, POSE2)]
    return scans, relative_pose(scans[0].pose, scans[1].pose)


@pytest.fixture(scope="module")
def clean_pair():
    return simulated("paper-intersection")


@pytest.fixture(scope="module")
def truck_pair():
    return simulated("paper-intersection-ego-truck")


def test_defaults_are_filled_and_bad_parameters_named():
    assert settings() == {
        "methods": ["icp_point_to_plane", "gicp", "ndt"],
        "trials": 8,
        "max_translation_m": 0.5,
        "max_rotation_deg": 2.0,
        "seed": 0,
        "parameters": {},
    }
    with pytest.raises(ConfigError, match=r"rematch.parameters: .*voxl_m"):
        settings(parameters={"voxl_m": 0.1})
    with pytest.raises(ConfigError, match=r"rematch.parameters: voxel_m"):
        settings(parameters={"voxel_m": -1})
    with pytest.raises(ConfigError, match=r"config key rematch.methods.0"):
        settings(methods=["loam"])


def test_offsets_are_seeded_within_bounds_and_exact_start_errors():
    a = start_offsets(200, 0.5, 2.0, seed=3)
    assert np.array_equal(a, start_offsets(200, 0.5, 2.0, seed=3))
    assert not np.array_equal(a, start_offsets(200, 0.5, 2.0, seed=4))
    t, angle = np.linalg.norm(a[:, :3], axis=1), np.degrees(np.linalg.norm(a[:, 3:], axis=1))
    assert t.max() <= 0.5 and angle.max() <= 2.0
    assert t.min() < 0.2 and t.max() > 0.45 and angle.max() > 1.9  # they fill the ball, not its shell
    # uniform in the ball: the median radius is 0.5 * 0.5^(1/3) = 0.397 m
    assert abs(np.median(t) - 0.397) < 0.03
    T_ref = pose_from_xyzrpy([1, 2, 3, 0.1, -0.2, 0.3])
    for offset in a[:5]:
        assert np.allclose(
            pose_error(perturbed(T_ref, offset), T_ref),
            (np.linalg.norm(offset[:3]), np.degrees(np.linalg.norm(offset[3:]))),
        )


def test_clean_surfaces_with_truth_give_sub_centimetre_errors(clean_pair):
    (scan1, scan2), truth = clean_pair
    table = rematch(scan1.xyz, scan2.xyz, truth, settings(trials=3))
    assert list(table["method"]) == ["icp_point_to_plane"] * 3 + ["gicp"] * 3 + ["ndt"] * 3
    assert table["converged"].all()
    assert table["start_translation_m"].max() > 0.05  # the trials really start off the truth
    assert table["translation_error_m"].max() < 0.01
    assert table["rotation_error_deg"].max() < 0.1
    assert (table["seconds"] > 0).all()


def test_same_config_same_errors(clean_pair):
    (scan1, scan2), truth = clean_pair
    s = settings(methods=["gicp"], trials=3, seed=7)
    first, second = rematch(scan1.xyz, scan2.xyz, truth, s), rematch(scan1.xyz, scan2.xyz, truth, s)
    for column in ("start_dx_m", "start_rz_deg", "start_translation_m"):
        assert np.array_equal(first[column], second[column])
    # Open3D sums over threads in no fixed order: equal to rounding, not to the last bit.
    for column in ("translation_error_m", "rotation_error_deg", "fitness"):
        assert np.allclose(first[column], second[column], rtol=0, atol=1e-9)
    other = rematch(scan1.xyz, scan2.xyz, truth, {**s, "seed": 8})
    assert not np.array_equal(first["start_dx_m"], other["start_dx_m"])


def test_methods_that_fail_or_diverge_give_rows_not_errors(clean_pair):
    (scan1, scan2), truth = clean_pair
    # Too few points to match at all.
    few = rematch(scan1.xyz[:5], scan2.xyz[:5], truth, settings(methods=["icp", "ndt"], trials=2))
    assert len(few["method"]) == 4 and not few["converged"].any()
    assert np.isnan(few["translation_error_m"]).all()
    assert all("too few to match" in text for text in few["failure"])
    # NDT cells too small for the data: Open3D refuses or returns the guess untouched.
    tiny_cells = rematch(
        scan1.xyz, scan2.xyz, truth, settings(methods=["ndt"], trials=2, parameters={"ndt_resolution_m": 0.01})
    )
    assert not tiny_cells["converged"].any() and all(tiny_cells["failure"])
    # Started 30 m off with a 1 m correspondence distance: nothing to pair, ICP never moves.
    far = rematch(
        scan1.xyz, scan2.xyz, truth @ pose_from_xyzrpy([30, 0, 0, 0, 0, 0]), settings(methods=["icp"], trials=2)
    )
    assert not far["converged"].any() and np.isnan(far["translation_error_m"]).all()
    assert all("poor fitness" in text and "guess unchanged" in text for text in far["failure"])
    columns = summary_columns(few)
    assert columns["rematch_icp_translation_median_m"] is None and columns["rematch_icp_converged_share"] == 0


def test_own_vehicle_body_pulls_point_to_plane_icp_until_ego_vehicle_removes_it(truck_pair):
    """What it must show: stage 0 (the truck body in both scans) against the ego_vehicle stage."""
    (scan1, scan2), truth = truck_pair
    pair = RegisteredPair(scan1.xyz, apply_pose(truth, scan2.xyz), truth, scan1.sensor, scan2.sensor)
    stack = [{"ego_vehicle": {"radius_m": None, "box_m": TRUCK_BOX}}]
    stage0, ego = apply_stack(pair, stack)
    assert ego.removed1 > 0.4 * len(scan1.xyz)  # the body hides about 40% of the rays
    # 5 cm cells keep the near body dense (0.2 m cells thin it out and hide the effect: README).
    s = settings(methods=["icp_point_to_plane"], trials=4, parameters={"voxel_m": 0.05})
    errors = {}
    for stage in (stage0, ego):
        # the study's pair holds scan 2 in frame 1 (here by the truth): rematch takes it in its own frame
        scan2_own = apply_pose(invert_pose(truth), stage.pair.xyz2)
        errors[stage.level] = np.median(rematch(stage.pair.xyz1, scan2_own, truth, s)["translation_error_m"])
    assert errors[1] < 0.01  # the truth is known exactly and the surfaces are clean
    assert errors[0] > 5 * errors[1]


def test_run_writes_rematch_tables_and_summary_columns(tmp_path, clean_pair):
    (scan1, scan2), _ = clean_pair
    paths = [tmp_path / "scan1.parquet", tmp_path / "scan2.parquet"]
    for scan, path in zip((scan1, scan2), paths):
        write_scan(scan, path)
    config = tmp_path / "study.yaml"
    config.write_text(
        yaml.safe_dump(
            {
                "grid": {"elevation_deg": [-22.5, 15.0], "min_points": 5},
                "hypotheses": [{"ego_vehicle": {"radius_m": 8.0}}],
                "rematch": {"methods": ["gicp", "icp"], "trials": 2},
            }
        )
    )
    out = tmp_path / "out"
    assert main(["run", *map(str, paths), "--config", str(config), "--out", str(out), "--register", "truth"]) == 0
    summary = pd.read_parquet(out / "summary.parquet")
    stage_dirs = [out / "stages" / stage for stage in summary["stage"]]
    for stage_dir, row in zip(stage_dirs, summary.itertuples()):
        table, meta = read_rematch(stage_dir / "rematch.parquet")
        assert meta["reference"] == "truth" and meta["stage"] == row.stage
        assert len(table["method"]) == 4
        expected = np.median(table["translation_error_m"][table["method"] == "gicp"])
        assert row.rematch_gicp_translation_median_m == pytest.approx(expected)
        assert row.rematch_gicp_translation_median_m < 0.01
    # The field's rows alone carry no rematch columns: the summary joins them.
    rows = read_stats([d / "stats.json" for d in stage_dirs])
    assert not any(key.startswith("rematch_") for key in rows[0])


def _rows(level_values: dict[str, list[tuple[float, float]]]) -> list[dict]:
    """Summary rows: per pair, per level, (field p95 m, icp median translation error m)."""
    names = ["none", "ego_vehicle", "shadow"]
    return [
        {
            "pair": pair,
            "stage": f"{level:02d}-{names[level]}-0000000{level}",
            "level": level,
            "hypothesis": names[level],
            "p95_magnitude": p95,
            "rematch_icp_translation_median_m": error,
            "rematch_icp_translation_p90_m": 2 * error,
            "rematch_icp_rotation_median_deg": 0.1,
            "rematch_icp_rotation_p90_deg": 0.2,
            "rematch_icp_converged_share": 1.0,
        }
        for pair, values in level_values.items()
        for level, (p95, error) in enumerate(values)
    ]


def test_a_hypothesis_that_shrinks_the_field_but_worsens_matching_is_shown_as_such(monkeypatch):
    import matplotlib.pyplot as plt

    from helpers.layout import assert_fixed_layout
    from lidarfield.plots.rematch import hypothesis_effects, study_rematch_figure
    from lidarfield.report.rematch import pair_rematch_table, study_rematch_parts

    # ego_vehicle: field smaller, errors smaller; shadow: field smaller, errors larger
    rows = _rows({"a": [(1.0, 0.10), (0.5, 0.02), (0.4, 0.05)], "b": [(2.0, 0.20), (1.0, 0.04), (0.9, 0.06)]})
    ego, shadow = hypothesis_effects(rows, ["icp"])
    assert ego["field_p95_change_m"] == pytest.approx(-0.75) and ego["translation_change_m"] == pytest.approx(-0.12)
    assert not ego["worse_matching"]
    assert shadow["field_p95_change_m"] == pytest.approx(-0.1) and shadow["translation_change_m"] == pytest.approx(
        0.025
    )
    assert shadow["translation_relative_change"] == pytest.approx(1.0)  # +150% and +50%
    assert shadow["worse_matching"] and shadow["pairs"] == 2 and ego["verdict"] == "better"
    # a change within 10% of the error is no change: not flagged
    slight = hypothesis_effects(_rows({"a": [(1.0, 0.100), (0.5, 0.105)]}), ["icp"])[0]
    assert slight["verdict"] == "no clear change" and not slight["worse_matching"]
    # nor is +70% of 0.1 mm (0.07 mm): below a millimetre nothing is called a change
    tiny = hypothesis_effects(_rows({"a": [(1.0, 0.0001), (0.5, 0.00017)]}), ["icp"])[0]
    assert tiny["translation_relative_change"] == pytest.approx(0.7)
    assert tiny["verdict"] == "no clear change" and not tiny["worse_matching"]
    fig = study_rematch_figure(rows, ["icp"], dpi=60)
    bars = [bar for bars in fig.axes[0].containers for bar in bars]
    assert [bar.get_hatch() for bar in bars] == [None, "//"]
    assert_fixed_layout(fig)
    plt.close(fig)
    html = "".join(study_rematch_parts(rows, dpi=60))
    assert html.count('<tr class="flag">') == 1 and "field shrinks, matching worse" in html
    pair_html = pair_rematch_table([r for r in rows if r["pair"] == "a"])
    assert pair_html.count("<tr") == 4 and ">5<" in pair_html  # 3 stages + header; 0.05 m = 5 cm
    assert study_rematch_parts([{"pair": "a", "level": 0, "p95_magnitude": 1.0}], dpi=60) == []  # no rematch columns


def test_pose_error_figure_draws_every_stage_and_method(tmp_path, clean_pair):
    from helpers.layout import assert_fixed_layout
    from lidarfield.plots.rematch import pose_error_figure

    (scan1, scan2), truth = clean_pair
    s = settings(methods=["icp", "ndt"], trials=2)
    table = rematch(scan1.xyz[::4], scan2.xyz[::4], truth, s)
    failed = rematch(scan1.xyz[:5], scan2.xyz[:5], truth, s)
    fig = pose_error_figure([(0, "none", table), (1, "ego_vehicle", failed)], "sim", dpi=60, reference="truth")
    assert_fixed_layout(fig)
    assert "against the truth" in fig.axes[0].get_title()
    assert [t.get_text() for t in fig.axes[1].get_xticklabels()] == ["00\nnone", "01\nego_vehicle"]
    # stage 1 has no estimate: one x per method at the top of each panel
    assert sum(len(line.get_xdata()) for line in fig.axes[0].get_lines() if line.get_marker() == "x") == 2
    # a diverged trial (1e11 m off) is a triangle at 10 m: the axes keep the estimates' scale
    diverged = {
        **table,
        "translation_error_m": np.where(np.arange(len(table["trial"])) == 0, 1e11, table["translation_error_m"]),
    }
    fig = pose_error_figure([(0, "none", diverged)], "sim", dpi=60, reference="truth")
    triangles = [line for line in fig.axes[0].get_lines() if line.get_marker() == "^"]
    assert [list(line.get_ydata()) for line in triangles] == [[10.0]]
    assert fig.axes[0].get_ylim()[1] < 100
