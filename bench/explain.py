"""Benchmark: ``lidarfield explain`` on a 120,000-point pair (60,000 per cloud).

Target (issue 25): under 15 s. The pair: the built-in scene paper-intersection-ego-car
(the method's intersection, the sensor 2 m up on a car's roof, another car driving at 5 m/s)
seen by the 80-channel sensor of the method's simulated pair; sensor 2 1 m further and 0.5 s
later; scan 2
registered 0.3 m off in x; each cloud subsampled to 60,000 points (fixed seed). Default
candidates and explain settings, the grid of the default study.

Timed, best of 2: the loop (``explain_pair``: every step's suggestions, the chosen hypothesis
applied again, the new stage's field and statistics) and writing its folder (figures, page,
stack, steps). Baseline in the same run: applying the stack it found once, with every stage's
field and statistics (``apply_stack`` + ``analyse_field``), i.e. what running the found stack
costs without searching for it.

Run: ``python bench/explain.py [points_per_cloud]``.
"""

from __future__ import annotations

import dataclasses
import sys
import tempfile

import numpy as np

from lidarfield.analysis.explain import ExplainSettings
from lidarfield.analysis.field_stats import analyse_field
from lidarfield.poses import pose_from_xyzrpy
from lidarfield.registration import register_pair
from lidarfield.report.explain import write_explanation
from lidarfield.sensors.models import PRESETS
from lidarfield.simulation.raycast import simulate_scan
from lidarfield.simulation.scene import load_scene
from lidarfield.study.config import validate_config
from lidarfield.study.explain import explain_pair, format_step
from lidarfield.study.stack import apply_stack
from timing import best_time, machine  # bench/timing.py

GRID = {"kind": "spherical", "azimuth_bins": 36, "elevation_deg": [-22.5, 15.0], "elevation_bins": 5, "min_points": 30}


def ego_car_pair(n: int):
    """The pair registered by the truth, each cloud subsampled to ``n`` points."""
    scene, sensor = load_scene("paper-intersection-ego-car"), PRESETS["paper-sim-80"]
    scans = [
        simulate_scan(scene, sensor, pose_from_xyzrpy(pose), time_s=t, seed=seed, range_noise_m=0.02)
        for seed, pose, t in ((1, [0, 0, 2, 0, 0, 0], 0.0), (2, [1, 0, 2, 0, 0, 0.0037], 0.5))
    ]
    pair = register_pair(scans[0], scans[1], "truth")
    rng = np.random.default_rng(0)
    keep = [np.sort(rng.choice(len(xyz), size=min(n, len(xyz)), replace=False)) for xyz in (pair.xyz1, pair.xyz2)]
    return pair.subset(*keep)


def bench_pair(n: int):
    pair = ego_car_pair(n)
    shift = pose_from_xyzrpy([0.3, 0, 0, 0, 0, 0])  # scan 2 registered 0.3 m off
    return dataclasses.replace(pair, xyz2=pair.xyz2 + shift[:3, 3], T_1_2=shift @ pair.T_1_2)


def main(n: int) -> None:
    pair = bench_pair(n)
    study = validate_config({"grid": GRID}, require_pairs=False)
    print(machine())
    print(f"pair: {len(pair.xyz1):,} + {len(pair.xyz2):,} points; default candidates and explain settings; best of 2")

    def loop():
        return explain_pair(pair, study.grid, study.grid_section, ExplainSettings(), None, ".", "bench")

    explain_s, explanation = best_time(loop, repeat=2)
    for row in explanation.steps:
        print(f"  step {row['step']}: {format_step(row)}")
    print(f"  stopped: {explanation.stop}")
    with tempfile.TemporaryDirectory() as out:
        write_s, _ = best_time(
            lambda: write_explanation(explanation, study.grid, study.grid_section, out, study.config["plots"]), 2
        )

    def run_stack():
        return [analyse_field(s.pair, study.grid) for s in apply_stack(pair, explanation.stack, ".", GRID)]

    baseline_s, _ = best_time(run_stack, repeat=2)
    print(f"explain loop            {explain_s:7.2f} s")
    print(f"writing its folder      {write_s:7.2f} s  (figures, page, stack, steps)")
    print(f"explain in all          {explain_s + write_s:7.2f} s  (target: under 15 s)")
    print(f"baseline: the stack found applied once, with its fields {baseline_s:7.2f} s")
    print(f"ratio loop / baseline   {explain_s / baseline_s:7.1f}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 60_000)
