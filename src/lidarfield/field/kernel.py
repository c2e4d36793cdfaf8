"""The discrepancy-vector field: per voxel, counts and means of both clouds and mean2 - mean1.

The kernel never sorts points. Each cloud's points get a dense index (the spherical voxel id
itself, or for a Cartesian grid a cell index inside the bounding box of both clouds) and every
per-voxel sum is one ``np.bincount`` in float64: counts, coordinate sums and the sums of the six
coordinate products that give each cloud's spread in the voxel (for ``se`` and ``z``, see
``significance``, and for the local surface normal, ``surface``). Out-of-grid points get the index one past the
end, whose bin is dropped. ``reference.py`` holds a pandas groupby version of the same
contract for the tests and the benchmark.
"""

from __future__ import annotations

import numpy as np

from .grid import CARTESIAN_BITS, FieldSettings, Grid, SphericalGrid, relative_columns
from .significance import (
    COVARIANCE_ENTRIES,
    ScanPattern,
    Viewpoint,
    covariance_from_sums,
    normal_standard_error,
    pattern_covariance,
    read_by_normal_part,
    surface_axes,
    vector_covariance,
    vector_standard_error,
    viewpoint_covariance,
    whitened_vectors,
    z_score,
)
from .surface import normals_from_covariance, pooled_covariance, shared_spread

GRID_COLUMNS = {"spherical": ("az_bin", "el_bin", "r_bin"), "cartesian": ("ix", "iy", "iz")}
VALUE_COLUMNS = ("n1", "n2", "x1", "y1", "z1", "x2", "y2", "z2", "u", "v", "w", "magnitude", "se", "z", "valid")
# The local surface of each valid voxel (``surface``): written after VALUE_COLUMNS, optional
# when a field file is read (files written before them lack them).
SURFACE_COLUMNS = ("nx", "ny", "nz", "planarity")
# Each valid vector in units of its own sampling noise, C^-1/2 d, or on a surface seen from two
# places its normal part (``significance``): what the randomness tests read. Optional when a
# field file is read, like the surface columns.
WHITENED_COLUMNS = ("wu", "wv", "ww")
# A surface voxel's standard error of its normal part n . d (``significance``; NaN elsewhere): the
# weight of its normal part in the field's rigid fit (``field.rigid_fit.field_normal_part_fit``).
# Optional when a field file is read.
NORMAL_SE_COLUMN = "se_normal"
# Whether the randomness tests read the voxel by its normal part alone: a surface voxel of a pair
# from two places (``significance``). Optional when a field file is read.
NORMAL_READ_COLUMN = "read_normal"

# A Cartesian bounding box with more cells than this (and than a few per point) falls back to
# np.unique for compaction: the dense bincount arrays would cost more than the sort.
_MAX_DENSE_CELLS = 1 << 24


def field_columns(grid: Grid) -> tuple[str, ...]:
    """The column names of the field Parquet for ``grid``, in order."""
    return (
        "voxel",
        *GRID_COLUMNS[grid.kind],
        *VALUE_COLUMNS,
        *SURFACE_COLUMNS,
        *WHITENED_COLUMNS,
        NORMAL_SE_COLUMN,
        NORMAL_READ_COLUMN,
    )


def discrepancy_field(
    xyz1: np.ndarray,
    xyz2: np.ndarray,
    settings: FieldSettings,
    origin=(0.0, 0.0, 0.0),
    viewpoint: Viewpoint | None = None,
) -> dict[str, np.ndarray]:
    """The field of two clouds in the same frame, binned about ``origin`` (sensor 1).

    One row per voxel holding points of either cloud, sorted by voxel id; the columns of
    ``field_columns(settings.grid)``. Means are NaN where a cloud has no point; ``u, v, w``
    and ``magnitude`` are NaN and ``valid`` False where either count is below ``min_points``
    or, with ``max_component_m`` set, any |component| exceeds it; ``se`` and ``z`` (see
    ``significance``) and the surface columns ``nx, ny, nz, planarity`` (see ``surface``) are
    NaN there too. ``viewpoint``: sensor 2's origin and which points both sensors could see,
    when known (the vectors' covariance then includes the change of viewpoint on what both
    could see, see ``significance``).
    """
    grid = settings.grid
    columns1, columns2 = relative_columns(xyz1, origin), relative_columns(xyz2, origin)
    if isinstance(grid, SphericalGrid):
        # The out-of-grid id n_voxels lands in a bin that _aggregate drops: no masking pass.
        n = grid.n_voxels
        index1 = grid.assign_columns(*columns1, out_id=n)
        index2 = grid.assign_columns(*columns2, out_id=n)
        dense = (index1, index2, n, _identity)
    else:
        dense = _cartesian_dense_index(grid.assign_columns(*columns1), grid.assign_columns(*columns2))
    return _aggregate(dense, columns1, columns2, origin, settings, viewpoint=_viewpoint(viewpoint, origin))


def field_from_voxel_ids(
    ids1: np.ndarray,
    xyz1: np.ndarray,
    ids2: np.ndarray,
    xyz2: np.ndarray,
    settings: FieldSettings,
    origin=(0.0, 0.0, 0.0),
    patterns: tuple[ScanPattern | None, ScanPattern | None] = (None, None),
    viewpoint: Viewpoint | None = None,
) -> dict[str, np.ndarray]:
    """The field from voxel ids already assigned by ``settings.grid`` (-1 = out of grid).

    For callers that bin once and aggregate several subsets (e.g. the survivors of each
    stage); same result as ``discrepancy_field`` when ``origin`` is the one the ids were
    assigned about (it only orients the normals). ``patterns``: each cloud's lattice of rays,
    when known (its sampling noise then includes the lattice's phase, see ``significance``);
    ``viewpoint``: as in ``discrepancy_field``.
    """
    grid = settings.grid
    ids1, ids2 = np.asarray(ids1, dtype=np.int64), np.asarray(ids2, dtype=np.int64)
    if isinstance(grid, SphericalGrid):
        n = grid.n_voxels
        dense = (np.where(ids1 < 0, n, ids1), np.where(ids2 < 0, n, ids2), n, _identity)
    else:
        dense = _cartesian_dense_index(ids1, ids2)
    zero = (0.0, 0.0, 0.0)
    columns1, columns2 = relative_columns(xyz1, zero), relative_columns(xyz2, zero)
    field = _aggregate(dense, columns1, columns2, zero, settings, patterns, _viewpoint(viewpoint, origin))
    if any(origin):
        _orient_normals(field, origin)
    return field


def _orient_normals(field: dict[str, np.ndarray], origin) -> None:
    """Flip the normals of ``field`` to face ``origin`` (in place)."""
    normal = np.vstack([field["nx"], field["ny"], field["nz"]])
    centre = 0.5 * (
        np.vstack([field["x1"], field["y1"], field["z1"]]) + np.vstack([field["x2"], field["y2"], field["z2"]])
    )
    away = np.einsum("ij,ij->j", normal, centre - np.asarray(origin, dtype=np.float64).reshape(3, 1)) > 0
    for axis in ("nx", "ny", "nz"):
        field[axis] = np.where(away, -field[axis], field[axis])


def _viewpoint(viewpoint: Viewpoint | None, origin) -> tuple | None:
    """Both sensors' origins (sensor 1 at ``origin``) and the shared-point masks, or None."""
    if viewpoint is None:
        return None
    origins = (np.asarray(origin, dtype=np.float64), np.asarray(viewpoint.origin2, dtype=np.float64))
    return origins, (np.asarray(viewpoint.shared1, dtype=bool), np.asarray(viewpoint.shared2, dtype=bool))


def _identity(occupied: np.ndarray) -> np.ndarray:
    return occupied


def _aggregate(dense, columns1, columns2, origin, settings: FieldSettings, patterns=(None, None), viewpoint=None):
    """Counts, sums and means per dense index, then the field columns (see module docstring);
    with ``viewpoint`` (origins, shared masks) the spread of each voxel's shared points too."""
    index1, index2, n, to_voxel = dense
    counts1, sums1, products1 = _bin_sums(index1, columns1, n)
    counts2, sums2, products2 = _bin_sums(index2, columns2, n)
    occupied = np.flatnonzero((counts1 + counts2) > 0)
    voxel = to_voxel(occupied).astype(np.int64)
    n1, n2 = counts1[occupied], counts2[occupied]
    # Sums are of coordinates relative to the origin (one column copy per cloud serves both
    # the binning and the sums); the origin goes back onto the means.
    offset = np.asarray(origin, dtype=np.float64).reshape(3, 1)
    sums1, sums2 = sums1[:, occupied], sums2[:, occupied]
    mean1 = _means(sums1, n1) + offset
    mean2 = _means(sums2, n2) + offset
    covariance1 = covariance_from_sums(n1, sums1, products1[:, occupied])
    covariance2 = covariance_from_sums(n2, sums2, products2[:, occupied])
    shared = None
    if viewpoint is not None:
        origins, masks = viewpoint
        spreads = []
        for index, columns, mask in ((index1, columns1, masks[0]), (index2, columns2, masks[1])):
            counts, sums, products = _bin_sums(np.where(mask, index, n), columns, n)
            spreads += [
                counts[occupied],
                covariance_from_sums(counts[occupied], sums[:, occupied], products[:, occupied]),
            ]
        shared = origins, tuple(spreads)
    return assemble_field(
        settings.grid, voxel, n1, n2, mean1, mean2, settings, covariance1, covariance2, origin, patterns, shared
    )


def assemble_field(
    grid: Grid,
    voxel: np.ndarray,
    n1: np.ndarray,
    n2: np.ndarray,
    mean1: np.ndarray,
    mean2: np.ndarray,
    settings: FieldSettings,
    covariance1: np.ndarray,
    covariance2: np.ndarray,
    origin=(0.0, 0.0, 0.0),
    patterns: tuple[ScanPattern | None, ScanPattern | None] = (None, None),
    shared: tuple | None = None,
) -> dict[str, np.ndarray]:
    """The field columns from per-voxel counts, (3, V) means and (6, V) covariances (rows in
    ``significance.COVARIANCE_ENTRIES`` order): vectors, their se, z and whitened vectors
    (with each cloud's scan ``patterns`` where given, and with ``shared`` = (both sensors'
    origins, (counts and covariances of each cloud's shared points: n1, C1, n2, C2)) the change
    of viewpoint on what both sensors could see), validity, bins, and the local surface
    (normal and planarity, ``surface``; normals towards ``origin``) of each valid voxel."""
    valid = (n1 >= settings.min_points) & (n2 >= settings.min_points)
    uvw = mean2 - mean1
    if settings.max_component_m is not None:
        with np.errstate(invalid="ignore"):
            valid &= np.all(np.abs(uvw) <= settings.max_component_m, axis=0)
    uvw[:, ~valid] = np.nan
    columns: dict[str, np.ndarray] = {"voxel": voxel, **grid.bins(voxel)}
    columns["n1"], columns["n2"] = n1.astype(np.int64), n2.astype(np.int64)
    for k, mean in ((1, mean1), (2, mean2)):
        for i, axis in enumerate("xyz"):
            columns[f"{axis}{k}"] = mean[i]
    columns["u"], columns["v"], columns["w"] = uvw
    columns["magnitude"] = np.sqrt(np.einsum("ij,ij->j", uvw, uvw))
    columns["valid"] = valid
    # Normals of the valid voxels only: an eigen-decomposition per occupied voxel cost a fine
    # Cartesian grid more than the rest of the kernel.
    midpoint = 0.5 * (mean1[:, valid] + mean2[:, valid])
    centre = midpoint - np.asarray(origin, dtype=np.float64).reshape(3, 1)
    normal = np.full((3, len(valid)), np.nan)
    planarity = np.full(len(valid), np.nan)
    spread = pooled_covariance(n1[valid], covariance1[:, valid], n2[valid], covariance2[:, valid])
    normal[:, valid], planarity[valid] = normals_from_covariance(spread, centre)
    terms = []
    for pattern, mean in zip(patterns, (mean1, mean2)):
        if pattern is not None:
            lattice = np.zeros((6, len(valid)))
            lattice[:, valid] = pattern_covariance(mean[:, valid], normal[:, valid], spread, pattern)
            terms.append(lattice)
    if shared is not None:
        origins, (ns1, cs1, ns2, cs2) = shared
        seen_by_both = shared_spread(n1[valid] + n2[valid], ns1[valid], cs1[:, valid], ns2[valid], cs2[:, valid])
        viewpoint = np.zeros((6, len(valid)))
        viewpoint[:, valid] = viewpoint_covariance(midpoint, normal[:, valid], seen_by_both, origins)
        terms.append(viewpoint)
    combined = vector_covariance(n1, covariance1, n2, covariance2, tuple(terms))
    columns["se"] = vector_standard_error(uvw, combined)
    columns["z"] = z_score(columns["magnitude"], columns["se"])
    columns["nx"], columns["ny"], columns["nz"] = normal
    columns["planarity"] = planarity
    axes = surface_axes(normal, planarity)
    surface = np.isfinite(axes[0])
    columns[NORMAL_SE_COLUMN] = np.where(surface, normal_standard_error(axes, combined), np.nan)
    # From one place the scan pattern's term models a surface's in-plane sampling; from two the
    # change of viewpoint makes it unknown, so a surface the line of sight crosses is read by its
    # normal part (``significance``).
    origins = None if shared is None else shared[0]
    columns[NORMAL_READ_COLUMN] = read_by_normal_part(axes, 0.5 * (mean1 + mean2), origins)
    read = np.where(columns[NORMAL_READ_COLUMN], axes, np.nan)
    columns["wu"], columns["wv"], columns["ww"] = whitened_vectors(uvw, combined, read)
    return {name: columns[name] for name in field_columns(grid)}


def _bin_sums(index: np.ndarray, columns: tuple[np.ndarray, ...], n: int):
    """Counts (n,), column sums (3, n) and sums of column products (6, n, in
    ``COVARIANCE_ENTRIES`` order) per dense index; index n (out of grid) dropped."""
    counts = np.bincount(index, minlength=n + 1)[:n]
    sums = np.empty((3, n))
    for axis, column in enumerate(columns):
        sums[axis] = np.bincount(index, weights=column, minlength=n + 1)[:n]
    products = np.empty((6, n))
    for row, (a, b) in enumerate(COVARIANCE_ENTRIES):
        products[row] = np.bincount(index, weights=columns[a] * columns[b], minlength=n + 1)[:n]
    return counts, sums, products


def _means(sums: np.ndarray, counts: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / counts, np.nan)


def _cartesian_dense_index(ids1: np.ndarray, ids2: np.ndarray):
    """Dense indices for packed Cartesian ids (-1 = out); returns (index1, index2, n, to_voxel).

    Within the bounding box of both clouds the index is ``dx + nx * (dy + ny * dz)``, which
    orders cells like the packed id (iz, then iy, then ix), so occupied indices map to sorted
    voxel ids. A box too large for dense counting is compacted with ``np.unique`` instead.
    """
    inside1, inside2 = ids1 >= 0, ids2 >= 0
    packed = np.concatenate([ids1[inside1], ids2[inside2]])
    if packed.size == 0:
        return np.zeros(len(ids1), np.int64), np.zeros(len(ids2), np.int64), 0, _identity
    mask = (1 << CARTESIAN_BITS) - 1
    lows, sizes = [], []
    for axis in range(3):
        cell = (packed >> (CARTESIAN_BITS * axis)) & mask
        lows.append(int(cell.min()))
        sizes.append(int(cell.max()) - lows[-1] + 1)
    n = sizes[0] * sizes[1] * sizes[2]
    if n > max(_MAX_DENSE_CELLS, 4 * packed.size):
        voxels, inverse = np.unique(packed, return_inverse=True)
        return (
            _scatter(inverse[: inside1.sum()], inside1, len(voxels)),
            _scatter(inverse[inside1.sum() :], inside2, len(voxels)),
            len(voxels),
            lambda occupied: voxels[occupied],
        )

    def dense(ids: np.ndarray, inside: np.ndarray) -> np.ndarray:
        index = np.zeros(len(ids), dtype=np.int64)
        for axis in (2, 1, 0):
            index *= sizes[axis]
            index += ((ids >> (CARTESIAN_BITS * axis)) & mask) - lows[axis]
        index[~inside] = n
        return index

    def to_voxel(occupied: np.ndarray) -> np.ndarray:
        dx = occupied % sizes[0] + lows[0]
        dy = (occupied // sizes[0]) % sizes[1] + lows[1]
        dz = occupied // (sizes[0] * sizes[1]) + lows[2]
        return dx | (dy << CARTESIAN_BITS) | (dz << (2 * CARTESIAN_BITS))

    return dense(ids1, inside1), dense(ids2, inside2), n, to_voxel


def _scatter(values: np.ndarray, inside: np.ndarray, out_value: int) -> np.ndarray:
    index = np.full(len(inside), out_value, dtype=np.int64)
    index[inside] = values
    return index
