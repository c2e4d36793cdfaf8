"""Registration settings, bad input, analytic recoveries on synthetic clouds, the aligned-copy
translation and the ``register`` command."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import ROOT
from lidarfield.cli import main
from lidarfield.errors import ConfigError, InputError, RegistrationError
from lidarfield.io.pose_files import read_pose
from lidarfield.pair import read_pair
from lidarfield.poses import pose_error, pose_from_xyzrpy
from lidarfield.registration import (
    METHODS,
    parse_settings,
    register_pair,
    translation_from_aligned_copy,
    write_transform,
)
from lidarfield.scan import Scan

TRUE_T = pose_from_xyzrpy([0.3, -0.2, 0.05, 0.0, 0.0, np.radians(2.0)])


def _box_room(rng, n=20000) -> np.ndarray:
    """Points on the floor, walls and two boxes of a 20 x 16 m yard: every direction constrained."""
    faces = [
        lambda u, v: np.column_stack([u * 20 - 10, v * 16 - 8, np.full_like(u, -1.8)]),  # ground
        lambda u, v: np.column_stack([np.full_like(u, 10), v * 16 - 8, u * 4 - 1.8]),  # walls
        lambda u, v: np.column_stack([np.full_like(u, -10), v * 16 - 8, u * 4 - 1.8]),
        lambda u, v: np.column_stack([u * 20 - 10, np.full_like(u, 8), v * 4 - 1.8]),
        lambda u, v: np.column_stack([u * 20 - 10, np.full_like(u, -8), v * 4 - 1.8]),
        lambda u, v: np.column_stack([np.full_like(u, 3), v * 2 + 2, u * 2 - 1.8]),  # box sides
        lambda u, v: np.column_stack([u * 3 + 3, np.full_like(u, 2), v * 2 - 1.8]),
        lambda u, v: np.column_stack([np.full_like(u, -4), v * 3 - 5, u * 1.5 - 1.8]),
        lambda u, v: np.column_stack([u * 2 - 6, np.full_like(u, -2), v * 1.5 - 1.8]),
    ]
    per_face = n // len(faces)
    return np.vstack([f(rng.random(per_face), rng.random(per_face)) for f in faces])


@pytest.fixture(scope="module")
def synthetic_pair():
    """Scan 2 is the same yard seen from sensor 2 at TRUE_T in frame 1 (fresh samples, 1 cm noise)."""
    rng = np.random.default_rng(7)
    world1 = _box_room(rng)
    world2 = _box_room(rng)
    inverse = np.linalg.inv(TRUE_T)
    xyz2 = world2 @ inverse[:3, :3].T + inverse[:3, 3] + rng.normal(0, 0.01, world2.shape)
    pose1 = pose_from_xyzrpy([100, 50, 2, 0, 0, 0.3])
    scan1 = Scan(world1 + rng.normal(0, 0.01, world1.shape), {"intensity": rng.random(len(world1))}, pose=pose1)
    scan2 = Scan(xyz2, {"intensity": rng.random(len(xyz2))}, pose=pose1 @ TRUE_T)
    return scan1, scan2


@pytest.mark.parametrize("method", ["icp", "icp_point_to_plane", "gicp", "ndt"])
def test_synthetic_yard_recovers_known_pose(synthetic_pair, method):
    pair = register_pair(*synthetic_pair, {"method": method, "voxel_m": 0.1})
    translation, rotation = pose_error(pair.T_1_2, TRUE_T)
    assert translation < 0.01 and rotation < 0.1  # from 36 cm and 2 deg away
    assert pair.registration["translation_error_m"] == pytest.approx(translation)
    assert pair.registration["converged"] is True
    np.testing.assert_array_equal(pair.attributes2["intensity"], synthetic_pair[1].attributes["intensity"])


def test_reference_guess_and_file_guess_start_where_told(synthetic_pair, tmp_path):
    guess_file = tmp_path / "guess.txt"
    write_transform(guess_file, TRUE_T)
    for guess in ("truth", str(guess_file), TRUE_T.ravel().tolist()):
        reg = register_pair(*synthetic_pair, {"method": "icp", "guess": guess, "max_iterations": 1}).registration
        np.testing.assert_allclose(reg["guess_T_1_2"], TRUE_T, atol=1e-12)


def test_open3d_refusal_is_reported_not_raised(synthetic_pair):
    # Cells of 1 cm hold fewer than 6 points each: Open3D's NDT refuses to run.
    pair = register_pair(*synthetic_pair, {"method": "ndt", "ndt_resolution_m": 0.01})
    reg = pair.registration
    assert reg["converged"] is False
    assert "NDT voxels" in reg["failure"] and "refused the input" in reg["warning"]
    np.testing.assert_array_equal(pair.T_1_2, np.eye(4))


def test_identity_on_a_displaced_pair_warns_of_poor_fitness(synthetic_pair):
    scan1, scan2 = synthetic_pair
    far = Scan(scan2.xyz + [0, 0, 5.0])
    reg = register_pair(scan1, far, "identity").registration
    # Nothing was iterated, but a transform that fits this poorly is not a registration.
    assert reg["converged"] is False
    assert reg["fitness"] < 0.1 and "poor fitness" in reg["warning"]
    assert register_pair(scan1, scan2, "identity").registration["converged"] is True


def test_transform_file_sets_T_1_2(synthetic_pair, tmp_path):
    path = tmp_path / "T.txt"
    write_transform(path, TRUE_T, "pose of sensor 2 in frame 1")
    pair = register_pair(*synthetic_pair, {"transform": "T.txt"}, base_dir=tmp_path)
    np.testing.assert_allclose(pair.T_1_2, TRUE_T, atol=1e-15)
    assert pair.registration["transform_file"] == str(path)
    assert pair.registration["fitness"] > 0.9


def test_truth_without_poses_names_the_scan(synthetic_pair):
    scan1, scan2 = synthetic_pair
    bare = Scan(scan2.xyz, source="drive/scan2.pcd")
    with pytest.raises(RegistrationError, match="drive/scan2.pcd"):
        register_pair(scan1, bare, "truth")
    with pytest.raises(RegistrationError, match="guess 'truth'"):
        register_pair(scan1, bare, {"method": "icp", "guess": "truth"})


def test_missing_and_malformed_transform_files_name_the_file(synthetic_pair, tmp_path):
    with pytest.raises(InputError, match="nothere.txt: pose file not found"):
        register_pair(*synthetic_pair, {"transform": str(tmp_path / "nothere.txt")})
    bad = tmp_path / "bad.txt"
    bad.write_text("1 0 0 0\n0 1 0 zero\n")
    with pytest.raises(InputError, match="bad.txt: line 2 is not numeric"):
        register_pair(*synthetic_pair, {"transform": str(bad)})
    short = tmp_path / "short.txt"
    short.write_text("1 2 3 4 5\n")
    with pytest.raises(InputError, match="short.txt: not a pose"):
        register_pair(*synthetic_pair, {"method": "gicp", "guess": str(short)})


@pytest.mark.parametrize(
    "settings, message",
    [
        ("lsq", "unknown method 'lsq'; methods: " + ", ".join(METHODS)),
        ({"method": "ndt", "voxel_size": 1}, r"unknown setting\(s\) \['voxel_size'\]"),
        ({"method": "icp", "guess": [1, 2, 3, 4, 5]}, "register.guess: .*5 numbers"),
        ({"method": "icp", "voxel_m": -1}, "register.voxel_m"),
        ({"method": "gicp", "voxel_deg": 0}, "register.voxel_deg: expected a positive number"),
        ({"method": "ndt", "ndt_min_points_per_voxel": 3}, "at least|>= 4"),
        ({"method": "icp", "min_fitness": 2}, "min_fitness"),
        ({"transform": "T.txt", "guess": [0] * 6}, "'transform' takes no other settings"),
        ({"method": "identity", "voxel_m": 0.2}, "unknown setting"),
        (3, "expected a method name or a mapping"),
    ],
)
def test_bad_settings_are_config_errors(settings, message):
    with pytest.raises(ConfigError, match=message):
        parse_settings(settings)


def test_settings_defaults_and_forms():
    s = parse_settings({"method": "ndt", "ndt_resolution_m": 1.5, "guess": [0, 3, 0, 0, 0, 0]})
    assert s.params["ndt_resolution_m"] == [1.5] and s.params["voxel_m"] == 0.2
    np.testing.assert_allclose(s.guess[:3, 3], [0, 3, 0])
    assert parse_settings("truth").method == "truth"
    assert parse_settings({"method": "icp", "guess": "reference"}).guess == "truth"


# --- the translation of an aligned copy ------------------------------------------------------
def _organised(rng, n=400) -> np.ndarray:
    rows = rng.normal(0, 10, (n, 3))
    rows[rng.random(n) < 0.3] = np.nan  # no-return rows
    return rows


def test_translation_from_aligned_copy_recovers_the_shift():
    rng = np.random.default_rng(3)
    original = _organised(rng)
    shift = np.array([-0.4, 2.9, 0.01])
    T = translation_from_aligned_copy(original, original + shift)
    np.testing.assert_allclose(T[:3, 3], shift, atol=1e-12)
    np.testing.assert_array_equal(T[:3, :3], np.eye(3))


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda a: a @ pose_from_xyzrpy([0, 0, 0, 0, 0, 0.01])[:3, :3].T, "not a pure translation"),
        (lambda a: a[:-1], "400 rows vs 399"),
        (lambda a: np.where(np.isnan(a), 0.0, a), "NaN in the other"),
    ],
)
def test_aligned_copy_that_is_not_a_translation_is_refused(change, message):
    original = _organised(np.random.default_rng(4))
    with pytest.raises(RegistrationError, match=message):
        translation_from_aligned_copy(original, change(original + [0, 3, 0]))


# --- the command ---------------------------------------------------------------------------------
def test_cli_from_aligned_writes_the_committed_transform(expd, tmp_path, capsys):
    out = tmp_path / "T.txt"
    code = main(
        [
            "register",
            "--from-aligned",
            str(expd / "Cloud10_ExpD.txt"),
            str(expd / "Cloud10Aligned_ExpD.txt"),
            "--out",
            str(out),
        ]
    )
    assert code == 0
    assert "spread" in capsys.readouterr().out
    committed = read_pose(ROOT / "config" / "expd-T_1_10.txt")
    np.testing.assert_allclose(read_pose(out), committed, atol=1e-12)


def test_cli_registers_with_reference_poses(shared_data, tmp_path, capsys):
    folder = shared_data / "ouster-os1-128"
    poses = folder / "OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt"
    out = tmp_path / "registered.parquet"
    args = [
        "register",
        str(folder / "lb_n3_scan0_xyz_refl_float32.bin"),
        str(folder / "lb_n3_scan1_xyz_refl_float32.bin"),
        "--out",
        str(out),
        "--method",
        "truth",
        "--pose1",
        f"{poses}#0",
        "--pose2",
        f"{poses}#1",
    ]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "method truth: converged True" in printed and "against the reference poses: 0.0000 m" in printed
    pair, meta = read_pair(out)
    assert meta["registration"]["method"] == "truth"
    np.testing.assert_allclose(pair.origin2, [0.2454105, -0.0068616, 0.0084499], atol=1e-6)


def test_cli_bad_transform_file_exits_2_without_output(shared_data, tmp_path, capsys):
    folder = shared_data / "ouster-os1-128"
    out = tmp_path / "registered.parquet"
    scans = [str(folder / f"lb_n3_scan{k}_xyz_refl_float32.bin") for k in (0, 1)]
    assert main(["register", *scans, "--out", str(out), "--transform", str(tmp_path / "missing.txt")]) == 2
    assert "missing.txt: pose file not found" in capsys.readouterr().err
    assert not out.exists()
