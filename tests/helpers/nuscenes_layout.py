"""A nuScenes v1.0-mini-like folder written from simulated scans with known poses, for the
nuScenes reader's tests: two scenes of one log, LIDAR_TOP key frames and sweeps interleaved in
time (sweeps before a scene's first key frame and after its last belong to it, tied to their
nearest sample, as nuScenes does), a RADAR_FRONT channel to be ignored, tables in shuffled
order. The expected poses are computed here with scipy, independently of the reader."""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from lidarfield import load_scene, pose_from_xyzrpy, sensor_model, simulate_scan
from lidarfield.scan import Scan

VERSION = "v1.0-mini"
LOG = "n015-2018-07-18-11-07-57+0800"
# nuScenes' own LIDAR_TOP calibrations (ego-from-lidar, quaternion [w, x, y, z]): the lidar
# 1.84 m up, rotated about z by about -90 deg (its x points to the vehicle's right), slightly
# tilted; one per scene, as nuScenes has one calibrated_sensor record per log.
LIDAR_TOP_CALIBRATIONS = [
    ([0.985793, 0.0, 1.84019], [0.706749235646644, -0.015300993788500868, 0.01739745181256607, -0.7070846669051719]),
    ([0.943713, 0.0, 1.84023], [0.7077955119163518, -0.006492242056004365, 0.010646214713995808, -0.7063073142877817]),
]
RADAR_FRONT_CALIBRATION = ([3.412, 0.0, 0.5], [0.9999984769132877, 0.0, 0.0, 0.0017453283658983088])
T0_US = 1531883530_000_000
# (scene, time after T0 in s, key frame?) of every LIDAR_TOP sweep, the drive in time order.
LIDAR_SWEEPS = [
    ("scene-0061", 0.05, False),  # before the scene's first key frame: its nearest sample is the first
    ("scene-0061", 0.10, True),
    ("scene-0061", 0.15, False),
    ("scene-0061", 0.25, False),
    ("scene-0061", 0.30, True),
    ("scene-0061", 0.35, False),  # after its last key frame
    ("scene-0103", 0.55, False),  # the next scene's, before its first key frame
    ("scene-0103", 0.60, True),
    ("scene-0103", 0.70, False),
    ("scene-0103", 0.80, True),
]
SCENES = ["scene-0061", "scene-0103"]


@dataclass(frozen=True)
class Sweep:
    """One LIDAR_TOP sample_data written, with what the reader should find."""

    scene: str
    filename: str
    timestamp_us: int
    key_frame: bool
    lidar_pose: np.ndarray  # world-from-lidar, 4x4
    ego_pose: np.ndarray  # world-from-ego, 4x4
    scan: Scan  # the simulated points (sensor frame), with ring
    intensity: np.ndarray


def token(*parts) -> str:
    return hashlib.md5("/".join(map(str, parts)).encode()).hexdigest()


def pose(translation, rotation) -> np.ndarray:
    """4x4 from nuScenes' translation and quaternion [w, x, y, z] (scipy normalises it)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat(rotation, scalar_first=True).as_matrix()
    T[:3, 3] = translation
    return T


def quaternion(T: np.ndarray) -> list[float]:
    return Rotation.from_matrix(T[:3, :3]).as_quat(scalar_first=True).tolist()


def ego_pose_at(t: float) -> np.ndarray:
    """The vehicle driving through the paper's intersection along x at 5 m/s, turning slowly,
    pitching and rolling a little; its origin 1.16 m up, so that the lidar is near 3 m."""
    return pose_from_xyzrpy([-2.0 + 5.0 * t, 0.3 * t, 1.16, 0.01 * np.sin(9 * t), -0.008 * t, 0.2 * t])


def write_nuscenes_layout(root: Path, city_origin=(0.0, 0.0, 0.0)) -> list[Sweep]:
    """``root/v1.0-mini/*.json``, ``root/samples/LIDAR_TOP``, ``root/sweeps/LIDAR_TOP`` and a
    ``root/samples/RADAR_FRONT`` file; returns the LIDAR_TOP sweeps written, in time order.
    The tables' global frame is the scene's shifted by ``city_origin`` (metres): nuScenes' maps
    put the vehicle hundreds to thousands of metres from the global origin."""
    to_global = np.eye(4)
    to_global[:3, 3] = city_origin
    scene_model, model = load_scene("paper-intersection"), sensor_model("hdl32")
    tables = {name: [] for name in ("scene", "sample", "sample_data", "ego_pose", "calibrated_sensor", "sensor")}
    lidar_sensor, radar_sensor = token("sensor", "LIDAR_TOP"), token("sensor", "RADAR_FRONT")
    tables["sensor"] += [
        {"token": radar_sensor, "channel": "RADAR_FRONT", "modality": "radar"},
        {"token": lidar_sensor, "channel": "LIDAR_TOP", "modality": "lidar"},
    ]
    calibration = {}
    for k, scene in enumerate(SCENES):
        translation, rotation = LIDAR_TOP_CALIBRATIONS[k]
        calibration[scene] = (token("calibration", scene, "LIDAR_TOP"), pose(translation, rotation))
        tables["calibrated_sensor"] += [
            {
                "token": calibration[scene][0],
                "sensor_token": lidar_sensor,
                "translation": translation,
                "rotation": rotation,
                "camera_intrinsic": [],
            },
            {
                "token": token("calibration", scene, "RADAR_FRONT"),
                "sensor_token": radar_sensor,
                "translation": RADAR_FRONT_CALIBRATION[0],
                "rotation": RADAR_FRONT_CALIBRATION[1],
                "camera_intrinsic": [],
            },
        ]
    # Samples: the key frames; every sweep tied to its scene's nearest one.
    samples = {scene: [t for s, t, key in LIDAR_SWEEPS if s == scene and key] for scene in SCENES}
    for scene in SCENES:
        tokens = [token("sample", scene, t) for t in samples[scene]]
        tables["scene"].append(
            {
                "token": token("scene", scene),
                "log_token": token("log", LOG),
                "nbr_samples": len(tokens),
                "first_sample_token": tokens[0],
                "last_sample_token": tokens[-1],
                "name": scene,
                "description": "simulated: the paper's intersection",
            }
        )
        for i, t in enumerate(samples[scene]):
            tables["sample"].append(
                {
                    "token": tokens[i],
                    "timestamp": _us(t),
                    "prev": tokens[i - 1] if i else "",
                    "next": tokens[i + 1] if i + 1 < len(tokens) else "",
                    "scene_token": token("scene", scene),
                }
            )
    sweeps = []
    rng = np.random.default_rng(7)
    for k, (scene, t, key) in enumerate(LIDAR_SWEEPS):
        ego = to_global @ ego_pose_at(t)
        lidar = ego @ calibration[scene][1]
        scan = simulate_scan(scene_model, model, np.linalg.solve(to_global, lidar), seed=k, range_noise_m=0.02)
        intensity = rng.integers(0, 256, len(scan)).astype(np.float32)
        folder = "samples" if key else "sweeps"
        filename = f"{folder}/LIDAR_TOP/{LOG}__LIDAR_TOP__{_us(t)}.pcd.bin"
        (root / filename).parent.mkdir(parents=True, exist_ok=True)
        rows = np.column_stack([scan.xyz, intensity, scan.attributes["ring"]]).astype("<f4")
        rows.tofile(root / filename)
        sweeps.append(Sweep(scene, filename, _us(t), key, lidar, ego, scan, intensity))
        nearest = min(samples[scene], key=lambda s: abs(s - t))
        tables["ego_pose"].append(
            {
                "token": token("ego", t),
                "timestamp": _us(t),
                "rotation": quaternion(ego),
                "translation": ego[:3, 3].tolist(),
            }
        )
        tables["sample_data"].append(
            {
                "token": token("sample_data", "LIDAR_TOP", t),
                "sample_token": token("sample", scene, nearest),
                "ego_pose_token": token("ego", t),
                "calibrated_sensor_token": calibration[scene][0],
                "timestamp": _us(t),
                "fileformat": "pcd",
                "is_key_frame": key,
                "height": 0,
                "width": 0,
                "filename": filename,
                "prev": "",
                "next": "",
            }
        )
    _chain([r for r in tables["sample_data"]], [s.scene for s in sweeps])
    # RADAR_FRONT at every key frame, 5 ms later, with its own ego pose: to be ignored.
    for scene in SCENES:
        for t in samples[scene]:
            filename = f"samples/RADAR_FRONT/{LOG}__RADAR_FRONT__{_us(t + 0.005)}.pcd"
            (root / filename).parent.mkdir(parents=True, exist_ok=True)
            (root / filename).write_bytes(b"# .PCD v0.7 - radar\n")
            ego = to_global @ ego_pose_at(t + 0.005)
            tables["ego_pose"].append(
                {
                    "token": token("ego", t + 0.005),
                    "timestamp": _us(t + 0.005),
                    "rotation": quaternion(ego),
                    "translation": ego[:3, 3].tolist(),
                }
            )
            tables["sample_data"].append(
                {
                    "token": token("sample_data", "RADAR_FRONT", t),
                    "sample_token": token("sample", scene, t),
                    "ego_pose_token": token("ego", t + 0.005),
                    "calibrated_sensor_token": token("calibration", scene, "RADAR_FRONT"),
                    "timestamp": _us(t + 0.005),
                    "fileformat": "pcd",
                    "is_key_frame": True,
                    "height": 0,
                    "width": 0,
                    "filename": filename,
                    "prev": "",
                    "next": "",
                }
            )
    folder = root / VERSION
    folder.mkdir(parents=True)
    order = np.random.default_rng(3)
    for name, rows in tables.items():  # the tables' order is not the time order
        rows = [rows[i] for i in order.permutation(len(rows))]
        (folder / f"{name}.json").write_text(json.dumps(rows, indent=0))
    return sweeps


def _us(t: float) -> int:
    return T0_US + round(t * 1e6)


def _chain(records: list[dict], scenes: list[str]) -> None:
    """prev/next links of one channel's records (in time order), within each scene."""
    for i, record in enumerate(records):
        if i and scenes[i - 1] == scenes[i]:
            record["prev"] = records[i - 1]["token"]
        if i + 1 < len(records) and scenes[i + 1] == scenes[i]:
            record["next"] = records[i + 1]["token"]
