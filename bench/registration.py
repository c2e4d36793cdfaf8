"""Time and accuracy of each registration method on the Ouster OS1-128 frames 0 -> 1 (default
settings), against point-to-point ICP measured in the same run.

Run: python bench/registration.py [--repeat N]
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from timing import best_time, machine  # bench/timing.py

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("LIDARFIELD_DATA", ROOT.parent / "shared" / "data")) / "ouster-os1-128"


def main() -> int:
    from lidarfield.io import read_scan
    from lidarfield.io.pose_files import read_kitti_poses
    from lidarfield.registration import register_pair

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    poses = read_kitti_poses(DATA / "OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt")
    scans = [read_scan(DATA / f"lb_n3_scan{k}_xyz_refl_float32.bin") for k in (0, 1)]
    for scan, pose in zip(scans, poses):
        scan.pose = pose
    print(machine())
    print(f"scans: {len(scans[0])} and {len(scans[1])} points; best of {args.repeat} runs")
    baseline = None
    for method in ("icp", "icp_point_to_plane", "gicp", "ndt", "identity"):
        best, pair = best_time(lambda: register_pair(*scans, {"method": method}), args.repeat)
        baseline = baseline or best
        reg = pair.registration
        print(
            f"{method:20s} {best:7.3f} s  x{best / baseline:5.2f} of icp   error "
            f"{reg['translation_error_m'] * 100:5.2f} cm "
            f"{reg['rotation_error_deg']:.3f} deg  fitness {reg['fitness']:.3f}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
