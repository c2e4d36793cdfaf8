"""Neighbour distances carried past removed points (the fast path) against a new search of the
survivors (the plain reference): equal to the bit, on synthetic clouds with duplicates and on
real scans, and through the workflow's neighbours and suggest jobs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from helpers.clouds import synthetic_cloud
from lidarfield.analysis.suggest import candidate_steps
from lidarfield.hypotheses import outliers as outliers_module
from lidarfield.hypotheses.outliers import after_removal, neighbour_distances
from lidarfield.io import read_scan
from lidarfield.io.parquet_table import read_table
from lidarfield.pair import RegisteredPair
from lidarfield.stage_points import CHANGES, read_stage_points
from lidarfield.study.jobs import write_stage
from lidarfield.study.stack import initial_stage, next_stage

GRID = {"kind": "spherical", "azimuth_bins": 36, "elevation_bins": 5, "elevation_deg": [-15, 15], "min_points": 10}


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
    xyz = synthetic_cloud(rng)
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
    monkeypatch.setattr(
        outliers_module,
        "_search",
        lambda cloud, points, k, workers: searched.append(len(points)) or search(cloud, points, k, workers),
    )
    azimuth = np.degrees(np.arctan2(xyz[:, 1], xyz[:, 0]))
    for keep in (~((azimuth > 100) & (azimuth < 160)), np.linalg.norm(xyz, axis=1) < 20):
        searched.clear()
        carried = after_removal(before, xyz, keep, workers=1)
        assert 0 < searched[0] < 0.1 * np.count_nonzero(keep)  # a tenth of a new search at most
        assert_same(carried, neighbour_distances(xyz[keep], 20, workers=1))


def test_the_suggest_jobs_carry_the_pairs_distances_to_every_stage(tmp_path, expd):
    """A real pair through a crop and a shadow stage: the neighbours job searches the registered
    pair once, and each stage's suggest job, fed it and the removed files of its stages, writes
    the suggestions a job searching anew writes; the removed files' ``row`` columns put the
    registered pair back together."""
    from lidarfield.cli import run_in_process
    from lidarfield.pair import write_pair

    pair = RegisteredPair(read_scan(expd / "Cloud1_ExpD.txt").xyz, read_scan(expd / "Cloud10Aligned_ExpD.txt").xyz)
    write_pair(tmp_path / "registered.parquet", pair)
    stages = [initial_stage(pair)]
    for level, step in enumerate([{"crop": {"max_range_m": 25.0}}, {"shadow": {"origins": [1]}}], start=1):
        stages.append(next_stage(stages[-1].pair, step, level, study_grid=GRID))
        assert 0 < stages[-1].removed1 < len(stages[-2].pair.xyz1) / 2
    dirs = [tmp_path / f"s{stage.level}" for stage in stages]
    ids = [f"0{stage.level}-x-0000000{stage.level}" for stage in stages]
    for stage, folder in zip(stages, dirs):
        folder.mkdir()
        previous = ids[stage.level - 1] if stage.level else None
        write_stage(stage, ids[stage.level], previous, folder / CHANGES, folder / "removed.parquet")
    argv = [
        "job",
        "neighbours",
        "--points",
        str(tmp_path / "registered.parquet"),
        "--k",
        "20",
        "5",
        "--out",
        str(tmp_path / "neighbours.parquet"),
    ]
    assert run_in_process(argv) == 0

    def suggest(level, *extra):
        candidates = candidate_steps([{"outliers": {}}, {"outliers": {"nb_neighbors": 5}}, {"ego_vehicle": {}}], [])
        out = dirs[level] / f"suggestions{len(extra)}.parquet"
        argv = [
            "job",
            "suggest",
            "--registered",
            str(tmp_path / "registered.parquet"),
            "--stage-changes",
            *[str(folder / CHANGES) for folder in dirs[: level + 1]],
            "--candidates",
            json.dumps(candidates),
            "--grid",
            json.dumps(GRID),
            "--out",
            str(out),
            *extra,
        ]
        assert run_in_process(argv) == 0
        return read_table(out)[0]

    changes = [folder / "neighbour_changes.parquet" for folder in dirs]
    for level in range(3):
        removed = [str(folder / "removed.parquet") for folder in dirs[1 : level + 1]]
        carried = suggest(
            level,
            "--neighbours",
            str(tmp_path / "neighbours.parquet"),
            "--removed",
            *removed,
            "--changes",
            *map(str, changes[1:level]),
            "--changes-out",
            str(changes[level]),
        )
        searched = suggest(level)
        assert list(carried["hypothesis"]) and set(carried["params"]) == set(searched["params"])
        for name in searched:
            np.testing.assert_array_equal(carried[name], searched[name])
    # Stage 0 changes nothing; the crop and the shadow each change some rows, far fewer than all.
    assert len(read_table(changes[0])[0]["row"]) == 0
    for level in (1, 2):
        rows = read_table(changes[level])[0]["row"]
        assert 0 < len(rows) < 0.2 * (len(stages[level].pair.xyz1) + len(stages[level].pair.xyz2))

    # The carried distances themselves, at the last stage: a new search's.
    from lidarfield.analysis.neighbour_file import carry_to_stage

    last, _ = read_stage_points(tmp_path / "registered.parquet", [folder / CHANGES for folder in dirs])
    carry_to_stage(
        last, tmp_path / "neighbours.parquet", [dirs[1] / "removed.parquet", dirs[2] / "removed.parquet"], [changes[1]]
    )
    assert set(last.neighbours) == {(1, 20), (2, 20), (1, 5), (2, 5)}
    for (cloud, k), carried in last.neighbours.items():
        assert_same(carried, neighbour_distances(last.xyz1 if cloud == 1 else last.xyz2, k))

    # A removed file that does not fit the pair's distances: an error naming it.
    from lidarfield.errors import InputError

    with pytest.raises(InputError, match="neighbours.parquet"):
        carry_to_stage(last, tmp_path / "neighbours.parquet", [dirs[2] / "removed.parquet"], [])


def test_changes_stored_whole_where_a_stage_searched_anew_carry_on_exactly(tmp_path):
    """A stage that searched anew (or whose cloud fell below k) stores its distances whole; the
    next stage starts from them and still equals a new search."""
    from lidarfield.analysis.neighbour_file import apply_change, kept, read_changes, write_changes

    rng = np.random.default_rng(5)
    xyz = synthetic_cloud(rng)
    registered = neighbour_distances(xyz, 20, workers=1)
    keep1 = rng.random(len(xyz)) > 0.1
    stage1 = neighbour_distances(xyz[keep1], 20, workers=1)
    write_changes(tmp_path / "whole.parquet", {(1, 20): (None, stage1)})
    write_changes(
        tmp_path / "partial.parquet",
        {(1, 20): (kept(registered, keep1), after_removal(registered, xyz, keep1, workers=1))},
    )
    for name in ("whole", "partial"):
        change = read_changes(tmp_path / f"{name}.parquet")[(1, 20)]
        assert_same(apply_change(kept(registered, keep1), change, name), stage1)
    tiny = np.zeros(len(xyz), dtype=bool)
    tiny[:7] = True  # fewer points than k: k itself changes, so the rows are stored whole
    write_changes(
        tmp_path / "tiny.parquet", {(1, 20): (kept(registered, tiny), after_removal(registered, xyz, tiny, workers=1))}
    )
    assert_same(
        apply_change(kept(registered, tiny), read_changes(tmp_path / "tiny.parquet")[(1, 20)], "tiny"),
        neighbour_distances(xyz[tiny], 20, workers=1),
    )


def test_apply_stack_carries_what_the_previous_stage_searched(expd):
    """``lidarfield run``'s path: a stage's memoised distances reach the next stage exactly."""
    from lidarfield.hypotheses.outliers import cloud_neighbour_distances
    from lidarfield.study.stack import apply_stack

    pair = RegisteredPair(read_scan(expd / "Cloud1_ExpD.txt").xyz, read_scan(expd / "Cloud10Aligned_ExpD.txt").xyz)
    stack = [{"crop": {"max_range_m": 25.0}}, {"outliers": {}}, {"shadow": {"origins": [1]}}]
    for stage in apply_stack(pair, stack, study_grid=GRID):
        if stage.level:
            assert set(stage.pair.neighbours) == {(1, 20), (2, 20)}
            for (cloud, k), carried in stage.pair.neighbours.items():
                assert_same(carried, neighbour_distances(stage.pair.xyz1 if cloud == 1 else stage.pair.xyz2, k))
        (
            cloud_neighbour_distances(stage.pair, 1, 20),
            cloud_neighbour_distances(stage.pair, 2, 20),
        )  # as a candidate would
