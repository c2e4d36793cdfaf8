"""A simulated pair registered by its truth has an exact pose (``RegisteredPair.pose_exact``), and
its default suggestions do not fit the pose with a correction: the pose's part of such a fit is
noise alone there. Anything else that places sensor 2 (a scan matching, a pose moved after, real
scans' recorded poses) keeps both variants."""

from __future__ import annotations

import dataclasses

import pytest

from lidarfield.analysis.suggest import candidate_steps, suggestions
from lidarfield.field.grid import field_settings_from_config
from lidarfield.pair import read_pair, write_pair
from lidarfield.poses import pose_from_xyzrpy
from lidarfield.registration import register_pair
from lidarfield.sensors.models import PRESETS
from lidarfield.simulation.raycast import simulate_scan
from lidarfield.simulation.scene import load_scene

GRID = {"kind": "spherical", "azimuth_bins": 36, "elevation_deg": [-22.5, 15], "elevation_bins": 5}
WITH_POSE = {"range_calibration": {"with_pose": True}}


@pytest.fixture(scope="module")
def scans():
    scene = load_scene("paper-intersection")
    return [
        simulate_scan(scene, PRESETS["vlp16"], pose_from_xyzrpy(pose), seed=k, range_noise_m=0.01)
        for k, pose in enumerate(([0, 0, 2, 0, 0, 0], [1.0, 0.5, 2, 0, 0, 0.05]))
    ]


def moved(pair, metres: float):
    """The pair with sensor 2 put ``metres`` off in x (as a misregistration is)."""
    shift = pose_from_xyzrpy([metres, 0, 0, 0, 0, 0])
    return dataclasses.replace(pair, xyz2=pair.xyz2 + shift[:3, 3], T_1_2=shift @ pair.T_1_2)


def test_simulated_scans_registered_by_their_truth_have_an_exact_pose_and_keep_it_on_disk(scans, tmp_path):
    pair = register_pair(*scans, "truth")
    assert all(scan.simulated for scan in scans)
    assert pair.pose_exact
    write_pair(tmp_path / "registered.parquet", pair)
    assert read_pair(tmp_path / "registered.parquet")[0].pose_exact
    assert not moved(pair, 0.001).pose_exact


def test_a_scan_matching_or_recorded_poses_are_not_exact(scans):
    assert not register_pair(*scans, {"method": "icp", "guess": "truth"}).pose_exact
    recorded = [dataclasses.replace(scan, source="scan.pcd") for scan in scans]  # real scans with poses
    assert not any(scan.simulated for scan in recorded)
    assert not register_pair(*recorded, "truth").pose_exact


def fitted_with_pose(table) -> list[str]:
    return [h for h, p in zip(table["hypothesis"], table["params"]) if '"with_pose":true' in p]


def test_the_default_suggestions_fit_the_pose_only_where_it_is_not_exact(scans):
    pair = register_pair(*scans, "truth")
    settings = field_settings_from_config(GRID)
    defaults = candidate_steps(None, [], ".", GRID)
    assert any(params.get("with_pose") for spec in defaults for params in spec.values())
    exact = suggestions(pair, settings, defaults, ".", GRID, defaults=True)
    assert fitted_with_pose(exact) == []
    assert "range_calibration" in exact["hypothesis"] and "realign" in exact["hypothesis"]
    assert fitted_with_pose(suggestions(moved(pair, 0.05), settings, defaults, ".", GRID, defaults=True))
    # asked for by name (a config's suggest list), a fit with the pose runs on an exact pose too
    asked = suggestions(pair, settings, candidate_steps([WITH_POSE], [], ".", GRID), ".", GRID)
    assert fitted_with_pose(asked) == ["range_calibration"]
