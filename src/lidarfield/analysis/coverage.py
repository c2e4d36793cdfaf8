"""Where one scan saw and the other did not: an azimuth sector one cloud fills and the other
leaves empty.

The field is made of the voxels both clouds fill, so a scan that sees a sector less (a sensor
mounted against part of its vehicle, or set to a sector) leaves no vector there: the field of
the rest can read ``random`` with half the scene missing from one scan. The points say it: in
the frame of the scan that misses them, the other cloud has returns in a run of azimuth
sectors where its own cloud has none at all, at any elevation or range. A 360-degree lidar
returns something in every direction from a street, a car park or a room (the ground, the
vehicle it sits on), so a run of empty sectors of ``MIN_SECTOR_DEG`` is a field of view, not
a scene; a change of viewpoint hides at most a part of a sector's elevations (an object
close to one sensor), never all of them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..hypotheses.geometry import own_frame_points
from ..pair import RegisteredPair
from ..poses import in_sensor_frame

SECTOR_DEG = 10.0
# A run of empty sectors at least this wide is a field of view (two sectors: a lidar's
# azimuth limits cut at any angle leave at least one whole sector empty per 20 deg).
MIN_SECTOR_DEG = 20.0
# ... and the other cloud has at least this share of its points in it (a few returns of the
# other scan in an empty direction are a sky, a window, a far wall out of range).
MIN_POINT_SHARE = 0.01


@dataclass(frozen=True)
class BlindSector:
    """Scan ``blind`` (1 or 2) returned nothing in azimuth [``start_deg``, ``end_deg``] of its
    own frame (counter-clockwise from +x; ``end_deg`` may exceed 180 where it wraps), where the
    other cloud has ``points`` (mask over the other cloud's points)."""

    blind: int
    start_deg: float
    end_deg: float
    points: np.ndarray

    def statement(self) -> str:
        other = 3 - self.blind
        return (
            f"scan {self.blind} returned nothing in azimuth {self.start_deg:.0f} to {self.end_deg:.0f} deg of its "
            f"frame, where cloud {other} has {int(self.points.sum())} points: a field of view narrower than scan "
            f"{other}'s there"
        )


def empty_runs(own: np.ndarray, other: np.ndarray, min_other: int) -> list[tuple[int, int]]:
    """Runs of circular bins (first, count) where ``own`` is 0 and the bins of the run hold at
    least ``min_other`` of ``other`` together; the whole circle is no run (a scan with no point)."""
    empty = own == 0
    n = len(own)
    if empty.all() or not empty.any():
        return []
    start = int(np.flatnonzero(~empty)[0])  # rotate so that no run wraps past the end
    order = (np.arange(n) + start) % n
    runs, k = [], 0
    while k < n:
        if not empty[order[k]]:
            k += 1
            continue
        first = k
        while k < n and empty[order[k]]:
            k += 1
        if other[order[first:k]].sum() >= min_other:
            runs.append((int(order[first]), k - first))
    return runs


def blind_sectors(pair: RegisteredPair) -> list[BlindSector]:
    """The widest blind sector of each scan, if it has one (``MIN_SECTOR_DEG`` wide or more, with
    ``MIN_POINT_SHARE`` of the other cloud's points in it)."""
    bins = int(round(360.0 / SECTOR_DEG))
    own = own_frame_points(pair)
    frames = (np.eye(4), pair.T_1_2)
    found = []
    for k in (0, 1):
        other = pair.xyz2 if k == 0 else pair.xyz1
        if not len(own[k]) or not len(other):
            continue
        other_own = in_sensor_frame(other, frames[k])
        sector_own, sector_other = (_sector(xyz, bins) for xyz in (own[k], other_own))
        counts = [np.bincount(s, minlength=bins) for s in (sector_own, sector_other)]
        runs = [r for r in empty_runs(*counts, MIN_POINT_SHARE * len(other)) if r[1] * SECTOR_DEG >= MIN_SECTOR_DEG]
        if runs:
            first, length = max(runs, key=lambda r: r[1])
            chosen = (np.arange(first, first + length) % bins).tolist()
            start = -180.0 + first * SECTOR_DEG
            found.append(BlindSector(k + 1, start, start + length * SECTOR_DEG, np.isin(sector_other, chosen)))
    return found


def _sector(xyz: np.ndarray, bins: int) -> np.ndarray:
    azimuth = np.degrees(np.arctan2(xyz[:, 1], xyz[:, 0]))
    return np.minimum(((azimuth + 180.0) / SECTOR_DEG).astype(np.int64), bins - 1)
