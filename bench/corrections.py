"""Benchmark: the correcting hypotheses (``realign``, ``range_calibration``, ``deskew``) on a pair
of 120,000-point clouds (target < 1 s each), against the time of computing the field of the same
pair in the same run; with baselines in the same run: ``realign`` on every point of cloud 2 (its
default until its ``max_points`` subset, 2026-11-25) and on 0.2 m voxels (its default before
that), and the field without the scan patterns' covariance (before 2026-11-25).

The pair: the simulated paper intersection seen twice by the paper's 80-channel sensor at a
0.14 deg azimuth step (2 cm range noise, different seeds, scan 2 yawed 0.21 deg and measured with
``range_scale=1.003, range_offset_m=0.03``), registered by the truth, 120,000 points of each
cloud kept (evenly spaced rows). "The field" is ``analyse_field`` with the default settings
(binning, aggregation, tags and statistics: the field job's work). ``deskew`` is asked for a
10 m/s motion of both clouds (``motion_source: settings``: the simulated scans are still).

Run: ``python bench/corrections.py [--repeat N]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import os

import numpy as np

from lidarfield.analysis.field_stats import analyse_field
from lidarfield.field.grid import field_settings_from_config
from lidarfield.field.kernel import field_from_voxel_ids
from lidarfield.field.pair_field import scan_patterns
from lidarfield.hypotheses import apply_step
from lidarfield.pair import RegisteredPair
from lidarfield.poses import pose_from_xyzrpy
from lidarfield.registration import register_pair
from lidarfield.sensors.models import PRESETS
from lidarfield.simulation.raycast import simulate_scan
from lidarfield.simulation.scene import load_scene
from timing import best_time, machine  # bench/timing.py

N = 120_000


def faulty_pair(n: int = N) -> RegisteredPair:
    scene = load_scene("paper-intersection")
    sensor = dataclasses.replace(PRESETS["paper-sim-80"], azimuth_resolution_deg=0.14)
    scans = [
        simulate_scan(scene, sensor, pose_from_xyzrpy([0, 0, 3, 0, 0, 0]), seed=1, range_noise_m=0.02),
        simulate_scan(
            scene,
            sensor,
            pose_from_xyzrpy([0, 0, 3, 0, 0, 0.0037]),
            seed=2,
            range_noise_m=0.02,
            range_scale=1.003,
            range_offset_m=0.03,
        ),
    ]
    pair = register_pair(*scans, "truth")
    if min(len(pair.xyz1), len(pair.xyz2)) < n:
        raise SystemExit(f"the simulated clouds have {len(pair.xyz1)} and {len(pair.xyz2)} points, fewer than {n}")
    keep = [np.zeros(len(xyz), bool) for xyz in (pair.xyz1, pair.xyz2)]
    for k in keep:
        k[np.linspace(0, len(k) - 1, n).round().astype(np.int64)] = True
    return pair.subset(*keep)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3, help="best of this many runs")
    args = parser.parse_args()
    pair = faulty_pair()
    print(machine())
    print(f"load average {os.getloadavg()[0]:.2f}; two clouds of {len(pair.xyz1):,} and {len(pair.xyz2):,} points")
    settings = field_settings_from_config({})
    field, _ = best_time(lambda: analyse_field(pair, settings), args.repeat)
    print(f"field (analyse_field, default settings): {field:.3f} s")
    ids = settings.grid.assign(pair.xyz1), settings.grid.assign(pair.xyz2)
    kernel = {}
    for name, patterns in (("with", scan_patterns(pair)), ("without", (None, None))):
        kernel[name], _ = best_time(
            lambda: field_from_voxel_ids(ids[0], pair.xyz1, ids[1], pair.xyz2, settings, patterns=patterns), args.repeat
        )
    print(
        f"field kernel with the scan patterns' covariance {kernel['with']:.3f} s, without {kernel['without']:.3f} s "
        f"= {kernel['with'] / kernel['without']:.2f} x"
    )
    moving = {"motion_source": "settings", "velocity_mps": [10.0, 0.0, 0.0]}
    seconds_of = {}
    for step in (
        {"range_calibration": {}},
        {"range_calibration": {"per_ring": True}},
        {"realign": {}},
        {"realign": {"max_points": N}},
        {"realign": {"voxel_m": 0.2}},
        {"deskew": moving},
    ):
        seconds, outcome = best_time(lambda: apply_step(pair, step), args.repeat)
        seconds_of[str(step)] = seconds
        c = outcome.fitted
        if "scale" in c:
            fit = f"scale {c['scale']:.5f}, offset {c['offset_m'] * 1e3:.1f} mm, {c['points']} points"
        elif "translation_m" in c:
            fit = (
                f"translation {np.round(c['translation_m'], 4).tolist()} m, angle {c['angle_deg']:.4f} deg, "
                f"{c['correspondences']} pairs"
            )
        else:
            fit = f"largest displacement {max(c[k]['max_displacement_m'] for k in ('cloud1', 'cloud2')):.3f} m"
        print(
            f"{list(step)[0]:18s} {str(list(step.values())[0]):18s} {seconds:.3f} s "
            f"= {seconds / field:.2f} x the field | {fit}"
        )
    subset, every_point = seconds_of[str({"realign": {}})], seconds_of[str({"realign": {"max_points": N}})]
    print(f"realign on its default subset of cloud 2 / on every point: {subset / every_point:.2f} x")
    print(f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
