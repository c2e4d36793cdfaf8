"""Benchmark: a stage's suggestions with the outliers candidate's neighbour distances carried
from the stage before (as the workflow's suggest jobs do) against a new search (the baseline),
stage by stage through a stack, on a real scan pair. One core.

Run: ``python bench/suggest_carry.py`` (the HDL-32E pair of ``../shared/data``, source.ply
in target.ply's frame by ``T_target_source.txt``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lidarfield.analysis.suggest import candidate_steps, suggestions
from lidarfield.grid import field_settings_from_config
from lidarfield.hypotheses.outliers import carry_neighbours
from lidarfield.io import read_scan
from lidarfield.pair import RegisteredPair
from lidarfield.stack import apply_stack

from timing import best_time, machine  # bench/timing.py

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "hdl32-pair"
GRID = {"kind": "spherical", "azimuth_bins": 36, "elevation_bins": 5, "elevation_deg": [-30, 10], "min_points": 30}
STACK = [{"ego_vehicle": {"radius_m": 3.0}}, {"crop": {"max_range_m": 40}}, {"shadow": {"origins": [1, 2]}}]


def main() -> None:
    T_target_source = np.loadtxt(DATA / "T_target_source.txt")
    pair = RegisteredPair(read_scan(DATA / "target.ply").xyz, read_scan(DATA / "source.ply").xyz, T_target_source)
    pair.xyz2 = pair.xyz2 @ T_target_source[:3, :3].T + T_target_source[:3, 3]
    settings = field_settings_from_config(GRID)
    print(machine())
    print(f"HDL-32E pair: {len(pair.xyz1)} + {len(pair.xyz2)} points")
    applied, previous = [], None
    for stage in apply_stack(pair, STACK, study_grid=GRID):
        applied += [stage.spec] if stage.spec else []
        candidates = candidate_steps(None, applied, ".", GRID)

        def suggest(carry: bool) -> dict:
            stage.pair.neighbours.clear()
            if carry:  # what the workflow's suggest job does (from files) and apply_stack does
                carry_neighbours(previous.pair, stage.keep1, stage.keep2, stage.pair)
            return suggestions(stage.pair, settings, candidates, study_grid=GRID, defaults=True)

        searched_s, searched = best_time(lambda: suggest(False))
        if previous is not None:
            carried_s, carried = best_time(lambda: suggest(True))
            assert all(np.array_equal(carried[c], searched[c]) for c in carried), "carried suggestions differ"
            print(f"stage {stage.level} ({stage.name}, {stage.removed1} + {stage.removed2} removed): suggestions "
                  f"{searched_s * 1000:.0f} ms searching anew, {carried_s * 1000:.0f} ms carried ({carried_s / searched_s:.2f}x)")  # fmt: skip
        else:
            print(f"stage 0: suggestions {searched_s * 1000:.0f} ms (nothing to carry)")
        previous = stage

if __name__ == "__main__":
    main()
