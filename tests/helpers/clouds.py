"""Synthetic point clouds used by more than one test file (numpy only)."""

from __future__ import annotations

import math

import numpy as np


def voxel_centre_clouds(per_voxel: int = 40, seed: int = 0, spread_deg: float = 1.0) -> np.ndarray:
    """Blobs of points around the centre of every voxel of the default SphericalGrid (36 x 10 deg,
    5 x 8 deg from -20 to +20), at 8-12 m: at least 4 deg from any voxel edge, so a motion of a
    few millimetres (or 2 deg of yaw) keeps every point in its voxel."""
    rng = np.random.default_rng(seed)
    az_c, el_c = np.meshgrid(np.arange(5.0, 360.0, 10.0), np.arange(-16.0, 20.0, 8.0))
    az = np.repeat(az_c.ravel(), per_voxel) + rng.uniform(-spread_deg, spread_deg, az_c.size * per_voxel)
    el = np.repeat(el_c.ravel(), per_voxel) + rng.uniform(-spread_deg, spread_deg, az_c.size * per_voxel)
    r = rng.uniform(8.0, 12.0, az.size)
    az, el = np.radians(az), np.radians(el)
    return np.column_stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)])


def synthetic_cloud(rng) -> np.ndarray:
    """A surface with exact duplicates (a point repeated 30 times: all its neighbours at 0),
    doubled points, a tight cluster and isolated points far away."""
    surface = np.column_stack([rng.uniform(-5, 5, (3000, 2)), rng.normal(scale=0.01, size=3000)])
    repeated = np.repeat(surface[:1] + [0, 0, 1.0], 30, axis=0)
    doubled = surface[rng.choice(3000, 200, replace=False)]
    cluster = rng.normal(loc=[8.0, 8.0, 0.0], scale=1e-4, size=(25, 3))
    isolated = rng.uniform(-50, 50, size=(10, 3))
    xyz = np.vstack([surface, repeated, doubled, cluster, isolated])
    return xyz[rng.permutation(len(xyz))]


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


def targets(
    per_voxel: int, seed: int, noise_m: float = 0.02, half_deg: float = 1.5, range_m: float = 10.0
) -> np.ndarray:
    """Points on a square target facing the sensor at the centre of every voxel of the default
    SphericalGrid, 2 cm of noise along the line of sight: two seeds are two independent
    samplings of the same surfaces."""
    rng = np.random.default_rng(seed)
    az, el = np.meshgrid(np.radians(np.arange(5.0, 360.0, 10.0)), np.radians(np.arange(-16.0, 20.0, 8.0)))
    az, el = np.repeat(az.ravel(), per_voxel), np.repeat(el.ravel(), per_voxel)
    sight = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    across = np.column_stack([-np.sin(az), np.cos(az), np.zeros_like(az)])
    up = np.cross(sight, across)
    half = range_m * math.radians(half_deg)
    a, b = rng.uniform(-half, half, (2, len(az)))
    r = range_m + rng.normal(scale=noise_m, size=len(az))
    return sight * r[:, None] + across * a[:, None] + up * b[:, None]
