"""A scan that does not fit its sensor model, a stage that removes most of a cloud, a field
without a valid voxel, a registration that does not fit: said plainly, at ingest, in the log,
the summary and by ``lidarfield run``."""

from __future__ import annotations

import logging

import numpy as np
import pandas as pd
import pytest
import yaml

from lidarfield.commands.scans import run_pair
from lidarfield.io import read_scan, write_scan
from lidarfield.poses import pose_from_xyzrpy
from lidarfield.scan import Scan
from lidarfield.sensors.fit import ELEVATION_TOLERANCE_DEG, fit_warning, sensor_fit
from lidarfield.sensors.models import PRESETS, SensorModel
from lidarfield.simulation.raycast import simulate_scan
from lidarfield.simulation.scene import load_scene

VLP16 = PRESETS["vlp16"]  # -15..15 deg, 0.5..100 m


def _at(elevation_deg, range_m) -> np.ndarray:
    """Points at the given elevations and ranges (azimuth spread over the circle)."""
    elevation, distance = np.radians(np.asarray(elevation_deg, float)), np.asarray(range_m, float)
    azimuth = np.linspace(0, 2 * np.pi, len(distance), endpoint=False)
    horizontal = distance * np.cos(elevation)
    return np.column_stack([horizontal * np.cos(azimuth), horizontal * np.sin(azimuth), distance * np.sin(elevation)])


def test_shares_outside_the_limits_are_counted_beyond_the_tolerance():
    inside = [-15.0, 15.0, 15.0 + 0.9 * ELEVATION_TOLERANCE_DEG, 0.0] * 20  # 80 points, the third within tolerance
    elevations = [30.0] * 15 + [-40.0] * 5 + inside  # 20 of 100 outside
    ranges = [150.0] * 6 + [10.0] * 90 + [0.2] * 4  # 10 outside: the 6 far ones also in elevation
    fit = sensor_fit(_at(elevations, ranges), VLP16)
    assert fit["outside_elevation"] == pytest.approx(0.20)
    assert fit["outside_range"] == pytest.approx(0.10)
    assert fit["outside"] == pytest.approx(0.24)  # 20 + 4 (the 150 m ones are among the 20)
    assert fit["elevation_deg"] == pytest.approx([-40.0, 30.0]) and fit["model_elevation_deg"] == [-15.0, 15.0]
    assert fit["range_m"] == pytest.approx([0.2, 150.0]) and fit["model_range_m"] == [0.5, 100.0]
    warning = fit_warning(fit, "a.bin")
    assert warning.startswith("a.bin: 24.0% of the points do not fit sensor model 'vlp16': ")
    assert "20.0% outside its elevation limits (data -40.0 to 30.0 deg, model -15.0 to 15.0 deg)" in warning
    assert "10.0% outside its range limits (data 0.20 to 150.0 m, model 0.5 to 100 m)" in warning


def test_one_percent_outside_is_not_reported_and_no_model_no_fit():
    fit = sensor_fit(_at([0.0] * 99 + [40.0], [10.0] * 100), VLP16)
    assert fit["outside"] == pytest.approx(0.01) and fit_warning(fit, "a") == ""
    assert sensor_fit(_at([0.0], [10.0]), None) is None and fit_warning(None, "a") == ""


def test_real_scans_against_their_sensors(expd, shared_data):
    # ExpD's VLP-16 scans fit: a few returns past the datasheet's 100 m only.
    fit = sensor_fit(read_scan(expd / "Cloud1_ExpD.txt").xyz, VLP16)
    assert 0 < fit["outside"] < 0.001 and fit_warning(fit, "Cloud1") == ""
    # The HDL-32E PCD holds 7% of its rows at (0, 0, 0): returns that did not come back.
    fit = sensor_fit(read_scan(shared_data / "hdl32-pair" / "251370668.pcd").xyz, PRESETS["hdl32"])
    assert 0.07 < fit["outside_range"] < 0.075 and fit["range_m"][0] == 0.0 and fit["outside_elevation"] == 0
    assert "outside its range limits (data 0.00 to" in fit_warning(fit, "251370668.pcd")


@pytest.fixture(scope="module")
def wide_scans(tmp_path_factory):
    """Two scans of a +-45 deg sensor written as KITTI .bin files, which carry no sensor model."""
    wide = SensorModel("wide-64", tuple(np.linspace(-45, 45, 64)), 1.0, 0.3, 100.0)
    folder = tmp_path_factory.mktemp("wide")
    paths = []
    for k, pose in enumerate(([0, 0, 3, 0, 0, 0], [1, 0, 3, 0, 0, 0.02]), start=1):
        scan = simulate_scan(load_scene("paper-intersection"), wide, pose_from_xyzrpy(pose))
        write_scan(Scan(scan.xyz), folder / f"wide{k}.bin")
        paths.append(folder / f"wide{k}.bin")
    return paths


def test_the_wrong_sensor_model_is_said_at_ingest_in_the_summary_and_by_run(wide_scans, tmp_path, caplog, capsys):
    from lidarfield.cli import main

    config = tmp_path / "study.yaml"
    config.write_text(yaml.safe_dump({"hypotheses": [{"field_of_view": {}}]}))
    with caplog.at_level(logging.WARNING):
        main(
            [
                "run",
                *map(str, wide_scans),
                "--config",
                str(config),
                "--sensor",
                "os1-128",
                "--out",
                str(tmp_path / "out"),
            ]
        )
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 2 and all("do not fit sensor model 'os1-128'" in w for w in warnings)
    summary = pd.read_parquet(tmp_path / "out" / "summary.parquet")
    # +-22.5 of +-45 deg: about half of each scan (the ground rings fill the low elevations).
    for k in (1, 2):
        assert (0.45 < summary[f"sensor_outside{k}"]).all() and (summary[f"sensor_outside{k}"] < 0.65).all()
    assert summary["sensor_warning"].str.contains("data -45.0 to 45.0 deg, model -22.5 to 22.5 deg").all()
    printed = capsys.readouterr().out
    assert "sensor model: scan 1: " in printed
    fov = summary.iloc[1]
    share = fov["removed1"] / (fov["removed1"] + fov["n1"])
    assert share > 0.5 and f"field_of_view removed {share:.0%} of cloud 1" in printed
    assert share == pytest.approx(summary.iloc[0]["sensor_outside1"], abs=0.02)


def test_a_pair_without_overlap_says_so_and_is_not_converged(tmp_path, capsys):
    for name, rows in (("one.txt", "1 0 0\n"), ("far.txt", "100 0 0\n101 0 0\n100 1 0\n")):
        (tmp_path / name).write_text(rows)
    config = tmp_path / "study.yaml"
    # No suggestions: the default candidates include field_of_view, which needs a sensor model.
    study = {"grid": {"min_points": 1}, "hypotheses": [{"crop": {"max_range_m": 50.0}}], "suggest": []}
    config.write_text(yaml.safe_dump(study))
    rows = run_pair(tmp_path / "one.txt", tmp_path / "far.txt", config, tmp_path / "out")
    assert [r["registration_converged"] for r in rows] == [False, False]
    assert rows[0]["registration_fitness"] == 0.0 and "poor fitness 0.000" in rows[0]["registration_warning"]
    assert rows[0]["voxels_valid"] == 1 and rows[0]["field_warning"] == ""
    assert rows[1]["voxels_valid"] == 0 and rows[1]["max_magnitude"] is None  # NaN, null in JSON
    assert rows[1]["field_warning"] == "no valid voxel: cloud 2 has no point left"
    summary = pd.read_parquet(tmp_path / "out" / "summary.parquet")
    assert list(summary["field_warning"]) == ["", "no valid voxel: cloud 2 has no point left"]
    # The clouds 100 m apart share no voxel holding min_points of both.
    config.write_text(yaml.safe_dump({"grid": {"min_points": 2}, "suggest": []}))
    (row,) = run_pair(tmp_path / "far.txt", tmp_path / "one.txt", config, tmp_path / "out2")
    assert row["field_warning"].startswith(
        "no valid voxel: no voxel of the grid holds min_points of both clouds (3 and 1"
    )
