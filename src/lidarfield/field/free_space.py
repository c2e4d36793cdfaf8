"""Free space and co-visibility: where a sensor's rays passed through, and what it could see,
from the range image of its returns.

A point (in a sensor's frame) lies in that sensor's free space when a ball of radius m (a
margin that grows with range and the beam's width) around it does: it is nearer, by more than
m, than every return within m across the ray from its direction (and at least the beams on
either side). A direction the sensor did not see says nothing: no return in the point's cell,
a point outside its elevation limits or nearer than its minimum range, and a point behind
what it measured. :func:`free_space_evidence` is the vectorised kernel (a minimum filter of
the range image per window size); :func:`free_space_evidence_loop` the plain per-point
reference it is tested against.

A point is **co-visible** from the other sensor (:func:`co_visible`, :func:`shared_points` for
a pair) when that sensor could have seen its surface: it is in the sensor's view (range limits,
elevation limits widened by half the beam's width),
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
from dataclasses import dataclass, field

import numpy as np

from ..pair import RegisteredPair
from ..poses import apply_pose, invert_pose
from ..sensors.models import SensorModel

# The margin across the ray is rounded up to a step of this ratio, so that few windows are filtered.
_WINDOW_RATIO = 1.25
# The margin of the free-space and co-visibility tests, m = MARGIN_M + range x tan(BEAM_WIDTH_DEG):
# moving_objects' defaults, and the field's co-visibility (a surface within it is one surface).
MARGIN_M = 0.2
BEAM_WIDTH_DEG = 0.2


def ranges(xyz: np.ndarray) -> np.ndarray:
    """3-D distance of each point from the origin of its frame."""
    return np.sqrt(np.einsum("ij,ij->i", xyz, xyz))


@dataclass(frozen=True)
class RangeImage:
    """What one sensor measured: the nearest range of its returns per cell of an azimuth x
    elevation grid (rows: elevation from ``elevation_start``; columns: azimuth from
    ``-pi - azimuth_step / 2``, so that a beam fired at a multiple of the step is in the middle
    of its cell; inf: no return), and what it can see (its elevation limits and minimum range)."""

    azimuth_step: float  # rad
    elevation_step: float  # rad
    elevation_start: float  # rad, the lower edge of row 0
    elevation_limits: tuple[float, float]  # rad: the lowest and highest beam
    nearest: np.ndarray  # (rows, columns)
    min_range_m: float = 0.0
    # the nearest range over each window size (rows, columns), made when first asked for
    _around: dict = field(default_factory=dict, compare=False, repr=False)

    def cells(self, xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(row, column, in view) of points given in the sensor's frame; row 0 for those out of view."""
        row, column, elevation = _cells(
            xyz, self.azimuth_step, self.elevation_step, self.elevation_start, self.nearest.shape
        )
        lo, hi = self.elevation_limits
        inside = (elevation >= lo) & (elevation <= hi) & (row >= 0) & (row < self.nearest.shape[0])
        return np.where(inside, row, 0), column, inside

    def windows(self, angle: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rows, columns) on each side of a cell that cover ``angle`` (rad) on each side of a
        direction in it, the angle rounded up to a power of 1.25 of the smaller cell side: at
        least one (the beams on either side)."""
        base = min(self.azimuth_step, self.elevation_step)
        power = np.ceil(np.log(np.maximum(angle, base) / base) / math.log(_WINDOW_RATIO) - 1e-9)
        angle = base * _WINDOW_RATIO**power
        rows = np.minimum(np.ceil(angle / self.elevation_step - 1e-9), self.nearest.shape[0])
        columns = np.minimum(np.ceil(angle / self.azimuth_step - 1e-9), self.nearest.shape[1] // 2)
        return np.maximum(rows, 1).astype(np.int64), np.maximum(columns, 1).astype(np.int64)

    def around(self, rows: int, columns: int, farthest: bool = False) -> np.ndarray:
        """The nearest range over each cell's window of ``rows`` and ``columns`` on each side
        (azimuth wraps around; inf: no return in the window), or with ``farthest`` the farthest
        of the cells' nearest returns (-inf: no return)."""
        if (rows, columns, farthest) not in self._around:
            from scipy.ndimage import maximum_filter, minimum_filter

            size = (2 * rows + 1, min(2 * columns + 1, self.nearest.shape[1]))
            if farthest:
                image = np.where(np.isfinite(self.nearest), self.nearest, -np.inf)
                around = maximum_filter(image, size=size, mode=("constant", "wrap"), cval=-np.inf)
            else:
                around = minimum_filter(self.nearest, size=size, mode=("constant", "wrap"), cval=np.inf)
            self._around[rows, columns, farthest] = around
        return self._around[rows, columns, farthest]


def _directions(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth and elevation (rad) of points in a sensor's frame."""
    return np.arctan2(xyz[:, 1], xyz[:, 0]), np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1]))


def _cells(xyz: np.ndarray, azimuth_step: float, elevation_step: float, elevation_start: float, shape):
    """(row, column, elevation) of points on a range image's grid; rows may fall outside it."""
    azimuth, elevation = _directions(xyz)
    column = np.floor((azimuth + math.pi + azimuth_step / 2) / azimuth_step).astype(np.int64) % shape[1]
    return np.floor((elevation - elevation_start) / elevation_step).astype(np.int64), column, elevation


def range_image(
    xyz: np.ndarray,
    resolution_rad: tuple[float, float],
    min_range_m: float = 0.0,
    elevation_limits_rad: tuple[float, float] | None = None,
) -> RangeImage:
    """The range image of a cloud in its own sensor's frame: ``resolution_rad`` = (azimuth,
    elevation) size of a cell (the azimuth step rounded to a whole number of columns); the
    elevation limits are the sensor's lowest and highest beam (None: the cloud's)."""
    columns = max(1, round(2 * math.pi / resolution_rad[0]))
    if elevation_limits_rad is None:
        elevation = _directions(xyz)[1]
        elevation_limits_rad = (float(elevation.min()), float(elevation.max())) if len(xyz) else (0.0, 0.0)
    lo, hi = elevation_limits_rad
    step = resolution_rad[1]
    shape = (int((hi - lo) // step) + 2, columns)  # beams in the middle of rows, from half a row below the lowest
    row, column, _ = _cells(xyz, 2 * math.pi / columns, step, lo - step / 2, shape)
    nearest = np.full(shape, np.inf)
    np.minimum.at(nearest, (np.clip(row, 0, shape[0] - 1), column), ranges(xyz))
    return RangeImage(2 * math.pi / columns, step, lo - step / 2, (lo, hi), nearest, min_range_m)


def margins(r: np.ndarray, margin_m: float, beam_width_deg: float) -> np.ndarray:
    """How far (m) a point at range ``r`` must be inside the other sensor's free space, along
    the ray and across it: the margin plus range x tan(beam width)."""
    return margin_m + r * math.tan(math.radians(beam_width_deg))


def free_space_evidence(xyz: np.ndarray, image: RangeImage, margin_m: float, beam_width_deg: float) -> np.ndarray:
    """Mask of the points (given in the frame of the sensor of ``image``) that lie where its
    rays passed through: in its view (elevation limits, beyond its minimum range), with a
    return in their cell, and nearer by more than the margin than every return in the window
    of cells that covers the margin across the ray too (an angle of margin / range on each
    side)."""
    r = ranges(xyz)
    row, column, inside = image.cells(xyz)
    seen = np.flatnonzero(inside & np.isfinite(image.nearest[row, column]) & (r >= image.min_range_m) & (r > 0))
    evidence = np.zeros(len(xyz), dtype=bool)
    for at, margin, window in _windows(image, r[seen], margin_m, beam_width_deg):
        nearest = image.around(*window)[row[seen[at]], column[seen[at]]]
        evidence[seen[at]] = r[seen[at]] < nearest - margin
    return evidence


def co_visible(
    xyz: np.ndarray, image: RangeImage, margin_m: float, beam_width_deg: float, max_range_m: float = math.inf
) -> np.ndarray:
    """Mask of the points (given in the frame of the sensor of ``image``) that it could have
    seen (see the module docstring): in its view (range limits, and elevation limits widened by
    half the beam's width); not hidden (a return in its azimuth cell, on its beam or those on
    either side, at least as far as the point less the margin m); not seen through (not every
    return in the window of :func:`free_space_evidence` farther than the point by more than m)."""
    r = ranges(xyz)
    row, column, elevation = _cells(
        xyz, image.azimuth_step, image.elevation_step, image.elevation_start, image.nearest.shape
    )
    row = np.clip(row, 0, image.nearest.shape[0] - 1)
    # The outermost beams see half their width beyond their direction.
    angle = math.radians(beam_width_deg) / 2
    lo, hi = image.elevation_limits
    in_view = (elevation >= lo - angle) & (elevation <= hi + angle)
    margin = margins(r, margin_m, beam_width_deg)
    # Hidden: the rays nearest its direction (its azimuth cell, the beams on either side) all
    # stopped short of it; a wider window would see past a pole's edge into its shadow.
    out = in_view & (r >= image.min_range_m) & (r <= max_range_m) & (r > 0)
    out &= image.around(1, 0, farthest=True)[row, column] >= r - margin
    # Seen through: every return of its window farther by more than the margin. The window is
    # at least a cell on each side, so a return that near settles most points at once.
    unsettled = np.flatnonzero(out & (image.around(1, 1)[row, column] > r + margin))
    for at, at_margin, window in _windows(image, r[unsettled], margin_m, beam_width_deg):
        points = unsettled[at]
        out[points] = image.around(*window)[row[points], column[points]] <= r[points] + at_margin
    return out


def _windows(image: RangeImage, r: np.ndarray, margin_m: float, beam_width_deg: float):
    """(positions into ``r``, their margins, (rows, columns) of their window) per distinct
    window of the points at ranges ``r``: the window covers the margin across the ray."""
    margin = margins(r, margin_m, beam_width_deg)
    rows, columns = image.windows(margin / r)
    span = int(columns.max(initial=0)) + 1
    sizes, which = np.unique(rows * span + columns, return_inverse=True)
    for index, size in enumerate(sizes):
        at = np.flatnonzero(which == index)
        yield at, margin[at], (int(size // span), int(size % span))


def sensor_resolution_rad(model: SensorModel) -> tuple[float, float]:
    """A sensor's (azimuth, elevation) range-image cell: its azimuth step and the widest gap
    between neighbouring channels (so that each row holds a channel)."""
    channels = np.sort(np.asarray(model.elevation_deg, dtype=float))
    gap = float(np.diff(channels).max()) if len(channels) > 1 else model.azimuth_resolution_deg
    return math.radians(model.azimuth_resolution_deg), math.radians(gap)


def sensor_view(model: SensorModel | None) -> tuple[float, tuple[float, float] | None]:
    """A sensor's minimum range and elevation limits (rad) from its model (none known: 0 and None)."""
    if model is None:
        return 0.0, None
    return model.min_range_m, tuple(math.radians(v) for v in model.elevation_limits_deg)


def shared_points(pair: RegisteredPair) -> tuple[np.ndarray, np.ndarray] | None:
    """Per cloud, the mask of its points the other sensor could have seen (:func:`co_visible`,
    with the default margin), from both sensors' models and range images; None when a sensor
    model is missing."""
    if pair.sensor1 is None or pair.sensor2 is None:
        return None
    models = (pair.sensor1, pair.sensor2)
    own = (pair.xyz1, apply_pose(invert_pose(pair.T_1_2), pair.xyz2))
    images = [range_image(xyz, sensor_resolution_rad(model), *sensor_view(model)) for xyz, model in zip(own, models)]
    other = (apply_pose(invert_pose(pair.T_1_2), pair.xyz1), pair.xyz2)  # each cloud in the other's frame
    return (
        co_visible(other[0], images[1], MARGIN_M, BEAM_WIDTH_DEG, models[1].max_range_m),
        co_visible(other[1], images[0], MARGIN_M, BEAM_WIDTH_DEG, models[0].max_range_m),
    )


def free_space_evidence_loop(
    xyz: np.ndarray, other: np.ndarray, image: RangeImage, margin_m: float, beam_width_deg: float
) -> np.ndarray:
    """Reference of :func:`free_space_evidence`, one point at a time against every return of
    ``other`` (the cloud ``image`` was made of, in its sensor's frame), on the same cells and
    windows."""
    rows, columns = image.nearest.shape
    other_row, other_column, _ = _cells(
        other, image.azimuth_step, image.elevation_step, image.elevation_start, (rows, columns)
    )
    other_row = np.clip(other_row, 0, rows - 1)
    other_r = ranges(other)
    row, column, inside = image.cells(xyz)
    out = np.zeros(len(xyz), dtype=bool)
    for i, (p, a, b, ok) in enumerate(zip(xyz, row, column, inside)):
        r = float(np.linalg.norm(p))
        if not ok or r < image.min_range_m or r == 0 or not ((other_row == a) & (other_column == b)).any():
            continue
        margin = margin_m + r * math.tan(math.radians(beam_width_deg))
        k_rows, k_columns = (int(k[0]) for k in image.windows(np.array([margin / r])))
        gap = (other_column - b) % columns
        near = (np.abs(other_row - a) <= k_rows) & ((gap <= k_columns) | (gap >= columns - k_columns))
        out[i] = r < other_r[near].min() - margin
    return out


def co_visible_loop(
    xyz: np.ndarray,
    other: np.ndarray,
    image: RangeImage,
    margin_m: float,
    beam_width_deg: float,
    max_range_m: float = math.inf,
) -> np.ndarray:
    """Reference of :func:`co_visible`, one point at a time against every return of ``other``
    (the cloud ``image`` was made of, in its sensor's frame): the nearest return of each cell
    of its azimuth cell's column on its beam and those on either side, and the nearest return in
    its window."""
    rows, columns = image.nearest.shape
    other_row, other_column, _ = _cells(
        other, image.azimuth_step, image.elevation_step, image.elevation_start, (rows, columns)
    )
    other_row = np.clip(other_row, 0, rows - 1)
    other_r = ranges(other)
    lo, hi = image.elevation_limits
    out = np.zeros(len(xyz), dtype=bool)
    for i, p in enumerate(xyz):
        r = float(np.linalg.norm(p))
        (row,), (column,), (elevation,) = _cells(
            p[None], image.azimuth_step, image.elevation_step, image.elevation_start, (rows, columns)
        )
        half_beam = math.radians(beam_width_deg) / 2
        if r == 0 or not image.min_range_m <= r <= max_range_m or not lo - half_beam <= elevation <= hi + half_beam:
            continue
        row = min(max(row, 0), rows - 1)
        margin = margin_m + r * math.tan(math.radians(beam_width_deg))
        k_rows, k_columns = (int(k[0]) for k in image.windows(np.array([margin / r])))
        gap = (other_column - column) % columns
        near = (np.abs(other_row - row) <= k_rows) & ((gap <= k_columns) | (gap >= columns - k_columns))
        if not near.any():
            continue
        beside = near & (np.abs(other_row - row) <= 1) & (other_column == column)
        nearest_beside = [other_r[beside & (other_row == k)].min() for k in np.unique(other_row[beside])]
        out[i] = bool(nearest_beside) and max(nearest_beside) >= r - margin and other_r[near].min() <= r + margin
    return out
