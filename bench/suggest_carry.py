"""Benchmark: a stage's suggestions with the outliers candidate's neighbour distances carried
from the previous stage's past what this stage removed (as the workflow's suggest jobs do, from
the changes the stages before recorded), carried from the registered pair's past everything the
stages removed (what they did before), and searched anew (the baseline), stage by stage
through a stack, on a real scan pair.

Run: ``python bench/suggest_carry.py`` (the HDL-32E pair of ``../shared/data``, source.ply
in target.ply's frame by ``T_target_source.txt``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lidarfield.analysis.suggest import candidate_steps, suggestions
from lidarfield.field.grid import field_settings_from_config
from lidarfield.hypotheses.outliers import after_removal, neighbour_distances
from lidarfield.io import read_scan
from lidarfield.pair import RegisteredPair
from lidarfield.study.stack import apply_stack
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
    registered = {
        (cloud, 20): neighbour_distances(xyz, 20, workers=1) for cloud, xyz in ((1, pair.xyz1), (2, pair.xyz2))
    }
    survivors = {1: np.arange(len(pair.xyz1)), 2: np.arange(len(pair.xyz2))}  # rows of the registered pair
    previous_pair, previous = pair, registered  # the stage before's points and distances
    applied = []
    for stage in apply_stack(pair, STACK, study_grid=GRID):
        applied += [stage.spec] if stage.spec else []
        candidates = candidate_steps(None, applied, ".", GRID)
        survivors = {1: survivors[1][stage.keep1], 2: survivors[2][stage.keep2]}
        keeps = {1: stage.keep1, 2: stage.keep2}

        def from_registered(cloud, k, distances):
            keep = np.zeros(len(distances), dtype=bool)
            keep[survivors[cloud]] = True
            return after_removal(distances, pair.xyz1 if cloud == 1 else pair.xyz2, keep, workers=1)

        def from_previous(cloud, k, distances):
            return after_removal(
                previous[(cloud, k)], previous_pair.xyz1 if cloud == 1 else previous_pair.xyz2, keeps[cloud], workers=1
            )

        def suggest(carry) -> dict:
            stage.pair.neighbours.clear()
            if carry is not None:
                for (cloud, k), distances in registered.items():
                    stage.pair.neighbours[(cloud, k)] = carry(cloud, k, distances)
            return suggestions(stage.pair, settings, candidates, study_grid=GRID, defaults=True)

        searched_s, searched = best_time(lambda: suggest(None))
        registered_s, carried = best_time(lambda: suggest(from_registered))
        assert all(np.array_equal(carried[c], searched[c]) for c in carried), "carried suggestions differ"
        previous_s, carried = best_time(lambda: suggest(from_previous))
        assert all(np.array_equal(carried[c], searched[c]) for c in carried), "carried suggestions differ"
        print(
            f"stage {stage.level} ({stage.name}, {len(pair.xyz1) - len(survivors[1])} + "
            f"{len(pair.xyz2) - len(survivors[2])} "
            f"removed so far): suggestions {searched_s * 1000:.0f} ms searching anew, {registered_s * 1000:.0f} ms "
            f"carried "
            f"from the registered pair ({registered_s / searched_s:.2f}x), {previous_s * 1000:.0f} ms from the stage "
            f"before "
            f"({previous_s / searched_s:.2f}x)"
        )
        # the last timed run carried from the stage before: its distances start the next stage
        previous_pair, previous = stage.pair, {key: stage.pair.neighbours[key] for key in registered}


if __name__ == "__main__":
    main()
