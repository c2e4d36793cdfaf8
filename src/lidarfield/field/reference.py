"""A plain reference for the field kernel: the grid's bins written out in degrees, and a pandas
groupby over them.

Slow and obvious on purpose, and independent of ``grid.assign``'s arithmetic and of the
kernel's sums of products: covariances come from pandas' own ``cov`` and ``se`` from a plain
loop over voxels with 3x3 matrices, as are the normals and planarity (one ``eigh`` per voxel).
The tests check ``field.discrepancy_field`` (binning,
aggregation, se and z) against it and the benchmark times the kernel against it.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .grid import CARTESIAN_BITS, CARTESIAN_OFFSET, CartesianGrid, FieldSettings, SphericalGrid
from .significance import (
    GRAZING_MIN,
    SPREAD_FLOOR_M,
    SPREAD_MIN_POINTS,
    SURFACE_PLANARITY_MIN,
    VIEWPOINT_DENSITY_EXPONENT,
    VIEWPOINT_MAX_REWEIGHT,
    Viewpoint,
)
from .surface import MIN_SPREAD_M2


def discrepancy_field_reference(
    xyz1: np.ndarray,
    xyz2: np.ndarray,
    settings: FieldSettings,
    origin=(0.0, 0.0, 0.0),
    viewpoint: Viewpoint | None = None,
) -> dict[str, np.ndarray]:
    """Same contract as ``field.discrepancy_field``, computed with a pandas groupby."""
    grid = settings.grid
    ids1, ids2 = plain_voxel_ids(grid, xyz1, origin), plain_voxel_ids(grid, xyz2, origin)
    return field_from_voxel_ids_reference(ids1, xyz1, ids2, xyz2, settings, origin, viewpoint)


def plain_voxel_ids(grid: SphericalGrid | CartesianGrid, xyz: np.ndarray, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The voxel id of each point (-1 outside the grid), by the grid's definition in degrees."""
    d = np.asarray(xyz, dtype=np.float64) - np.asarray(origin, dtype=np.float64)
    if isinstance(grid, CartesianGrid):
        cell = np.floor((d - np.asarray(grid.origin)) / grid.cell_m)
        inside = np.all((cell >= -CARTESIAN_OFFSET) & (cell < CARTESIAN_OFFSET), axis=1)
        index = np.where(inside[:, None], cell, 0).astype(np.int64) + CARTESIAN_OFFSET
        ids = index[:, 0] | (index[:, 1] << CARTESIAN_BITS) | (index[:, 2] << (2 * CARTESIAN_BITS))
        return np.where(inside, ids, -1)
    azimuth = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    elevation = np.degrees(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])))
    lo, hi = grid.elevation_span_deg
    inside = (elevation >= lo) & (elevation <= hi)  # False for NaN points
    if grid.azimuth_edges_deg is None:
        az = np.floor(((azimuth - grid.azimuth_offset_deg) % 360.0) / (360.0 / grid.azimuth_bins))
    else:  # uneven columns: the last edge at or below the point's azimuth, counted from the first
        edges = np.asarray(grid.azimuth_edges_deg) - grid.azimuth_edges_deg[0]
        az = np.array([np.count_nonzero(edges <= a) - 1 for a in (azimuth - grid.azimuth_edges_deg[0]) % 360.0])
    az = np.where(inside, az, 0).astype(np.int64) % grid.azimuth_bins
    if grid.elevation_edges_deg is None:
        el = np.floor((elevation - lo) / ((hi - lo) / grid.elevation_bins))
    else:
        el = np.array([np.count_nonzero(np.asarray(grid.elevation_edges_deg) <= e) - 1 for e in elevation])
    el = np.minimum(el, grid.elevation_bins - 1)
    ids = az + grid.azimuth_bins * np.where(inside, el, 0).astype(np.int64)
    if grid.range_edges_m is not None:
        edges = np.asarray(grid.range_edges_m, dtype=np.float64)
        r = np.linalg.norm(d, axis=1)
        inside &= (r >= edges[0]) & (r <= edges[-1])
        shell = np.minimum(np.searchsorted(edges, r, side="right") - 1, len(edges) - 2)
        ids = ids + grid.azimuth_bins * grid.elevation_bins * np.where(inside, shell, 0)
    return np.where(inside, ids, -1)


def field_from_voxel_ids_reference(
    ids1: np.ndarray,
    xyz1: np.ndarray,
    ids2: np.ndarray,
    xyz2: np.ndarray,
    settings: FieldSettings,
    origin=(0.0, 0.0, 0.0),
    viewpoint: Viewpoint | None = None,
) -> dict[str, np.ndarray]:
    """Same contract as ``field.field_from_voxel_ids`` (without scan patterns), computed with a
    pandas groupby."""
    grid = settings.grid
    per_cloud, covariances, shared = [], [], []
    masks = (None, None) if viewpoint is None else (viewpoint.shared1, viewpoint.shared2)
    for k, xyz, ids, mask in ((1, xyz1, ids1, masks[0]), (2, xyz2, ids2, masks[1])):
        frame = pd.DataFrame(np.asarray(xyz, dtype=np.float64), columns=["x", "y", "z"])
        frame["voxel"] = ids
        frame["shared"] = True if mask is None else np.asarray(mask, dtype=bool)
        frame = frame[frame["voxel"] >= 0]
        seen_by_both = frame[frame["shared"]]
        shared += [seen_by_both.groupby("voxel").size().to_dict(), _covariances(seen_by_both)]
        grouped = frame.groupby("voxel").agg(
            **{f"n{k}": ("x", "size"), f"x{k}": ("x", "mean"), f"y{k}": ("y", "mean"), f"z{k}": ("z", "mean")}
        )
        per_cloud.append(grouped)
        covariances.append(_covariances(frame))
    table = per_cloud[0].join(per_cloud[1], how="outer").sort_index()
    table[["n1", "n2"]] = table[["n1", "n2"]].fillna(0).astype(np.int64)
    viewpoints = (
        None if viewpoint is None else (np.asarray(origin, float), np.asarray(viewpoint.origin2, float), shared)
    )

    valid = (table["n1"] >= settings.min_points) & (table["n2"] >= settings.min_points)
    for out, a, b in (("u", "x2", "x1"), ("v", "y2", "y1"), ("w", "z2", "z1")):
        table[out] = table[a] - table[b]
        if settings.max_component_m is not None:
            valid &= table[out].abs() <= settings.max_component_m
    for out in ("u", "v", "w"):
        table.loc[~valid, out] = np.nan
    table["magnitude"] = np.sqrt(table["u"] ** 2 + table["v"] ** 2 + table["w"] ** 2)
    table["valid"] = valid
    table["se"] = [
        _standard_error(row, *covariances, viewpoints) if row.valid else np.nan for row in table.itertuples()
    ]
    table["z"] = table["magnitude"] / table["se"]

    surfaces = [_surface(row, *covariances, origin) if row.valid else (np.nan,) * 4 for row in table.itertuples()]
    table[["nx", "ny", "nz", "planarity"]] = np.array(surfaces, dtype=np.float64).reshape(-1, 4)

    voxel = table.index.to_numpy(dtype=np.int64)
    columns = {"voxel": voxel, **grid.bins(voxel)}
    for name in ("n1", "n2", "x1", "y1", "z1", "x2", "y2", "z2", "u", "v", "w", "magnitude", "se", "z", "valid"):
        columns[name] = table[name].to_numpy()
    for name in ("nx", "ny", "nz", "planarity"):
        columns[name] = table[name].to_numpy()
    two_places = viewpoints is not None and bool(np.any(viewpoints[0] != viewpoints[1]))
    read = [
        _surface_reading(row, *covariances, viewpoints, surfaces[k], two_places) if row.valid else (np.nan,) * 5
        for k, row in enumerate(table.itertuples())
    ]
    read = np.array(read, dtype=np.float64).reshape(-1, 5).T
    columns["wu"], columns["wv"], columns["ww"], columns["se_normal"] = read[:4]
    columns["read_normal"] = read[4] == 1.0
    return columns


def _surface(row, covariance1: dict, covariance2: dict, origin) -> tuple[float, float, float, float]:
    """Normal (towards ``origin``) and planarity (l2 - l3) / l2 of one voxel's pooled
    within-cloud covariance ((n1 - 1) S1 + (n2 - 1) S2) / (n1 + n2 - 2)."""
    pooled = _pooled(row, covariance1, covariance2)
    if pooled is None:
        return (np.nan,) * 4
    values, vectors = np.linalg.eigh(pooled)
    l3, l2 = max(values[0], 0.0), max(values[1], 0.0)
    if not l2 > MIN_SPREAD_M2:
        return (np.nan,) * 4
    normal = vectors[:, 0]
    centre = 0.5 * np.array([row.x1 + row.x2, row.y1 + row.y2, row.z1 + row.z2]) - np.asarray(origin)
    if normal @ centre > 0:
        normal = -normal
    return (*normal, (l2 - l3) / l2)


def _pooled(row, covariance1: dict, covariance2: dict, counts=None) -> np.ndarray | None:
    """((n1 - 1) S1 + (n2 - 1) S2) / (n1 + n2 - 2) of one voxel (``counts``: n1 and n2 when not
    the row's), a cloud of one point adding nothing; None with fewer than 3 points in all."""
    n1, n2 = (row.n1, row.n2) if counts is None else counts
    if n1 + n2 < 3:
        return None
    scatter = np.zeros((3, 3))
    for n, covariance in ((n1, covariance1), (n2, covariance2)):
        if n >= 2:
            scatter += (n - 1) * covariance[row.Index]
    return scatter / (n1 + n2 - 2)


def _covariances(frame: pd.DataFrame) -> dict[int, np.ndarray]:
    """voxel -> 3x3 sample covariance (ddof 1; NaN for one point), two-pass: products of
    coordinates about their group's mean, summed per group."""
    centred = frame[["x", "y", "z"]] - frame.groupby("voxel")[["x", "y", "z"]].transform("mean")
    products = pd.DataFrame({"voxel": frame["voxel"]})
    for a in "xyz":
        for b in "xyz":
            products[a + b] = centred[a] * centred[b]
    grouped = products.groupby("voxel")
    covariance = grouped.sum().div(grouped.size() - 1, axis=0).replace([np.inf, -np.inf], np.nan)
    return dict(zip(covariance.index, covariance.to_numpy().reshape(-1, 3, 3)))


def _vector_covariance(row, covariance1: dict, covariance2: dict, viewpoints) -> np.ndarray | None:
    """S1/n1 + S2/n2 of one voxel, a cloud of fewer than SPREAD_MIN_POINTS points borrowing the
    other's S, plus the floor on the diagonal, plus (with both sensors' origins and the shared
    points' counts and covariances, ``viewpoints``) min((3 + 1 / facing) |b| / r, 1)^2 times the
    pooled spread of the shared points times their share squared, r the nearer sensor's range to
    the voxel's centre, facing |ray . normal| from sensor 1 (at least GRAZING_MIN); None where
    neither cloud has enough points."""
    own = [row.n1 >= SPREAD_MIN_POINTS, row.n2 >= SPREAD_MIN_POINTS]
    if not any(own):
        return None
    spreads = [c[row.Index] if ok else None for c, ok in zip((covariance1, covariance2), own)]
    spread1 = spreads[0] if own[0] else spreads[1]
    spread2 = spreads[1] if own[1] else spreads[0]
    floor = SPREAD_FLOOR_M**2 * (1 / row.n1 + 1 / row.n2)
    combined = spread1 / row.n1 + spread2 / row.n2 + floor * np.eye(3)
    if viewpoints is not None:
        count1, shared1, count2, shared2 = viewpoints[2]
        counts = count1.get(row.Index, 0), count2.get(row.Index, 0)
        pooled = _pooled(row, shared1, shared2, counts)
        if pooled is not None:
            pooled = pooled * ((counts[0] + counts[1]) / (row.n1 + row.n2)) ** 2
        centre = 0.5 * np.array([row.x1 + row.x2, row.y1 + row.y2, row.z1 + row.z2])
        r = min(np.linalg.norm(centre - viewpoints[0]), np.linalg.norm(centre - viewpoints[1]))
        normal = np.array(_surface(row, covariance1, covariance2, viewpoints[0])[:3])
        ray = (centre - viewpoints[0]) / np.linalg.norm(centre - viewpoints[0])
        facing = abs(ray @ normal) if np.all(np.isfinite(normal)) else GRAZING_MIN
        reweight = (
            (VIEWPOINT_DENSITY_EXPONENT + 1 / max(facing, GRAZING_MIN))
            * np.linalg.norm(viewpoints[1] - viewpoints[0])
            / r
        )
        if pooled is not None:
            combined += min(reweight, VIEWPOINT_MAX_REWEIGHT) ** 2 * pooled
    return combined


def _standard_error(row, covariance1: dict, covariance2: dict, viewpoints) -> float:
    """se of one voxel's vector along its direction: sqrt(d^T C d) / |d|."""
    d = np.array([row.u, row.v, row.w])
    combined = _vector_covariance(row, covariance1, covariance2, viewpoints)
    if not np.all(np.isfinite(d)) or combined is None:
        return np.nan
    length = np.linalg.norm(d)
    along = d @ combined @ d / length**2 if length > 0 else np.trace(combined) / 3
    return float(np.sqrt(max(along, 0.0)))


def _surface_reading(row, covariance1: dict, covariance2: dict, viewpoints, surface, two_places) -> tuple:
    """The whitened vector of one voxel, the standard error of its normal part and whether the
    tests read it by that part: C^-1/2 d (the symmetric root), NaN, 0; on a surface (normal and
    planarity ``surface``, planarity at least SURFACE_PLANARITY_MIN) sqrt(n^T C n), and with
    ``two_places``, where the line of sight from sensor 1 to the voxel's centre meets the surface
    at more than grazing (|n . s| >= GRAZING_MIN), the normal part over it, along the normal,
    and 1."""
    d = np.array([row.u, row.v, row.w])
    combined = _vector_covariance(row, covariance1, covariance2, viewpoints)
    if not np.all(np.isfinite(d)) or combined is None:
        return (np.nan,) * 4 + (0.0,)
    normal = np.asarray(surface[:3])
    se_normal = np.nan
    if np.all(np.isfinite(normal)) and surface[3] >= SURFACE_PLANARITY_MIN:
        se_normal = np.sqrt(normal @ combined @ normal)
        if two_places:
            sight = 0.5 * np.array([row.x1 + row.x2, row.y1 + row.y2, row.z1 + row.z2]) - viewpoints[0]
            if abs(normal @ sight) / np.linalg.norm(sight) >= GRAZING_MIN:
                return (*(normal * (normal @ d) / se_normal), se_normal, 1.0)
    values, vectors = np.linalg.eigh(combined)
    return (*(vectors @ ((vectors.T @ d) / np.sqrt(values))), se_normal, 0.0)
