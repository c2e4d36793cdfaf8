"""Issue 25's ego-car drive: the built-in scene paper-intersection-ego-car (the sensor 2 m up on
a car's roof, carrying its body, another car driving at 5 m/s), sensor 2 1 m further and 0.5 s
later, 2 cm range noise; for the explain tests and bench/explain.py."""

from __future__ import annotations

import dataclasses

import numpy as np

from lidarfield.pair import RegisteredPair
from lidarfield.poses import pose_from_xyzrpy
from lidarfield.registration import register_pair
from lidarfield.sensors.models import PRESETS
from lidarfield.simulation.raycast import simulate_scan
from lidarfield.simulation.scene import load_scene


def ego_car_pair(sensor: str, points: int | None = None, azimuth_resolution_deg: float | None = None) -> RegisteredPair:
    """The pair registered by the truth, seen by the preset ``sensor`` (at
    ``azimuth_resolution_deg`` instead of its own step, when given); each cloud subsampled to
    ``points`` (fixed seed) when given."""
    scene, model = load_scene("paper-intersection-ego-car"), PRESETS[sensor]
    if azimuth_resolution_deg is not None:
        model = dataclasses.replace(model, azimuth_resolution_deg=azimuth_resolution_deg)
    scans = [
        simulate_scan(scene, model, pose_from_xyzrpy(pose), time_s=t, seed=seed, range_noise_m=0.02)
        for seed, pose, t in ((1, [0, 0, 2, 0, 0, 0], 0.0), (2, [1, 0, 2, 0, 0, 0.0037], 0.5))
    ]
    pair = register_pair(scans[0], scans[1], "truth")
    if points is None:
        return pair
    rng = np.random.default_rng(0)
    keep = [np.sort(rng.choice(len(xyz), size=min(points, len(xyz)), replace=False)) for xyz in (pair.xyz1, pair.xyz2)]
    return pair.subset(*keep)


def registered_off(pair: RegisteredPair, x_m: float = 0.3) -> RegisteredPair:
    """The pair with scan 2 registered ``x_m`` off in x."""
    shift = pose_from_xyzrpy([x_m, 0, 0, 0, 0, 0])
    return dataclasses.replace(pair, xyz2=pair.xyz2 + shift[:3, 3], T_1_2=shift @ pair.T_1_2)
