"""Neighbour distances carried past removed points (the fast path) against a new search of the
survivors (the plain reference): equal to the bit, on synthetic clouds with duplicates and on
real scans, and from stage to stage of a stack in memory (``lidarfield run``, ``explain``)."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.clouds import removals, synthetic_cloud
from lidarfield.hypotheses import outliers as outliers_module
from lidarfield.hypotheses.outliers import after_removal, neighbour_distances
from lidarfield.io import read_scan
from lidarfield.pair import RegisteredPair

GRID = {"kind": "spherical", "azimuth_bins": 36, "elevation_bins": 5, "elevation_deg": [-15, 15], "min_points": 10}


def assert_same(carried, searched):
    assert carried.k == searched.k
    np.testing.assert_array_equal(carried.mean, searched.mean)
    np.testing.assert_array_equal(carried.reach, searched.reach)


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


@pytest.fixture
def expd_counted(expd, monkeypatch):
    """The ExpD VLP-16 scan, its distances, and the points every search from now on asks for."""
    xyz = read_scan(expd / "Cloud1_ExpD.txt").xyz.astype(np.float64)
    before = neighbour_distances(xyz, 20, workers=1)
    searched = []
    search = outliers_module._search
    monkeypatch.setattr(
        outliers_module,
        "_search",
        lambda cloud, points, k, workers: searched.append(len(points)) or search(cloud, points, k, workers),
    )
    return xyz, before, searched


def test_carried_distances_on_a_real_scan_search_only_near_what_was_removed(expd_counted):
    """The ExpD VLP-16 scan after a field-of-view sector and a crop at 20 m: the same distances
    as a new search, for a search of only the points whose neighbourhood reached a removed one."""
    xyz, before, searched = expd_counted
    azimuth = np.degrees(np.arctan2(xyz[:, 1], xyz[:, 0]))
    for keep in (~((azimuth > 100) & (azimuth < 160)), np.linalg.norm(xyz, axis=1) < 20):
        searched.clear()
        carried = after_removal(before, xyz, keep, workers=1)
        assert 0 < searched[0] < 0.1 * np.count_nonzero(keep)  # a tenth of a new search at most
        assert_same(carried, neighbour_distances(xyz[keep], 20, workers=1))


def test_apply_stack_carries_what_the_previous_stage_searched(expd):
    """``lidarfield run``'s path: a stage's memoised distances reach the next stage exactly."""
    from lidarfield.hypotheses.outliers import cloud_neighbour_distances
    from lidarfield.study.stack import apply_stack

    pair = RegisteredPair(read_scan(expd / "Cloud1_ExpD.txt").xyz, read_scan(expd / "Cloud10Aligned_ExpD.txt").xyz)
    stack = [{"crop": {"max_range_m": 25.0}}, {"outliers": {}}, {"shadow": {"origins": [1]}}]
    for stage in apply_stack(pair, stack, study_grid=GRID):
        if stage.level:
            assert set(stage.pair.neighbours) == {(1, 20), (2, 20)}
            for cloud, k in stage.pair.neighbours:
                carried = cloud_neighbour_distances(stage.pair, cloud, k)  # carried when first asked for
                assert_same(carried, neighbour_distances(stage.pair.xyz1 if cloud == 1 else stage.pair.xyz2, k))
        (
            cloud_neighbour_distances(stage.pair, 1, 20),
            cloud_neighbour_distances(stage.pair, 2, 20),
        )  # as a candidate would


def rigidly_moved(xyz: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray]:
    """``xyz`` turned a few degrees and moved half a metre, as ``realign`` moves cloud 2, and
    the motion (4x4)."""
    from lidarfield.poses import pose_from_xyzrpy

    T = pose_from_xyzrpy([*rng.uniform(-0.5, 0.5, 3), *np.radians(rng.uniform(-3, 3, 3))])
    return xyz @ T[:3, :3].T + T[:3, 3], T


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("k", [20, 4])
def test_distances_moved_rigidly_equal_a_new_search_on_synthetic_clouds(seed, k):
    """Measured again at the new places for the same neighbours, the distances of a cloud
    moved as a whole are a new search's to the bit, duplicates and isolated points included,
    and after a removal too (the neighbours renumbered among the survivors)."""
    from lidarfield.hypotheses.outliers import after_rigid_move

    rng = np.random.default_rng(seed)
    xyz = synthetic_cloud(rng)
    before = neighbour_distances(xyz, k, workers=1)
    moved, _ = rigidly_moved(xyz, rng)
    assert_same(after_rigid_move(before, moved, workers=1), neighbour_distances(moved, k, workers=1))
    keep = rng.random(len(xyz)) > 0.1
    survivors = after_removal(before, xyz, keep, workers=1)
    assert_same(after_rigid_move(survivors, moved[keep], workers=1), neighbour_distances(moved[keep], k, workers=1))


def test_distances_moved_rigidly_on_a_real_scan_search_almost_nothing(expd_counted):
    """The ExpD VLP-16 scan moved as realign moves cloud 2: the same distances as a new search,
    for a search of a few points at most (whose k-th and (k+1)-th neighbours are too near to
    tell apart after rounding)."""
    from lidarfield.hypotheses.outliers import after_rigid_move

    xyz, before, searched = expd_counted
    moved, _ = rigidly_moved(xyz, np.random.default_rng(4))
    carried = after_rigid_move(before, moved, workers=1)
    assert sum(searched) < 0.001 * len(xyz)
    assert_same(carried, neighbour_distances(moved, 20, workers=1))


def test_a_stage_that_moves_a_cloud_as_a_whole_carries_its_distances_and_one_that_bends_it_does_not():
    """``carry_neighbours`` after a correction: cloud 2 moved with sensor 2's pose (realign's
    way) keeps its distances, equal to a new search; cloud 2 scaled about sensor 2 (a range
    calibration's way) does not (searched anew when asked for); cloud 1, unmoved, is carried."""
    from lidarfield.hypotheses.outliers import carry_neighbours, cloud_neighbour_distances

    rng = np.random.default_rng(5)
    before = RegisteredPair(synthetic_cloud(rng), synthetic_cloud(rng))
    for cloud in (1, 2):
        cloud_neighbour_distances(before, cloud, 20)
    every1, every2 = np.ones(len(before.xyz1), bool), np.ones(len(before.xyz2), bool)
    moved, T = rigidly_moved(before.xyz2, rng)
    rigid = RegisteredPair(before.xyz1, moved, T @ before.T_1_2)
    carry_neighbours(before, every1, every2, rigid, moved=(2,))
    assert set(rigid.neighbours) == {(1, 20), (2, 20)}
    assert_same(cloud_neighbour_distances(rigid, 2, 20), neighbour_distances(moved, 20))
    assert_same(cloud_neighbour_distances(rigid, 1, 20), neighbour_distances(before.xyz1, 20))
    # carried on again before anyone asked (a stage that removed some of cloud 2): found then
    unasked = RegisteredPair(before.xyz1, moved, T @ before.T_1_2)
    carry_neighbours(before, every1, every2, unasked, moved=(2,))
    some2 = np.arange(len(moved)) % 3 > 0
    later = RegisteredPair(before.xyz1, moved[some2], unasked.T_1_2)
    carry_neighbours(unasked, every1, some2, later)
    assert_same(cloud_neighbour_distances(later, 2, 20), neighbour_distances(moved[some2], 20))
    scaled = RegisteredPair(before.xyz1, before.xyz2 * 1.001, before.T_1_2)
    carry_neighbours(before, every1, every2, scaled, moved=(2,))
    assert set(scaled.neighbours) == {(1, 20)}
