"""Benchmark: ``lidarfield explain`` on a pair of 2 x 60,000 points, or as many as asked for.

Targets: under 15 s at 2 x 60,000 (issue 25), under 5 s at 2 x 120,000 (issue 38). The pair:
the built-in scene paper-intersection-ego-car (the method's intersection, the sensor 2 m up on
a car's roof, another car driving at 5 m/s) seen by the 80-channel sensor of the method's
simulated pair; sensor 2 1 m further and 0.5 s later; scan 2 registered 0.3 m off in x; each
cloud subsampled to exactly the points asked for (fixed seed). At its own azimuth step (0.2 deg)
the sensor returns about 102,000 points of this scene, so for more the same 80 channels scan
at the coarsest of ``AZIMUTH_STEPS_DEG`` that returns enough (0.15 deg: about 136,000). Default
candidates and explain settings, the grid of the default study.

Timed, best of 2, each run on a fresh copy of the pair (what a run derives from the clouds and
remembers, e.g. ``outliers``' neighbour distances on the pair object and ``range_calibration``'s
planes by the cloud array, is not carried to the next run, as it is not from one command to the
next): the loop (``explain_pair``: every step's suggestions, the chosen hypothesis applied
again, the new stage's field and statistics) and writing its folder (figures, page, stack,
steps), one after the other; then both as the command runs them (``explain_into``: each
stage's figures drawn by a second process while the loop goes on, the candidates of a step
evaluated by a pool of threads, when more than one core is usable), with the figures' process
started inside the time, and again started before it, as ``lidarfield explain`` starts it
before reading and registering the scans (its start-up then overlaps the registration, which
this benchmark does not run). Baseline in the same run:
applying the stack it found once, with every stage's field and statistics (``apply_stack`` +
``analyse_field``), i.e. what running the found stack costs without searching for it.

OpenBLAS runs with one thread unless ``OPENBLAS_NUM_THREADS`` is set, as the command runs it
(``lidarfield.cli.one_blas_thread``).

Run: ``python bench/explain.py [points_per_cloud]``.
"""

from __future__ import annotations

import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from lidarfield.cli import one_blas_thread

one_blas_thread()  # as the command runs: before numpy is imported
from timing import best_time, machine  # noqa: E402 (bench/timing.py)

STARTUP_S = 1.5  # longer than the figures' process takes to start (its imports)
AZIMUTH_STEPS_DEG = (0.2, 0.15, 0.1)  # the sensor's own step first
GRID = {"kind": "spherical", "azimuth_bins": 36, "elevation_deg": [-22.5, 15.0], "elevation_bins": 5, "min_points": 30}


def main(n: int) -> None:
    # Imported here, not at the top: the figures' process is spawned and imports this module
    # first, as the command's imports ``lidarfield.cli`` (9 ms); the tests' ego-car drive alone
    # takes a second to import, which the command never pays.
    from lidarfield.analysis.field_stats import analyse_field
    from lidarfield.analysis.stopping_rule import ExplainSettings
    from lidarfield.commands.scans import explain_into, stage_figures
    from lidarfield.report.explanation import write_explanation
    from lidarfield.study.config import validate_config
    from lidarfield.study.explain_loop import explain_pair, format_step
    from lidarfield.study.stack import apply_stack

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from helpers.ego_car import ego_car_pair, registered_off  # the tests' ego-car drive

    for step in AZIMUTH_STEPS_DEG:
        pair = registered_off(ego_car_pair("paper-sim-80", points=n, azimuth_resolution_deg=step))
        if min(len(pair.xyz1), len(pair.xyz2)) >= n:
            break
    else:
        sys.exit(f"the sensor returns fewer than {n:,} points of the scene even at {step} deg")
    study = validate_config({"grid": GRID}, require_pairs=False)
    print(machine())
    print(
        f"pair: {len(pair.xyz1):,} + {len(pair.xyz2):,} points (azimuth step {step} deg); "
        "default candidates and explain settings; best of 2"
    )

    def fresh():
        # new arrays too: the planes of range_calibration are remembered by their cloud array
        return replace(pair, xyz1=pair.xyz1.copy(), xyz2=pair.xyz2.copy(), neighbours={})

    def loop():
        return explain_pair(fresh(), study.grid, study.grid_section, ExplainSettings(), None, ".", "bench")

    explain_s, explanation = best_time(loop, repeat=2)
    for row in explanation.steps:
        print(f"  step {row['step']}: {format_step(row)}")
    print(f"  stopped: {explanation.stop}")
    with tempfile.TemporaryDirectory() as out:
        write_s, _ = best_time(
            lambda: write_explanation(explanation, study.grid, study.grid_section, out, study.config["plots"]), 2
        )

    with tempfile.TemporaryDirectory() as out:
        command_s, _ = best_time(lambda: explain_into(fresh(), study, Path(out)), 2)

    def started_before() -> float:
        """``explain_into`` with the figures' process started before it, as ``lidarfield
        explain`` starts it before reading and registering the scans: its start-up (0.63 s of
        CPU, 2026-11-28) left out of the time, not out of the command."""
        with tempfile.TemporaryDirectory() as out, stage_figures(study, Path(out)) as figures:
            pair = fresh()
            time.sleep(STARTUP_S)
            start = time.perf_counter()
            explain_into(pair, study, Path(out), figures)
            return time.perf_counter() - start

    started_s = min(started_before() for _ in range(2))

    def run_stack():
        return [analyse_field(s.pair, study.grid) for s in apply_stack(fresh(), explanation.stack, ".", GRID)]

    baseline_s, _ = best_time(run_stack, repeat=2)
    print(f"explain loop            {explain_s:7.2f} s")
    print(f"writing its folder      {write_s:7.2f} s  (figures, page, stack, steps)")
    print(f"explain in all          {explain_s + write_s:7.2f} s  (the loop, then the folder)")
    print(f"as the command runs     {command_s:7.2f} s  (issue 38: under 5 s at 2 x 120,000 points)")
    print(f"... its figures' process started before {started_s:7.2f} s  (as the command starts it: while registering)")
    print(f"baseline: the stack found applied once, with its fields {baseline_s:7.2f} s")
    print(f"ratio loop / baseline   {explain_s / baseline_s:7.1f}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 60_000)
