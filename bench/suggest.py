"""Benchmark: "what to try next" on a 90,000-point pair (45,000 per cloud), per candidate.

Target: under 1 s per candidate on one core. Each candidate's time is split into the
hypothesis itself (``apply_step``) and the rest (its field from the voxel ids binned once, and
the comparison); the baseline, in the same run, is the same candidate with both fields
recomputed from scratch by the pandas reference (``field_reference``), i.e. without binning
once. For ``outliers`` the hypothesis is also timed with Open3D's ``remove_statistical_outlier``
(its previous implementation, same keep-masks), Open3D imported beforehand, and the import of
Open3D and of scipy's k-d tree are timed in fresh processes. The pair is the street scene of
``bench/hypotheses.py`` (VLP-16 limits, sensor 2 3 m away), the study grid 36 x 5 over
-20..20 deg.

Run: ``python bench/suggest.py [points_per_cloud]``. Pin to one core with ``taskset -c 0``.
"""

from __future__ import annotations

import subprocess
import sys
import time

import numpy as np

from hypotheses import street_scan  # bench/hypotheses.py
from lidarfield.analysis.suggest import candidate_steps, compare_fields, suggestions
from lidarfield.field.grid import field_settings_from_config
from lidarfield.field.reference import discrepancy_field_reference
from lidarfield.hypotheses import apply_step
from lidarfield.pair import RegisteredPair
from lidarfield.poses import pose_from_xyzrpy
from lidarfield.sensors.models import PRESETS
from timing import best_time, machine  # bench/timing.py

GRID = {
    "kind": "spherical",
    "azimuth_bins": 36,
    "azimuth_offset_deg": 0.0,
    "elevation_deg": [-20.0, 20.0],
    "elevation_bins": 5,
    "range_edges_m": None,
    "min_points": 30,
    "max_component_m": None,
}


def main(n: int) -> None:
    rng = np.random.default_rng(0)
    T_1_2 = pose_from_xyzrpy([0.3, 3.0, 0.0, 0.0, 0.01, 0.02])
    pair = RegisteredPair(
        street_scan(n, np.eye(4), rng), street_scan(n, T_1_2, rng), T_1_2, PRESETS["vlp16"], PRESETS["vlp16"]
    )
    settings = field_settings_from_config(GRID)
    candidates = candidate_steps(None, [], ".", GRID)
    print(machine())
    print(f"pair: {n:,} + {n:,} points; candidates: every built-in with its defaults; best of 3")
    print(f"{'candidate':15s} {'total':>8s} {'hypothesis':>11s} {'rest':>8s} | {'baseline':>9s} {'ratio':>6s}")
    for spec in candidates:
        (name,) = spec
        total, table = best_time(lambda: suggestions(pair, settings, [spec], ".", GRID))
        hypothesis, masks = best_time(lambda: apply_step(pair, spec, ".", GRID))
        baseline = best_time(lambda: _baseline(pair, settings, spec), repeat=1)[0]
        print(
            f"{name:15s} {total:7.3f}s {hypothesis:10.3f}s {total - hypothesis:7.3f}s | {baseline:8.3f}s "
            f"{baseline / total:5.1f}x"
            f"   energy reduction {table['energy_reduction'][0]:+.3f}"
        )
        if name == "outliers":
            previous, previous_masks = best_time(
                lambda: [_open3d_inliers(xyz, **spec[name]) for xyz in (pair.xyz1, pair.xyz2)]
            )
            assert all(np.array_equal(a, b) for a, b in zip(masks, previous_masks))
            print(
                f"{'':15s} {'':8s} {previous:10.3f}s with Open3D (imported): {previous / hypothesis:.2f}x the k-d "
                f"tree's time"
            )
    for module in ("open3d", "scipy.spatial"):
        code = f"import time; t = time.perf_counter(); import {module}; print(time.perf_counter() - t)"
        seconds = min(
            float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout)
            for _ in range(3)
        )
        print(f"import {module}: {seconds:.2f} s in a fresh process (best of 3)")


def _open3d_inliers(xyz, nb_neighbors, std_ratio):
    import open3d as o3d

    _, index = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz)).remove_statistical_outlier(
        nb_neighbors, std_ratio
    )
    return np.isin(np.arange(len(xyz)), np.asarray(index))


def _baseline(pair, settings, spec):
    keep1, keep2 = apply_step(pair, spec, ".", GRID)
    before = discrepancy_field_reference(pair.xyz1, pair.xyz2, settings)
    after = discrepancy_field_reference(pair.xyz1[keep1], pair.xyz2[keep2], settings)
    return compare_fields(before, after)


if __name__ == "__main__":
    start = time.perf_counter()
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 45_000)
    print(f"whole run {time.perf_counter() - start:.1f} s")
