"""Benchmark: one simulated scan of the paper scene, Open3D kernel against the numpy reference.

The paper-intersection scene, sensor paper-sim-80 at (0, 0, 3): 80 channels x 1800 azimuth
steps of 0.2 deg = 144,000 rays. Prints the machine, seconds per scan and rays per second of
``simulate_scan`` (whole scan: rays, casting, float64 refinement, Scan), of the Open3D kernel
alone (``first_hits``) and of the plain numpy Moller-Trumbore reference on the same rays, and
their ratio. trimesh's own intersector needs rtree or embreex, which the project does not
install, so the numpy kernel is the baseline. Target: under 0.5 s per scan.
Run: python bench/raycast.py [--repeat R]
"""

from __future__ import annotations

import argparse

import numpy as np

from lidarfield.poses import pose_from_xyzrpy as pose_from_values
from lidarfield.sensors.models import PRESETS
from lidarfield.simulation.raycast import (
    azimuth_steps,
    beam_directions,
    first_hits,
    first_hits_reference,
    simulate_scan,
)
from lidarfield.simulation.scene import load_scene
from timing import best_time, machine  # bench/timing.py


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()

    scene, sensor = load_scene("paper-intersection"), PRESETS["paper-sim-80"]
    pose = pose_from_values([0, 0, 3, 0, 0, 0])
    steps, n = azimuth_steps(sensor)
    directions = beam_directions(steps * 2 * np.pi / n, np.radians(sensor.elevation_deg)).reshape(-1, 3)
    origins = np.broadcast_to(pose[:3, 3], directions.shape).copy()
    mesh = scene.mesh_at(0.0)
    rays = len(directions)

    print(machine())
    print(f"scene: paper-intersection ({len(mesh.faces)} triangles), sensor paper-sim-80, {rays:,} rays")
    scan_s, scan = best_time(lambda: simulate_scan(scene, sensor, pose), args.repeat)
    rolling_s, _ = best_time(
        lambda: simulate_scan(
            scene, sensor, pose, rolling_shutter=True, linear_velocity_mps=(5, 0, 0), angular_velocity_rps=(0, 0, 0.5)
        ),
        args.repeat,
    )
    kernel_s, (fast, _) = best_time(lambda: first_hits(mesh, origins, directions), args.repeat)
    reference_s, (plain, _) = best_time(lambda: first_hits_reference(mesh, origins, directions), 1)
    agree = np.array_equal(np.isfinite(fast), np.isfinite(plain))
    print(
        f"simulate_scan (whole scan):      {scan_s:.3f} s/scan  {rays / scan_s / 1e6:6.2f} M rays/s  "
        f"({len(scan):,} points; target < 0.5 s: {'met' if scan_s < 0.5 else 'MISSED'})"
    )
    print(f"  with rolling shutter:          {rolling_s:.3f} s/scan  {rays / rolling_s / 1e6:6.2f} M rays/s")
    print(f"first_hits (Open3D + float64):   {kernel_s:.3f} s       {rays / kernel_s / 1e6:6.2f} M rays/s")
    print(f"first_hits_reference (numpy):    {reference_s:.3f} s       {rays / reference_s / 1e6:6.2f} M rays/s")
    print(f"kernel speed-up over reference:  {reference_s / kernel_s:.1f}x (same hits: {agree})")


if __name__ == "__main__":
    main()
