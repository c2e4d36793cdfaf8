"""Free space and co-visibility: where a sensor's rays passed through, and what it could see,
from the range image of its returns.

A sensor's range image has one row per channel (beam), ordered by elevation, and one column
per azimuth step of its model: a return goes to its own channel's row (its ``ring``, where the
scan carries one, else the channel nearest its elevation), so a layout with uneven channels
(a VLP-32C's 9.4 deg gap below -15.6 deg, the sparse edges of "gradient" layouts) keeps the
resolution of its dense part. A point asked about goes to the channel nearest its elevation.

A point (in a sensor's frame) lies in that sensor's free space when a ball of radius m (a
margin that grows with range and the beam's width) around it does: it is nearer, by more than
m, than every return within m across the ray from its direction: the channels within the
angle m / range of its nearest channel and the next one beyond on each side (so at least the
beams on either side), the azimuth columns within that angle and at least one on each side.
A direction the sensor did not see says nothing: no return in the point's cell, a point
outside its elevation limits or nearer than its minimum range, a point behind what it
measured, and a point in a gap between channels farther from its nearest channel than both
the angle m / range and the layout's usual channel spacing (the median gap: no ray passed
near it). :func:`free_space_evidence` is the vectorised kernel (a minimum filter along
azimuth per window, then a sparse table of minima over rows); :func:`free_space_evidence_loop`
the plain per-point reference it is tested against.

A point is **co-visible** from the other sensor (:func:`co_visible`, :func:`shared_points` for
a pair) when that sensor could have seen its surface: it is in the sensor's view (range limits,
elevation limits widened by half the beam's width, not deep in a gap between channels),
it is not hidden from the sensor (its rays nearest the point's direction, in its azimuth cell
on the beams on either side, all stopped short of it by more than the margin: a shadow; or none
returned: outside an azimuth sector, nothing seen there), and not in its free space (every
return within the margin's window farther by more than the margin: the rays passed through it,
something moved). Ground between two rings is co-visible (the ring below is nearer, the one above
farther), and so is an edge that some rays of the window hit and others pass. The field uses it
to tell the change of viewpoint on a surface both sensors saw from content only one of them saw
(``significance``). :func:`co_visible_loop` is its plain per-point reference.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..pair import RegisteredPair
from ..poses import in_sensor_frame
from ..sensors.models import SensorModel
from ..sensors.rig import LidarView
from .channels import measured_rings

# The margin across the ray is rounded up to a step of this ratio, so that few windows are filtered.
_WINDOW_RATIO = 1.25
# The margin of the free-space and co-visibility tests, m = MARGIN_M + range x tan(BEAM_WIDTH_DEG):
# moving_objects' defaults, and the field's co-visibility (a surface within it is one surface).
MARGIN_M = 0.2
BEAM_WIDTH_DEG = 0.2
# Angles closer than this share of the usual channel spacing are equal (floating-point rounding).
_TOLERANCE = 1e-9


def ranges(xyz: np.ndarray) -> np.ndarray:
    """3-D distance of each point from the origin of its frame."""
    return np.sqrt(np.einsum("ij,ij->i", xyz, xyz))


@dataclass(frozen=True)
class RangeImage:
    """What one sensor measured: the nearest range of its returns per cell of a channel x
    azimuth grid (rows: the channels by ascending elevation, ``channels``; columns: azimuth from
    ``-pi - azimuth_step / 2``, so that a beam fired at a multiple of the step is in the middle
    of its cell; inf: no return), and what it can see (the elevations of its lowest and highest
    channel, its minimum range)."""

    azimuth_step: float  # rad
    channels: np.ndarray  # (rows,) rad, ascending: each row's beam elevation
    nearest: np.ndarray  # (rows, columns)
    min_range_m: float = 0.0
    # per (columns on each side, farthest): the levels of a sparse table of the rows' extremes, made as asked for
    _tables: dict = field(default_factory=dict, compare=False, repr=False)
    # a pair's images are shared by the candidates' threads (RegisteredPair.remembered): one
    # thread at a time extends a table, or two would append the same level twice
    _tables_lock: threading.Lock = field(default_factory=threading.Lock, compare=False, repr=False)

    @property
    def elevation_limits(self) -> tuple[float, float]:
        return float(self.channels[0]), float(self.channels[-1])

    @cached_property
    def channel_spacing(self) -> float:
        """The layout's usual gap between neighbouring channels (the median; one channel: the azimuth step)."""
        return float(np.median(np.diff(self.channels))) if len(self.channels) > 1 else self.azimuth_step

    def cells(self, xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(row: the nearest channel, column, elevation, elevation off that channel) of points
        given in the sensor's frame."""
        azimuth, elevation = directions(xyz)
        row = nearest_channel(elevation, self.channels)
        return row, self.columns(azimuth), elevation, np.abs(elevation - self.channels[row])

    def columns(self, azimuth: np.ndarray) -> np.ndarray:
        step = self.azimuth_step
        return np.floor((azimuth + math.pi + step / 2) / step).astype(np.int64) % self.nearest.shape[1]

    def sampled(self, off_channel: np.ndarray, angle: np.ndarray) -> np.ndarray:
        """Whether a ray passed near directions ``off_channel`` (rad) from their nearest channel:
        within ``angle`` of it, or within the usual channel spacing (not deep in a wide gap)."""
        return off_channel <= np.maximum(angle, self.channel_spacing) * (1 + _TOLERANCE)

    def windows(self, row: np.ndarray, angle: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(first row, last row, columns on each side) of the windows that cover ``angle`` (rad)
        on each side of directions whose nearest channel is ``row``: the angle rounded up to a
        power of 1.25 of the smaller of the azimuth step and the usual channel spacing; the
        channels within it of the nearest one and the next beyond on each side (at least the
        beams on either side); the columns within it, at least one."""
        base = min(self.azimuth_step, self.channel_spacing)
        power = np.ceil(np.log(np.maximum(angle, base) / base) / math.log(_WINDOW_RATIO) - 1e-9)
        angle = base * _WINDOW_RATIO**power
        tolerance = _TOLERANCE * self.channel_spacing
        centre = self.channels[row]
        first = np.searchsorted(self.channels, centre - angle + tolerance, side="right") - 1
        last = np.searchsorted(self.channels, centre + angle - tolerance, side="left")
        columns = np.minimum(np.ceil(angle / self.azimuth_step - 1e-9), self.nearest.shape[1] // 2)
        rows = len(self.channels)
        return np.clip(first, 0, rows - 1), np.clip(last, 0, rows - 1), np.maximum(columns, 1).astype(np.int64)

    def extreme(
        self, first: np.ndarray, last: np.ndarray, column: np.ndarray, columns: int, farthest: bool = False
    ) -> np.ndarray:
        """The nearest range over rows ``first..last`` and ``columns`` on each side of ``column``
        (azimuth wraps around; inf: no return there), or with ``farthest`` the farthest of the
        cells' nearest returns (-inf: no return)."""
        level = np.floor(np.log2(last - first + 1)).astype(np.int64)
        pick = np.maximum if farthest else np.minimum
        out = np.empty(len(first))
        for k in range(int(level.min(initial=0)), int(level.max(initial=-1)) + 1):
            at = level == k
            at = slice(None) if at.all() else at  # one level for all (the usual case): no copies
            table = self._level(columns, farthest, k)
            out[at] = pick(table[first[at], column[at]], table[last[at] - (1 << k) + 1, column[at]])
        return out

    def _level(self, columns: int, farthest: bool, level: int) -> np.ndarray:
        """Level ``level`` of the sparse table of the extremes over ``columns`` on each side:
        the extreme over rows i..i + 2^level - 1 (past the last row: the last row's)."""
        with self._tables_lock:
            return self._made_level(columns, farthest, level)

    def _made_level(self, columns: int, farthest: bool, level: int) -> np.ndarray:
        levels = self._tables.get((columns, farthest))
        if levels is None:
            from scipy.ndimage import maximum_filter1d, minimum_filter1d

            size = min(2 * columns + 1, self.nearest.shape[1])
            if farthest:
                image = np.where(np.isfinite(self.nearest), self.nearest, -np.inf)
                levels = [maximum_filter1d(image, size=size, axis=1, mode="wrap")]
            else:
                levels = [minimum_filter1d(self.nearest, size=size, axis=1, mode="wrap")]
            self._tables[columns, farthest] = levels
        pick = np.maximum if farthest else np.minimum
        while len(levels) <= level:
            below, span = levels[-1], 1 << (len(levels) - 1)
            above = below.copy()  # the last rows keep their own extreme: the rows past them are none
            pick(below[:-span], below[span:], out=above[:-span])
            levels.append(above)
        return levels[level]


def directions(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth and elevation (rad) of points in a sensor's frame."""
    return np.arctan2(xyz[:, 1], xyz[:, 0]), np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1]))


def nearest_channel(elevation: np.ndarray, channels: np.ndarray) -> np.ndarray:
    """Index of the channel (ascending elevations) nearest each elevation."""
    above = np.clip(np.searchsorted(channels, elevation), 1, max(len(channels) - 1, 1))
    if len(channels) == 1:
        return np.zeros(len(elevation), dtype=np.int64)
    below_nearer = (elevation - channels[above - 1]) <= (channels[above] - elevation)
    return np.where(below_nearer, above - 1, above).astype(np.int64)


def channel_rows(elevation: np.ndarray, channels: np.ndarray, ring: np.ndarray | None = None) -> np.ndarray:
    """The channel (row) of each return: its ring's where the scan carries one, else the one
    nearest its elevation. Drivers number rings differently (a VLP-32C's by laser ID in
    Argoverse 2, by elevation in ROS), so a ring is matched to a channel by the elevation of its
    returns (:func:`~lidarfield.field.channels.measured_rings`): in the same order when there
    are as many rings as channels, else the nearest; returns without a ring (NaN, negative)
    take the channel nearest their own, and so do the returns of a ring that is no channel: one
    whose returns lie on average farther from its channel than the layout's usual gap (a driver
    that writes ring 0 for every point, or rings of another layout)."""
    rows = nearest_channel(elevation, channels)
    if ring is None:
        return rows
    rings = measured_rings(elevation, ring)
    known = rings.index >= 0
    if not known.any():
        return rows
    which = rings.index[known]
    if len(rings.names) == len(channels):
        row_of_ring = np.empty(len(rings.names), dtype=np.int64)
        row_of_ring[np.argsort(rings.elevation, kind="stable")] = np.arange(len(rings.names))
    else:
        row_of_ring = nearest_channel(rings.elevation, channels)
    gap = float(np.median(np.diff(channels))) if len(channels) > 1 else np.inf
    off = np.bincount(
        which, weights=np.abs(elevation[known] - channels[row_of_ring[which]]), minlength=len(rings.names)
    )
    is_channel = off <= gap * rings.counts  # mean distance from its channel within one gap
    rows[known] = np.where(is_channel[which], row_of_ring[which], rows[known])
    return rows


def uniform_channels(lo: float, hi: float, step: float) -> np.ndarray:
    """Channels ``step`` apart from ``lo`` up to the first at or above ``hi`` (rad)."""
    return lo + step * np.arange(max(1, math.ceil((hi - lo) / step - 1e-9) + 1))


def sensor_channels(model: SensorModel) -> np.ndarray:
    """A sensor model's channel elevations (rad), ascending."""
    return np.radians(np.sort(np.asarray(model.elevation_deg, dtype=float)))


def range_image(
    xyz: np.ndarray,
    azimuth_step: float,
    channels: np.ndarray,
    min_range_m: float = 0.0,
    ring: np.ndarray | None = None,
) -> RangeImage:
    """The range image of a cloud in its own sensor's frame: one row per channel (``channels``,
    rad, ascending; see :func:`channel_rows` for ``ring``), columns of ``azimuth_step`` (rad,
    rounded to a whole number of columns)."""
    columns = max(1, round(2 * math.pi / azimuth_step))
    channels = np.asarray(channels, dtype=np.float64)
    image = RangeImage(2 * math.pi / columns, channels, np.full((len(channels), columns), np.inf), min_range_m)
    azimuth, elevation = directions(xyz)
    np.minimum.at(image.nearest, (channel_rows(elevation, channels, ring), image.columns(azimuth)), ranges(xyz))
    return image


def margins(r: np.ndarray, margin_m: float, beam_width_deg: float) -> np.ndarray:
    """How far (m) a point at range ``r`` must be inside the other sensor's free space, along
    the ray and across it: the margin plus range x tan(beam width)."""
    return margin_m + r * math.tan(math.radians(beam_width_deg))


def free_space_evidence(xyz: np.ndarray, image: RangeImage, margin_m: float, beam_width_deg: float) -> np.ndarray:
    """Mask of the points (given in the frame of the sensor of ``image``) that lie where its
    rays passed through: in its view (elevation limits, beyond its minimum range, near a
    channel), with a return in their cell, and nearer by more than the margin than every
    return in the window of channels and columns that covers the margin across the ray too (an
    angle of margin / range on each side)."""
    r = ranges(xyz)
    row, column, elevation, off = image.cells(xyz)
    lo, hi = image.elevation_limits
    margin = margins(r, margin_m, beam_width_deg)
    angle = margin / np.maximum(r, 1e-300)
    seen = (elevation >= lo) & (elevation <= hi) & (r >= image.min_range_m) & (r > 0)
    seen &= np.isfinite(image.nearest[row, column]) & image.sampled(off, angle)
    seen = np.flatnonzero(seen)
    evidence = np.zeros(len(xyz), dtype=bool)
    for at, first, last, columns in _windows(image, row[seen], angle[seen]):
        points = seen[at]
        evidence[points] = r[points] < image.extreme(first, last, column[points], columns) - margin[points]
    return evidence


def co_visible(
    xyz: np.ndarray, image: RangeImage, margin_m: float, beam_width_deg: float, max_range_m: float = math.inf
) -> np.ndarray:
    """Mask of the points (given in the frame of the sensor of ``image``) that it could have
    seen (see the module docstring): in its view (range limits, elevation limits widened by
    half the beam's width, near a channel); not hidden (a return in its azimuth cell, on its
    beam or those on either side, at least as far as the point less the margin m); not seen
    through (not every return in the window of :func:`free_space_evidence` farther than the
    point by more than m)."""
    r = ranges(xyz)
    row, column, elevation, off = image.cells(xyz)
    # The outermost beams see half their width beyond their direction.
    half_beam = math.radians(beam_width_deg) / 2
    lo, hi = image.elevation_limits
    margin = margins(r, margin_m, beam_width_deg)
    angle = margin / np.maximum(r, 1e-300)
    out = (elevation >= lo - half_beam) & (elevation <= hi + half_beam) & image.sampled(off, angle)
    out &= (r >= image.min_range_m) & (r <= max_range_m) & (r > 0)
    # Hidden: the rays nearest its direction (its azimuth cell, the beams on either side) all
    # stopped short of it; a wider window would see past a pole's edge into its shadow.
    below, above = beside_rows(image, row)
    out &= image.extreme(below, above, column, 0, farthest=True) >= r - margin
    # Seen through: every return of its window farther by more than the margin. The window is
    # at least a channel and a column on each side, so a return that near settles most points at once.
    unsettled = np.flatnonzero(out & (image.extreme(below, above, column, 1) > r + margin))
    for at, first, last, columns in _windows(image, row[unsettled], angle[unsettled]):
        points = unsettled[at]
        out[points] = image.extreme(first, last, column[points], columns) <= r[points] + margin[points]
    return out


def hidden(xyz: np.ndarray, image: RangeImage, margin_m: float, beam_width_deg: float, columns: int = 0) -> np.ndarray:
    """Mask of the points (given in the frame of the sensor of ``image``) that it could not see
    for something nearer in their direction (the z-buffer test): within its elevation limits
    (widened by half the beam's width), and the rays nearest their direction (their azimuth
    cell and ``columns`` on each side, their nearest channel and those on either side)
    returned, all nearer than the point by more than the margin. Unlike ``not co_visible``, a
    direction with no return says nothing (a sector the sensor did not scan, a ray that went
    out of range, a return thinned away): only an occluder hides."""
    r = ranges(xyz)
    row, column, elevation, _ = image.cells(xyz)
    half_beam = math.radians(beam_width_deg) / 2
    lo, hi = image.elevation_limits
    below, above = beside_rows(image, row)
    farthest = image.extreme(below, above, column, columns, farthest=True)
    inside = (elevation >= lo - half_beam) & (elevation <= hi + half_beam)
    return inside & np.isfinite(farthest) & (farthest < r - margins(r, margin_m, beam_width_deg))


def beside_rows(image: RangeImage, row: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rows of the beams on either side of channels ``row`` (the same row at the edges)."""
    return np.maximum(row - 1, 0), np.minimum(row + 1, len(image.channels) - 1)


def _windows(image: RangeImage, row: np.ndarray, angle: np.ndarray):
    """(positions, first rows, last rows, columns on each side) per distinct column window of
    the directions of nearest channels ``row`` and angles ``angle`` across the ray."""
    first, last, columns = image.windows(row, angle)
    for size in np.unique(columns):
        at = np.flatnonzero(columns == size)
        yield at, first[at], last[at], int(size)


def sensor_image(xyz: np.ndarray, model: SensorModel, ring: np.ndarray | None = None) -> RangeImage:
    """The range image of a cloud in its sensor's frame on its model's channels and azimuth step."""
    return range_image(xyz, math.radians(model.azimuth_resolution_deg), sensor_channels(model), model.min_range_m, ring)


def thinned_columns(image: RangeImage, returns: int) -> int:
    """The columns on each side within which a row of ``image``, made of ``returns`` points,
    holds a return on average: half the mean gap between a row's returns, in columns (0 at the
    model's density; a cloud thinned to a fifth leaves four cells in five empty, and an empty
    cell beside a ray that returned nearer is no evidence that the sensor saw past it)."""
    return int(image.nearest.size / max(returns, 1) // 2)


def occluded_points(pair: RegisteredPair, sensor: int, occluders: np.ndarray | None = None) -> np.ndarray | None:
    """Mask of the points of the cloud other than ``sensor``'s (1 or 2) that every lidar of scan
    ``sensor`` had hidden behind something nearer (:func:`hidden`, the default margin, over
    :func:`thinned_columns`), from their models and the range images of their returns
    (``occluders``: a mask of those to take, default all); None when a lidar's model is missing."""
    if any(view.sensor is None for view in pair.lidars(sensor)):
        return None
    source = pair
    if occluders is not None and not occluders.all():  # all: the pair's own images
        every = np.ones(len(pair.xyz2 if sensor == 1 else pair.xyz1), dtype=bool)
        source = pair.subset(occluders, every) if sensor == 1 else pair.subset(every, occluders)
    own = source.xyz1 if sensor == 1 else source.xyz2
    images = lidar_images(source, sensor)
    columns = {id(view): thinned_columns(image, len(own[view.points])) for view, image in images}

    def seen(xyz: np.ndarray, view: LidarView, image: RangeImage) -> np.ndarray:
        return ~hidden(xyz, image, MARGIN_M, BEAM_WIDTH_DEG, columns[id(view)])

    return ~any_lidar(pair.xyz2 if sensor == 1 else pair.xyz1, images, seen)


def lidar_images(pair: RegisteredPair, cloud: int, image_of=None) -> list[tuple[LidarView, RangeImage]]:
    """Each lidar of cloud 1 or 2 (:meth:`RegisteredPair.lidars`) with the range image of its
    own points in its own frame: ``image_of(xyz, view, ring)``, by default on its model's
    channels (:func:`sensor_image`), those made once per pair for the same points and pose
    (``RegisteredPair.remembered``; the images are shared: not to be changed)."""
    if image_of is not None:
        return _lidar_images(pair, cloud, image_of)
    return pair.remembered(
        ("range images", cloud),
        lambda: _lidar_images(pair, cloud, lambda own, view, ring: sensor_image(own, view.sensor, ring)),
        (cloud,),
    )


def _lidar_images(pair: RegisteredPair, cloud: int, image_of) -> list[tuple[LidarView, RangeImage]]:
    xyz = pair.xyz1 if cloud == 1 else pair.xyz2
    ring = (pair.attributes1 if cloud == 1 else pair.attributes2).get("ring")
    return [
        (
            view,
            image_of(in_sensor_frame(xyz[view.points], view.pose), view, None if ring is None else ring[view.points]),
        )
        for view in pair.lidars(cloud)
    ]


def shared_points(pair: RegisteredPair) -> tuple[np.ndarray, np.ndarray] | None:
    """Per cloud, the mask of its points the other scan's lidars could have seen (:func:`co_visible`
    from any of them, with the default margin), from their models and range images; None when
    a lidar's model is missing."""
    if any(view.sensor is None for cloud in (1, 2) for view in pair.lidars(cloud)):
        return None

    def seen(own: np.ndarray, view: LidarView, image: RangeImage) -> np.ndarray:
        return co_visible(own, image, MARGIN_M, BEAM_WIDTH_DEG, view.sensor.max_range_m)

    images = lidar_images(pair, 1), lidar_images(pair, 2)
    return any_lidar(pair.xyz1, images[1], seen), any_lidar(pair.xyz2, images[0], seen)


def any_lidar(xyz: np.ndarray, images: list[tuple[LidarView, RangeImage]], test) -> np.ndarray:
    """Mask of the points (frame 1) for which ``test(the points in a lidar's frame, the lidar,
    its range image)`` holds with any of the lidars of ``images``."""
    mask = np.zeros(len(xyz), dtype=bool)
    for view, image in images:
        mask |= test(in_sensor_frame(xyz, view.pose), view, image)
    return mask


class _Reference:
    """The returns of the cloud a range image was made of, one by one, for the per-point references."""

    def __init__(self, image: RangeImage, other: np.ndarray, ring: np.ndarray | None):
        azimuth, elevation = directions(other)
        self.image, self.r = image, ranges(other)
        self.row = channel_rows(elevation, image.channels, ring)
        self.column = image.columns(azimuth)

    def point(self, p: np.ndarray, margin_m: float, beam_width_deg: float):
        """(range, nearest channel, column, elevation, off its channel, margin, angle) of a point."""
        r = float(np.linalg.norm(p))
        azimuth, elevation = math.atan2(p[1], p[0]), math.atan2(p[2], math.hypot(p[0], p[1]))
        row = int(np.argmin(np.abs(self.image.channels - elevation)))
        column = int(self.image.columns(np.array([azimuth]))[0])
        margin = margin_m + r * math.tan(math.radians(beam_width_deg))
        off = abs(elevation - self.image.channels[row])
        return r, row, column, elevation, off, margin, margin / r if r > 0 else math.inf

    def window(self, row: int, column: int, angle: float) -> np.ndarray:
        """Mask of the returns in the window of a direction."""
        (first,), (last,), (k,) = self.image.windows(np.array([row]), np.array([angle]))
        columns = self.image.nearest.shape[1]
        gap = (self.column - column) % columns
        return (self.row >= first) & (self.row <= last) & ((gap <= k) | (gap >= columns - k))


def free_space_evidence_loop(
    xyz: np.ndarray,
    other: np.ndarray,
    image: RangeImage,
    margin_m: float,
    beam_width_deg: float,
    ring: np.ndarray | None = None,
) -> np.ndarray:
    """Reference of :func:`free_space_evidence`, one point at a time against every return of
    ``other`` (the cloud ``image`` was made of, in its sensor's frame, with its ``ring``), on
    the same channels and windows."""
    returns = _Reference(image, other, ring)
    lo, hi = image.elevation_limits
    out = np.zeros(len(xyz), dtype=bool)
    for i, p in enumerate(xyz):
        r, row, column, elevation, off, margin, angle = returns.point(p, margin_m, beam_width_deg)
        in_cell = (returns.row == row) & (returns.column == column)
        if r == 0 or r < image.min_range_m or not lo <= elevation <= hi or not in_cell.any():
            continue
        if image.sampled(np.array([off]), np.array([angle]))[0]:
            out[i] = r < returns.r[returns.window(row, column, angle)].min() - margin
    return out


def co_visible_loop(
    xyz: np.ndarray,
    other: np.ndarray,
    image: RangeImage,
    margin_m: float,
    beam_width_deg: float,
    max_range_m: float = math.inf,
    ring: np.ndarray | None = None,
) -> np.ndarray:
    """Reference of :func:`co_visible`, one point at a time against every return of ``other``
    (the cloud ``image`` was made of, in its sensor's frame, with its ``ring``): the nearest
    return of each channel of its azimuth cell on its nearest channel and those on either side,
    and the nearest return in its window."""
    returns = _Reference(image, other, ring)
    lo, hi = image.elevation_limits
    half_beam = math.radians(beam_width_deg) / 2
    out = np.zeros(len(xyz), dtype=bool)
    for i, p in enumerate(xyz):
        r, row, column, elevation, off, margin, angle = returns.point(p, margin_m, beam_width_deg)
        if r == 0 or not image.min_range_m <= r <= max_range_m or not lo - half_beam <= elevation <= hi + half_beam:
            continue
        near = returns.window(row, column, angle)
        if not near.any() or not image.sampled(np.array([off]), np.array([angle]))[0]:
            continue
        beside = near & (np.abs(returns.row - row) <= 1) & (returns.column == column)
        nearest_beside = [returns.r[beside & (returns.row == k)].min() for k in np.unique(returns.row[beside])]
        out[i] = bool(nearest_beside) and max(nearest_beside) >= r - margin and returns.r[near].min() <= r + margin
    return out
