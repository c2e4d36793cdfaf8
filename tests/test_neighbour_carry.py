"""Neighbour distances carried from a stage to its survivors (the fast path) against a new
search of the survivors (the plain reference): equal to the bit, on synthetic clouds with
duplicates and on real scans, and through the workflow's suggest jobs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lidarfield.analysis.neighbour_file import read_neighbours
from lidarfield.analysis.suggest import candidate_steps
from lidarfield.hypotheses import outliers as outliers_module
from lidarfield.hypotheses.outliers import after_removal, neighbour_distances
from lidarfield.io import read_scan
from lidarfield.io.parquet_table import read_table
from lidarfield.pair import RegisteredPair, read_pair
from lidarfield.pipeline import write_stage
from lidarfield.stack import initial_stage, next_stage

from test_outliers import _synthetic_cloud


def assert_same(carried, searched):
    assert carried.k == searched.k
    np.testing.assert_array_equal(carried.mean, searched.mean)
    np.testing.assert_array_equal(carried.reach, searched.reach)


def removals(xyz: np.ndarray, rng) -> dict[str, np.ndarray]:
    """Keep-masks of the kinds of removal hypotheses make, and the edge cases."""
    n = len(xyz)
    azimuth = np.degrees(np.arctan2(xyz[:, 1], xyz[:, 0]))
    _, inverse, counts = np.unique(xyz, axis=0, return_inverse=True, return_counts=True)
    duplicated = np.flatnonzero(counts[inverse.ravel()] > 1)
    some_copies = np.ones(n, dtype=bool)
    some_copies[duplicated[::2]] = False  # one copy of a doubled point goes, its twin stays
    few = np.zeros(n, dtype=bool)
    few[:5] = True
    return {
        "a sector": ~((azimuth > 20) & (azimuth < 70)),
        "scattered points": rng.random(n) > 0.05,
        "some copies of duplicates": some_copies,
        "nothing": np.ones(n, dtype=bool),
        "all but fewer than k": few,
        "everything": np.zeros(n, dtype=bool),
    }


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("k", [20, 4])
def test_carried_distances_equal_a_new_search_on_synthetic_clouds(seed, k):
    rng = np.random.default_rng(seed)
    xyz = _synthetic_cloud(rng)
    before = neighbour_distances(xyz, k, workers=1)
    for label, keep in removals(xyz, rng).items():
        carried = after_removal(before, xyz, keep, workers=1)
        assert len(carried) == np.count_nonzero(keep), label
        assert_same(carried, neighbour_distances(xyz[keep], k, workers=1))


def test_carried_distances_on_a_real_scan_search_only_near_what_was_removed(expd, monkeypatch):
    """The ExpD VLP-16 scan after a field-of-view sector and a crop at 20 m: the same distances
    as a new search, for a search of only the points whose neighbourhood reached a removed one."""
    xyz = read_scan(expd / "Cloud1_ExpD.txt").xyz.astype(np.float64)
    before = neighbour_distances(xyz, 20, workers=1)
    searched = []
    search = outliers_module._search
    monkeypatch.setattr(outliers_module, "_search", lambda cloud, points, k, workers: searched.append(len(points)) or search(cloud, points, k, workers))
    azimuth = np.degrees(np.arctan2(xyz[:, 1], xyz[:, 0]))
    for keep in (~((azimuth > 100) & (azimuth < 160)), np.linalg.norm(xyz, axis=1) < 20):
        searched.clear()
        carried = after_removal(before, xyz, keep, workers=1)
        assert 0 < searched[0] < 0.1 * np.count_nonzero(keep)  # a tenth of a new search at most
        assert_same(carried, neighbour_distances(xyz[keep], 20, workers=1))


def test_the_suggest_jobs_carry_the_distances_to_the_next_stage(tmp_path, expd):
    """Stage 1 (a crop) of a real pair: its suggest job fed the stage-0 job's neighbours.parquet
    writes the suggestions and the neighbours file that a job searching anew writes, and the
    removed file's ``row`` column puts stage 0's points back together."""
    from lidarfield.cli import run_in_process

    pair = RegisteredPair(read_scan(expd / "Cloud1_ExpD.txt").xyz, read_scan(expd / "Cloud10Aligned_ExpD.txt").xyz)
    stage0 = initial_stage(pair)
    stage1 = next_stage(stage0.pair, {"crop": {"max_range_m": 25.0}}, 1)
    assert 0 < stage1.removed1 < len(pair.xyz1) / 2
    dirs = [tmp_path / "s0", tmp_path / "s1"]
    for stage, folder in zip((stage0, stage1), dirs):
        folder.mkdir()
        write_stage(stage, f"0{stage.level}-x-0000000{stage.level}", folder / "points.parquet", folder / "removed.parquet")

    grid = {"kind": "spherical", "azimuth_bins": 36, "elevation_bins": 5, "elevation_deg": [-15, 15], "min_points": 10}

    def suggest(folder, out_name, *extra):
        candidates = candidate_steps([{"outliers": {}}, {"ego_vehicle": {}}], [])
        argv = ["job", "suggest", "--points", str(folder / "points.parquet"), "--candidates", json.dumps(candidates),
                "--grid", json.dumps(grid), "--out", str(folder / f"{out_name}.parquet"),
                "--neighbours-out", str(folder / f"{out_name}-neighbours.parquet"), *extra]  # fmt: skip
        assert run_in_process(argv) == 0
        return read_table(folder / f"{out_name}.parquet")[0], read_neighbours(folder / f"{out_name}-neighbours.parquet")

    suggest(dirs[0], "suggestions")
    carried_table, carried = suggest(
        dirs[1], "carried", "--previous-neighbours", str(dirs[0] / "suggestions-neighbours.parquet"), "--removed", str(dirs[1] / "removed.parquet")
    )  # fmt: skip
    searched_table, searched = suggest(dirs[1], "searched")
    assert set(carried) == set(searched) == {(1, 20), (2, 20)}
    for key in searched:
        assert_same(carried[key], searched[key])
    for name in searched_table:
        np.testing.assert_array_equal(carried_table[name], searched_table[name])
    assert carried_table["hypothesis"][list(carried_table["hypothesis"]).index("outliers")] == "outliers"

    survivors, _ = read_pair(dirs[1] / "points.parquet")
    removed, _ = read_table(dirs[1] / "removed.parquet")
    rows = removed["row"][removed["cloud"] == 1]
    rebuilt = np.empty((len(survivors.xyz1) + len(rows), 3))
    keep = np.ones(len(rebuilt), dtype=bool)
    keep[rows] = False
    rebuilt[keep] = survivors.xyz1
    rebuilt[rows] = np.column_stack([removed[c][removed["cloud"] == 1] for c in "xyz"])
    np.testing.assert_array_equal(rebuilt, read_pair(dirs[0] / "points.parquet")[0].xyz1)
