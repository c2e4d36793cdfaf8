"""Argoverse 2 sensor dataset: one log folder, ``sensors/lidar/<timestamp_ns>.feather``,
``city_SE3_egovehicle.feather`` and ``calibration/egovehicle_SE3_sensor.feather``.

Each sweep holds both roof lidars' points (two Velodyne VLP-32C; ``laser_number`` 0-31 the up
lidar, 32-63 the down lidar) in the vehicle frame, each point with its time after the sweep's
timestamp. The pose table gives the vehicle's pose in the city frame, ``city_SE3_egovehicle``,
at listed times; the calibration table each sensor's pose in the vehicle frame,
``egovehicle_SE3_sensor``. A study's scans are written in ``frame`` (``up_lidar``, the default,
``down_lidar``, or ``egovehicle``): each scan's pose is ``city_SE3_egovehicle(t) @
egovehicle_SE3_<frame>``, world-from-frame with the world the city frame, at the sweep's time
t; between listed poses the vehicle's pose is interpolated (translation linear, rotation by
slerp), and a sweep without a listed pose within 50 ms, or outside the poses' time span, is an
error. ``lidars`` (default both) chooses whose points the scans keep.

Lidars: each scan is a rig (:mod:`lidarfield.sensors.rig`) of the lidars it keeps, each placed
where the calibration mounts it in the scan's frame (``T_frame_vehicle @
egovehicle_SE3_<lidar>``), each a ``vlp32c`` (or the sequence's ``sensor:``), and each point
names its lidar (``lidar`` attribute, from ``laser_number``): the hypotheses that reason about
rays take each point's own lidar, the down one upside down 0.3 m below the up one. The scan's
own sensor model, for what reads one model (the field's scan patterns, the sensor fit at
ingest): ``vlp32c`` when the scans are one lidar's points in that lidar's own frame, else
none unless ``sensor:`` gives one (one model about the frame's origin describes neither
lidar's points).

Reading the index reads these two tables and lists the sweeps, never a sweep: the ingest jobs
read the points, with the options (frame, lidars, ``T_frame_vehicle``) each scan carries.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import ConfigError
from ..io.formats.av2 import FRAMES, LIDARS, feather_columns
from ..poses import QUATERNION_TOLERANCE, interpolate_pose, invert_pose, poses_from_quaternions
from . import DatasetScan, DatasetSequence

SENSOR = "vlp32c"
POSES = "city_SE3_egovehicle.feather"
CALIBRATION = Path("calibration") / "egovehicle_SE3_sensor.feather"
SWEEPS = Path("sensors") / "lidar"
POSE_COLUMNS = ("qw", "qx", "qy", "qz", "tx_m", "ty_m", "tz_m")
MAX_POSE_GAP_NS = 50_000_000  # a sweep's pose comes from listed poses within 50 ms


def read_index(settings: dict, base_dir: Path) -> DatasetSequence:
    root = Path(settings["path"])
    folder = Path(base_dir) / root
    frame = settings.get("frame") or "up_lidar"
    if frame not in FRAMES:
        raise ConfigError(f"dataset.frame: {frame!r} is not one of {', '.join(FRAMES)}")
    chosen = settings.get("lidars") or list(LIDARS)
    unknown = [name for name in chosen if name not in LIDARS]
    if unknown:
        raise ConfigError(f"dataset.lidars: {unknown} unknown; the lidars are {', '.join(LIDARS)}")
    lidars = [name for name in LIDARS if name in chosen]  # one order: equal settings, equal stage ids
    sweeps = _sweeps(folder)
    if not sweeps:
        raise ConfigError("dataset: no Argoverse 2 sweep (<timestamp_ns>.feather) in the log", folder / SWEEPS)
    mounted = sensor_poses(folder / CALIBRATION, [n for n in dict.fromkeys([frame, *lidars]) if n != "egovehicle"])
    vehicle_frame = np.eye(4) if frame == "egovehicle" else mounted[frame]
    stamps_ns, city = read_ego_poses(folder / POSES)
    frame_vehicle = invert_pose(vehicle_frame)
    lidar_poses = {name: (frame_vehicle @ mounted[name]).tolist() for name in lidars}
    options = {"frame": frame, "lidars": lidars, "T_frame_vehicle": frame_vehicle.tolist(), "lidar_poses": lidar_poses}
    scans = [
        DatasetScan(
            str(root / SWEEPS / path.name),
            "av2",
            (_pose_at(stamps_ns, city, stamp, path, folder / POSES) @ vehicle_frame).tolist(),
            stamp / 10**9,  # int / int: correctly rounded (the ns exceed 2**53: * 1e-9 rounds twice)
            options,
        )
        for stamp, path in sweeps
    ]
    sensor = SENSOR if lidars == [frame] else None
    return DatasetSequence(
        scans, sensor, f"Argoverse 2 log {root.name} ({' + '.join(lidars)} in the {frame} frame)", deskewed=True
    )


def _sweeps(folder: Path) -> list[tuple[int, Path]]:
    """(timestamp_ns, file) of the log's sweeps in time order; other files are not the layout's."""
    if not folder.is_dir():
        raise ConfigError("dataset: no such Argoverse 2 log folder", folder)
    if not (folder / SWEEPS).is_dir():
        raise ConfigError(f"dataset: not an Argoverse 2 log (no {SWEEPS.as_posix()}/ in it)", folder)
    found = [(int(p.stem), p) for p in (folder / SWEEPS).glob("*.feather") if p.stem.isdigit()]
    return sorted(found)


def quaternion_poses(columns: dict[str, np.ndarray], path: Path, what: str) -> np.ndarray:
    """(N, 4, 4) poses of a table's qw, qx, qy, qz (scalar first) and tx_m, ty_m, tz_m columns."""
    q = np.column_stack([np.asarray(columns[c], dtype=np.float64) for c in POSE_COLUMNS[:4]])
    t = np.column_stack([np.asarray(columns[c], dtype=np.float64) for c in POSE_COLUMNS[4:]])
    norm = np.linalg.norm(q, axis=1)
    bad = ~(np.isfinite(q).all(axis=1) & np.isfinite(t).all(axis=1) & (np.abs(norm - 1.0) < QUATERNION_TOLERANCE))
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise ConfigError(
            f"dataset: {what}: row {row} is no pose (a unit quaternion qw qx qy qz and a finite translation); "
            f"{int(bad.sum())} such row(s)",
            path,
        )
    return poses_from_quaternions(q, t)


def sensor_pose(path: Path, sensor: str) -> np.ndarray:
    """``egovehicle_SE3_<sensor>`` (4x4) from the log's calibration table."""
    return sensor_poses(path, [sensor])[sensor]


def sensor_poses(path: Path, sensors: list[str]) -> dict[str, np.ndarray]:
    """``egovehicle_SE3_<sensor>`` (4x4) of each of ``sensors``, the calibration table read once."""
    what = "the calibration (egovehicle_SE3_sensor)"
    columns = feather_columns(
        path, ("sensor_name",) + POSE_COLUMNS, f"dataset: {what}", ConfigError, text=("sensor_name",)
    )
    names = [str(name) for name in columns["sensor_name"].tolist()]
    poses = {}
    for sensor in sensors:
        if sensor not in names:
            raise ConfigError(f"dataset: {what} has no sensor {sensor!r}; its sensors: {', '.join(names)}", path)
        row = names.index(sensor)
        columns_of_row = {c: columns[c][row : row + 1] for c in POSE_COLUMNS}
        poses[sensor] = quaternion_poses(columns_of_row, path, f"{what}, {sensor}")[0]
    return poses


def read_ego_poses(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(timestamps in ns ascending, city_SE3_egovehicle poses (N, 4, 4)) of the log's pose table."""
    what = "the vehicle's poses (city_SE3_egovehicle)"
    columns = feather_columns(path, ("timestamp_ns",) + POSE_COLUMNS, f"dataset: {what}", ConfigError)
    stamps = columns["timestamp_ns"]
    if stamps.dtype.kind not in "iu":
        raise ConfigError(f"dataset: {what}: timestamp_ns is {stamps.dtype}, not integer nanoseconds", path)
    if len(stamps) == 0:
        raise ConfigError(f"dataset: {what}: the table holds no pose", path)
    poses = quaternion_poses(columns, path, what)
    order = np.argsort(stamps, kind="stable")
    return stamps.astype(np.int64)[order], poses[order]


def _pose_at(stamps_ns: np.ndarray, poses: np.ndarray, stamp: int, sweep: Path, pose_file: Path) -> np.ndarray:
    """The vehicle's pose at a sweep's timestamp: the listed one, or interpolated between the
    two listed around it, the nearer within 50 ms; a ConfigError naming the sweep otherwise."""
    k = int(np.searchsorted(stamps_ns, stamp))
    if k < len(stamps_ns) and stamps_ns[k] == stamp:
        return poses[k]
    gap_ns = min(abs(int(stamps_ns[j]) - stamp) for j in (k - 1, k) if 0 <= j < len(stamps_ns))
    if gap_ns > MAX_POSE_GAP_NS:
        raise ConfigError(
            f"dataset: no pose of the vehicle within 50 ms of this sweep (the nearest in {pose_file} is "
            f"{gap_ns * 1e-6:.1f} ms away)",
            sweep,
        )
    if k == 0 or k == len(stamps_ns):
        side = "before the first" if k == 0 else "after the last"
        raise ConfigError(
            f"dataset: this sweep was taken {gap_ns * 1e-6:.1f} ms {side} pose of the vehicle in {pose_file}, "
            "outside the poses' time span (poses are interpolated, not extrapolated)",
            sweep,
        )
    # Times relative to the pose before: nanoseconds since 1970 in float seconds keep 0.2 us only.
    first = int(stamps_ns[k - 1])
    span = np.array([0.0, (int(stamps_ns[k]) - first) * 1e-9])
    return interpolate_pose(span, poses[k - 1 : k + 1], (stamp - first) * 1e-9)


def describe(path: Path) -> str | None:
    """A log folder's sweeps, their time span, its poses and calibrated lidars (tables only)."""
    if not (path / SWEEPS).is_dir() or not (path / POSES).is_file():
        return None
    sweeps = _sweeps(path)
    span = f", {(sweeps[-1][0] - sweeps[0][0]) * 1e-9:.1f} s" if len(sweeps) > 1 else ""
    lines = [f"{path}: Argoverse 2 sensor log", f"  {len(sweeps)} lidar sweeps{span}"]
    try:
        stamps, _ = read_ego_poses(path / POSES)
        lines.append(f"  {len(stamps)} vehicle poses over {(stamps[-1] - stamps[0]) * 1e-9:.1f} s")
    except ConfigError as e:
        lines.append(f"  vehicle poses: {e}")
    try:
        calibrated = [name for name in LIDARS if _has_sensor(path / CALIBRATION, name)]
        lines.append(f"  calibrated lidars: {', '.join(calibrated) or 'none'}")
    except ConfigError as e:
        lines.append(f"  calibration: {e}")
    return "\n".join(lines)


def _has_sensor(path: Path, sensor: str) -> bool:
    try:
        sensor_pose(path, sensor)
    except ConfigError as e:
        if f"has no sensor {sensor!r}" in str(e):
            return False
        raise
    return True
