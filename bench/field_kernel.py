"""Benchmark: the field kernel against the pandas groupby reference, same clouds, same run.

Two clouds of 1,000,000 points each (a noisy ring scene around the sensor, cloud 2 shifted by a
few centimetres) on the experimental 36 x 5 spherical grid. Prints the machine, points per
second of both implementations and their ratio. Targets: >= 20 M points/s on one core and
>= 4x the baseline. Run: python bench/field_kernel.py [--points N] [--repeat R]
"""

from __future__ import annotations

import argparse

import numpy as np

from lidarfield.field.grid import CartesianGrid, FieldSettings, SphericalGrid
from lidarfield.field.kernel import discrepancy_field, field_from_voxel_ids
from lidarfield.field.reference import discrepancy_field_reference, field_from_voxel_ids_reference
from lidarfield.field.significance import Viewpoint
from timing import best_time, machine  # bench/timing.py

SENSOR2 = (1.0, 0.0, 0.0)
SHARED = 0.9  # the share of each cloud's points the other sensor could see, drawn at random


def clouds(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    azimuth = rng.uniform(-np.pi, np.pi, n)
    elevation = np.radians(rng.uniform(-16.0, 16.0, n))
    r = rng.uniform(2.0, 60.0, n)
    xyz1 = np.column_stack(
        [r * np.cos(elevation) * np.cos(azimuth), r * np.cos(elevation) * np.sin(azimuth), r * np.sin(elevation)]
    )
    xyz2 = xyz1 + np.array([0.03, -0.02, 0.01]) + rng.normal(scale=0.02, size=xyz1.shape)
    return xyz1, xyz2


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=1_000_000, help="points per cloud")
    parser.add_argument("--repeat", type=int, default=5, help="best of this many runs")
    args = parser.parse_args()
    xyz1, xyz2 = clouds(args.points)
    total = 2 * args.points
    print(machine())
    print(f"numpy {np.__version__}; two clouds of {args.points:,} points; best of {args.repeat}")
    cases = {
        "spherical 36x5": SphericalGrid(),
        "spherical 36x5, 5 range shells": SphericalGrid(range_edges_m=(0.0, 5.0, 10.0, 20.0, 40.0, 80.0)),
        "cartesian 1 m": CartesianGrid(cell_m=1.0),
    }
    print("end to end: binning + aggregation (reference: plain binning in degrees); aggregation: from voxel ids")
    rng = np.random.default_rng(1)
    viewpoint = Viewpoint(SENSOR2, rng.random(args.points) < SHARED, rng.random(args.points) < SHARED)
    for name, grid in cases.items():
        settings = FieldSettings(grid)
        ids1, ids2 = grid.assign(xyz1), grid.assign(xyz2)
        runs = {
            "end to end": (
                lambda: discrepancy_field(xyz1, xyz2, settings),
                lambda: discrepancy_field_reference(xyz1, xyz2, settings),
            ),
            "aggregation": (
                lambda: field_from_voxel_ids(ids1, xyz1, ids2, xyz2, settings),
                lambda: field_from_voxel_ids_reference(ids1, xyz1, ids2, xyz2, settings),
            ),
            # Sensor 2 1 m away: the vectors' covariance gains the change of viewpoint on the
            # shared points (a second pass of sums over them).
            "+ viewpoint": (
                lambda: field_from_voxel_ids(ids1, xyz1, ids2, xyz2, settings, viewpoint=viewpoint),
                lambda: field_from_voxel_ids_reference(ids1, xyz1, ids2, xyz2, settings, viewpoint=viewpoint),
            ),
        }
        for what, (fast, reference) in runs.items():
            kernel, _ = best_time(fast, args.repeat)
            baseline, _ = best_time(reference, max(1, args.repeat // 2))
            print(
                f"{name:31s} {what:11s} kernel {kernel * 1e3:6.1f} ms = {total / kernel / 1e6:5.1f} M points/s | "
                f"pandas groupby {baseline * 1e3:6.1f} ms = {total / baseline / 1e6:4.1f} M points/s | "
                f"ratio {baseline / kernel:4.1f}x"
            )


if __name__ == "__main__":
    main()
