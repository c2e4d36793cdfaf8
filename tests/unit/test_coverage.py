"""Blind sectors (analysis.coverage): an azimuth run one scan left empty and the other fills."""

from __future__ import annotations

import numpy as np

from lidarfield.analysis.coverage import blind_sectors, empty_runs
from lidarfield.pair import RegisteredPair
from lidarfield.poses import apply_pose, pose_from_xyzrpy


def ring_of_points(n: int, seed: int, keep_deg: float = 180.0) -> np.ndarray:
    """Points on a cylinder of radius 10 m about the origin, azimuths within +-keep_deg."""
    rng = np.random.default_rng(seed)
    azimuth = np.radians(rng.uniform(-keep_deg, keep_deg, n))
    return np.column_stack([10 * np.cos(azimuth), 10 * np.sin(azimuth), rng.uniform(-2, 2, n)])


def test_empty_runs_wrap_round_the_circle_and_need_the_other_s_points():
    own = np.array([0, 5, 5, 0, 0, 5, 0, 0])
    other = np.array([3, 1, 1, 0, 2, 1, 1, 9])
    # bins 6, 7, 0 form one run across the end (13 points), bins 3-4 another (2)
    assert sorted(empty_runs(own, other, 1)) == [(3, 2), (6, 3)]
    assert empty_runs(own, other, 5) == [(6, 3)]
    assert empty_runs(np.zeros(8), other, 1) == [] and empty_runs(np.ones(8), other, 1) == []


def test_a_scan_cut_behind_has_a_blind_sector_and_full_scans_none():
    T = pose_from_xyzrpy([1.0, 0.5, 0.0, 0.0, 0.0, 0.3])  # sensor 2 moved and turned 17 deg
    full1 = ring_of_points(20000, 1)
    cut2 = ring_of_points(20000, 2, keep_deg=135.0)  # scan 2 sees 90 deg less, behind it
    pair = RegisteredPair(full1, apply_pose(T, cut2), T)
    (sector,) = blind_sectors(pair)
    assert sector.blind == 2
    # the run of whole 10 deg sectors inside (135, 225) deg of scan 2's frame
    assert 130 <= sector.start_deg <= 150 and 210 <= sector.end_deg <= 230
    own2 = (pair.xyz1 - T[:3, 3]) @ T[:3, :3]
    azimuth = np.degrees(np.arctan2(own2[:, 1], own2[:, 0])) % 360
    assert np.all((azimuth[sector.points] > 130) & (azimuth[sector.points] < 230))
    assert "scan 2 returned nothing" in sector.statement()
    full2 = RegisteredPair(full1, apply_pose(T, ring_of_points(20000, 3)), T)
    assert blind_sectors(full2) == []
