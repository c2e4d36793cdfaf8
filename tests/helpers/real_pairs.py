"""The real shared pairs with their reference poses, started off them: what ``realign`` is
measured on against the tool's registrations (``tests/unit/test_realign_real.py``,
``bench/realign_real.py``, the table in docs/hypotheses.md).

The pairs (from the shared data folder): the method's ExpD VLP-16 pair (Cloud10 onto Cloud1 by
``config/expd-T_1_10.txt``, the authors' translation-only NDT), the HDL-32E pair of fast_gicp /
small_gicp (scan 251371071 onto 251370668 by ``T_target_source.txt``; ``relative.txt`` is the
other repository's estimate) and the Ouster OS1-128 frames 0 -> 1 and 1 -> 2 (by their KITTI
poses, from scan matching). None of the references is a truth: each is a registration.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from lidarfield.field.free_space import shared_points
from lidarfield.hypotheses import apply_step
from lidarfield.io import read_scan
from lidarfield.io.pose_files import read_kitti_poses, read_pose
from lidarfield.pair import RegisteredPair
from lidarfield.poses import apply_pose, pose_from_xyzrpy, relative_pose
from lidarfield.registration import register_pair
from lidarfield.scan import Scan
from lidarfield.sensors.models import PRESETS

ROOT = Path(__file__).resolve().parents[2]
PAIRS = ("expd", "hdl32", "os1 0->1", "os1 1->2")
REGISTRATIONS = ("gicp", "ndt", "icp_point_to_plane", "icp")
# The starts, 0.3 m and 0.5 deg off the reference (offset @ T_ref; x y z in m, roll pitch yaw in
# rad, frame 1).
OFFSETS = {
    "+x, yaw": pose_from_xyzrpy([0.3, 0, 0, 0, 0, np.radians(0.5)]),
    "yz, roll": pose_from_xyzrpy([0, 0.3 / np.sqrt(2), 0.3 / np.sqrt(2), np.radians(0.5), 0, 0]),
}


@dataclass
class RealPair:
    name: str
    scan1: Scan
    scan2: Scan
    reference: np.ndarray  # T_1_2
    sensor: str  # the preset realign is given for both scans
    other_reference: np.ndarray | None = None  # an independent estimate, where one is published


def real_pair(data: Path, name: str) -> RealPair:
    """One of ``PAIRS``, read from the shared data folder ``data``."""
    if name == "expd":
        scans = [read_scan(data / "expd-vlp16" / f"Cloud{k}_ExpD.txt") for k in (1, 10)]
        return RealPair(name, *scans, read_pose(ROOT / "config" / "expd-T_1_10.txt"), "vlp16")
    if name == "hdl32":
        folder = data / "hdl32-pair"
        scans = [read_scan(folder / f"{stamp}.pcd") for stamp in (251370668, 251371071)]
        return RealPair(
            name, *scans, read_pose(folder / "T_target_source.txt"), "hdl32", read_pose(folder / "relative.txt")
        )
    if name in ("os1 0->1", "os1 1->2"):
        folder = data / "ouster-os1-128"
        a, b = (0, 1) if name == "os1 0->1" else (1, 2)
        poses = read_kitti_poses(folder / "OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt")
        scans = [read_scan(folder / f"lb_n3_scan{k}_xyz_refl_float32.bin") for k in (a, b)]
        return RealPair(name, *scans, relative_pose(poses[a], poses[b]), "os1-128")
    raise ValueError(f"unknown pair {name!r}; pairs: {', '.join(PAIRS)}")


def point_distance_cm(T: np.ndarray, reference: np.ndarray, xyz2: np.ndarray) -> float:
    """Median over scan 2's points ``xyz2`` (its own frame) of ``|T p - T_ref p|``, cm."""
    difference = xyz2 @ (T[:3, :3] - reference[:3, :3]).T + (T[:3, 3] - reference[:3, 3])
    return float(np.median(np.linalg.norm(difference, axis=1)) * 100)


def registered(real: RealPair, method: str, start: np.ndarray) -> np.ndarray:
    """Where the tool's registration ``method`` (default settings) lands from ``start``."""
    return register_pair(real.scan1, real.scan2, {"method": method, "guess": start.ravel().tolist()}).T_1_2


def pair_at(real: RealPair, T: np.ndarray | None = None, models: bool = True) -> RegisteredPair:
    """``real`` registered at ``T`` (default: its reference) by a transform, as a study of it
    registered by a pose file is, with both scans' sensor models or none."""
    T = real.reference if T is None else T
    model = PRESETS[real.sensor] if models else None
    xyz2 = real.scan2.xyz @ T[:3, :3].T + T[:3, 3]
    return RegisteredPair(real.scan1.xyz, xyz2, T, model, model, registration={"method": "transform"})


def realigned(real: RealPair, start: np.ndarray, params: dict | None = None, models: bool = True) -> np.ndarray:
    """Where ``realign`` lands on the pair registered at ``start`` (as the suggestions run it
    on a pair registered off), with both scans' sensor models or none."""
    return apply_step(pair_at(real, start, models), {"realign": params or {}}).T_1_2


def shared_pair(real: RealPair, T: np.ndarray) -> RealPair:
    """``real`` cut to the points both sensors could see with sensor 2 at ``T`` (the field's
    shared points, as ``realign``'s refit takes them)."""
    model = PRESETS[real.sensor]
    shared1, shared2 = shared_points(RegisteredPair(real.scan1.xyz, apply_pose(T, real.scan2.xyz), T, model, model))
    return replace(real, scan1=real.scan1.subset(shared1), scan2=real.scan2.subset(shared2))
