"""Planning a 1,000-scan KITTI odometry sequence named as a dataset against the same scans
named as files with a poses file (what Snakemake does when it parses the Snakefile:
validate_config), in the same run.

Planning reads a dataset's index only (the file listing, calib.txt, times.txt, poses/XX.txt),
never the points, so the scans here are tiny .bin files: their size does not matter.

Run: python bench/dataset_planning.py [n_scans] [repeat]
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

from lidarfield.io.pose_files import write_kitti_poses
from lidarfield.poses import pose_from_xyzrpy
from lidarfield.study.config import validate_config
from timing import best_time, machine  # bench/timing.py

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # KITTI's own Tr
from helpers.datasets import KITTI_TR  # noqa: E402


def write_layout(root: Path, n: int) -> tuple[dict, dict, dict]:
    """A KITTI odometry sequence 00 of ``n`` one-point scans on a 10 m/s drive, and the three
    ways of naming it: the dataset, a glob with lidar poses, a list of files with lidar poses."""
    folder = root / "dataset" / "sequences" / "00"
    (folder / "velodyne").mkdir(parents=True)
    point = np.array([[10.0, 0.0, 0.0, 0.5]], dtype=np.float32).tobytes()
    for k in range(n):
        (folder / "velodyne" / f"{k:06d}.bin").write_bytes(point)
    (folder / "calib.txt").write_text("Tr: " + " ".join(f"{v:.12e}" for v in KITTI_TR[:3].ravel()) + "\n")
    (folder / "times.txt").write_text("".join(f"{0.1 * k:e}\n" for k in range(n)))
    lidar = np.stack([pose_from_xyzrpy([1.0 * k, 0.0, 0.0, 0.0, 0.0, 0.001 * k]) for k in range(n)])
    (root / "dataset" / "poses").mkdir()
    write_kitti_poses(root / "dataset" / "poses" / "00.txt", KITTI_TR @ lidar @ np.linalg.inv(KITTI_TR))
    write_kitti_poses(root / "lidar_poses.txt", lidar)
    files = [f"dataset/sequences/00/velodyne/{k:06d}.bin" for k in range(n)]
    return (
        {"dataset": {"format": "kitti", "path": "dataset", "sequence": "00"}},
        {"scans": "dataset/sequences/00/velodyne/*.bin", "poses": "lidar_poses.txt", "sensor": "hdl64"},
        {"scans": files, "poses": "lidar_poses.txt", "sensor": "hdl64"},
    )


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    repeat = int(sys.argv[2]) if len(sys.argv) > 2 else 7
    print(machine())
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        ways = dict(
            zip(("dataset: {format: kitti}", "scans: glob + poses", "scans: list + poses"), write_layout(root, n))
        )

        def plan(entry: dict):
            return validate_config({"sequences": {"drive": entry}}, base_dir=root)

        plans = {label: plan(entry) for label, entry in ways.items()}  # warm: imports, file cache
        first = plans["dataset: {format: kitti}"].pairs
        for label, study in plans.items():
            assert len(study.pairs) == n - 1, label
            pose = np.array(study.pairs["drive-500"].scan2.spec["pose"])
            assert np.abs(pose - np.array(first["drive-500"].scan2.spec["pose"])).max() < 1e-9, label
        times = {}
        for _ in range(2):  # interleaved, so that a change in the machine's load hits all three
            for label, entry in ways.items():
                seconds, _ = best_time(lambda entry=entry: plan(entry), repeat=repeat)
                times[label] = min(times.get(label, float("inf")), seconds)
        base = times["dataset: {format: kitti}"]
        for label, seconds in times.items():
            print(
                f"{n} scans, {n - 1} pairs, {label}: {seconds * 1000:.0f} ms (best of {2 * repeat}); "
                f"dataset / this: {base / seconds:.2f}"
            )


if __name__ == "__main__":
    main()
