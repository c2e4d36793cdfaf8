"""Summary statistics of a discrepancy field: sizes, its rigid part, and its directional order.

Everything is computed over the *valid* voxels and returned as plain Python floats (NaN where a
figure is undefined, e.g. no valid voxel; ``summary_json_safe`` turns NaN into null for JSON).

- The rigid part is fitted point-to-plane on the voxel means (``rigid_fit``): each valid
  voxel constrains the motion only along its surface normal, weighted by min(n1, n2) and its
  planarity, robustly (Cauchy IRLS). ``rigid_translation_m`` is t and ``rigid_rotation_deg``
  the angle of R: the correction that would move scan 2 onto scan 1 (a shift of scan 2 by
  +d gives t = -d). ``rigid_information`` is the fit's 6 x 6 information matrix (row-major,
  36 numbers; rx, ry, rz in rad, tx, ty, tz in m, about sensor 1) and ``rigid_unconstrained``
  the directions the scene does not constrain (names; the fit does not move along them, so
  t and R hold 0 there by construction, not by measurement).
  ``rigid_energy_share`` = 1 - sum w |e|^2 / sum w |v|^2 over valid voxels, w = min(n1, n2),
  e the residual vector ``rigid_fit.voxel_residuals`` (the field vector minus what the rigid
  part predicts the voxel mean to see: the normal part on a plane): near 1 when a
  registration error explains the field, low for a scale error or local disagreements.
- ``mean_resultant_length`` = |sum w u/|u|| / sum w: 1 when all vectors point the same way,
  about 1/sqrt(voxels) for random directions.
- ``voxels_significant``: valid voxels with |z| >= ``z_min`` (``significance``);
  ``p_direction``, ``p_coherence`` and ``verdict``: is the field random (``randomness``);
  ``field_energy`` = sum min(n1, n2) |v|^2 and, when the field carries tag columns,
  ``energy_share_{tag}`` for each tag (``tags``).
- ``elevation_edges_deg``, ``azimuth_edges_deg``, ``binning`` and ``binning_warning`` (from
  ``analyse_field``): the grid's edges the pair's field used, why, and a warning when its
  points cluster on an edge (``field.channels``).
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext

import numpy as np

from ..defaults import default
from ..field.channels import pair_binning
from ..field.grid import FieldSettings
from ..field.kernel import NORMAL_READ_COLUMN, SURFACE_COLUMNS, WHITENED_COLUMNS
from ..field.pair_field import pair_field
from ..field.rigid_fit import RigidFit, field_rigid_part
from ..pair import RegisteredPair
from ..poses import weighted_rigid_transform  # noqa: F401 (re-exported: the tests' Kabsch)
from ..threads import usable_threads
from .randomness import neighbour_pairs, randomness_tests
from .tags import depth_edges, energy_shares, voxel_energy, voxel_tags

STATISTIC_KEYS = (
    "voxels",
    "voxels_valid",
    "max_magnitude",
    "mean_magnitude",
    "rms_magnitude",
    "p95_magnitude",
    "paper_max_metric",
    "rigid_translation_m",
    "rigid_rotation_deg",
    "rigid_energy_share",
    "rigid_information",
    "rigid_unconstrained",
    "mean_resultant_length",
    "voxels_significant",
    "share_significant",
    "p_direction",
    "p_coherence",
    "verdict",
    "field_energy",
)


def analyse_field(pair: RegisteredPair, settings: FieldSettings) -> tuple[dict[str, np.ndarray], dict]:
    """The field of a pair (``pair_field``) with its tag columns, and its statistics (with the
    edges used and why). Where more than one core is usable (``usable_threads``, as for the
    candidates), the depth edges, which need no field, are found by a second thread meanwhile."""
    binning = pair_binning(settings, pair)
    with ThreadPoolExecutor(1) if usable_threads() > 1 else nullcontext() as pool:
        on_edge = None if pool is None else pool.submit(depth_edges, pair, binning.settings)
        columns, binning, ids = pair_field(pair, settings, binning)
        rigid = field_rigid_part(columns)  # fitted once: the tags and the statistics both read it
        on_edge = None if on_edge is None else on_edge.result()
    columns.update(voxel_tags(columns, pair, binning.settings, ids, rigid, on_edge))
    return columns, {**field_statistics(columns, binning.settings, rigid), **binning.statistics()}


def field_statistics(
    columns: dict[str, np.ndarray],
    settings: FieldSettings | None = None,
    rigid: tuple[RigidFit, np.ndarray] | None = None,
) -> dict:
    """The summary figures of a field (the columns of ``field.discrepancy_field``).

    ``settings`` gives ``z_min`` (default 3) and the grid whose neighbours the coherence test
    uses; without it ``p_coherence`` is NaN and the verdict rests on the directions alone.
    ``rigid``: the field's ``field_rigid_part``, when the caller has it.
    """
    valid = np.asarray(columns["valid"], dtype=bool)
    uvw = np.column_stack([columns[c][valid] for c in ("u", "v", "w")]).astype(np.float64)
    magnitude = np.asarray(columns["magnitude"], dtype=np.float64)[valid]
    weight = np.minimum(columns["n1"][valid], columns["n2"][valid]).astype(np.float64)

    stats: dict = {"voxels": int(len(valid)), "voxels_valid": int(valid.sum())}
    if magnitude.size:
        stats["max_magnitude"] = float(magnitude.max())
        stats["mean_magnitude"] = float(magnitude.mean())
        stats["rms_magnitude"] = float(np.sqrt(np.mean(magnitude**2)))
        stats["p95_magnitude"] = float(np.percentile(magnitude, 95))
        stats["paper_max_metric"] = float(np.linalg.norm(np.abs(uvw).max(axis=0)))
    else:
        for key in ("max_magnitude", "mean_magnitude", "rms_magnitude", "p95_magnitude", "paper_max_metric"):
            stats[key] = math.nan
    fit, residual = rigid or field_rigid_part(columns)
    stats["rigid_translation_m"] = [float(c) for c in fit.translation]
    stats["rigid_rotation_deg"] = fit.rotation_deg
    stats["rigid_energy_share"] = rigid_energy_share(uvw, residual[valid], weight)
    stats["rigid_information"] = [float(c) for c in fit.information.ravel()]
    stats["rigid_unconstrained"] = list(fit.unconstrained)
    stats["mean_resultant_length"] = mean_resultant_length(uvw, weight)
    z_min = default("grid", "z_min") if settings is None else settings.z_min
    significant = int(np.count_nonzero(np.abs(columns["z"][valid]) >= z_min))
    stats["voxels_significant"] = significant
    stats["share_significant"] = significant / magnitude.size if magnitude.size else math.nan
    if settings is None:
        neighbours = (np.zeros(0, np.int64), np.zeros(0, np.int64))
    else:
        neighbours = neighbour_pairs(settings.grid, np.asarray(columns["voxel"])[valid])
    whitened = np.column_stack([columns[c][valid] for c in WHITENED_COLUMNS]).astype(np.float64)
    stats.update(randomness_tests(whitened, neighbours, tests_axes(columns, valid)))
    stats["field_energy"] = float(voxel_energy(columns).sum())
    stats.update(energy_shares(columns))
    return stats


def tests_axes(columns: dict[str, np.ndarray], valid: np.ndarray) -> np.ndarray | None:
    """(M, 3): the normal of each valid voxel the randomness tests read along it alone
    (``read_normal``, ``significance``), NaN for the others; None for a field without that
    column (written before it: its whitened vectors are whole)."""
    if NORMAL_READ_COLUMN not in columns:
        return None
    read = np.asarray(columns[NORMAL_READ_COLUMN], dtype=bool)[valid]
    normal = np.column_stack([np.asarray(columns[c], dtype=np.float64)[valid] for c in SURFACE_COLUMNS[:3]])
    return np.where(read[:, None], normal, np.nan)


def rigid_energy_share(vectors: np.ndarray, residual: np.ndarray, weight: np.ndarray) -> float:
    """1 - weighted residual energy left by the rigid part / weighted field energy (NaN without
    a fit or without energy)."""
    energy = float(weight @ np.sum(vectors**2, axis=1))
    if not energy > 0 or not np.all(np.isfinite(residual)):
        return math.nan
    return float(1.0 - (weight @ np.sum(residual**2, axis=1)) / energy)


def mean_resultant_length(vectors: np.ndarray, weight: np.ndarray) -> float:
    """Weighted length of the mean unit vector (zero vectors ignored); NaN without any."""
    length = np.linalg.norm(vectors, axis=1)
    keep = (length > 0) & (weight > 0)
    if not keep.any():
        return math.nan
    units = vectors[keep] / length[keep, None]
    return float(np.linalg.norm(weight[keep] @ units) / weight[keep].sum())


def summary_json_safe(value):
    """``value`` with every NaN/inf float replaced by None (strict JSON has no NaN)."""
    if isinstance(value, dict):
        return {k: summary_json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [summary_json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
