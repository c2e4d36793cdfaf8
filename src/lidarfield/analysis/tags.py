"""Where each discrepancy could come from: per valid voxel, tags computed from geometry.

Tags say what a voxel's points and vector look like, not what the stack did, so that an
analyst (and the suggestions) can see which adversity a field's energy sits with. A voxel can
carry several tags; an invalid voxel carries none. The point-based tags hold when at least
``POINT_SHARE`` of either cloud's points in the voxel qualify:

- ``fov_edge``: the point lies within ``FOV_EDGE_DEG`` of the *other* sensor's elevation limits
  or beyond them (or beyond its range limits), as ``field_of_view`` sees it; needs both
  sensor models (without them no voxel is tagged).
- ``near_sensor``: the point is within ``NEAR_SENSOR_M`` of either sensor's origin.
- ``depth_edge``: the first-radial-cluster rule of ``shadow`` (its defaults, on the study's
  angular grid, about both sensors) would remove the point: the ranges of its cell split into
  separate surfaces.

From the vector and counts:

- ``rigid``: the field's rigid part (the point-to-plane fit of ``rigid_fit``) leaves a
  residual vector (``rigid_fit.voxel_residuals``: the vector minus what the rigid part
  predicts the voxel mean to see, the normal part on a plane) no longer than
  ``RIGID_RESIDUAL_SHARE`` of the vector (it explains >= 75% of its energy).
- ``radial``: the vector within ``RADIAL_DEG`` of the line of sight from sensor 1 (either way)
  and *not* ``rigid``: a wall seen head-on turns a shift into a vector along the line of
  sight, which the rigid part explains; radial is what it does not.
- ``count_imbalance``: one cloud has at least ``IMBALANCE_RATIO`` times the other's points.

The energy of a voxel is min(n1, n2) |v|^2 (the weight of the rigid fit: the precision of a
difference of means is set by the smaller count); ``energy_shares`` gives each tag's share of
the stage's field energy.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import HypothesisError
from ..field.grid import FieldSettings, SphericalGrid
from ..field.kernel import WHITENED_COLUMNS
from ..field.rigid_fit import RigidFit, field_rigid_part
from ..pair import RegisteredPair

TAGS = ("fov_edge", "near_sensor", "depth_edge", "radial", "rigid", "count_imbalance")
POINT_SHARE = 0.1
FOV_EDGE_DEG = 1.0
NEAR_SENSOR_M = 5.0
RADIAL_DEG = 25.0
RIGID_RESIDUAL_SHARE = 0.5
IMBALANCE_RATIO = 3.0


def tag_column(tag: str) -> str:
    """The field Parquet column of a tag."""
    return f"tag_{tag}"


def voxel_energy(columns: dict[str, np.ndarray]) -> np.ndarray:
    """min(n1, n2) |v|^2 per voxel, 0 where invalid (m^2 x points)."""
    weight = np.minimum(columns["n1"], columns["n2"]).astype(np.float64)
    with np.errstate(invalid="ignore"):
        energy = weight * np.asarray(columns["magnitude"], dtype=np.float64) ** 2
    return np.where(np.asarray(columns["valid"], dtype=bool), energy, 0.0)


def whitened_energy(columns: dict[str, np.ndarray]) -> np.ndarray:
    """|C^-1/2 d|^2 per voxel: its vector's squared length in units of its sampling noise (the
    whitened columns, ``significance``; about 3 for a vector sampling alone explains), 0 where
    invalid or without whitened columns."""
    whitened = np.column_stack([np.asarray(columns[c], dtype=np.float64) for c in WHITENED_COLUMNS])
    energy = np.sum(np.nan_to_num(whitened) ** 2, axis=1)
    return np.where(np.asarray(columns["valid"], dtype=bool), energy, 0.0)


def voxel_tags(
    columns: dict[str, np.ndarray],
    pair: RegisteredPair,
    settings: FieldSettings,
    ids: tuple[np.ndarray, np.ndarray] | None = None,
    rigid: tuple[RigidFit, np.ndarray] | None = None,
    on_edge: list[np.ndarray] | None = None,
) -> dict[str, np.ndarray]:
    """``{tag_column(tag): bool (V,)}`` for the field ``columns`` of ``pair`` (binned about
    sensor 1); ``ids``: each cloud's voxel ids, ``rigid``: the field's ``field_rigid_part``,
    and ``on_edge``: each cloud's points on a depth edge (``depth_edges``), when the caller
    has them."""
    valid = np.asarray(columns["valid"], dtype=bool)
    voxel = np.asarray(columns["voxel"], dtype=np.int64)
    ids = ids or tuple(settings.grid.assign(xyz) for xyz in (pair.xyz1, pair.xyz2))
    rows = [_rows(voxel, cloud_ids) for cloud_ids in ids]
    counts = [columns["n1"], columns["n2"]]

    def point_tag(flags) -> np.ndarray:
        shares = [_share(row, flag, count) for row, flag, count in zip(rows, flags, counts)]
        return (shares[0] >= POINT_SHARE) | (shares[1] >= POINT_SHARE)

    tags = {
        "fov_edge": point_tag(_near_fov_edge(pair)),
        "near_sensor": point_tag([_near_a_sensor(xyz, pair) for xyz in (pair.xyz1, pair.xyz2)]),
        "depth_edge": point_tag(depth_edges(pair, settings) if on_edge is None else on_edge),
        **vector_tags(columns, rigid),
        "count_imbalance": _imbalanced(columns["n1"], columns["n2"]),
    }
    return {tag_column(tag): tags[tag] & valid for tag in TAGS}


def vector_tags(
    columns: dict[str, np.ndarray], rigid_part: tuple[RigidFit, np.ndarray] | None = None
) -> dict[str, np.ndarray]:
    """``{"rigid": bool (V,), "radial": bool (V,)}``: the tags of the vectors alone (no points
    needed), for a field with the surface columns; invalid voxels carry none. ``rigid_part``:
    the field's ``field_rigid_part``, when the caller has it."""
    valid = np.asarray(columns["valid"], dtype=bool)
    _, residual = rigid_part or field_rigid_part(columns)
    rigid = _rigid(columns, valid, residual)
    return {"rigid": rigid, "radial": _radial(columns) & ~rigid & valid}


def energy_shares(columns: dict[str, np.ndarray]) -> dict[str, float]:
    """``energy_share_{tag}``: the share of the field energy in the voxels carrying each tag."""
    energy = voxel_energy(columns)
    total = float(energy.sum())
    return {
        f"energy_share_{tag}": float(energy[np.asarray(columns[tag_column(tag)], dtype=bool)].sum() / total)
        if total > 0 and tag_column(tag) in columns
        else math.nan
        for tag in TAGS
    }


def _rows(voxel: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """Row of each point's voxel in the field (-1 outside the grid)."""
    if len(voxel) == 0:
        return np.full(len(ids), -1, dtype=np.int64)
    row = np.minimum(np.searchsorted(voxel, ids), len(voxel) - 1)
    return np.where((ids >= 0) & (voxel[row] == ids), row, -1)


def _share(row: np.ndarray, flag: np.ndarray, count: np.ndarray) -> np.ndarray:
    hits = np.bincount(row[(row >= 0) & flag], minlength=len(count)).astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, hits / np.maximum(count, 1), 0.0)


def _near_fov_edge(pair: RegisteredPair) -> list[np.ndarray]:
    from ..hypotheses.field_of_view import Params, seen_by

    narrowed = Params(margin_deg=-FOV_EDGE_DEG)
    try:
        return [~seen_by(pair.xyz1, pair.lidars(2), narrowed), ~seen_by(pair.xyz2, pair.lidars(1), narrowed)]
    except HypothesisError:  # a sensor model is missing: its limits are unknown
        return [np.zeros(len(pair.xyz1), bool), np.zeros(len(pair.xyz2), bool)]


def _near_a_sensor(xyz: np.ndarray, pair: RegisteredPair) -> np.ndarray:
    return (np.linalg.norm(xyz, axis=1) < NEAR_SENSOR_M) | (np.linalg.norm(xyz - pair.origin2, axis=1) < NEAR_SENSOR_M)


def depth_edges(pair: RegisteredPair, settings: FieldSettings) -> list[np.ndarray]:
    """Each cloud's points on a depth edge: those ``shadow`` removes on the field's own cells
    (``settings``' grid, channel-aware edges included). Needs no field."""
    from ..hypotheses.shadow import Params, angular_config, shadow

    grid = settings.grid  # the field's own cells, channel-aware edges included
    angular = angular_config(grid.to_config()) if isinstance(grid, SphericalGrid) else None
    keep1, keep2 = shadow(pair, Params(grid=angular))
    return [~keep1, ~keep2]


def _radial(columns: dict[str, np.ndarray]) -> np.ndarray:
    uvw = np.column_stack([columns[c] for c in ("u", "v", "w")])
    sight = 0.5 * (
        np.column_stack([columns[c] for c in ("x1", "y1", "z1")])
        + np.column_stack([columns[c] for c in ("x2", "y2", "z2")])
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        cosine = np.einsum("ij,ij->i", uvw, sight) / (np.linalg.norm(uvw, axis=1) * np.linalg.norm(sight, axis=1))
    return np.abs(cosine) >= math.cos(math.radians(RADIAL_DEG))


def _rigid(columns: dict[str, np.ndarray], valid: np.ndarray, residual: np.ndarray) -> np.ndarray:
    magnitude = np.asarray(columns["magnitude"], dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return valid & (magnitude > 0) & (np.linalg.norm(residual, axis=1) <= RIGID_RESIDUAL_SHARE * magnitude)


def _imbalanced(n1: np.ndarray, n2: np.ndarray) -> np.ndarray:
    low, high = np.minimum(n1, n2), np.maximum(n1, n2)
    return high >= IMBALANCE_RATIO * low
