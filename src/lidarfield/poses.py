"""Rigid poses as 4x4 homogeneous matrices: x-y-z-roll-pitch-yaw, command-line strings, algebra
(pose files: :mod:`lidarfield.io.pose_files`).

Conventions: ``T_a_b`` maps points from frame b to frame a (``x_a = T_a_b @ x_b``), so a
world-from-sensor pose is ``T_w_s``. Angles are radians with R = Rz(yaw) Ry(pitch) Rx(roll).
"""

from __future__ import annotations

import re

import numpy as np

from .errors import InputError

# A rotation block farther than this from orthonormal is not a rigid pose (KITTI files
# print 9 to 19 significant digits, so real poses are orthonormal to ~1e-6).
_ORTHONORMAL_TOLERANCE = 1e-3
NUMBER_SEPARATORS = re.compile(r"[\s,;]+")


def pose_from_xyzrpy(values) -> np.ndarray:
    """4x4 pose from (x, y, z, roll, pitch, yaw): metres and radians, R = Rz(yaw) Ry(pitch) Rx(roll)."""
    x, y, z, roll, pitch, yaw = np.asarray(values, dtype=np.float64).reshape(6)
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    T = np.eye(4)
    T[:3, :3] = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    T[:3, 3] = x, y, z
    return T


def xyzrpy_from_pose(T: np.ndarray) -> np.ndarray:
    """(x, y, z, roll, pitch, yaw) of a pose; pitch in [-pi/2, pi/2] (the inverse of pose_from_xyzrpy)."""
    T = np.asarray(T, dtype=np.float64)
    R = T[:3, :3]
    pitch = np.arctan2(-R[2, 0], np.hypot(R[0, 0], R[1, 0]))
    roll = np.arctan2(R[2, 1], R[2, 2])
    yaw = np.arctan2(R[1, 0], R[0, 0])
    return np.array([*T[:3, 3], roll, pitch, yaw])


def parse_pose_arg(text: str) -> np.ndarray:
    """A pose from a command-line string of numbers separated by commas or spaces:
    6 = x,y,z,roll,pitch,yaw (m, rad); 12 = KITTI 3x4 row-major; 16 = 4x4 row-major."""
    try:
        numbers = np.array([float(v) for v in NUMBER_SEPARATORS.split(str(text).strip()) if v], dtype=np.float64)
    except ValueError:
        raise InputError(f"pose {text!r} is not a list of numbers") from None
    if len(numbers) == 6:
        with np.errstate(invalid="ignore"):  # cos(inf): reported below as a NaN in the rotation
            T = pose_from_xyzrpy(numbers)
        _finite(T, f"pose {text!r}")
        return T
    if len(numbers) in (12, 16):
        return rigid_pose(pose_from_numbers(numbers), f"pose {text!r}")
    raise InputError(
        f"pose {text!r} has {len(numbers)} numbers; expected 6 (x,y,z,roll,pitch,yaw), 12 (3x4) or 16 (4x4)"
    )


def pose_from_numbers(numbers: np.ndarray) -> np.ndarray:
    """A 4x4 pose from 12 (3x4) or 16 (4x4) row-major numbers."""
    T = np.eye(4)
    T[: len(numbers) // 4] = numbers.reshape(-1, 4)
    return T


def rigid_pose(T: np.ndarray, where) -> np.ndarray:
    """``T`` if it is a finite rigid pose; else an InputError naming ``where`` and the problem."""
    _finite(T, where)
    R = T[:3, :3]
    if not np.allclose(T[3], [0, 0, 0, 1], atol=1e-9):
        raise InputError(f"not a rigid pose: bottom row is {T[3].tolist()}, expected [0, 0, 0, 1]", where)
    if np.abs(R.T @ R - np.eye(3)).max() > _ORTHONORMAL_TOLERANCE or np.linalg.det(R) <= 0:
        raise InputError("not a rigid pose: the 3x3 block is not a rotation", where)
    return T


def _finite(T: np.ndarray, where) -> None:
    """A pose holds finite numbers only: the error says in which part it does not."""
    parts = {"rotation": T[:3, :3], "translation": T[:3, 3], "bottom row": T[3]}
    bad = [name for name, values in parts.items() if not np.isfinite(values).all()]
    if bad:
        raise InputError(f"not a rigid pose: NaN or infinite value(s) in the {' and the '.join(bad)}", where)


# --- algebra ----------------------------------------------------------------------------------
def apply_pose(T: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """Points (N, 3) mapped by the pose: ``R @ p + t`` for each point."""
    T = np.asarray(T, dtype=np.float64)
    xyz = np.asarray(xyz)
    # Column by column: numpy's (N, 3) @ (3, 3) does not reach BLAS and was 10x slower (7 ms
    # for 60,000 points, 30 ms from float32), a tenth of a hypothesis job.
    out = np.empty((len(xyz), 3), dtype=np.float64)
    for i in range(3):
        out[:, i] = T[i, 0] * xyz[:, 0] + T[i, 1] * xyz[:, 1] + T[i, 2] * xyz[:, 2] + T[i, 3]
    return out


def in_sensor_frame(xyz: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Points given in a frame expressed in the frame of a sensor at ``pose`` in it (rotation
    included); at the identity, the points themselves (no rounding, no copy)."""
    if np.array_equal(pose, np.eye(4)):
        return xyz
    return apply_pose(invert_pose(pose), xyz)


def invert_pose(T: np.ndarray) -> np.ndarray:
    """The inverse of a rigid pose (exact: transpose of the rotation)."""
    T = np.asarray(T, dtype=np.float64)
    inverse = np.eye(4)
    inverse[:3, :3] = T[:3, :3].T
    inverse[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return inverse


def relative_pose(T_w_1: np.ndarray, T_w_2: np.ndarray) -> np.ndarray:
    """The pose of frame 2 in frame 1, ``T_1_2 = inv(T_w_1) @ T_w_2``."""
    return invert_pose(T_w_1) @ np.asarray(T_w_2, dtype=np.float64)


def rotation_angle(R: np.ndarray) -> float:
    """The angle (radians) of a rotation matrix, accurate for small angles too."""
    R = np.asarray(R, dtype=np.float64)[:3, :3]
    sine = 0.5 * np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    cosine = 0.5 * (np.trace(R) - 1.0)
    return float(np.arctan2(sine, cosine))


def constant_twist(T_a_b: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The sensor's linear (m/s) and angular (rad/s) velocity in its own frame, taken as constant
    (a constant twist), that moves it from frame a to frame b (``T_a_b``, the pose of b in a) in
    ``dt_s`` seconds: the rotation vector over the time, and the chord over the time in the
    frame halfway through the rotation (where a constant twist's velocity points along the
    chord; exact for a straight drive or a level arc up to the chord's length, 0.6% short over
    33 deg of turn)."""
    from scipy.spatial.transform import Rotation  # only where a motion is derived

    T_a_b = np.asarray(T_a_b, dtype=np.float64)
    w = Rotation.from_matrix(T_a_b[:3, :3]).as_rotvec() / dt_s
    return rotation_from_vector(0.5 * w * dt_s).T @ (T_a_b[:3, 3] / dt_s), w


def velocities_from_neighbours(stamps_s, poses) -> list[tuple[np.ndarray, np.ndarray] | None]:
    """Per pose of a timed sequence (world-from-sensor 4x4s, stamps ascending), the sensor's
    velocities in its own frame: the ``constant_twist`` between its neighbours (the previous
    and the next pose; the pose itself at an end). None where a neighbour's time is missing or
    not later."""
    out = []
    for k in range(len(poses)):
        a, b = max(k - 1, 0), min(k + 1, len(poses) - 1)
        if None in (stamps_s[a], stamps_s[b]) or not stamps_s[b] > stamps_s[a]:
            out.append(None)
            continue
        out.append(constant_twist(relative_pose(poses[a], poses[b]), stamps_s[b] - stamps_s[a]))
    return out


def pose_error(T_est: np.ndarray, T_ref: np.ndarray) -> tuple[float, float]:
    """(translation error in metres, rotation error in degrees) of ``T_est`` against ``T_ref``:
    the translation and angle of ``inv(T_ref) @ T_est``."""
    E = relative_pose(T_ref, T_est)
    return float(np.linalg.norm(E[:3, 3])), float(np.degrees(rotation_angle(E)))


def interpolate_pose(stamps_s: np.ndarray, poses: np.ndarray, at_s: float) -> np.ndarray | None:
    """The pose at ``at_s`` between timed poses (stamps ascending): translation linear, rotation
    by slerp. None when ``at_s`` lies outside [first stamp, last stamp]."""
    from scipy.spatial.transform import Rotation, Slerp

    stamps_s = np.asarray(stamps_s, dtype=np.float64)
    if len(stamps_s) == 0 or not stamps_s[0] <= at_s <= stamps_s[-1]:
        return None
    k = int(np.clip(np.searchsorted(stamps_s, at_s, side="right") - 1, 0, len(stamps_s) - 1))
    if stamps_s[k] == at_s or k == len(stamps_s) - 1:
        return np.asarray(poses[k], dtype=np.float64).copy()
    t0, t1 = stamps_s[k], stamps_s[k + 1]
    fraction = (at_s - t0) / (t1 - t0)
    rotation = Slerp([0.0, 1.0], Rotation.from_matrix(np.asarray(poses[k : k + 2])[:, :3, :3]))(fraction)
    T = np.eye(4)
    T[:3, :3] = rotation.as_matrix()
    T[:3, 3] = (1 - fraction) * poses[k][:3, 3] + fraction * poses[k + 1][:3, 3]
    return T


def weighted_rigid_transform(
    source: np.ndarray, target: np.ndarray, weight: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """R (3x3) and t (3,) minimising sum w |R source + t - target|^2 (weighted Kabsch).

    NaN-filled when fewer than 3 points carry weight (the rotation is then undetermined).
    """
    if np.count_nonzero(weight > 0) < 3:
        return np.full((3, 3), np.nan), np.full(3, np.nan)
    w = weight / weight.sum()
    centroid_source = w @ source
    centroid_target = w @ target
    covariance = (source - centroid_source).T @ ((target - centroid_target) * w[:, None])
    u, _, vt = np.linalg.svd(covariance)
    # Reflection guard: force det(R) = +1.
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rotation, centroid_target - rotation @ centroid_source


def poses_of_attached_frame(poses: np.ndarray, extrinsic: np.ndarray) -> np.ndarray:
    """Poses of a frame rigidly attached to the one ``poses`` (M, 4, 4) describe, at
    ``extrinsic`` (its pose in that frame): ``inv(E) @ P @ E``, the world being the attached
    frame at the poses' origin. KITTI's lidar poses are its camera poses with E = Tr. The exact
    inverse, not the transpose: a dataset's E is often rigid to 1e-7 only."""
    return np.linalg.inv(extrinsic) @ np.asarray(poses) @ extrinsic


def skew(v) -> np.ndarray:
    """The cross-product matrix [v]x of a 3-vector: [v]x @ u = v x u."""
    x, y, z = np.asarray(v, dtype=np.float64)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def rotation_from_vector(omega) -> np.ndarray:
    """The rotation exp([omega]x) of a rotation vector (axis times angle, rad): Rodrigues."""
    omega = np.asarray(omega, dtype=np.float64)
    angle = float(np.linalg.norm(omega))
    if angle < 1e-15:
        return np.eye(3)
    K = skew(omega / angle)
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * K @ K


# A quaternion further than this from unit length is a mistake in the data, not rounding.
QUATERNION_TOLERANCE = 1e-3


def poses_from_quaternions(q_wxyz, translations) -> np.ndarray:
    """(N, 4, 4) poses of (N, 4) quaternions, scalar first (w, x, y, z), normalised here, and
    (N, 3) translations. The caller checks them (finite, within QUATERNION_TOLERANCE of unit)."""
    q = np.asarray(q_wxyz, dtype=np.float64).reshape(-1, 4)
    w, x, y, z = (q / np.linalg.norm(q, axis=1)[:, None]).T
    poses = np.zeros((len(q), 4, 4))
    poses[:, 0, :3] = np.column_stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)])
    poses[:, 1, :3] = np.column_stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)])
    poses[:, 2, :3] = np.column_stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])
    poses[:, :3, 3] = np.asarray(translations, dtype=np.float64).reshape(-1, 3)
    poses[:, 3, 3] = 1.0
    return poses
