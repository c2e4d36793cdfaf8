"""Example plugin hypothesis: remove the points of objects that moved between the two scans.

The plain example of a plugin file. To remove moving objects, use the built-in
``moving_objects`` (free-space evidence grown to objects): this rule also removes whatever one
sensor alone saw.

A plugin is a plain Python file with a function ``(pair, params) -> (keep1, keep2)``. Use it
from a study config with

    hypotheses:
      - plugin: {file: hypotheses/moving_cars.py, function: remove,
                 params: {min_gap_m: 1.0, z_range_m: [-2.5, 0.5]}}

(``file`` relative to the folder the study runs from). ``pair`` is a
``lidarfield.pair.RegisteredPair``: ``pair.xyz1`` and ``pair.xyz2`` are both clouds in scan 1's
sensor frame (N x 3, metres, read-only), ``pair.origin2`` is sensor 2's position in that frame,
``pair.T_1_2`` its 4x4 pose, ``pair.sensor1/2`` the sensor models, ``pair.attributes1/2`` the
per-point attributes (intensity, ring, time, when the scans have them). Return one boolean
array per cloud, True for the points to keep.

The rule: after registration the static scene lies on top of itself, so a point with no point
of the other scan within ``min_gap_m`` belongs to something that moved (or that only one
sensor saw). Only points in the height band of cars, ``z_range_m`` in frame 1, are candidates,
so that walls and ground seen from one sensor only are left to the other hypotheses.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def remove(pair, params: dict) -> tuple[np.ndarray, np.ndarray]:
    """Keep-masks: False for car-height points farther than ``min_gap_m`` from the other scan."""
    min_gap_m = float(params.get("min_gap_m", 1.0))
    z_low, z_high = params.get("z_range_m", [-2.5, 0.5])
    return (
        _keep(pair.xyz1, pair.xyz2, min_gap_m, z_low, z_high),
        _keep(pair.xyz2, pair.xyz1, min_gap_m, z_low, z_high),
    )


def _keep(points: np.ndarray, other: np.ndarray, min_gap_m: float, z_low: float, z_high: float) -> np.ndarray:
    keep = np.ones(len(points), dtype=bool)
    if len(other) == 0:
        return keep
    candidate = (points[:, 2] >= z_low) & (points[:, 2] <= z_high)
    gap, _ = cKDTree(other).query(points[candidate], distance_upper_bound=min_gap_m)
    keep[candidate] = np.isfinite(gap)  # inf: no point of the other scan within min_gap_m
    return keep
