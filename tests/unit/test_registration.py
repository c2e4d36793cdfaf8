"""Registration on real scans (the Ouster OS1-128 frames with reference poses, the ExpD pair, the
VLP-16 capture from one place) and on a simulated room with its truth."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import ROOT
from lidarfield.io import read_scan
from lidarfield.io.pose_files import read_kitti_poses, read_pose
from lidarfield.poses import apply_pose, pose_error, pose_from_xyzrpy, relative_pose
from lidarfield.registration import (
    read_xyz_rows,
    register_pair,
    translation_from_aligned_copy,
    translation_offsets,
)
from lidarfield.scan import Scan
from lidarfield.sensors.models import PRESETS
from lidarfield.simulation.raycast import simulate_scan
from lidarfield.simulation.scene import scene_from_dict

COMMITTED_T_1_10 = ROOT / "config" / "expd-T_1_10.txt"
OUSTER_POSES = "OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt"


@pytest.fixture(scope="module")
def ouster_frames(shared_data):
    """The three frames with their reference world-from-sensor poses."""
    folder = shared_data / "ouster-os1-128"
    poses = read_kitti_poses(folder / OUSTER_POSES)
    scans = [read_scan(folder / f"lb_n3_scan{k}_xyz_refl_float32.bin") for k in range(3)]
    for scan, pose in zip(scans, poses):
        scan.pose = pose
    return scans


@pytest.fixture(scope="module")
def expd_scan_pair(expd):
    """ExpD's Cloud1 and Cloud10 as the text reader reads them (rows without a return dropped)."""
    return read_scan(expd / "Cloud1_ExpD.txt"), read_scan(expd / "Cloud10_ExpD.txt")


@pytest.fixture(scope="module")
def authors_T_1_10(expd):
    return translation_from_aligned_copy(
        read_xyz_rows(expd / "Cloud10_ExpD.txt"), read_xyz_rows(expd / "Cloud10Aligned_ExpD.txt")
    )


# The voxel is capped by an angle at the pair's median range (matching.voxel_size); a cap no
# range reaches asks for the fixed voxel_m (the 0.2 m that tilted the small-room pairs below).
FIXED_VOXEL = {"voxel_deg": 1e6}
# A 0.3 m voxel keeps each match under a second or two; the default 0.2 m gives the same errors
# within 1 cm (see the report).
FAST = {"voxel_m": 0.3, **FIXED_VOXEL}


@pytest.mark.parametrize(
    "method, frames",
    [(m, f) for m in ("icp", "gicp", "ndt") for f in ((0, 1), (1, 2))] + [("icp_point_to_plane", (0, 1))],
)
def test_ouster_scan_matching_from_identity_recovers_reference_pose(ouster_frames, method, frames):
    a, b = frames
    pair = register_pair(ouster_frames[a], ouster_frames[b], {"method": method, **FAST})
    reg = pair.registration
    reference = relative_pose(ouster_frames[a].pose, ouster_frames[b].pose)
    print(
        f"{method} frames {a}-{b}: {reg['translation_error_m'] * 100:.2f} cm, {reg['rotation_error_deg']:.3f} deg, "
        f"fitness {reg['fitness']:.3f}"
    )
    assert (reg["translation_error_m"], reg["rotation_error_deg"]) == pytest.approx(pose_error(pair.T_1_2, reference))
    assert reg["translation_error_m"] < 0.05
    assert reg["rotation_error_deg"] < 0.2
    # The identity guess is itself 25 cm off: the method moved to the answer.
    assert np.linalg.norm(reference[:3, 3]) > 0.2
    assert reg["converged"] is True and "warning" not in reg
    assert reg["fitness"] > 0.9
    np.testing.assert_allclose(pair.xyz2, apply_pose(pair.T_1_2, ouster_frames[b].xyz))


def test_truth_gives_the_exact_relative_pose(ouster_frames):
    pair = register_pair(ouster_frames[0], ouster_frames[1], "truth")
    expected = np.linalg.inv(ouster_frames[0].pose) @ ouster_frames[1].pose
    np.testing.assert_allclose(pair.T_1_2, expected, atol=1e-12)
    np.testing.assert_allclose(pair.origin2, expected[:3, 3], atol=1e-12)
    assert pair.registration["translation_error_m"] == pytest.approx(0, abs=1e-12)
    assert pair.registration["converged"] is True
    np.testing.assert_array_equal(pair.xyz1, ouster_frames[0].xyz)
    np.testing.assert_allclose(pair.xyz2, ouster_frames[1].xyz @ expected[:3, :3].T + expected[:3, 3])
    assert set(pair.attributes2) == set(ouster_frames[1].attributes)


@pytest.mark.parametrize("method", ["icp", "ndt"])
def test_guess_30_m_off_reports_not_converged(ouster_frames, method):
    settings = {"method": method, "guess": [30, 0, 0, 0, 0, 0], "voxel_m": 0.5, "max_iterations": 20, **FIXED_VOXEL}
    pair = register_pair(ouster_frames[0], ouster_frames[1], settings)
    reg = pair.registration
    print(f"{method} from 30 m off: fitness {reg['fitness']:.3f}, error {reg['translation_error_m']:.1f} m")
    assert reg["converged"] is False
    assert reg["fitness"] < reg["min_fitness"]
    assert "did not converge" in reg["warning"] and "poor fitness" in reg["warning"]
    assert reg["translation_error_m"] > 1.0


def test_unrelated_clouds_report_not_converged(ouster_frames, expd_scan_pair):
    pair = register_pair(
        expd_scan_pair[0], ouster_frames[0], {"method": "gicp", "voxel_m": 0.5, "max_iterations": 20, **FIXED_VOXEL}
    )
    assert pair.registration["converged"] is False
    assert pair.registration["fitness"] < 0.5
    assert "translation_error_m" not in pair.registration  # the ExpD scan has no pose


def test_expd_ndt_agrees_with_the_authors_translation(expd_scan_pair, authors_T_1_10):
    # The van drove about +3 m along y. Start 30 cm beyond that, so that an NDT that stops at
    # its guess could not pass.
    guess = [0, 3.3, 0, 0, 0, 0]
    pair = register_pair(*expd_scan_pair, {"method": "ndt", "guess": guess})
    reg = pair.registration
    difference = pair.T_1_2[:3, 3] - authors_T_1_10[:3, 3]
    print(
        f"NDT T_1_10 translation {pair.T_1_2[:3, 3]}, authors {authors_T_1_10[:3, 3]}, "
        f"difference {difference} = {np.linalg.norm(difference) * 100:.2f} cm; fitness {reg['fitness']:.3f}"
    )
    assert reg["converged"] is True
    assert np.linalg.norm(pair.T_1_2[:3, 3] - guess[:3]) > 0.2
    # Open3D's NDT, ICP and GICP land 2.7 to 7 cm from the authors' translation, mostly along
    # the direction of travel, which the parking lot constrains weakly: the 5 cm is not
    # met (see the report). The estimate fits scan 1 at least as tightly as the authors' does.
    assert np.linalg.norm(difference) < 0.08
    authors = register_pair(*expd_scan_pair, {"transform": str(COMMITTED_T_1_10)}).registration
    print(f"inlier RMSE: NDT {reg['inlier_rmse']:.4f} m, authors' translation {authors['inlier_rmse']:.4f} m")
    assert reg["inlier_rmse"] <= authors["inlier_rmse"]


def test_expd_wrong_direction_guess_is_a_poor_fit_not_a_crash(expd_scan_pair):
    pair = register_pair(*expd_scan_pair, {"method": "ndt", "guess": [0, -3, 0, 0, 0, 0]})
    assert pair.registration["converged"] is False
    assert pair.registration["fitness"] < 0.3


def test_ndt_that_never_leaves_its_guess_is_not_converged(expd_scan_pair):
    # 12.5 cm cells (the authors' MATLAB grid step) hold too few VLP-16 points: Open3D's NDT
    # returns the guess as it was, which here fits well; it must still not pass as converged.
    pair = register_pair(*expd_scan_pair, {"method": "ndt", "ndt_resolution_m": 0.125, "guess": [0, 3, 0, 0, 0, 0]})
    reg = pair.registration
    assert reg["fitness"] > reg["min_fitness"]
    assert reg["converged"] is False and "guess unchanged" in reg["warning"]
    np.testing.assert_array_equal(pair.T_1_2, reg["guess_T_1_2"])


def test_committed_expd_transform_matches_the_data(expd, authors_T_1_10):
    committed = read_pose(COMMITTED_T_1_10)
    np.testing.assert_allclose(committed, authors_T_1_10, rtol=0, atol=1e-9)
    offsets = translation_offsets(
        read_xyz_rows(expd / "Cloud10_ExpD.txt"), read_xyz_rows(expd / "Cloud10Aligned_ExpD.txt")
    )
    assert len(offsets) == 12683
    assert np.abs(offsets - committed[:3, 3]).max() < 1e-9  # a pure translation
    assert committed[:3, 3] == pytest.approx([-0.00128, 2.99632, 0.0], abs=1e-4)


def test_transform_file_registers_expd_like_the_aligned_copy(expd, expd_scan_pair):
    pair = register_pair(*expd_scan_pair, {"transform": str(COMMITTED_T_1_10)})
    aligned = read_scan(expd / "Cloud10Aligned_ExpD.txt")
    np.testing.assert_allclose(pair.xyz2, aligned.xyz, atol=1e-9)
    np.testing.assert_allclose(pair.origin2, read_pose(COMMITTED_T_1_10)[:3, 3])
    assert pair.registration["method"] == "transform"
    assert pair.registration["fitness"] > 0.6


@pytest.fixture(scope="module")
def vlp16_capture(shared_data):
    """Two consecutive rotations of the VLP-16 capture, taken from one place (ranges 0.6-1.8 m):
    the identity is their relative pose."""
    path = shared_data / "velodyne-pcap" / "sample_velodyne_vlp16_gps.pcap"
    if not path.is_file():
        pytest.skip(f"{path} not found")
    return [read_scan(f"{path}#{k}") for k in (0, 1)]


@pytest.mark.parametrize("method", ["gicp", "icp_point_to_plane"])
def test_pair_from_one_place_in_a_small_room_registers_to_the_identity(vlp16_capture, method):
    pair = register_pair(*vlp16_capture, {"method": method})
    fixed = register_pair(*vlp16_capture, {"method": method, **FIXED_VOXEL})
    (translation, rotation), (_, fixed_rotation) = (pose_error(p.T_1_2, np.eye(4)) for p in (pair, fixed))
    reg = pair.registration
    print(
        f"{method}: {rotation:.3f} deg, {translation * 1000:.2f} mm at {reg['voxel_used_m']:.3f} m voxels; "
        f"{fixed_rotation:.3f} deg at 0.2 m"
    )
    # Median range 1.3 m: 1 deg is 2.3 cm; 0.2 m voxels leave ~340 points and tilt it 0.3-0.4 deg.
    assert reg["voxel_used_m"] == pytest.approx(0.023, abs=0.002)
    assert fixed.registration["points_used"][0] < 400 and fixed_rotation > 0.25
    assert rotation < 0.03 and translation < 0.002
    assert reg["converged"] is True


# A room 4 x 3 m and 2.5 m high with a table and a cabinet (median range 1.9 m from its middle).
ROOM = {
    "objects": [
        {"kind": "plane", "size": [4, 3]},
        {"kind": "box", "size": [4, 3, 0.1], "center": [0, 0, 2.45]},
        {"kind": "box", "size": [0.1, 3, 2.4], "center": [2.05, 0, 1.2]},
        {"kind": "box", "size": [0.1, 3, 2.4], "center": [-2.05, 0, 1.2]},
        {"kind": "box", "size": [4, 0.1, 2.4], "center": [0, 1.55, 1.2]},
        {"kind": "box", "size": [4, 0.1, 2.4], "center": [0, -1.55, 1.2]},
        {"kind": "box", "size": [1.2, 0.8, 0.75], "center": [1.0, 0.8, 0.375]},
        {"kind": "box", "size": [0.5, 1.0, 1.8], "center": [-1.6, -0.9, 0.9]},
    ]
}


@pytest.mark.parametrize("preset", ["vlp16", "hdl32"])
def test_simulated_room_registers_to_its_truth(preset):
    scene, sensor = scene_from_dict(ROOM), PRESETS[preset]
    poses = [pose_from_xyzrpy([0.1, 0, 0.9, 0, 0, 0]), pose_from_xyzrpy([0.2, 0.05, 0.9, 0, 0, np.radians(3)])]
    scans = [
        Scan(simulate_scan(scene, sensor, pose, seed=k, range_noise_m=0.01).xyz, sensor=sensor, pose=pose)
        for k, pose in enumerate(poses)
    ]
    pair, fixed = (register_pair(*scans, {"method": "gicp", **extra}) for extra in ({}, FIXED_VOXEL))
    reg = pair.registration
    print(
        f"{preset}: {reg['rotation_error_deg']:.3f} deg, {reg['translation_error_m'] * 1000:.2f} mm at "
        f"{reg['voxel_used_m']:.3f} m voxels; {fixed.registration['rotation_error_deg']:.3f} deg at 0.2 m"
    )
    # From the identity guess (3 deg and 11 cm off); 0.2 m voxels: 0.18-0.20 deg off.
    assert reg["rotation_error_deg"] < 0.04 and reg["translation_error_m"] < 0.002
    assert fixed.registration["rotation_error_deg"] > 0.1
