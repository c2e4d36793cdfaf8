"""Poses: files, KITTI lines, x-y-z-roll-pitch-yaw, and the algebra on them."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lidarfield.errors import InputError
from lidarfield.io.pose_files import read_kitti_poses, read_pose, write_kitti_poses
from lidarfield.poses import (
    apply_pose,
    invert_pose,
    parse_pose_arg,
    pose_error,
    pose_from_xyzrpy,
    relative_pose,
    rotation_angle,
    xyzrpy_from_pose,
)

OUSTER_POSES = "ouster-os1-128/OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt"


def _random_poses(n, seed=3):
    rng = np.random.default_rng(seed)
    values = np.column_stack(
        [rng.uniform(-50, 50, (n, 3)), rng.uniform(-3, 3, n), rng.uniform(-1.5, 1.5, n), rng.uniform(-3, 3, n)]
    )
    return values, [pose_from_xyzrpy(v) for v in values]


def test_xyzrpy_round_trip():
    values, poses = _random_poses(50)
    for v, T in zip(values, poses):
        np.testing.assert_allclose(xyzrpy_from_pose(T), v, atol=1e-12)
        np.testing.assert_allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-12)


def test_rotation_order_is_z_y_x():
    def axis_rotation(axis, angle):
        c, s = np.cos(angle), np.sin(angle)
        i, j = [k for k in range(3) if k != axis]
        R = np.eye(3)
        R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
        return R if axis != 1 else R.T  # about y, the sine signs swap

    roll, pitch, yaw = 0.3, -0.2, 1.1
    expected = axis_rotation(2, yaw) @ axis_rotation(1, pitch) @ axis_rotation(0, roll)
    np.testing.assert_allclose(pose_from_xyzrpy([0, 0, 0, roll, pitch, yaw])[:3, :3], expected, atol=1e-15)
    # yaw 90 deg turns +x into +y
    np.testing.assert_allclose(
        apply_pose(pose_from_xyzrpy([1, 2, 3, 0, 0, np.pi / 2]), [[1, 0, 0]]), [[1, 3, 3]], atol=1e-15
    )


def test_kitti_file_round_trip_and_line_selection(tmp_path):
    _, poses = _random_poses(4)
    path = tmp_path / "poses.txt"
    write_kitti_poses(path, poses)
    np.testing.assert_allclose(read_kitti_poses(path), poses, atol=0)
    np.testing.assert_allclose(read_pose(path, line=2), poses[2], atol=0)
    with pytest.raises(InputError, match="line 4 requested .* 4 KITTI"):
        read_pose(path, line=4)


def test_matrix_files(tmp_path, shared_data):
    T = read_pose(shared_data / "hdl32-pair" / "relative.txt")
    np.testing.assert_allclose(T[:3, 3], [0.485657, 0.10642, -0.0131581])
    assert rotation_angle(T) == pytest.approx(np.radians(0.71), abs=np.radians(0.02))
    three_by_four = tmp_path / "t.txt"
    three_by_four.write_text("\n".join(" ".join(map(str, row)) for row in T[:3]))
    np.testing.assert_array_equal(read_pose(three_by_four), T)
    one_line = tmp_path / "o.txt"
    one_line.write_text(",".join(map(str, T.ravel())))
    np.testing.assert_array_equal(read_pose(one_line), T)


def test_ouster_reference_poses(shared_data):
    poses = read_kitti_poses(shared_data / OUSTER_POSES, expected=3)
    assert poses.shape == (3, 4, 4)
    np.testing.assert_array_equal(poses[0], np.eye(4))
    for a, b in zip(poses[:-1], poses[1:]):
        step, angle = pose_error(relative_pose(a, b), np.eye(4))
        assert 0.2 < step < 0.3 and angle < 0.2
    np.testing.assert_allclose(relative_pose(poses[0], poses[1])[:3, 3], [0.2454, -0.0069, 0.0084], atol=1e-4)


def test_relative_pose_and_inverse():
    _, (A, B) = _random_poses(2)
    T_a_b = relative_pose(A, B)
    np.testing.assert_allclose(A @ T_a_b, B, atol=1e-12)
    np.testing.assert_allclose(invert_pose(A) @ A, np.eye(4), atol=1e-12)
    points = np.random.default_rng(0).normal(size=(20, 3))
    np.testing.assert_allclose(apply_pose(invert_pose(A), apply_pose(A, points)), points, atol=1e-12)


def test_pose_error():
    T_ref = pose_from_xyzrpy([1, 2, 3, 0.1, 0.2, 0.3])
    delta = pose_from_xyzrpy([0.03, -0.04, 0, 0, 0, np.radians(0.5)])
    translation, rotation = pose_error(T_ref @ delta, T_ref)
    assert translation == pytest.approx(0.05, abs=1e-12)
    assert rotation == pytest.approx(0.5, abs=1e-9)
    assert rotation_angle(pose_from_xyzrpy([0, 0, 0, 1e-7, 0, 0])) == pytest.approx(1e-7, rel=1e-6)


@pytest.mark.parametrize(
    "text, expected",
    [
        ("1,1,3,0,0,0.05", pose_from_xyzrpy([1, 1, 3, 0, 0, 0.05])),
        ("1 0 0 2 0 1 0 3 0 0 1 4", pose_from_xyzrpy([2, 3, 4, 0, 0, 0])),
        (",".join(map(str, np.eye(4).ravel())), np.eye(4)),
    ],
)
def test_parse_pose_arg(text, expected):
    np.testing.assert_allclose(parse_pose_arg(text), expected, atol=1e-15)


@pytest.mark.parametrize(
    "text, words",
    [
        ("1,2,3,4,5", "5 numbers"),
        ("1,2,x,0,0,0", "not a list of numbers"),
        (",".join(["2"] * 12), "not a rotation"),
        ("nan,0,3,0,0,0", r"NaN or infinite value\(s\) in the translation$"),
        ("0,0,3,inf,0,0", r"NaN or infinite value\(s\) in the rotation$"),
    ],
)
def test_parse_pose_arg_errors(text, words):
    with pytest.raises(InputError, match=words):
        parse_pose_arg(text)


@pytest.mark.parametrize(
    "content, words",
    [
        ("1 0 0\n0 1 0\n0 0 1\n", "3 row"),
        ("1 2 3 4 5\n", "1 row"),
        ("1 0 0 0\n0 1 zero 0\n0 0 1 0\n0 0 0 1\n", "line 2 is not numeric"),
        ("", "empty pose file"),
        ("1 0 0 0\n0 1 0 0\n0 0 1 0\n1 1 0 1\n", "bottom row"),
        ("2 0 0 0\n0 1 0 0\n0 0 1 0\n", "not a rotation"),
        ("1 0 0 nan\n0 1 0 0\n0 0 1 0\n", r"NaN or infinite value\(s\) in the translation$"),
        ("1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 inf 1\n", r"in the bottom row$"),
        ("nan 0 0 0\n0 1 0 0\n0 0 1 inf\n", r"in the rotation and the translation$"),
    ],
)
def test_bad_pose_files(tmp_path, content, words):
    path = tmp_path / "pose.txt"
    path.write_text(content)
    with pytest.raises(InputError, match=words) as caught:
        read_pose(path)
    assert str(path) in str(caught.value)


def test_missing_pose_file(tmp_path):
    with pytest.raises(InputError, match="pose file not found"):
        read_pose(tmp_path / "none.txt")


def test_kitti_file_shorter_than_the_sequence(shared_data):
    with pytest.raises(InputError, match="holds 3 pose line.* for 5 scans") as caught:
        read_kitti_poses(shared_data / OUSTER_POSES, expected=5)
    assert OUSTER_POSES.split("/")[1] in str(caught.value)


def test_kitti_line_of_wrong_length(tmp_path):
    path = tmp_path / "p.txt"
    path.write_text(" ".join(["0"] * 12) + "\n1 2 3\n")
    with pytest.raises(InputError, match="line 2 has 3 numbers, expected 12"):
        read_kitti_poses(path)


def test_interpolate_pose_linear_translation_slerp_rotation():
    from lidarfield.poses import interpolate_pose, rotation_angle

    stamps = np.array([10.0, 10.4, 11.0])
    poses = np.stack(
        [pose_from_xyzrpy(p) for p in ([0, 0, 0, 0, 0, 0], [4, -2, 1, 0.2, 0, 0.8], [4, -2, 1, 0.2, 0, 0.8])]
    )
    quarter = interpolate_pose(stamps, poses, 10.1)
    np.testing.assert_allclose(quarter[:3, 3], [1.0, -0.5, 0.25])
    # Slerp: a quarter of the way turns a quarter of the angle, about the same axis.
    assert rotation_angle(quarter) == pytest.approx(rotation_angle(poses[1]) / 4)
    assert rotation_angle(relative_pose(quarter, poses[1])) == pytest.approx(3 * rotation_angle(poses[1]) / 4)
    np.testing.assert_array_equal(interpolate_pose(stamps, poses, 10.4), poses[1])
    np.testing.assert_array_equal(interpolate_pose(stamps, poses, 11.0), poses[2])
    assert interpolate_pose(stamps, poses, 9.999) is None and interpolate_pose(stamps, poses, 11.001) is None


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_apply_pose_matches_homogeneous_coordinates(dtype):
    rng = np.random.default_rng(7)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0.3, -0.2, 1.1]).as_matrix()
    T[:3, 3] = [5.0, -2.0, 0.5]
    xyz = rng.normal(scale=30, size=(1000, 3)).astype(dtype)
    reference = (np.column_stack([xyz.astype(np.float64), np.ones(len(xyz))]) @ T.T)[:, :3]
    out = apply_pose(T, xyz)
    assert out.dtype == np.float64 and out.shape == (1000, 3)
    np.testing.assert_allclose(out, reference, rtol=0, atol=1e-12)


def test_quaternions_and_rotation_vectors_match_scipy():
    """The one quaternion and rotation-vector conversion (bags, Argoverse 2, nuScenes, the
    rigid fit) against SciPy's."""
    from scipy.spatial.transform import Rotation

    from lidarfield.poses import poses_from_quaternions, rotation_from_vector, skew

    rng = np.random.default_rng(3)
    q = rng.normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    t = rng.normal(size=(50, 3))
    poses = poses_from_quaternions(q, t)
    expected = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()  # SciPy: scalar last
    assert np.abs(poses[:, :3, :3] - expected).max() < 1e-12
    assert np.array_equal(poses[:, :3, 3], t) and (poses[:, 3] == [0, 0, 0, 1]).all()
    for omega in (rng.normal(size=3), np.array([1e-9, 0.0, 0.0]), np.zeros(3)):
        assert np.abs(rotation_from_vector(omega) - Rotation.from_rotvec(omega).as_matrix()).max() < 1e-12
    u, v = rng.normal(size=3), rng.normal(size=3)
    assert np.allclose(skew(u) @ v, np.cross(u, v))


def test_velocities_from_neighbours_on_a_turning_drive():
    """The default simulated drive (a 5.5 m arc at 5 m/s, 5 scans a second): each scan's velocity
    in its own frame from its neighbours' poses is the drive's, to the chord's first order (0.6%
    over the two frames' 33 deg), its yaw rate the arc's; at the ends, from the pose itself."""
    from lidarfield.poses import velocities_from_neighbours
    from lidarfield.simulation.trajectory import PAPER_TURN, paper_turn_trajectory

    frames = paper_turn_trajectory(6)
    stamps = [k / PAPER_TURN["rate_hz"] for k in range(len(frames))]
    found = velocities_from_neighbours(stamps, [f.pose for f in frames])
    for frame, (v, w) in zip(frames, found):
        expected = frame.pose[:3, :3].T @ np.asarray(frame.linear_velocity_mps)
        assert np.linalg.norm(v - expected) < 0.01 * 5.0 and abs(v[1]) < 0.01
        assert np.allclose(w, frame.angular_velocity_rps, atol=1e-9)
    assert velocities_from_neighbours([0.0, None], [frames[0].pose, frames[1].pose]) == [None, None]
