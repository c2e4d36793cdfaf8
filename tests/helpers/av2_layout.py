"""An Argoverse 2 sensor log written from simulated scans with known poses, for the av2 tests.

Two VLP-32C lidars on a vehicle driving through the paper's intersection: the up lidar at the
drive's poses (tests/helpers/datasets.py), the down lidar upside down, pitched and offset below
it. Each sweep file holds both lidars' points in the vehicle frame, laser_number = ring (up) or
ring + 32 (down), offset_ns = the simulated firing time. The vehicle's poses are listed 30 ms
before and 20 ms after each sweep (and at the first sweep itself): the pose at the other sweeps
is the interpolation of its two neighbours, exactly (the listed rotations differ from the
sweep's by a turn about one axis, in proportion to the time, as slerp goes). x, y, z are
float64 by default (so that comparisons hold to 1e-9), float32 as in the dataset on request.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.feather as feather
from scipy.spatial.transform import Rotation

from helpers.datasets import DRIVE_XYZRPY
from lidarfield import Scan, load_scene, pose_from_xyzrpy, sensor_model, simulate_scan
from lidarfield.poses import invert_pose

# The lidars' poses in the vehicle frame (egovehicle_SE3_sensor): the up lidar on the roof,
# slightly tilted; the down lidar 30 cm below it, upside down, pitched 0.08 rad and offset.
UP_IN_VEHICLE = pose_from_xyzrpy([1.35, 0.0, 1.95, 0.004, -0.006, 0.012])
DOWN_IN_VEHICLE = pose_from_xyzrpy([1.30, 0.05, 1.65, np.pi, 0.08, -0.02])
FIRST_NS = 1_689_000_000_123_456_789
SWEEP_NS = 100_000_000
BEFORE_NS, AFTER_NS = 30_000_000, 20_000_000  # listed poses around the sweeps
TURN_RAD_PER_S = 0.3  # the listed poses' turn about the vehicle's z, relative to the sweep's pose
SPEED_MPS = (10.0, 0.5, 0.1)  # their displacement per second, in the vehicle's frame


@dataclass
class Av2Log:
    folder: Path
    up: list[Scan]  # the simulated scans in their lidar's frame
    down: list[Scan]
    up_poses: np.ndarray  # (N, 4, 4) world-from-up_lidar at each sweep
    down_poses: np.ndarray
    vehicle_poses: np.ndarray  # world-from-vehicle at each sweep
    stamps_ns: list[int]
    sweeps: list[Path]


def simulate_log(
    scene: str = "paper-intersection", up_poses: np.ndarray | None = None
) -> tuple[list[Scan], list[Scan], np.ndarray, np.ndarray, np.ndarray]:
    """Both lidars' scans of ``scene`` with the up lidar at ``up_poses`` (default: the drive's),
    sweep k taken at scene time k x 0.1 s."""
    scene, model = load_scene(scene), sensor_model("vlp32c")
    up_poses = np.stack([pose_from_xyzrpy(p) for p in DRIVE_XYZRPY]) if up_poses is None else up_poses
    vehicle_poses = up_poses @ invert_pose(UP_IN_VEHICLE)
    down_poses = vehicle_poses @ DOWN_IN_VEHICLE
    time_s = [k * SWEEP_NS * 1e-9 for k in range(len(up_poses))]
    up = [
        simulate_scan(scene, model, pose, time_s=t, seed=k, range_noise_m=0.02)
        for k, (pose, t) in enumerate(zip(up_poses, time_s))
    ]
    down = [
        simulate_scan(scene, model, pose, time_s=t, seed=50 + k, range_noise_m=0.02)
        for k, (pose, t) in enumerate(zip(down_poses, time_s))
    ]
    return up, down, up_poses, down_poses, vehicle_poses


_SIMULATED = None


def write_av2_log(folder: Path, xyz_dtype=np.float64, simulated=None) -> Av2Log:
    """The log folder of the simulated drive (the simulation is run once per test session), or
    of ``simulated`` (what :func:`simulate_log` returns; each sweep then has an ``object``
    column too, the simulator's labels, which the reader does not read)."""
    global _SIMULATED
    if simulated is None and _SIMULATED is None:
        _SIMULATED = simulate_log()
    up, down, up_poses, down_poses, vehicle_poses = simulated or _SIMULATED
    stamps = [FIRST_NS + k * SWEEP_NS + 1_000 * k for k in range(len(up))]
    (folder / "sensors" / "lidar").mkdir(parents=True)
    sweeps = []
    for k, stamp in enumerate(stamps):
        sweeps.append(folder / "sensors" / "lidar" / f"{stamp}.feather")
        write_sweep(sweeps[-1], up[k], down[k], xyz_dtype, labels=simulated is not None)
    write_ego_poses(folder / "city_SE3_egovehicle.feather", stamps, vehicle_poses)
    write_calibration(folder / "calibration" / "egovehicle_SE3_sensor.feather")
    (folder / "map").mkdir()  # other parts of a log: not the reader's business
    (folder / "map" / "log_map_archive.json").write_text("{}")
    (folder / "sensors" / "lidar" / "notes.txt").write_text("not a sweep")
    return Av2Log(folder, up, down, up_poses, down_poses, vehicle_poses, stamps, sweeps)


def intensity_of(scan: Scan, salt: int) -> np.ndarray:
    return ((np.arange(len(scan)) * 7 + salt) % 256).astype(np.uint8)


def write_sweep(path: Path, up: Scan, down: Scan, xyz_dtype=np.float64, labels: bool = False) -> None:
    """Both lidars' points in the vehicle frame, in firing-time order (up first at equal times);
    with ``labels`` their ``object`` labels too."""
    xyz = np.vstack([_to_vehicle(UP_IN_VEHICLE, up.xyz), _to_vehicle(DOWN_IN_VEHICLE, down.xyz)])
    laser = np.concatenate([up.attributes["ring"], down.attributes["ring"] + 32]).astype(np.uint8)
    offset = np.round(np.concatenate([up.attributes["time"], down.attributes["time"]]) * 1e9).astype(np.int64)
    intensity = np.concatenate([intensity_of(up, 0), intensity_of(down, 3)])
    order = np.argsort(offset, kind="stable")
    table = pa.table(
        {
            "x": xyz[order, 0].astype(xyz_dtype),
            "y": xyz[order, 1].astype(xyz_dtype),
            "z": xyz[order, 2].astype(xyz_dtype),
            "intensity": intensity[order],
            "laser_number": laser[order],
            "offset_ns": offset[order],
        }
    )
    if labels:
        table = table.append_column(
            "object", pa.array(np.concatenate([up.attributes["object"], down.attributes["object"]])[order])
        )
    feather.write_feather(table, path)


def _to_vehicle(lidar_in_vehicle: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    return xyz @ lidar_in_vehicle[:3, :3].T + lidar_in_vehicle[:3, 3]


def quaternion_columns(poses: np.ndarray) -> dict[str, np.ndarray]:
    x, y, z, w = Rotation.from_matrix(poses[:, :3, :3]).as_quat().T
    t = poses[:, :3, 3]
    return {"qw": w, "qx": x, "qy": y, "qz": z, "tx_m": t[:, 0], "ty_m": t[:, 1], "tz_m": t[:, 2]}


def listed_poses(stamps: list[int], vehicle_poses: np.ndarray) -> tuple[list[int], np.ndarray]:
    """The first sweep's pose at its time; every sweep's 30 ms before and 20 ms after it, turned
    and moved in proportion to the time (so slerp and linear interpolation give the sweep's)."""
    times, poses = [stamps[0]], [vehicle_poses[0]]
    for stamp, pose in zip(stamps, vehicle_poses):
        for dt_ns in (-BEFORE_NS, AFTER_NS):
            dt = dt_ns * 1e-9
            step = np.eye(4)
            step[:3, :3] = Rotation.from_rotvec([0.0, 0.0, TURN_RAD_PER_S * dt]).as_matrix()
            step[:3, 3] = np.array(SPEED_MPS) * dt
            times.append(stamp + dt_ns)
            poses.append(pose @ step)
    return times, np.stack(poses)


def write_ego_poses(path: Path, stamps: list[int], vehicle_poses: np.ndarray) -> None:
    times, poses = listed_poses(stamps, vehicle_poses)
    order = np.random.default_rng(0).permutation(len(times))  # the reader sorts them
    columns = {"timestamp_ns": np.array(times, dtype=np.int64)[order]}
    columns.update({name: values[order] for name, values in quaternion_columns(poses).items()})
    feather.write_feather(pa.table(columns), path)


def write_calibration(path: Path, sensors: dict[str, np.ndarray] | None = None) -> None:
    sensors = sensors or {
        "ring_front_center": pose_from_xyzrpy([1.6, 0.0, 1.4, -np.pi / 2, 0.0, -np.pi / 2]),
        "up_lidar": UP_IN_VEHICLE,
        "down_lidar": DOWN_IN_VEHICLE,
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    columns = {"sensor_name": list(sensors)}
    columns.update(quaternion_columns(np.stack(list(sensors.values()))))
    feather.write_feather(pa.table(columns), path)
