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
from .survivors import survivor_rows

# The one-ring test's first search: on a dense scan most points have another ring's point among
# their nearest few, which settles them for under a third of the time of all ``k`` (80 channels,
# 87,000 points: 70% settled by 8); the others are searched again for all ``k``.
FIRST_NEIGHBOURS = 8


def ring_normals(
    xyz: np.ndarray, normals: np.ndarray, elevation_deg, radius_m: float, k: int, one_ring: np.ndarray | None = None
) -> np.ndarray:
    """``normals`` (N, 3) of a cloud given in its own sensor's frame, with those of the points
    whose ``k`` nearest neighbours within ``radius_m`` hold one of the channels at
    ``elevation_deg`` replaced by their rings' (see the module; zero where none). ``one_ring``:
    those points (``one_ring_points``), when already known."""
    from scipy.spatial import cKDTree

    channels, channel = nearest_channels(xyz, elevation_deg)
    if one_ring is None:
        one_ring = one_ring_points(xyz, elevation_deg, radius_m, k)
    out = np.array(normals, dtype=np.float64, copy=True)
    order = np.argsort(channel, kind="stable")
    starts = np.searchsorted(channel[order], np.arange(len(channels) + 1))
    members = [order[a:b] for a, b in zip(starts[:-1], starts[1:])]  # each channel's points, ascending
    ringed = np.unique(channel[one_ring])
    needed = np.zeros(len(channels), dtype=bool)  # the channels with one-ring points and their neighbours
    for offset in (-1, 0, 1):
        needed[np.clip(ringed + offset, 0, len(channels) - 1)] = True
    trees = [cKDTree(xyz[m]) if needed[c] and len(m) else None for c, m in enumerate(members)]
    for c in ringed:
        own = members[c][one_ring[members[c]]]
        ring = _neighbours(trees[c], xyz[members[c]], xyz[own], k, np.inf)
        out[own] = _ring_normal(ring, *_neighbouring_rings(xyz, own, c, channels, members, trees, ring, k))
    return out


def one_ring_points(
    xyz: np.ndarray, elevation_deg, radius_m: float, k: int, rows: np.ndarray | None = None
) -> np.ndarray:
    """(N,) whether each point's ``k`` nearest neighbours within ``radius_m`` all lie on its
    channel (the nearest of ``elevation_deg``): the points ``ring_normals`` gives their rings'
    normals. It depends only on the points within ``radius_m``. ``rows``: only those points'
    answers (their neighbours still among all of ``xyz``)."""
    return witnessed_one_ring(xyz, elevation_deg, radius_m, k, rows)[0]


def witnessed_one_ring(
    xyz: np.ndarray, elevation_deg, radius_m: float, k: int, rows: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``one_ring_points`` and, for each point that is not, a witness: the index of a neighbour
    on another channel strictly nearer than its ``k``-th (among its ``k`` nearest however
    distance ties fall), -1 where none is known (``one_ring_after_removal``)."""
    from scipy.spatial import cKDTree

    _, channel = nearest_channels(xyz, elevation_deg)
    rows = np.arange(len(xyz)) if rows is None else np.asarray(rows)
    return _one_ring(cKDTree(xyz), channel, xyz[rows], channel[rows], radius_m, min(k, len(xyz)))


def one_ring_after_removal(
    one_ring: np.ndarray,
    witness: np.ndarray,
    keep: np.ndarray,
    kept: np.ndarray,
    near: np.ndarray,
    elevation_deg,
    radius_m: float,
    k: int,
) -> tuple[np.ndarray, np.ndarray]:
    """``witnessed_one_ring`` of the points ``kept`` (the points ``keep`` of the cloud that
    ``one_ring`` and ``witness`` answer for), the same as found afresh: only the kept points
    ``near`` a removed one (within ``radius_m``; rows of ``kept``) can change, and of those
    not the ones whose witness is kept. Removing points only makes a point's other neighbours
    nearer in rank and its ``k``-th neighbour farther, so a kept witness stays one of its ``k``
    nearest, strictly nearer than the ``k``-th. The others are tested again among ``kept``."""
    one_ring, witness = one_ring[keep], witness[keep]
    held = witness >= 0
    held[held] = keep[witness[held]]
    witness = np.where(held, survivor_rows(keep)[np.maximum(witness, 0)], -1)
    stale = near[~held[near]]
    if len(stale):
        one_ring[stale], witness[stale] = witnessed_one_ring(kept, elevation_deg, radius_m, k, stale)
    return one_ring, witness


def nearest_channels(xyz: np.ndarray, elevation_deg) -> tuple[np.ndarray, np.ndarray]:
    """The channels' elevations, ascending, and each point's nearest of them (its index)."""
    channels = np.sort(np.asarray(elevation_deg, dtype=np.float64))
    elevation = np.degrees(np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1])))
    return channels, np.searchsorted(0.5 * (channels[1:] + channels[:-1]), elevation)


def _neighbouring_rings(xyz: np.ndarray, own: np.ndarray, c: int, channels: np.ndarray, members, trees, ring, k: int):
    """For the points ``own`` of channel ``c`` (their ``ring``'s ``k`` nearest, (n, k, 3)): the
    ``k`` nearest of the channel below and of the one above within their reach (NaN where none),
    and each one's nearest distance (inf where none); ``members`` and ``trees`` each channel's
    (None where not needed)."""
    points = xyz[own]
    r = np.sqrt(np.einsum("ij,ij->i", points, points))
    sides, nearest = [], []
    for side in (c - 1, c + 1):
        if not 0 <= side < len(channels):
            sides.append(np.full_like(ring, np.nan))
            nearest.append(np.full(len(own), np.inf))
            continue
        reach = r * math.radians(abs(channels[side] - channels[c])) / GRAZING_MIN
        across = _neighbours(trees[side], xyz[members[side]], points, k, reach)
        if across is None:
            across = np.full_like(ring, np.nan)
        sides.append(across)
        gap = np.linalg.norm(across - points[:, None, :], axis=2)
        nearest.append(np.min(np.where(np.isfinite(gap), gap, np.inf), axis=1))
    return sides, nearest


def _one_ring(
    tree, channel: np.ndarray, points: np.ndarray, own: np.ndarray, radius_m: float, k: int
) -> tuple[np.ndarray, np.ndarray]:
    """Whether each of ``points`` (on channels ``own``) has its ``k`` nearest neighbours within
    ``radius_m`` (``tree`` of the points ``channel`` numbers) all on its channel, and its
    witness (``witnessed_one_ring``). A point whose first ``FIRST_NEIGHBOURS`` hold another
    channel's point strictly nearer than the farthest of them is not (that point is among the k
    nearest however distance ties fall), nor is one with another channel's point among fewer
    (they are all its neighbours within the radius); the others are searched for all ``k``."""
    one_ring = np.ones(len(points), dtype=bool)
    witness = np.full(len(points), -1, dtype=np.int64)
    pending = np.arange(len(points))
    if FIRST_NEIGHBOURS < k:
        other, sure, index, fewer = _other_channels(tree, channel, points, own, FIRST_NEIGHBOURS, radius_m)
        settled = sure.any(axis=1) | fewer
        one_ring[settled] = ~other[settled].any(axis=1)
        witness[settled] = _first(sure[settled], index[settled])
        pending = np.flatnonzero(~settled)
    other, sure, index, _ = _other_channels(tree, channel, points[pending], own[pending], k, radius_m)
    one_ring[pending] = ~other.any(axis=1)
    witness[pending] = _first(sure, index)
    return one_ring, witness


def _other_channels(tree, channel: np.ndarray, points: np.ndarray, own: np.ndarray, k: int, radius_m: float):
    """Each point's ``k`` nearest within ``radius_m`` (``tree`` of the points ``channel``
    numbers): which lie on another channel than ``own``; which of those are among its ``k``
    nearest however distance ties fall (strictly nearer than the ``k``-th, or all, when fewer
    than ``k`` lie within the radius); their indices (``len(channel)`` where missing); and
    whether fewer than ``k`` lie within the radius."""
    distance, index = tree.query(points, k=k, distance_upper_bound=radius_m)
    distance, index = distance.reshape(len(points), k), index.reshape(len(points), k)
    padded = np.append(channel, -1)  # the tree's index of a missing neighbour is len(channel)
    other = (padded[index] != own[:, None]) & (index < len(channel))
    fewer = ~np.isfinite(distance[:, -1])
    sure = other & ((distance < distance[:, -1:]) | fewer[:, None])
    return other, sure, index, fewer


def _first(sure: np.ndarray, index: np.ndarray) -> np.ndarray:
    """Per row the index of its first ``sure`` neighbour, -1 where none."""
    return np.where(sure.any(axis=1), index[np.arange(len(index)), sure.argmax(axis=1)], -1)


def _ring_normal(ring: np.ndarray, sides: list[np.ndarray], nearest: list[np.ndarray]) -> np.ndarray:
    """(n, 3) the normals of points from their own ``ring``'s and the neighbouring channels'
    ``sides`` (below, above) nearest points (n, k, 3; NaN where none), ``nearest`` each side's
    nearest distance (inf where none): each plane fitted only for the points that take it."""
    found = [np.isfinite(d) for d in nearest]
    normal = np.zeros((len(ring), 3))
    both = found[0] & found[1]
    _, ring_spread = _plane(ring[both])
    normal3, spread3 = _plane(np.concatenate([ring[both], sides[0][both], sides[1][both]], axis=1))
    # One surface across three rings: no thicker across their plane than the point's own ring is
    # across itself (its range noise).
    flat = spread3[:, 0] <= ring_spread[:, 1]
    three = np.zeros(len(ring), dtype=bool)
    three[both] = flat
    normal[three] = normal3[flat]
    # Otherwise the nearer neighbouring ring's plane (the outermost channels have one).
    two = (found[0] | found[1]) & ~three
    below = nearest[0] <= nearest[1]
    for side, takes in ((sides[0], two & below), (sides[1], two & ~below)):  # the sides' widths may differ
        normal[takes] = _plane(np.concatenate([ring[takes], side[takes]], axis=1))[0]
    return normal


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
