"""Voxel grids shared by the field and the hypotheses: spherical about an origin, or Cartesian.

``assign(xyz, origin)`` gives every point an int64 voxel id, or -1 when the point is outside
the grid. A point outside the elevation range or outside the range shells is *out*: it is
counted by the caller, never folded into an edge bin. Interval convention: each bin holds
``[lower edge, upper edge)``, except that the last elevation bin and the last range shell also
hold their upper edge (the grid is the closed interval ``[lo, hi]``), matching the
``field_of_view`` rule that drops points *strictly* outside a sensor's limits.

Spherical ids are dense: ``az_bin + azimuth_bins * (el_bin + elevation_bins * r_bin)``, so
``0 <= id < n_voxels`` and a bincount over the whole id range needs no compaction.

Cartesian ids pack the cell indices, each offset by ``CARTESIAN_OFFSET`` = 2**20 so negative
indices are fine, into 21 bits per axis: ``(ix + off) | (iy + off) << 21 | (iz + off) << 42``.
Indices beyond +-2**20 cells (1048 km at 1 m cells) are out of the grid. Sorting by id sorts
by (iz, iy, ix).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..checks import is_integer, is_number
from ..defaults import default
from ..errors import ConfigError

CARTESIAN_BITS = 21
CARTESIAN_OFFSET = 1 << (CARTESIAN_BITS - 1)
_CARTESIAN_MASK = (1 << CARTESIAN_BITS) - 1

SPHERICAL_KEYS = (
    "azimuth_bins",
    "azimuth_offset_deg",
    "elevation_deg",
    "elevation_bins",
    "range_edges_m",
    "elevation_edges_deg",
    "azimuth_edges_deg",
)
CARTESIAN_KEYS = ("cell_m", "origin")
# The elevation span of a spherical grid whose config gives no ``elevation_deg`` when neither
# scan has a sensor model nor rings to take it from (see ``field.channels``).
SENSORLESS_ELEVATION_DEG = (-20.0, 20.0)
# Edges this close (deg) to uniform ones are uniform: binned by arithmetic, not by look-up.
_UNIFORM_TOLERANCE_DEG = 1e-9
FIELD_KEYS = ("min_points", "max_component_m", "z_min")


def _as_points(xyz: np.ndarray) -> np.ndarray:
    xyz = np.asarray(xyz, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise ValueError(f"expected an (N, 3) array of points, got shape {xyz.shape}")
    return xyz


def relative_columns(xyz: np.ndarray, origin) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Contiguous coordinate columns relative to ``origin`` (fresh arrays, safe to modify)."""
    xyz = _as_points(xyz)
    ox, oy, oz = (float(c) for c in origin)
    return xyz[:, 0] - ox, xyz[:, 1] - oy, xyz[:, 2] - oz


@dataclass(frozen=True)
class SphericalGrid:
    """Azimuth bins over 360 deg (bin 0 starts at ``azimuth_offset_deg``), elevation bins over
    ``elevation_deg`` = (lo, hi), and optional range shells with edges ``range_edges_m``.

    ``elevation_deg`` None: the span follows the sensor (``field.channels``), and without one
    it is ``SENSORLESS_ELEVATION_DEG``. ``elevation_edges_deg`` / ``azimuth_edges_deg``: explicit,
    possibly uneven edges (channel-aware binning moves edges between channels and firings);
    they replace ``elevation_deg`` and ``elevation_bins`` / ``azimuth_bins`` and
    ``azimuth_offset_deg`` (the azimuth edges span 360 deg from the first).
    """

    azimuth_bins: int = default("grid", "azimuth_bins")
    azimuth_offset_deg: float = default("grid", "azimuth_offset_deg")
    elevation_deg: tuple[float, float] | None = default("grid", "elevation_deg")
    elevation_bins: int = default("grid", "elevation_bins")
    range_edges_m: tuple[float, ...] | None = default("grid", "range_edges_m")
    elevation_edges_deg: tuple[float, ...] | None = default("grid", "elevation_edges_deg")
    azimuth_edges_deg: tuple[float, ...] | None = default("grid", "azimuth_edges_deg")

    kind = "spherical"

    def __post_init__(self) -> None:
        for name in ("elevation_deg", "range_edges_m", "elevation_edges_deg", "azimuth_edges_deg"):
            object.__setattr__(self, name, _number_tuple(getattr(self, name)))
        if is_number(self.azimuth_offset_deg):
            object.__setattr__(self, "azimuth_offset_deg", float(self.azimuth_offset_deg))
        _check_edges(self.elevation_edges_deg, "elevation_edges_deg", -90.0, 90.0)
        _check_edges(self.azimuth_edges_deg, "azimuth_edges_deg", -math.inf, math.inf)
        if self.elevation_edges_deg is not None:
            edges = self.elevation_edges_deg
            object.__setattr__(self, "elevation_deg", (edges[0], edges[-1]))
            object.__setattr__(self, "elevation_bins", len(edges) - 1)
        if self.azimuth_edges_deg is not None:
            edges = self.azimuth_edges_deg
            if not math.isclose(edges[-1] - edges[0], 360.0, abs_tol=1e-6):
                raise ConfigError(f"grid.azimuth_edges_deg: must span 360 deg (last = first + 360), got {edges!r}")
            object.__setattr__(self, "azimuth_offset_deg", edges[0])
            object.__setattr__(self, "azimuth_bins", len(edges) - 1)
        _check_spherical(self)

    @property
    def follows_sensor(self) -> bool:
        """The config gave no elevation span: it is the sensor's (``field.channels``)."""
        return self.elevation_deg is None

    @property
    def elevation_span_deg(self) -> tuple[float, float]:
        return SENSORLESS_ELEVATION_DEG if self.elevation_deg is None else self.elevation_deg

    def elevation_edges(self) -> np.ndarray:
        """The elevation band edges (deg, increasing; ``elevation_bins`` + 1 of them)."""
        if self.elevation_edges_deg is not None:
            return np.asarray(self.elevation_edges_deg, dtype=np.float64)
        lo, hi = self.elevation_span_deg
        return np.linspace(lo, hi, self.elevation_bins + 1)

    def azimuth_edges(self) -> np.ndarray:
        """The azimuth column edges (deg, increasing, the last 360 deg after the first)."""
        if self.azimuth_edges_deg is not None:
            return np.asarray(self.azimuth_edges_deg, dtype=np.float64)
        return self.azimuth_offset_deg + np.linspace(0.0, 360.0, self.azimuth_bins + 1)

    def with_edges(self, elevation_edges, azimuth_edges) -> "SphericalGrid":
        """This grid with the given edges (deg); edges that are uniform give a uniform grid
        (binned by arithmetic, and its config as before)."""
        elevation_edges = np.asarray(elevation_edges, dtype=np.float64)
        azimuth_edges = np.asarray(azimuth_edges, dtype=np.float64)
        settings = {"range_edges_m": self.range_edges_m}
        lo, hi = float(elevation_edges[0]), float(elevation_edges[-1])
        if _uniform(elevation_edges):
            settings.update(elevation_deg=(lo, hi), elevation_bins=len(elevation_edges) - 1)
        else:
            settings["elevation_edges_deg"] = tuple(float(e) for e in elevation_edges)
        if _uniform(azimuth_edges):
            settings.update(azimuth_offset_deg=float(azimuth_edges[0]), azimuth_bins=len(azimuth_edges) - 1)
        else:
            settings["azimuth_edges_deg"] = tuple(float(e) for e in azimuth_edges)
        return SphericalGrid(**settings)

    @property
    def range_bins(self) -> int:
        return 0 if self.range_edges_m is None else len(self.range_edges_m) - 1

    @property
    def n_voxels(self) -> int:
        return self.azimuth_bins * self.elevation_bins * max(1, self.range_bins)

    def assign(self, xyz: np.ndarray, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        """Voxel id of each point binned about ``origin``; -1 outside the grid."""
        return self.assign_columns(*relative_columns(xyz, origin))

    def assign_columns(self, dx: np.ndarray, dy: np.ndarray, dz: np.ndarray, out_id: int = -1) -> np.ndarray:
        """Voxel ids from contiguous coordinate columns already relative to the origin (not
        modified), so a caller that needs the columns too extracts them once. ``out_id`` marks
        points outside the grid (the field kernel uses ``n_voxels`` so a bincount needs no mask)."""
        # Angles stay in radians and the modulo is a table look-up on integers: np.hypot,
        # np.degrees and float % are each several times slower than this arithmetic.
        # Explicit (uneven) edges are looked up with searchsorted instead.
        a = self.azimuth_bins
        rho = dx * dx
        rho += dy * dy
        np.sqrt(rho, out=rho)
        az = np.arctan2(dy, dx)
        if self.azimuth_edges_deg is None:
            az *= a / (2.0 * math.pi)
            # atan2 gives [-a/2, a/2] bins and the offset is taken in [-a/2, a/2): adding a makes
            # the value non-negative, so truncation is floor, and the table wraps [a, 2a] to [0, a].
            az += a - ((self.azimuth_offset_deg + 180.0) % 360.0 - 180.0) * (a / 360.0)
            with np.errstate(invalid="ignore"):  # NaN points get a garbage bin, masked out below
                az_int = az.astype(np.int64)
            np.clip(az_int, 0, 2 * a, out=az_int)
            ids = np.take(np.arange(2 * a + 1) % a, az_int)
        else:
            edges = np.radians(self.azimuth_edges())
            first = (edges[0] + math.pi) % (2.0 * math.pi) - math.pi  # in [-pi, pi): az - first > -2 pi
            az -= first
            az[az < 0.0] += 2.0 * math.pi
            ids = np.searchsorted(edges - edges[0], az, side="right") - 1
            np.clip(ids, 0, a - 1, out=ids)  # NaN sorts last: masked out below

        lo, hi = (math.radians(e) for e in self.elevation_span_deg)
        el = np.arctan2(dz, rho)
        inside = el >= lo
        inside &= el <= hi  # both False for NaN
        if self.elevation_edges_deg is None:
            el -= lo
            el *= self.elevation_bins / (hi - lo)
            with np.errstate(invalid="ignore"):
                el_bin = el.astype(np.int64)
        else:
            el_bin = np.searchsorted(np.radians(self.elevation_edges()), el, side="right") - 1
        np.clip(el_bin, 0, self.elevation_bins - 1, out=el_bin)
        el_bin *= a
        ids += el_bin

        if self.range_edges_m is not None:
            edges = np.asarray(self.range_edges_m, dtype=np.float64)
            rho *= rho
            rho += dz * dz
            r = np.sqrt(rho, out=rho)
            inside &= r >= edges[0]
            inside &= r <= edges[-1]
            r_bin = np.searchsorted(edges, r, side="right") - 1
            np.minimum(r_bin, self.range_bins - 1, out=r_bin)
            r_bin *= a * self.elevation_bins
            ids += r_bin
        return np.where(inside, ids, out_id)  # several times faster than np.putmask

    def bins(self, voxel_ids: np.ndarray) -> dict[str, np.ndarray]:
        """``az_bin, el_bin, r_bin`` of each id (r_bin -1 without shells; all -1 for id -1)."""
        ids = np.asarray(voxel_ids, dtype=np.int64)
        out = ids < 0
        az = ids % self.azimuth_bins
        el = (ids // self.azimuth_bins) % self.elevation_bins
        if self.range_edges_m is None:
            r = np.full(ids.shape, -1, dtype=np.int64)
        else:
            r = ids // (self.azimuth_bins * self.elevation_bins)
        for a in (az, el, r):
            a[out] = -1
        return {"az_bin": az, "el_bin": el, "r_bin": r}

    def to_config(self) -> dict[str, Any]:
        config = {
            "kind": self.kind,
            "azimuth_bins": self.azimuth_bins,
            "azimuth_offset_deg": self.azimuth_offset_deg,
            "elevation_deg": None if self.elevation_deg is None else list(self.elevation_deg),
            "elevation_bins": self.elevation_bins,
            "range_edges_m": None if self.range_edges_m is None else list(self.range_edges_m),
        }
        # explicit edges only where set: a uniform grid's config stays what it always was
        for name in ("elevation_edges_deg", "azimuth_edges_deg"):
            if getattr(self, name) is not None:
                config[name] = list(getattr(self, name))
        return config


@dataclass(frozen=True)
class CartesianGrid:
    """Cubic cells of side ``cell_m``; cell (0, 0, 0) spans [origin, origin + cell_m)."""

    cell_m: float = default("grid", "cell_m")
    origin: tuple[float, float, float] = tuple(default("grid", "origin"))

    kind = "cartesian"
    n_voxels = None  # the id space is sparse (63 bits)

    def __post_init__(self) -> None:
        object.__setattr__(self, "origin", _number_tuple(self.origin))
        if is_number(self.cell_m):
            object.__setattr__(self, "cell_m", float(self.cell_m))
        _check_cartesian(self)

    def assign(self, xyz: np.ndarray, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
        """Voxel id of each point; -1 for non-finite points or indices beyond +-2**20.

        ``origin`` is added to the grid's own origin (the frame the points are binned in).
        """
        return self.assign_columns(*relative_columns(xyz, origin))

    def assign_columns(self, dx: np.ndarray, dy: np.ndarray, dz: np.ndarray, out_id: int = -1) -> np.ndarray:
        """Voxel ids from coordinate columns relative to the ``origin`` of ``assign``."""
        ids = np.zeros(len(dx), dtype=np.int64)
        inside = np.ones(len(dx), dtype=bool)
        for axis, (d, o) in enumerate(zip((dx, dy, dz), self.origin)):
            cell = np.floor((d - o) / self.cell_m)
            inside &= (cell >= -CARTESIAN_OFFSET) & (cell < CARTESIAN_OFFSET)  # False for NaN
            index = np.where(inside, cell, 0.0).astype(np.int64) + CARTESIAN_OFFSET
            ids |= index << (CARTESIAN_BITS * axis)
        return np.where(inside, ids, out_id)

    def bins(self, voxel_ids: np.ndarray) -> dict[str, np.ndarray]:
        """``ix, iy, iz`` cell indices of each id (-1 ids give -1 everywhere)."""
        ids = np.asarray(voxel_ids, dtype=np.int64)
        out = ids < 0
        result = {}
        for axis, name in enumerate(("ix", "iy", "iz")):
            index = ((ids >> (CARTESIAN_BITS * axis)) & _CARTESIAN_MASK) - CARTESIAN_OFFSET
            index[out] = -1
            result[name] = index
        return result

    def to_config(self) -> dict[str, Any]:
        return {"kind": self.kind, "cell_m": self.cell_m, "origin": list(self.origin)}


Grid = SphericalGrid | CartesianGrid


def count_out_of_grid(voxel_ids: np.ndarray) -> int:
    """Number of points that ``assign`` put outside the grid."""
    return int(np.count_nonzero(np.asarray(voxel_ids) < 0))


@dataclass(frozen=True)
class FieldSettings:
    """The grid and the validity rules of the field (``grid`` section of the config)."""

    grid: Grid
    min_points: int = default("grid", "min_points")
    max_component_m: float | None = default("grid", "max_component_m")
    z_min: float = float(default("grid", "z_min"))  # a vector is significant when |z| >= z_min (see significance.py)

    def __post_init__(self) -> None:
        if not is_integer(self.min_points) or self.min_points < 1:
            raise ConfigError(f"grid.min_points: must be an integer >= 1, got {self.min_points!r}")
        if self.max_component_m is not None and not is_number(self.max_component_m, positive=True):
            raise ConfigError(f"grid.max_component_m: must be a positive number or null, got {self.max_component_m!r}")
        if not is_number(self.z_min, positive=True):
            raise ConfigError(f"grid.z_min: must be a positive number, got {self.z_min!r}")

    def to_config(self) -> dict[str, Any]:
        return {
            **self.grid.to_config(),
            "min_points": int(self.min_points),
            "max_component_m": self.max_component_m,
            "z_min": float(self.z_min),
        }


def grid_from_config(d: dict) -> Grid:
    """The grid of a config ``grid`` section (``min_points``/``max_component_m`` are ignored here)."""
    if not isinstance(d, dict):
        raise ConfigError(f"grid: expected a mapping of grid settings, got {type(d).__name__}")
    kind = d.get("kind", "spherical")
    own = {"spherical": SPHERICAL_KEYS, "cartesian": CARTESIAN_KEYS}.get(kind)
    if own is None:
        raise ConfigError(f"grid.kind: must be 'spherical' or 'cartesian', got {kind!r}")
    # The other kind's keys are ignored, not refused: the config schema fills in defaults for
    # both kinds, so a validated spherical config also carries cell_m and origin.
    known = ("kind", *SPHERICAL_KEYS, *CARTESIAN_KEYS, *FIELD_KEYS)
    for key in d:
        if key not in known:
            raise ConfigError(f"grid.{key}: unknown key (known: {', '.join(known)})")
    kwargs = {key: d[key] for key in own if key in d}
    return SphericalGrid(**kwargs) if kind == "spherical" else CartesianGrid(**kwargs)


def field_settings_from_config(d: dict) -> FieldSettings:
    """Grid plus ``min_points``, ``max_component_m`` and ``z_min`` (missing keys: the schema's
    defaults)."""
    return FieldSettings(grid_from_config(d), **{key: d[key] for key in FIELD_KEYS if key in d})


def _number_tuple(value):
    """Lists/tuples of plain numbers as a tuple of floats (hashable, JSON-stable); else as is."""
    if isinstance(value, (list, tuple)) and all(is_number(v) for v in value):
        return tuple(float(v) for v in value)
    return value


def _check_spherical(g: SphericalGrid) -> None:
    if not is_integer(g.azimuth_bins) or g.azimuth_bins < 1:
        raise ConfigError(f"grid.azimuth_bins: must be an integer >= 1, got {g.azimuth_bins!r}")
    if not is_integer(g.elevation_bins) or g.elevation_bins < 1:
        raise ConfigError(f"grid.elevation_bins: must be an integer >= 1, got {g.elevation_bins!r}")
    if not is_number(g.azimuth_offset_deg, finite=True):
        raise ConfigError(f"grid.azimuth_offset_deg: must be a finite number, got {g.azimuth_offset_deg!r}")
    el = g.elevation_deg
    if el is not None and (
        not isinstance(el, tuple)
        or len(el) != 2
        or not all(is_number(a) for a in el)
        or not -90.0 <= el[0] < el[1] <= 90.0
    ):
        raise ConfigError(f"grid.elevation_deg: must be null or [lo, hi] with -90 <= lo < hi <= 90, got {el!r}")
    edges = g.range_edges_m
    if edges is not None:
        ok = isinstance(edges, tuple) and len(edges) >= 2 and all(is_number(e, finite=True) for e in edges)
        if not ok or edges[0] < 0 or any(b <= a for a, b in zip(edges, edges[1:])):
            raise ConfigError(f"grid.range_edges_m: must be null or >= 2 increasing finite edges >= 0, got {edges!r}")


def _check_edges(edges, name: str, lo: float, hi: float) -> None:
    if edges is None:
        return
    ok = isinstance(edges, tuple) and len(edges) >= 2 and all(is_number(e, finite=True) for e in edges)
    if not ok or edges[0] < lo or edges[-1] > hi or any(b <= a for a, b in zip(edges, edges[1:])):
        raise ConfigError(
            f"grid.{name}: must be null or >= 2 increasing finite edges in [{lo:g}, {hi:g}], got {edges!r}"
        )


def _uniform(edges: np.ndarray) -> bool:
    return bool(np.all(np.abs(edges - np.linspace(edges[0], edges[-1], len(edges))) <= _UNIFORM_TOLERANCE_DEG))


def _check_cartesian(g: CartesianGrid) -> None:
    if not is_number(g.cell_m, positive=True):
        raise ConfigError(f"grid.cell_m: must be a positive number, got {g.cell_m!r}")
    o = g.origin
    if not isinstance(o, tuple) or len(o) != 3 or not all(is_number(c, finite=True) for c in o):
        raise ConfigError(f"grid.origin: must be three finite numbers, got {o!r}")
