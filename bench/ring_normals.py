"""Benchmark: ``ring_normals`` and ``realign`` (which calls it twice), the plain implementation
(tests/helpers/ring_normals_reference.py, as it was until 2026-11-25) against the fast one, in
the same run, with their results compared.

The pair: issue 27's drive, its first pair (tests/helpers/drive.py: the paper intersection seen
by the 80-channel sensor, two frames of about 87,000 points 0.3 m apart, registered by the
truth); ``ring_normals`` on its cloud 1 with Open3D's normals (as realign gives them), and on the
real VLP-16 scan ``expd-vlp16/Cloud1_ExpD.txt`` (../shared/data or LIDARFIELD_DATA) when found.

Run: ``python bench/ring_normals.py [--repeat N]``.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

import lidarfield.hypotheses.realign as realign_module
from lidarfield.hypotheses.realign import Params, realign
from lidarfield.hypotheses.ring_normals import ring_normals
from lidarfield.sensors.models import PRESETS
from timing import best_time, machine  # bench/timing.py

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from helpers.drive import drive_pair  # noqa: E402 (the tests' drive pair)
from helpers.ring_normals_reference import reference_ring_normals  # noqa: E402

IMPLEMENTATIONS = {"plain": reference_ring_normals, "fast": ring_normals}


def open3d_normals(xyz: np.ndarray) -> np.ndarray:
    """The normals realign starts from (its default radius and neighbours)."""
    import open3d as o3d

    from lidarfield.registration.matching import point_cloud

    params = Params()
    cloud = point_cloud(xyz, 0.0, 0.0)
    cloud.estimate_normals(
        o3d.geometry.KDTreeSearchParamHybrid(radius=params.normal_radius_m, max_nn=params.normal_max_nn)
    )
    return np.asarray(cloud.normals)


def compare_ring_normals(label: str, xyz: np.ndarray, sensor: str, repeat: int) -> None:
    params, normals = Params(), open3d_normals(xyz)
    seconds, outs = {}, {}
    for name, function in IMPLEMENTATIONS.items():
        seconds[name], outs[name] = best_time(
            lambda: function(xyz, normals, PRESETS[sensor].elevation_deg, params.normal_radius_m, params.normal_max_nn),
            repeat,
        )
    print(
        f"ring_normals, {label} ({len(xyz):,} points, {np.mean(np.any(outs['fast'] != normals, axis=1)):.0%} "
        f"replaced): plain {seconds['plain']:.3f} s, fast {seconds['fast']:.3f} s = "
        f"{seconds['fast'] / seconds['plain']:.2f} x; identical: {np.array_equal(outs['plain'], outs['fast'])}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5, help="best of this many runs")
    args = parser.parse_args()
    print(machine())
    print(f"load average {os.getloadavg()[0]:.2f}")
    pair = drive_pair()
    compare_ring_normals("the drive's cloud 1", pair.xyz1, "paper-sim-80", args.repeat)
    expd = Path(os.environ.get("LIDARFIELD_DATA", ROOT.parent / "shared" / "data")) / "expd-vlp16" / "Cloud1_ExpD.txt"
    if expd.is_file():
        from lidarfield.io import read_scan

        xyz = read_scan(expd).xyz
        compare_ring_normals("real VLP-16 Cloud1_ExpD", xyz[np.isfinite(xyz).all(axis=1)], "vlp16", args.repeat)
    seconds, T = {}, {}
    for name, function in IMPLEMENTATIONS.items():
        realign_module.ring_normals = function  # realign's own name for it
        seconds[name], outcome = best_time(lambda: realign(pair, Params()), args.repeat)
        T[name] = outcome.T_1_2
    realign_module.ring_normals = ring_normals
    print(
        f"realign, the drive's pair ({len(pair.xyz1):,} + {len(pair.xyz2):,} points): plain ring normals "
        f"{seconds['plain']:.3f} s, fast {seconds['fast']:.3f} s = {seconds['fast'] / seconds['plain']:.2f} x; "
        f"the same transform: {np.array_equal(T['plain'], T['fast'])}"
    )
    print(f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
