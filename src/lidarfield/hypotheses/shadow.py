"""``shadow``: the first radial cluster (McDermott & Rife 2022, the shadow mitigation the source
paper, Choate & Rife, uses; docs/references.md).

For each origin o in ``origins``, each cloud's points are binned about o on an angular grid
(azimuth x elevation; points are expressed in that sensor's frame). In each cell, that cloud's
ranges sorted ascending are split into segments wherever two consecutive ranges differ by more
than ``jump_m``; the first segment holding more than ``min_points`` points is the surface the
sensor sees first, and the cell's points nearer or farther than that segment are removed. A
cell with no such segment, and a point outside the grid, is left alone. Removals over all
origins are united: a point that one sensor sees past an object's edge, where the other is
blocked, is dropped. A scan of several lidars (:mod:`lidarfield.sensors.rig`) gives one origin per
lidar: its points are binned about each lidar's own origin and axes.

That is ``rule: first_cluster``, the default (the DESIGN's). ``rule: occlusion`` is the z-buffer
test instead (:func:`~lidarfield.field.free_space.occluded_points`): for each origin, the other
cloud's points that every lidar of that scan had hidden behind something nearer are removed.
It removes what lies behind a corner where the first radial cluster keeps it for being
continuous in range with the facade in a cell (the street canyon's gaps between buildings,
docs/diagnosis.md); ``explain``'s default candidate uses it.

:func:`first_cluster_keep` is the vectorised kernel (one sort, then cumulative tricks);
:func:`first_cluster_keep_loop` is the plain per-cell reference it is tested against.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import ConfigError, NotApplicableError
from ..field.free_space import MARGIN_M, occluded_points, ranges
from ..field.grid import SENSORLESS_ELEVATION_DEG, SphericalGrid, grid_from_config
from ..pair import RegisteredPair
from . import ego_vehicle
from .geometry import in_sensor_frame, near_in_own_frames, own_frame_points
from .params import doc

# The keys of a grid section that shape the angular cells (range shells play no part: the
# segmentation runs along the range).
ANGULAR_KEYS = ("azimuth_bins", "azimuth_offset_deg", "elevation_deg", "elevation_bins")
# Explicit edges (a grid's channel-aware or given ones): in a grid only where set, so the
# canonical JSON of a uniform grid, and the stage ids, stay what they were.
EDGE_KEYS = ("elevation_edges_deg", "azimuth_edges_deg")
RULES = ("first_cluster", "occlusion", "auto")


@dataclass(frozen=True)
class Params:
    jump_m: float = field(
        default=1.0, metadata=doc("a gap between consecutive ranges larger than this starts a new segment")
    )
    min_points: int = field(
        default=30, metadata=doc("the first segment with MORE than this many points is the visible surface")
    )
    origins: tuple[int, ...] = field(
        default=(1, 2), metadata=doc("the sensors about which cells are formed (1, 2 or both); removals are united")
    )
    rule: str = field(
        default="first_cluster",
        metadata=doc(
            "first_cluster: the segmentation above (DESIGN); occlusion: remove each point the other origin's "
            "lidars had hidden behind something nearer (their range image's rays in its direction all returned "
            "nearer by more than a margin; needs the sensor models; jump_m, min_points and grid play no part); "
            "auto: occlusion where the scans' sensor models are known, first_cluster where not",
            written_when_set=True,
        ),
    )
    grid: dict | None = field(
        default=None,
        metadata=doc(
            "angular grid {azimuth_bins, azimuth_offset_deg, elevation_deg, elevation_bins} (or explicit "
            "elevation_edges_deg, azimuth_edges_deg); null: the study's grid as configured, "
            f"{list(SENSORLESS_ELEVATION_DEG)} deg where it "
            "gives no elevation_deg (the cells do not follow the sensor)"
        ),
    )

    def __post_init__(self):
        if not self.jump_m > 0:
            raise ValueError(f"jump_m must be > 0, got {self.jump_m}")
        if self.min_points < 0:
            raise ValueError(f"min_points must be >= 0, got {self.min_points}")
        if (
            not self.origins
            or any(o not in (1, 2) for o in self.origins)
            or len(set(self.origins)) != len(self.origins)
        ):
            raise ValueError(f"origins must list sensor 1, sensor 2 or both, got {list(self.origins)}")
        if self.rule not in RULES:
            raise ValueError(f"rule must be one of {', '.join(RULES)}, got {self.rule!r}")
        if self.grid is not None:
            unknown = sorted(set(self.grid) - set(ANGULAR_KEYS + EDGE_KEYS) - {"kind"})
            if unknown or self.grid.get("kind", "spherical") != "spherical":
                raise ValueError(
                    f"grid takes the angular keys {', '.join(ANGULAR_KEYS + EDGE_KEYS)} of a spherical grid, "
                    f"got {self.grid}"
                )
            try:
                grid_from_config(self.grid)
            except ConfigError as e:
                raise ValueError(f"grid: {e}") from None

    def in_study(self, study_grid: dict | None) -> "Params":
        """These parameters with the study's angular grid filled in under any keys not given."""
        if study_grid is None or study_grid.get("kind", "spherical") != "spherical":
            return self
        study = {key: study_grid[key] for key in ANGULAR_KEYS + EDGE_KEYS if study_grid.get(key) is not None}
        given = {key: value for key, value in (self.grid or {}).items() if key != "kind"}
        grid = SphericalGrid(**{**study, **given})
        # The cells do not follow the sensor (field.channels is the field's): a study grid
        # without elevation_deg gives them the sensorless span, as before it could be omitted.
        merged = grid.to_config() | {"elevation_deg": list(grid.elevation_span_deg)}
        return replace(self, grid=angular_config(merged))

    def angular_grid(self) -> SphericalGrid:
        """The grid of the cells (the grid defaults where neither params nor study gave one)."""
        return SphericalGrid(**{key: value for key, value in (self.grid or {}).items() if key != "kind"})


def angular_config(grid_config: dict) -> dict:
    """The keys of a spherical grid's config that shadow's cells take."""
    return {key: value for key, value in grid_config.items() if key in ANGULAR_KEYS + EDGE_KEYS}


def first_cluster_keep(cells: np.ndarray, r: np.ndarray, jump_m: float, min_points: int) -> np.ndarray:
    """Keep-mask of the first radial cluster rule.

    ``cells``: dense non-negative cell ids (< 0: outside the grid, kept); ``r``: ranges >= 0.
    One value sort of the key ``cell * span + range`` (``span`` a power of two above every
    range, so cell and range come back out exactly up to the key's rounding, about 1e-11 m for
    a few hundred cells of 200 m); segments start where the cell changes or the range jumps;
    each cell's chosen segment is its first one longer than ``min_points``, and a point is kept
    when its range lies within that segment's [first, last] range. The comparison uses a
    tolerance of ``jump_m / 2``, which cannot change the answer: the nearest point of another
    segment is more than ``jump_m`` away.
    """
    inside = (cells >= 0) & np.isfinite(r)
    n_inside = int(np.count_nonzero(inside))
    if n_inside == 0:
        return np.ones(len(r), dtype=bool)
    n_cells = int(cells.max()) + 1
    span = 2.0 ** math.ceil(math.log2(float(r[inside].max()) + 1.0))
    key = cells * span + r
    key[~inside] = np.inf  # sorted to the end and cut off
    ordered = np.sort(key)[:n_inside]
    c = np.floor(ordered / span)
    rs = ordered - c * span
    c = c.astype(np.int64)

    starts = np.empty(n_inside, dtype=bool)
    starts[0] = True
    starts[1:] = (c[1:] != c[:-1]) | (np.diff(rs) > jump_m)
    first = np.flatnonzero(starts)  # sorted position of each segment's first point
    last = np.append(first[1:], n_inside) - 1
    segment_cell = c[first]

    # Segments are in (cell, range) order: a cell's first large segment is the first large
    # segment whose cell differs from the previous large segment's.
    large = np.flatnonzero(last - first + 1 > min_points)
    large_cell = segment_cell[large]
    is_first = np.ones(len(large), dtype=bool)
    is_first[1:] = large_cell[1:] != large_cell[:-1]
    chosen = large[is_first]

    # Per cell (plus one slot for the points outside): the kept range interval.
    lo = np.full(n_cells + 1, -np.inf)
    hi = np.full(n_cells + 1, np.inf)
    lo[segment_cell[chosen]] = rs[first[chosen]] - 0.5 * jump_m
    hi[segment_cell[chosen]] = rs[last[chosen]] + 0.5 * jump_m
    slot = np.where(inside, cells, n_cells)
    return (r >= lo[slot]) & (r <= hi[slot]) | ~inside


def first_cluster_keep_loop(cells: np.ndarray, r: np.ndarray, jump_m: float, min_points: int) -> np.ndarray:
    """Reference implementation of :func:`first_cluster_keep`: one plain loop per cell."""
    keep = np.ones(len(r), dtype=bool)
    for cell in np.unique(cells[cells >= 0]):
        index = np.flatnonzero(cells == cell)
        index = index[np.argsort(r[index], kind="stable")]
        segments, current = [], [index[0]]
        for previous, point in zip(index[:-1], index[1:]):
            if r[point] - r[previous] > jump_m:
                segments.append(current)
                current = []
            current.append(point)
        segments.append(current)
        for seg in segments:
            if len(seg) > min_points:
                lo, hi = r[seg[0]], r[seg[-1]]
                keep[index] = (r[index] >= lo) & (r[index] <= hi)
                break
    return keep


def shadow(pair: RegisteredPair, params: Params) -> tuple[np.ndarray, np.ndarray]:
    """Keep-masks of ``params.rule`` about each origin in ``params.origins``."""
    if params.rule != "first_cluster":
        masks = occlusion_keep(pair, params)
        if masks is not None:
            return masks
        if params.rule == "occlusion":
            raise NotApplicableError(
                "shadow: a scan has no sensor model, so its channels are unknown: give the sensor "
                "(--sensor, or 'sensor' in the pair's config) or use rule first_cluster or auto"
            )
    keep1 = np.ones(len(pair.xyz1), dtype=bool)
    keep2 = np.ones(len(pair.xyz2), dtype=bool)
    grid = params.angular_grid()
    for lidar in (view for origin in params.origins for view in pair.lidars(origin)):
        for xyz, keep in ((pair.xyz1, keep1), (pair.xyz2, keep2)):
            local = in_sensor_frame(xyz, lidar.pose)
            keep &= first_cluster_keep(grid.assign(local), ranges(local), params.jump_m, params.min_points)
    return keep1, keep2


def occlusion_keep(pair: RegisteredPair, params: Params) -> tuple[np.ndarray, np.ndarray] | None:
    """Keep-masks of ``rule: occlusion``; None where an origin's scan has no sensor model."""
    keep1 = np.ones(len(pair.xyz1), dtype=bool)
    keep2 = np.ones(len(pair.xyz2), dtype=bool)
    if np.linalg.norm(pair.origin2) <= MARGIN_M:
        # From one place a change of viewpoint hides nothing: what one scan hides of the
        # other's there moved (moving_objects reads it from the returns behind it).
        return keep1, keep2
    # What the vehicle carries (within ego_vehicle's radius of its sensor, where the other
    # scan has a point in its own sensor's frame) is its own body: neither hidden by a change
    # of viewpoint nor hiding by one (the ground behind it is ego_vehicle's). Farther, a wall
    # along the motion looks the same from both places.
    near = [ranges(own) <= ego_vehicle.Params().radius_m for own in own_frame_points(pair)]
    carried = near_in_own_frames(pair, (near[0], near[1]), MARGIN_M)
    for origin in params.origins:
        hidden = occluded_points(pair, origin, ~carried[origin - 1])
        if hidden is None:
            return None
        (keep2 if origin == 1 else keep1)[hidden] = False
    return keep1 | carried[0], keep2 | carried[1]
