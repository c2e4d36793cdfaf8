"""Dataset layouts written from simulated scans with known poses, for the dataset readers' tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lidarfield import load_scene, pose_from_xyzrpy, sensor_model, simulate_scan, write_scan
from lidarfield.io.pose_files import write_kitti_poses
from lidarfield.poses import invert_pose

# KITTI odometry sequence 00's own Tr (lidar to camera 0): a rotation that turns the lidar's
# x (forward) into the camera's z, and a few centimetres of lever arm.
KITTI_TR = np.array(
    [
        [4.276802385584e-04, -9.999672484946e-01, -8.084491683471e-03, -1.198459927713e-02],
        [-7.210626507497e-03, 8.081198471645e-03, -9.999413164504e-01, -5.403984729748e-02],
        [9.999738645903e-01, 4.859485810390e-04, -7.206933692422e-03, -2.921968648686e-01],
        [0.0, 0.0, 0.0, 1.0],
    ]
)
# Lidar poses of a short drive through the paper's intersection: forward along x with a turn.
DRIVE_XYZRPY = [
    [0.0, 0.0, 3.0, 0.0, 0.0, 0.0],
    [1.0, 0.1, 3.0, 0.0, 0.0, 0.02],
    [2.0, 0.3, 3.0, 0.0, 0.0, 0.05],
    [3.0, 0.6, 3.0, 0.0, 0.0, 0.08],
]


def simulated_drive(sensor: str = "vlp16") -> tuple[list, np.ndarray]:
    """Scans of the paper's intersection from the drive's poses (in their own lidar frame) and
    the poses (world-from-lidar)."""
    scene, model = load_scene("paper-intersection"), sensor_model(sensor)
    poses = np.stack([pose_from_xyzrpy(p) for p in DRIVE_XYZRPY])
    scans = [simulate_scan(scene, model, pose, seed=k, range_noise_m=0.02) for k, pose in enumerate(poses)]
    return scans, poses


def write_kitti_layout(root: Path, sequence: str = "07", Tr: np.ndarray = KITTI_TR, with_poses: bool = True):
    """A KITTI odometry folder of the simulated drive: velodyne/*.bin, calib.txt, times.txt and
    the camera-0 poses P = Tr @ L @ inv(Tr) of the lidar poses L (relative to the first scan).
    Returns the scans and their lidar poses relative to the first."""
    scans, poses = simulated_drive()
    lidar = invert_pose(poses[0]) @ poses
    folder = root / "sequences" / sequence
    (folder / "velodyne").mkdir(parents=True)
    for k, scan in enumerate(scans):
        write_scan(scan, folder / "velodyne" / f"{k:06d}.bin")
    P0 = " ".join(["7.07e+02", "0", "6.01e+02", "0", "0", "7.07e+02", "1.83e+02", "0", "0", "0", "1", "0"])
    Tr_text = " ".join(f"{v:.12e}" for v in Tr[:3].ravel())
    (folder / "calib.txt").write_text(f"P0: {P0}\nTr: {Tr_text}\n")
    (folder / "times.txt").write_text("".join(f"{0.1 * k:e}\n" for k in range(len(scans))))
    if with_poses:
        (root / "poses").mkdir()
        write_kitti_poses(root / "poses" / f"{sequence}.txt", Tr @ lidar @ np.linalg.inv(Tr))
    return scans, lidar


def stage_statistics(planned, pair_name: str) -> list[tuple[int, int, dict]]:
    """Each stage's (removed1, removed2, field statistics) of a planned study's pair,
    registered by truth, computed in this process."""
    from lidarfield.analysis.field_stats import analyse_field
    from lidarfield.commands.jobs import recorded_scan
    from lidarfield.registration import register_pair
    from lidarfield.study.stack import apply_stack

    pair = planned.pairs[pair_name]
    registered = register_pair(recorded_scan(pair.scan1.spec), recorded_scan(pair.scan2.spec), "truth")
    stages = apply_stack(registered, planned.hypotheses, planned.base_dir, planned.grid_section)
    return [(s.removed1, s.removed2, analyse_field(s.pair, planned.grid)[1]) for s in stages]


def assert_same_stage_statistics(stages: list, other: list) -> None:
    """The same points removed, stage by stage, and the same statistics within 1e-9 (the rigid
    fit's information matrix, in points x m^2 (up to ~1e6), within 1e-9 of its largest entry:
    its small entries differ by ~1e-12 of that, rounding)."""
    assert len(stages) == len(other)
    for (*removed, stats), (*removed_other, stats_other) in zip(stages, other):
        assert removed == removed_other
        assert stats.keys() == stats_other.keys() and stats["voxels_valid"] > 0
        for key, value in stats.items():
            if isinstance(value, str):
                assert value == stats_other[key], key
            else:
                atol = 1e-9 * np.abs(value).max() if key == "rigid_information" else 1e-9
                assert np.allclose(value, stats_other[key], rtol=0, atol=atol, equal_nan=True), key
