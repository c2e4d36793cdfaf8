"""Surface normals of a scan where a point's neighbours hold one ring: from its rings.

The normal of a point's nearest neighbours is the surface's only when they span the surface. On
a sparse lidar they often do not: on the ground 2 m below a VLP-16, neighbouring rings are 1.2 m
apart at 8 m and more farther out, so a point's 30 nearest neighbours within 1 m all lie on its
own ring, and their thinnest direction is across the ring *and the ray* (range noise thickens a
ring along the ray): a "normal" tilted from the vertical by the beam's elevation. A
point-to-plane fit on such normals is biased when the sensors were at two places (``realign``).

So where a point's ``k`` nearest neighbours within the radius all lie on its own channel, its
neighbourhood becomes the ``k`` nearest points of its own channel (the ring's tangent) and the
``k`` nearest of each neighbouring channel, below and above (across the rings). Its normal is
the least-spread direction of the three where they lie on one surface: no thicker across their
plane (least eigenvalue) than the point's own ring is across itself (its middle eigenvalue: the
range noise). Otherwise (a wall's foot: the ring above on the wall, the one below on the ground;
the outermost channels, with one neighbour) it is the plane of its ring and the nearer
neighbouring ring. A neighbouring channel counts only where its nearest point is within
``r x gap / GRAZING_MIN`` of the point (r its range, gap the angle between the two channels,
``field.significance.GRAZING_MIN``: the spacing of two rings on a surface seen at up to 84 deg
of incidence); with none, the normal is zero (the point constrains nothing). Channels are the
sensor model's, each point taking the nearest by elevation from its own sensor. The other
points keep the normals they were given.
"""

from __future__ import annotations

import math

import numpy as np

from ..field.significance import GRAZING_MIN


def ring_normals(xyz: np.ndarray, normals: np.ndarray, elevation_deg, radius_m: float, k: int) -> np.ndarray:
    """``normals`` (N, 3) of a cloud given in its own sensor's frame, with those of the points
    whose ``k`` nearest neighbours within ``radius_m`` hold one of the channels at
    ``elevation_deg`` replaced by their rings' (see the module; zero where none)."""
    from scipy.spatial import cKDTree

    channels = np.sort(np.asarray(elevation_deg, dtype=np.float64))
    elevation = np.degrees(np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1])))
    channel = np.searchsorted(0.5 * (channels[1:] + channels[:-1]), elevation)  # the nearest channel
    _, index = cKDTree(xyz).query(xyz, k=min(k, len(xyz)), distance_upper_bound=radius_m)
    index = index.reshape(len(xyz), -1)
    padded = np.append(channel, -1)
    neighbour_channel = padded[index]
    one_ring = np.all((neighbour_channel == channel[:, None]) | (neighbour_channel < 0), axis=1)
    out = np.array(normals, dtype=np.float64, copy=True)
    members = [np.flatnonzero(channel == c) for c in range(len(channels))]
    trees = [cKDTree(xyz[m]) if len(m) else None for m in members]
    r = np.sqrt(np.einsum("ij,ij->i", xyz, xyz))
    for c, own in enumerate(members):
        own = own[one_ring[own]]
        if len(own) == 0:
            continue
        points = xyz[own]
        ring = _neighbours(trees[c], xyz[members[c]], points, k, np.inf)
        sides, nearest = [], []
        for side in (c - 1, c + 1):
            if not 0 <= side < len(channels):
                sides.append(np.full_like(ring, np.nan))
                nearest.append(np.full(len(own), np.inf))
                continue
            reach = r[own] * math.radians(abs(channels[side] - channels[c])) / GRAZING_MIN
            across = _neighbours(trees[side], xyz[members[side]], points, k, reach)
            if across is None:
                across = np.full_like(ring, np.nan)
            sides.append(across)
            gap = np.linalg.norm(across - points[:, None, :], axis=2)
            nearest.append(np.min(np.where(np.isfinite(gap), gap, np.inf), axis=1))
        found = [np.isfinite(d) for d in nearest]
        _, ring_spread = _plane(ring)
        normal3, spread3 = _plane(np.concatenate([ring, *sides], axis=1))
        # One surface across three rings: no thicker across their plane than the point's own
        # ring is across itself (its range noise).
        three = found[0] & found[1] & (spread3[:, 0] <= ring_spread[:, 1])
        # Otherwise the nearer neighbouring ring's plane (the outermost channels have one).
        nearer = np.where(nearest[0] <= nearest[1], 0, 1)
        two = np.where(
            (nearer == 0)[:, None],
            _plane(np.concatenate([ring, sides[0]], axis=1))[0],
            _plane(np.concatenate([ring, sides[1]], axis=1))[0],
        )
        chosen = np.where(three[:, None], normal3, np.where((found[0] | found[1])[:, None], two, 0.0))
        out[own] = chosen
    return out


def _neighbours(tree, cloud: np.ndarray, points: np.ndarray, k: int, reach) -> np.ndarray | None:
    """(n, k, 3) the ``k`` nearest points of ``cloud`` (its ``tree``) to each point, NaN where
    farther than ``reach`` (scalar or (n,)) or missing; None when the cloud is empty."""
    if tree is None or tree.n == 0:
        return None
    k = min(k, tree.n)
    distance, index = tree.query(points, k=k)
    distance, index = distance.reshape(len(points), k), index.reshape(len(points), k)
    near = distance <= np.reshape(reach, (-1, 1))
    out = cloud[np.minimum(index, tree.n - 1)]
    out[~near] = np.nan
    return out


def _plane(patch: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per patch (n, m, 3; NaN rows ignored): the unit eigenvector of its points' least spread
    and the spread's eigenvalues (n, 3), ascending (NaN with fewer than 3 points)."""
    valid = np.all(np.isfinite(patch), axis=2)
    count = valid.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(valid[:, :, None], patch, 0.0).sum(axis=1) / count[:, None]
        centred = np.where(valid[:, :, None], patch - mean[:, None, :], 0.0)
        covariance = np.einsum("nmi,nmj->nij", centred, centred) / np.maximum(count, 1)[:, None, None]
    values, vectors = np.linalg.eigh(np.nan_to_num(covariance))
    values[count < 3] = np.nan
    return vectors[:, :, 0], values
