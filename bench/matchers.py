"""Open3D against small_gicp for the ICP-family methods, on the shared real scans, with the same
settings (the register defaults: the same downsampled clouds, 0.2 m or 1 deg at the median
range, 1 m correspondence distance, 50 iterations at most, normals / covariances from 30
neighbours) and the same fitness measure (lidarfield's: the share of scan-2 points within 0.5 m
of scan 1), from the same 8 seeded rematch starts about each pair's reference pose.

small_gicp stops when an iteration changes the pose by less than ``--epsilon`` (metres and
radians); Open3D when fitness and RMSE change by less than 1e-6 (relative). Its own default,
1e-3 m and 0.1 deg, stops earlier than Open3D; ``--epsilon 1e-6`` asks for the same precision.

Run: python bench/matchers.py [--trials 8] [--threads 2] [--epsilon 1e-6] [--methods gicp ...]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from timing import machine  # bench/timing.py

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("LIDARFIELD_DATA", ROOT.parent / "shared" / "data"))
SMALL_GICP_TYPES = {"icp": "ICP", "icp_point_to_plane": "PLANE_ICP", "gicp": "GICP"}


def pairs():
    """(name, xyz1, xyz2 in its own frame, reference T_1_2) of each shared real pair."""
    from lidarfield.io import read_scan
    from lidarfield.io.pose_files import read_kitti_poses, read_pose
    from lidarfield.poses import relative_pose

    hdl = DATA / "hdl32-pair"
    yield (
        "hdl32-pair",
        read_scan(hdl / "target.ply").xyz,
        read_scan(hdl / "source.ply").xyz,
        read_pose(hdl / "T_target_source.txt"),
    )
    expd = DATA / "expd-vlp16"
    yield (
        "expd-vlp16",
        read_scan(expd / "Cloud1_ExpD.txt").xyz,
        read_scan(expd / "Cloud10_ExpD.txt").xyz,
        read_pose(ROOT / "config" / "expd-T_1_10.txt"),
    )
    ouster = DATA / "ouster-os1-128"
    poses = read_kitti_poses(ouster / "OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt")
    scans = [read_scan(ouster / f"lb_n3_scan{k}_xyz_refl_float32.bin").xyz for k in (0, 1)]
    yield "ouster-os1-128", scans[0], scans[1], relative_pose(poses[0], poses[1])


def open3d_runs(method, xyz1, xyz2, guesses, p):
    from lidarfield.registration import matching
    from lidarfield.registration.core import scan_match

    started = time.perf_counter()
    clouds = matching.prepare(method, xyz1, xyz2, p)
    prepared = time.perf_counter() - started
    estimates = [scan_match(method, clouds, guess, p)[0] for guess in guesses]
    return estimates, prepared, time.perf_counter() - started, clouds


def small_gicp_runs(method, clouds, guesses, p, threads, epsilon):
    import small_gicp

    started = time.perf_counter()
    target = small_gicp.PointCloud(np.asarray(clouds.target.points))
    source = small_gicp.PointCloud(np.asarray(clouds.source.points))
    tree = small_gicp.KdTree(target, num_threads=threads)
    if method != "icp":
        small_gicp.estimate_normals_covariances(target, tree, p["normal_max_nn"], threads)
        small_gicp.estimate_normals_covariances(
            source, small_gicp.KdTree(source, num_threads=threads), p["normal_max_nn"], threads
        )
    prepared = time.perf_counter() - started
    estimates = [
        small_gicp.align(
            target,
            source,
            tree,
            init_T_target_source=guess,
            registration_type=SMALL_GICP_TYPES[method],
            max_correspondence_distance=p["max_correspondence_m"],
            num_threads=threads,
            max_iterations=p["max_iterations"],
            **epsilon,
        ).T_target_source
        for guess in guesses
    ]
    return estimates, prepared, time.perf_counter() - started


def main() -> int:
    from lidarfield.analysis.rematch import perturbed, start_offsets
    from lidarfield.poses import pose_error
    from lidarfield.registration import DEFAULTS, matching

    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--trials", type=int, default=8)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--epsilon", type=float, help="small_gicp's convergence thresholds (default: its own)")
    parser.add_argument("--methods", nargs="+", choices=list(SMALL_GICP_TYPES), default=list(SMALL_GICP_TYPES))
    args = parser.parse_args()
    epsilon = {} if args.epsilon is None else {"translation_epsilon": args.epsilon, "rotation_epsilon": args.epsilon}
    p = dict(DEFAULTS)
    offsets = start_offsets(args.trials, 0.5, 2.0, seed=0)
    print(machine())
    print(
        f"{args.trials} starts within 0.5 m and 2 deg of the reference; small_gicp with {args.threads} threads, "
        f"epsilon {args.epsilon or 'its default'}; times: preparation + all trials"
    )
    print(
        f"{'pair':15s} {'method':19s} {'backend':10s} {'prep s':>7s} {'total s':>8s} {'ratio':>6s} "
        f"{'med err cm':>10s} {'max err cm':>10s} {'med deg':>8s} {'fitness':>8s} {'vs open3d cm':>12s}"
    )
    for name, xyz1, xyz2, reference in pairs():
        guesses = [perturbed(reference, o) for o in offsets]
        for method in args.methods:
            o3d_T, o3d_prep, o3d_total, clouds = open3d_runs(method, xyz1, xyz2, guesses, p)
            sg_T, sg_prep, sg_total = small_gicp_runs(method, clouds, guesses, p, args.threads, epsilon)
            for backend, estimates, prep, total in (
                ("open3d", o3d_T, o3d_prep, o3d_total),
                ("small_gicp", sg_T, sg_prep, sg_total),
            ):
                errors = np.array([pose_error(T, reference) for T in estimates])
                fitness = np.median(
                    [
                        matching.evaluate(clouds.scored_source, clouds.scored_target, T, p["fitness_distance_m"])[0]
                        for T in estimates
                    ]
                )
                apart = np.median([pose_error(T, T0)[0] for T, T0 in zip(estimates, o3d_T)]) * 100
                print(
                    f"{name:15s} {method:19s} {backend:10s} {prep:7.3f} {total:8.3f} {total / o3d_total:6.2f} "
                    f"{np.median(errors[:, 0]) * 100:10.2f} {errors[:, 0].max() * 100:10.2f} "
                    f"{np.median(errors[:, 1]):8.3f} "
                    f"{fitness:8.3f} {apart:12.2f}"
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
