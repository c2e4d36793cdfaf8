"""KITTI odometry: ``sequences/XX/velodyne/*.bin``, ``sequences/XX/calib.txt``,
``sequences/XX/times.txt`` and ``poses/XX.txt``.

The poses file holds poses of the left camera (camera 0), ``T_w_cam``, with the world the
camera frame of the first scan; ``calib.txt``'s ``Tr`` maps lidar points into camera 0,
``T_cam_lidar``. Each scan's lidar pose is therefore ``inv(Tr) @ P @ Tr``: world-from-lidar with
the world the lidar frame of the first scan. Sequences 11-21 have no poses: they read, and a
study of them registers by scan matching (``register: truth`` needs poses). The scans are
HDL-64E sweeps, already de-skewed by the dataset, in the lidar frame.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import ConfigError, InputError
from ..io.pose_files import read_kitti_poses
from ..poses import poses_of_attached_frame
from . import DatasetScan, DatasetSequence

SENSOR = "hdl64"


def read_index(settings: dict, base_dir: Path) -> DatasetSequence:
    root = Path(settings["path"])
    sequence = str(settings.get("sequence") or "")
    folder = _sequence_folder(base_dir / root, sequence)
    scans = sorted((folder / "velodyne").glob("*.bin"))
    if not scans:
        raise ConfigError(f"dataset: no scan (velodyne/*.bin) in {folder / 'velodyne'}")
    Tr = read_calib(folder / "calib.txt")
    times = _times(folder / "times.txt", len(scans))
    poses_file = base_dir / root / "poses" / f"{sequence}.txt"
    poses = None
    if poses_file.is_file():
        try:
            camera = read_kitti_poses(poses_file)
        except InputError as e:
            raise ConfigError(f"dataset: {e}") from None
        if len(camera) != len(scans):
            raise ConfigError(f"dataset: {poses_file} holds {len(camera)} poses for {len(scans)} scans in {folder}")
        poses = poses_of_attached_frame(camera, Tr)
    relative = root / "sequences" / sequence / "velodyne"
    return DatasetSequence(
        [
            DatasetScan(
                str(relative / path.name),
                "bin",
                None if poses is None else poses[k].tolist(),
                None if times is None else times[k],
            )
            for k, path in enumerate(scans)
        ],
        SENSOR,
        f"KITTI odometry sequence {sequence}" + ("" if poses is not None else " (no poses)"),
        deskewed=True,
    )


def read_calib(path: Path) -> np.ndarray:
    """``Tr`` (lidar to camera 0, 4x4) of a KITTI odometry ``calib.txt``."""
    if not path.is_file():
        raise ConfigError("dataset: calib.txt not found (KITTI odometry keeps Tr, lidar to camera 0, there)", path)
    for line in path.read_text().splitlines():
        key, _, values = line.partition(":")
        if key.strip() == "Tr":
            try:
                numbers = np.array(values.split(), dtype=np.float64)
            except ValueError:
                numbers = np.zeros(0)
            if numbers.size != 12 or not np.isfinite(numbers).all():
                raise ConfigError(f"dataset: Tr holds {numbers.size} numbers, expected 12 finite ones (3x4)", path)
            Tr = np.eye(4)
            Tr[:3] = numbers.reshape(3, 4)
            return Tr
    raise ConfigError("dataset: calib.txt has no Tr line (lidar to camera 0)", path)


def _sequence_folder(root: Path, sequence: str) -> Path:
    sequences = root / "sequences"
    if not sequences.is_dir():
        raise ConfigError(f"dataset: not a KITTI odometry folder (no sequences/ in {root})")
    folder = sequences / sequence
    if not sequence or not folder.is_dir():
        known = sorted(p.name for p in sequences.iterdir() if p.is_dir())
        raise ConfigError(
            f"dataset.sequence: no sequence {sequence!r} in {sequences}; its sequences: {', '.join(known)}"
        )
    return folder


def _times(path: Path, count: int) -> list[float] | None:
    if not path.is_file():
        return None
    try:
        times = [float(line) for line in path.read_text().split()]
    except ValueError:
        raise ConfigError("dataset: times.txt holds something other than one time (s) per line", path) from None
    if len(times) != count:
        raise ConfigError(f"dataset: times.txt holds {len(times)} times for {count} scans", path)
    return times


def describe(path: Path) -> str | None:
    """The sequences of a KITTI odometry folder, their scans and whether poses are there."""
    sequences = path / "sequences"
    if not sequences.is_dir():
        return None
    lines = [f"{path}: KITTI odometry dataset"]
    for folder in sorted(p for p in sequences.iterdir() if p.is_dir()):
        count = sum(1 for _ in (folder / "velodyne").glob("*.bin"))
        times = _times(folder / "times.txt", count) if (folder / "times.txt").is_file() else None
        span = f", {times[-1] - times[0]:.1f} s" if times else ""
        poses = "poses" if (path / "poses" / f"{folder.name}.txt").is_file() else "no poses"
        calib = "" if (folder / "calib.txt").is_file() else ", no calib.txt"
        lines.append(f"  sequence {folder.name}: {count} scans{span}, {poses}{calib}")
    return "\n".join(lines)
