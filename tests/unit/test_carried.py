"""The vehicle's own body from the points it carries (analysis.carried): what stays put in both
sensors' own frames while they moved, and nothing from one place."""

from __future__ import annotations

import numpy as np
import pytest

from lidarfield.analysis.carried import OWN_M, STATIC_M, CarriedBody, carried_body, carried_points
from lidarfield.pair import RegisteredPair
from lidarfield.poses import apply_pose, pose_from_xyzrpy


def body_and_scene(T_1_2: np.ndarray, seed: int = 0) -> tuple[RegisteredPair, int]:
    """A cargo body's face behind the sensor (600 points on 2 x 2 m, 2 m away, the same in both
    sensors' frames but for 5 mm of noise) and a fixed scene (2,000 points on a cylinder 10 m round, both scans
    seeing the same points, 5 mm of noise): the pair with sensor 2 at ``T_1_2``, and how many
    points of each cloud are the body (the first ones)."""
    rng = np.random.default_rng(seed)
    body = np.column_stack([np.full(600, -2.0), rng.uniform(-1, 1, 600), rng.uniform(-1.5, 0.5, 600)])
    azimuth = rng.uniform(-np.pi, np.pi, 2000)
    scene = np.column_stack([10 * np.cos(azimuth), 10 * np.sin(azimuth), rng.uniform(-2, 2, 2000)])
    xyz1 = np.vstack([body, scene]) + rng.normal(0, 0.005, (2600, 3))
    xyz2 = np.vstack([apply_pose(T_1_2, body), scene]) + rng.normal(0, 0.005, (2600, 3))
    return RegisteredPair(xyz1, xyz2, T_1_2), len(body)


def every_point(pair: RegisteredPair) -> tuple[np.ndarray, np.ndarray]:
    return np.ones(len(pair.xyz1), dtype=bool), np.ones(len(pair.xyz2), dtype=bool)


def test_a_body_the_sensors_carried_along_a_drive_is_found_and_the_fixed_scene_is_not():
    drive = pose_from_xyzrpy([0.3, 0.0, 0.0, 0.0, 0.0, np.radians(6.9)])  # the zoo's intersection drive
    pair, n_body = body_and_scene(drive)
    for carried in carried_points(pair, every_point(pair)):
        assert carried[:n_body].all()  # every point of the body
        assert not carried[n_body:].any()  # no point of the scene: it has the other scan's return in frame 1
    only_body = np.arange(len(pair.xyz1)) < n_body
    assert carried_body(pair, ~only_body, ~only_body) == CarriedBody(2 * n_body, 2 * n_body)
    assert carried_body(pair, ~only_body, ~only_body).is_vehicle


@pytest.mark.parametrize("move_m", [0.0, 0.02])
def test_from_one_place_or_a_move_within_the_bound_nothing_is_carried(move_m):
    """A point is carried only if the motion moved it by more than STATIC_M - OWN_M (5 cm)."""
    assert move_m < STATIC_M - OWN_M
    pair, _ = body_and_scene(pose_from_xyzrpy([move_m, 0.0, 0.0, 0.0, 0.0, 0.0]))
    assert not any(carried.any() for carried in carried_points(pair, every_point(pair)))


def test_a_removal_is_the_vehicle_when_most_of_it_is_carried_and_enough():
    assert CarriedBody(100, 50).is_vehicle and not CarriedBody(101, 50).is_vehicle
    assert not CarriedBody(60, 49).is_vehicle  # too few points, all but 11 carried
    assert not CarriedBody(0, 0).is_vehicle
    assert "50 of the 100 points" in CarriedBody(100, 50).statement()
