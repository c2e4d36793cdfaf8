"""``moving_objects``: remove the objects that moved between the two scans, seen from free space.

With both sensor origins known (``T_1_2``), a point of one cloud is *evidence* of motion when it
lies where the other sensor's rays passed through, with a ball of free space around it: in the
other sensor's frame, it is nearer than every return of that sensor around its direction by
more than the margin m = ``margin_m + range x tan(beam_width_deg)``, "around" being the cells
of that sensor's range image (its angular resolution) within m across the ray, and at least
the beams on either side. So an edge that one beam passes and the next one hits is not free
space, nor is a surface that the registration's error moved by less than m. Directions the
other sensor did not see give no evidence either way: no return in the point's cell, a point
outside its elevation limits or nearer than its minimum range, and a point behind what it
measured (occluded).

A moving object gives such evidence only on its leading and trailing parts, so evidence grows
to objects: each cloud's points higher than ``ground_height_m`` above a plane fitted to its
ground (and the lower ones in the same ``voxel_m`` column as such a point less than twice that
high: an object's foot) are split into objects, the connected components of their occupied
voxels (``voxel_m``, 26 neighbours). An object is removed whole when at least
``min_evidence_points`` and ``min_evidence_share`` of its points are evidence, and with it
every object of the other cloud that shares at least ``min_overlap_share`` of its voxels (the
same object before or after it moved). Ground points are never removed. The removed file's
``reason`` column says why each point went: ``evidence``, or ``grown`` (the rest of a removed
object).

:func:`free_space_evidence` is the vectorised kernel (one range image per sensor, a minimum
filter per window size); :func:`free_space_evidence_loop` is the plain per-point reference it
is tested against; likewise :func:`connected_voxels` and :func:`connected_voxels_reference`.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import NotApplicableError
from ..pair import RegisteredPair
from ..sensors.models import SensorModel
from .geometry import in_sensor_frame, ranges
from .outcome import Outcome
from .params import doc

EVIDENCE, GROWN = "evidence", "grown"  # the removed file's reasons
# The ground plane is fitted to the points within these bands (m) of it, narrowing: the first
# guess is the densest 0.25 m layer of the lower half of the cloud.
_GROUND_BANDS_M = (1.0, 0.5, 0.25)
_LAYER_M = 0.25
_GROUND_SAMPLE = 100_000


@dataclass(frozen=True)
class Params:
    angular_resolution_deg: tuple[float, float] | None = field(
        default=None,
        metadata=doc(
            "[azimuth, elevation] size of the cells of each sensor's range image (null: its model's azimuth step "
            "and widest gap between channels)"
        ),
    )
    margin_m: float = field(
        default=0.2,
        metadata=doc(
            "a point is evidence when nearer by more than this margin (plus the beam term) than every return of the "
            "other sensor within the margin across the ray from its direction: a ball of free space around it"
        ),
    )
    beam_width_deg: float = field(
        default=0.2, metadata=doc("the beam's width: the margin grows by range x tan(beam_width_deg)")
    )
    ground_height_m: float | None = field(
        default=0.3,
        metadata=doc(
            "points lower than this above a plane fitted to the ground are ground: never removed (null: no ground, "
            "every point belongs to an object)"
        ),
    )
    voxel_m: float = field(
        default=0.3, metadata=doc("objects are the connected components of the occupied voxels of this size")
    )
    min_evidence_points: int = field(
        default=10, metadata=doc("an object is removed when at least this many of its points are evidence ...")
    )
    min_evidence_share: float = field(default=0.02, metadata=doc("... and at least this share of its points"))
    min_overlap_share: float | None = field(
        default=0.5,
        metadata=doc(
            "an object of one cloud is also removed when at least this share of its voxels are voxels of an object "
            "removed from the other cloud: the same object before or after it moved (null: never)"
        ),
    )

    def __post_init__(self):
        if self.angular_resolution_deg is not None and not all(0 < v <= 90 for v in self.angular_resolution_deg):
            raise ValueError(f"angular_resolution_deg must be in (0, 90], got {list(self.angular_resolution_deg)}")
        if not (self.margin_m >= 0 and 0 <= self.beam_width_deg < 90):
            raise ValueError(
                f"margin_m must be >= 0 and beam_width_deg in [0, 90); got {self.margin_m}, {self.beam_width_deg}"
            )
        if self.ground_height_m is not None and not self.ground_height_m > 0:
            raise ValueError(f"ground_height_m must be > 0 (or null), got {self.ground_height_m}")
        if not self.voxel_m > 0:
            raise ValueError(f"voxel_m must be > 0, got {self.voxel_m}")
        if self.min_overlap_share is not None and not 0 < self.min_overlap_share <= 1:
            raise ValueError(f"min_overlap_share must be in (0, 1] (or null), got {self.min_overlap_share}")
        if self.min_evidence_points < 1 or not 0 <= self.min_evidence_share <= 1:
            raise ValueError(
                "min_evidence_points must be >= 1 and min_evidence_share in [0, 1]; got "
                f"{self.min_evidence_points}, {self.min_evidence_share}"
            )


# The margin across the ray is rounded up to a step of this ratio, so that few windows are filtered.
_WINDOW_RATIO = 1.25


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

    def around(self, rows: int, columns: int) -> np.ndarray:
        """The nearest range over each cell's window of ``rows`` and ``columns`` on each side
        (azimuth wraps around)."""
        if (rows, columns) not in self._around:
            from scipy.ndimage import minimum_filter

            size = (2 * rows + 1, min(2 * columns + 1, self.nearest.shape[1]))
            self._around[rows, columns] = minimum_filter(
                self.nearest, size=size, mode=("constant", "wrap"), cval=np.inf
            )
        return self._around[rows, columns]


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


def margins(r: np.ndarray, params: Params) -> np.ndarray:
    """How far (m) a point at range ``r`` must be inside the other sensor's free space, along
    the ray and across it: the margin plus range x tan(beam width)."""
    return params.margin_m + r * math.tan(math.radians(params.beam_width_deg))


def free_space_evidence(xyz: np.ndarray, image: RangeImage, params: Params) -> np.ndarray:
    """Mask of the points (given in the frame of the sensor of ``image``) that lie where its
    rays passed through: in its view (elevation limits, beyond its minimum range), with a
    return in their cell, and nearer by more than the margin than every return in the window
    of cells that covers the margin across the ray too (an angle of margin / range on each
    side)."""
    r = ranges(xyz)
    row, column, inside = image.cells(xyz)
    seen = np.flatnonzero(inside & np.isfinite(image.nearest[row, column]) & (r >= image.min_range_m) & (r > 0))
    margin = margins(r[seen], params)
    rows, columns = image.windows(margin / r[seen])
    evidence = np.zeros(len(xyz), dtype=bool)
    span = int(columns.max(initial=0)) + 1
    sizes, which = np.unique(rows * span + columns, return_inverse=True)  # the distinct windows
    for index, size in enumerate(sizes):
        at = np.flatnonzero(which == index)
        nearest = image.around(int(size // span), int(size % span))[row[seen[at]], column[seen[at]]]
        evidence[seen[at]] = r[seen[at]] < nearest - margin[at]
    return evidence


def free_space_evidence_loop(xyz: np.ndarray, other: np.ndarray, image: RangeImage, params: Params) -> np.ndarray:
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
        margin = params.margin_m + r * math.tan(math.radians(params.beam_width_deg))
        k_rows, k_columns = (int(k[0]) for k in image.windows(np.array([margin / r])))
        gap = (other_column - b) % columns
        near = (np.abs(other_row - a) <= k_rows) & ((gap <= k_columns) | (gap >= columns - k_columns))
        out[i] = r < other_r[near].min() - margin
    return out


def heights_above_ground(xyz: np.ndarray) -> np.ndarray:
    """Each point's height above a plane ``z = a x + b y + c`` fitted by least squares to the
    ground: first the densest 0.25 m layer of the lower half of the cloud, then the points within
    1, 0.5 and 0.25 m of the plane so far; fitted on every k-th point of a large cloud (at most
    ``_GROUND_SAMPLE``: a plane has three parameters)."""
    if len(xyz) < 3:
        return np.full(len(xyz), np.inf)
    sample = xyz[:: max(1, len(xyz) // _GROUND_SAMPLE)]
    z = sample[:, 2]
    lower = z[z <= np.median(z)]
    edges = np.arange(lower.min(), lower.max() + 2 * _LAYER_M, _LAYER_M)
    counts, _ = np.histogram(lower, edges)
    plane = np.array([0.0, 0.0, edges[np.argmax(counts)] + _LAYER_M / 2])
    design = np.column_stack([sample[:, 0], sample[:, 1], np.ones(len(z))])
    for band in _GROUND_BANDS_M:
        near = np.abs(z - design @ plane) < band
        if np.count_nonzero(near) < 3:
            break
        plane, *_ = np.linalg.lstsq(design[near], z[near], rcond=None)
    return xyz[:, 2] - (xyz[:, 0] * plane[0] + xyz[:, 1] * plane[1] + plane[2])


def voxel_grid(clouds: list[np.ndarray], voxel_m: float) -> list[np.ndarray]:
    """Integer voxel coordinates of the points of each cloud on one grid (the same voxel in
    both clouds has the same coordinates), from 1 up: 0 and the top stay free for neighbours."""
    voxels = [np.floor(xyz / voxel_m).astype(np.int64) for xyz in clouds]
    occupied = [v for v in voxels if len(v)]
    low = np.min([v.min(axis=0) for v in occupied], axis=0) if occupied else np.zeros(3, np.int64)
    return [v - low + 1 for v in voxels]


def _packed(voxels: np.ndarray, size: np.ndarray) -> np.ndarray:
    """One int64 key per voxel of a grid of ``size`` (each coordinate below its size)."""
    return voxels @ np.array([size[1] * size[2], size[2], 1])


def off_ground(xyz: np.ndarray, voxels: np.ndarray, ground_height_m: float) -> np.ndarray:
    """Mask of the points that belong to objects: higher than ``ground_height_m`` above the
    ground, and the lower points of an object's foot, those in a voxel column that also holds
    a point between ``ground_height_m`` and twice that (a car's lowest strip, not the ground
    under a canopy)."""
    height = heights_above_ground(xyz)
    standing = height >= ground_height_m
    if not len(xyz):
        return standing
    column = voxels[:, 0] * (int(voxels[:, 1].max()) + 1) + voxels[:, 1]
    foot = np.unique(column[standing & (height < 2 * ground_height_m)])
    low = ~standing
    standing[low] = np.isin(column[low], foot)
    return standing


# Half of the 26 neighbours of a voxel: each edge of the voxel graph is found once.
_HALF_NEIGHBOURS = [d for d in itertools.product((-1, 0, 1), repeat=3) if d > (0, 0, 0)]


def connected_voxels(voxels: np.ndarray) -> np.ndarray:
    """Object label of each point (its voxel's coordinates, from 1 up): the connected
    component (26 neighbours) of its voxel among the occupied ones; labels 0..K-1, in no
    particular order."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if len(voxels) == 0:
        return np.zeros(0, dtype=np.int64)
    size = voxels.max(axis=0) + 2
    occupied, voxel_of_point = np.unique(_packed(voxels, size), return_inverse=True)
    first, second = [], []
    for step in _HALF_NEIGHBOURS:
        neighbour = occupied + int(_packed(np.array(step), size))
        at = np.minimum(np.searchsorted(occupied, neighbour), len(occupied) - 1)
        found = np.flatnonzero(occupied[at] == neighbour)
        first.append(found)
        second.append(at[found])
    first, second = np.concatenate(first), np.concatenate(second)
    graph = coo_matrix((np.ones(len(first), np.int8), (first, second)), shape=(len(occupied),) * 2)
    _, component = connected_components(graph, directed=False)
    return component[voxel_of_point.ravel()].astype(np.int64)


def connected_voxels_reference(voxels: np.ndarray) -> np.ndarray:
    """Reference of :func:`connected_voxels`: a flood fill over the occupied voxels, each
    voxel compared with all others (Chebyshev distance 1 = neighbours)."""
    occupied, voxel_of_point = np.unique(voxels, axis=0, return_inverse=True)
    label = np.full(len(occupied), -1)
    for seed in range(len(occupied)):
        if label[seed] >= 0:
            continue
        label[seed], stack = label.max() + 1, [seed]
        while stack:
            voxel = stack.pop()
            fresh = (np.abs(occupied - occupied[voxel]).max(axis=1) <= 1) & (label < 0)
            label[fresh] = label[seed]
            stack.extend(np.flatnonzero(fresh))
    return label[voxel_of_point.ravel()]


def evidenced_objects(evidence: np.ndarray, objects: np.ndarray, params: Params) -> np.ndarray:
    """Mask of the points of the objects (labels ``objects``; < 0: ground, never removed) with
    at least ``min_evidence_points`` evidence points making ``min_evidence_share`` of them."""
    on_object = objects >= 0
    label = objects[on_object]
    size = np.bincount(label)
    evidenced = np.bincount(label, weights=evidence[on_object], minlength=len(size))
    removed_object = (evidenced >= params.min_evidence_points) & (evidenced >= params.min_evidence_share * size)
    removed = np.zeros(len(objects), dtype=bool)
    removed[on_object] = removed_object[label]
    return removed


def overlapping_objects(objects: np.ndarray, keys: np.ndarray, removed_keys: np.ndarray, share: float) -> np.ndarray:
    """Mask of the points of the objects (labels ``objects``, < 0: ground) at least ``share``
    of whose voxels (``keys``, one per point) are among ``removed_keys`` (the voxels of the
    objects removed from the other cloud)."""
    on_object = np.flatnonzero(objects >= 0)
    out = np.zeros(len(objects), dtype=bool)
    if not len(on_object) or not len(removed_keys):
        return out
    span = int(keys.max()) + 1
    distinct = np.unique(objects[on_object] * span + keys[on_object])  # each (object, voxel) once
    label, key = distinct // span, distinct % span
    voxels = np.bincount(label)
    shared = np.bincount(label, weights=np.isin(key, removed_keys), minlength=len(voxels))
    out[on_object] = (shared >= share * voxels)[objects[on_object]] & (shared > 0)[objects[on_object]]
    return out


def resolution_rad(model: SensorModel | None, params: Params, sensor: int) -> tuple[float, float]:
    """The (azimuth, elevation) cell size of sensor 1's or 2's range image: the parameter, or
    its model's azimuth step and widest gap between neighbouring channels."""
    if params.angular_resolution_deg is not None:
        return tuple(math.radians(v) for v in params.angular_resolution_deg)
    if model is None:
        raise NotApplicableError(
            f"moving_objects: sensor {sensor} has no sensor model, so its angular resolution is unknown: give the "
            "sensor (--sensor, or 'sensor' in the pair's config) or moving_objects' angular_resolution_deg"
        )
    channels = np.sort(np.asarray(model.elevation_deg, dtype=float))
    gap = float(np.diff(channels).max()) if len(channels) > 1 else model.azimuth_resolution_deg
    return math.radians(model.azimuth_resolution_deg), math.radians(gap)


def sensor_view(model: SensorModel | None) -> tuple[float, tuple[float, float] | None]:
    """A sensor's minimum range and elevation limits (rad) from its model (none known: 0 and None)."""
    if model is None:
        return 0.0, None
    return model.min_range_m, tuple(math.radians(v) for v in model.elevation_limits_deg)


def check_origins(pair: RegisteredPair) -> None:
    """NotApplicableError when the pair does not say where sensor 2 was (registered by identity)."""
    if (pair.registration or {}).get("method") == "identity":
        raise NotApplicableError(
            "moving_objects needs where both sensors were, and this pair was registered by 'identity', which does "
            "not say where sensor 2 was: register it with 'truth', a transform file or scan matching (scans taken "
            "from one place: an identity transform file says so)"
        )


def pair_evidence(pair: RegisteredPair, params: Params) -> tuple[np.ndarray, np.ndarray]:
    """Free-space evidence of every point of cloud 1 against sensor 2's returns, and of cloud 2
    against sensor 1's."""
    own = (pair.xyz1, in_sensor_frame(pair.xyz2, pair.T_1_2))
    models = (pair.sensor1, pair.sensor2)
    images = [
        range_image(xyz, resolution_rad(model, params, sensor), *sensor_view(model))
        for sensor, (xyz, model) in enumerate(zip(own, models), 1)
    ]
    return (
        free_space_evidence(in_sensor_frame(pair.xyz1, pair.T_1_2), images[1], params),
        free_space_evidence(pair.xyz2, images[0], params),
    )


def moving_objects(pair: RegisteredPair, params: Params) -> Outcome:
    """Keep-masks without the evidenced objects of each cloud (and the objects of the other
    cloud that overlap them), and why each removed point went."""
    check_origins(pair)
    clouds = (pair.xyz1, pair.xyz2)
    evidence = pair_evidence(pair, params)
    voxels = voxel_grid(list(clouds), params.voxel_m)
    size = np.max([v.max(axis=0) for v in voxels if len(v)], axis=0) + 2 if any(map(len, voxels)) else np.ones(3)
    keys = [_packed(v, size) for v in voxels]
    objects, evidenced = [], []
    for xyz, v, cloud_evidence in zip(clouds, voxels, evidence):
        labels = np.full(len(xyz), -1, dtype=np.int64)
        standing = np.ones(len(xyz), dtype=bool)
        if params.ground_height_m is not None:
            standing = off_ground(xyz, v, params.ground_height_m)
        labels[standing] = connected_voxels(v[standing])
        objects.append(labels)
        evidenced.append(evidenced_objects(cloud_evidence, labels, params))
    keeps, reasons = [], []
    for k in (0, 1):
        removed = evidenced[k].copy()
        if params.min_overlap_share is not None:
            other = 1 - k
            removed_keys = np.unique(keys[other][evidenced[other]])
            removed |= overlapping_objects(objects[k], keys[k], removed_keys, params.min_overlap_share)
        keeps.append(~removed)
        reasons.append(np.where(removed, np.where(evidence[k], EVIDENCE, GROWN), ""))
    return Outcome(keeps[0], keeps[1], reason1=reasons[0], reason2=reasons[1])
