"""The plain ``ring_normals`` (as it was until 2026-11-25): every point's ``k`` nearest neighbours
in one query, every channel's tree, and all three planes of every one-ring point, the chosen one
picked after (the neighbouring rings' points gathered as the fast one does). The fast one
(``lidarfield.hypotheses.ring_normals``) must equal it."""

from __future__ import annotations

import numpy as np

from lidarfield.hypotheses.ring_normals import _neighbouring_rings, _neighbours, _plane


def reference_ring_normals(xyz: np.ndarray, normals: np.ndarray, elevation_deg, radius_m: float, k: int) -> np.ndarray:
    from scipy.spatial import cKDTree

    channels = np.sort(np.asarray(elevation_deg, dtype=np.float64))
    elevation = np.degrees(np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1])))
    channel = np.searchsorted(0.5 * (channels[1:] + channels[:-1]), elevation)
    _, index = cKDTree(xyz).query(xyz, k=min(k, len(xyz)), distance_upper_bound=radius_m)
    index = index.reshape(len(xyz), -1)
    padded = np.append(channel, -1)
    neighbour_channel = padded[index]
    one_ring = np.all((neighbour_channel == channel[:, None]) | (neighbour_channel < 0), axis=1)
    out = np.array(normals, dtype=np.float64, copy=True)
    members = [np.flatnonzero(channel == c) for c in range(len(channels))]
    trees = [cKDTree(xyz[m]) if len(m) else None for m in members]
    for c, own in enumerate(members):
        own = own[one_ring[own]]
        if len(own) == 0:
            continue
        ring = _neighbours(trees[c], xyz[members[c]], xyz[own], k, np.inf)
        sides, nearest = _neighbouring_rings(xyz, own, c, channels, members, trees, ring, k)
        found = [np.isfinite(d) for d in nearest]
        _, ring_spread = _plane(ring)
        normal3, spread3 = _plane(np.concatenate([ring, *sides], axis=1))
        three = found[0] & found[1] & (spread3[:, 0] <= ring_spread[:, 1])
        nearer = np.where(nearest[0] <= nearest[1], 0, 1)
        two = np.where(
            (nearer == 0)[:, None],
            _plane(np.concatenate([ring, sides[0]], axis=1))[0],
            _plane(np.concatenate([ring, sides[1]], axis=1))[0],
        )
        chosen = np.where(three[:, None], normal3, np.where((found[0] | found[1])[:, None], two, 0.0))
        out[own] = chosen
    return out
