"""Poses along a path for a simulated drive, and constant-velocity motion during a sweep.

A pose is a 4x4 world-from-sensor matrix (see :mod:`lidarfield.poses` for the conventions).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..poses import pose_from_xyzrpy
from ..scan import still_sweep


def moved_pose(pose: np.ndarray, dt_s, linear_velocity_mps, angular_velocity_rps) -> np.ndarray:
    """Pose(s) after ``dt_s`` seconds of constant motion: ``linear_velocity_mps`` in the world
    frame, ``angular_velocity_rps`` (rad/s) in the sensor frame. ``dt_s`` may be an array:
    the result is then (n, 4, 4)."""
    # Imported here: planning a simulated drive needs this module's poses, not SciPy (0.4 s).
    from scipy.spatial.transform import Rotation

    dt = np.atleast_1d(np.asarray(dt_s, dtype=float))
    rotation = Rotation.from_rotvec(dt[:, None] * np.asarray(angular_velocity_rps, dtype=float)).as_matrix()
    out = np.broadcast_to(np.eye(4), (len(dt), 4, 4)).copy()
    out[:, :3, :3] = pose[:3, :3] @ rotation
    out[:, :3, 3] = pose[:3, 3] + dt[:, None] * np.asarray(linear_velocity_mps, dtype=float)
    return out if np.ndim(dt_s) else out[0]


def motion_record(pose: np.ndarray, linear_velocity_mps, angular_velocity_rps, rolling_shutter: bool) -> dict:
    """A simulated scan's ``sweep_motion``: the motion its points carry, in its sensor frame at
    the sweep start (the linear velocity turned from the world frame by ``pose``); zero without
    rolling shutter, whose points are all taken at the sweep start."""
    if not rolling_shutter:
        return still_sweep()
    velocity = np.asarray(pose, dtype=float)[:3, :3].T @ np.asarray(linear_velocity_mps, dtype=float)
    return {
        "velocity_mps": [float(v) for v in velocity],
        "angular_velocity_rps": [float(w) for w in angular_velocity_rps],
    }


class TrajectoryFrame(NamedTuple):
    """One scan of a drive: its sweep-start pose and the sensor's velocities then (a tuple
    ``(pose, linear_velocity_mps, angular_velocity_rps)``; frame k is at time k / rate_hz)."""

    pose: np.ndarray  # 4x4 world-from-sensor
    linear_velocity_mps: tuple[float, float, float]  # world frame
    angular_velocity_rps: tuple[float, float, float]  # sensor frame


def arc_trajectory(
    center_xy,
    radius_m: float,
    start_angle_rad: float,
    speed_mps: float,
    rate_hz: float,
    frames: int,
    height_m: float,
) -> list[TrajectoryFrame]:
    """Scan poses along a circular arc driven at constant speed, heading tangent to the arc.

    Frame k is at angle ``start_angle_rad + k * speed_mps / (radius_m * rate_hz)`` about
    ``center_xy``, ``height_m`` above z = 0, level, its x axis along the direction of travel.
    ``speed_mps`` is signed: positive drives counter-clockwise about the centre, negative
    clockwise.
    """
    if radius_m <= 0 or rate_hz <= 0 or frames < 1:
        raise ValueError("arc_trajectory: radius_m and rate_hz must be positive, frames >= 1")
    yaw_rate = speed_mps / radius_m
    side = 1.0 if speed_mps >= 0 else -1.0  # the heading is 90 deg ahead of the radius, in the turn's sense
    out = []
    for k in range(frames):
        angle = start_angle_rad + yaw_rate * k / rate_hz
        position = (center_xy[0] + radius_m * np.cos(angle), center_xy[1] + radius_m * np.sin(angle), height_m)
        heading = angle + side * np.pi / 2
        velocity = (abs(speed_mps) * np.cos(heading), abs(speed_mps) * np.sin(heading), 0.0)
        out.append(TrajectoryFrame(pose_from_xyzrpy([*position, 0.0, 0.0, heading]), velocity, (0.0, 0.0, yaw_rate)))
    return out


# The default drive through the built-in `paper-intersection`: a left turn from the west arm
# (heading +x, 1.5 m right of the centre line) into the north arm (heading +y), about the
# corner of the north-west building at (-4, 4), radius 5.5 m, at 5 m/s, one scan every 0.2 s
# (every second sweep of a 10 Hz sensor). Nine scans cover 83 deg of the turn; every pose stays
# in the streets (the bands |x| < 4 m and |y| < 4 m), at least 2.5 m from every building.
PAPER_TURN = dict(
    center_xy=(-4.0, 4.0), radius_m=5.5, start_angle_rad=-np.pi / 2, speed_mps=5.0, rate_hz=5.0, height_m=3.0
)


def paper_turn_trajectory(frames: int = 9) -> list[TrajectoryFrame]:
    """The default drive of the study through ``paper-intersection`` (see ``PAPER_TURN``)."""
    return arc_trajectory(frames=frames, **PAPER_TURN)
