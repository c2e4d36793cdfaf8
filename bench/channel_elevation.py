"""Measurement: where one channel's elevation offset goes in the field (issue 36, docs/diagnosis.md).

For base pairs of the fault zoo from one place, scan 2's channel nearest -5 deg reported 1 deg
higher (the zoo's ``channel_elevation`` at ``obvious``): how many points that channel has, how far
they moved, how many voxels of the stage-0 field hold them and what share of those voxels' points
they are, and what the voxels' vectors are in units of their noise (whitened energy, about 3 for
noise) against the rest of the field; and the stage-0 verdict.

Run: ``python bench/channel_elevation.py [--base TEXT ...] [--deg D] [--points N]``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from helpers.fault_zoo import (  # noqa: E402
    Case,
    bases,
    default_study,
    faulted_channel_mask,
    faulted_pair,
    load_base,
)
from lidarfield.analysis.field_stats import field_statistics  # noqa: E402
from lidarfield.analysis.tags import whitened_energy  # noqa: E402
from lidarfield.field.pair_field import pair_field  # noqa: E402


def measure(name: str, level: str, points: int) -> dict:
    base = load_base(name, points)
    pair = faulted_pair(base, Case(name, "channel_elevation", level))
    clean = faulted_pair(base, Case(name, "none", ""))
    moved = faulted_channel_mask(base.scan2)
    settings = default_study().grid
    columns, _, ids = pair_field(pair, settings)
    clean_columns, _, _ = pair_field(clean, settings)
    stats = field_statistics(columns, settings)
    clean_stats = field_statistics(clean_columns, settings)
    valid = np.asarray(columns["valid"], bool)
    voxel = np.asarray(columns["voxel"], np.int64)
    energy = whitened_energy(columns)
    hit = np.isin(voxel, np.unique(ids[1][moved])) & valid
    in_valid = np.isin(ids[1][moved], voxel[valid])
    share = np.zeros(len(voxel))
    counts = np.bincount(np.searchsorted(voxel, ids[1][moved][in_valid]), minlength=len(voxel))
    share[hit] = counts[hit] / np.asarray(columns["n2"])[hit]
    lift = np.linalg.norm(pair.xyz2 - clean.xyz2, axis=1)[moved]
    return {
        "base": name,
        "points2": len(pair.xyz2),
        "channel_points": int(moved.sum()),
        "channel_share": moved.mean(),
        "channel_in_valid": in_valid.mean(),
        "lift_median_m": float(np.median(lift)),
        "voxels_valid": int(valid.sum()),
        "voxels_hit": int(hit.sum()),
        "channel_share_of_hit": float(np.median(share[hit])) if hit.any() else np.nan,
        "energy_hit": float(energy[hit].mean()) if hit.any() else np.nan,
        "energy_rest": float(energy[valid & ~hit].mean()),
        "energy_hit_share": float(energy[hit].sum() / energy.sum()),
        "significant_hit": int((np.abs(np.asarray(columns["z"])[hit]) >= settings.z_min).sum()),
        "magnitude_hit_m": float(np.median(np.asarray(columns["magnitude"])[hit])),
        "se_hit_m": float(np.median(np.asarray(columns["se"])[hit])),
        "clean_magnitude_hit_m": float(np.median(_at(clean_columns, voxel[hit], "magnitude"))),
        "verdict0": stats["verdict"],
        "p_direction": stats["p_direction"],
        "p_coherence": stats["p_coherence"],
        "clean_verdict0": clean_stats["verdict"],
        "clean_p_direction": clean_stats["p_direction"],
        "clean_p_coherence": clean_stats["p_coherence"],
    }


def _at(columns: dict, voxels: np.ndarray, column: str) -> np.ndarray:
    """``column`` of the field ``columns`` at the given voxels (NaN where it has none valid)."""
    voxel = np.asarray(columns["voxel"], np.int64)
    row = np.clip(np.searchsorted(voxel, voxels), 0, len(voxel) - 1)
    found = (voxel[row] == voxels) & np.asarray(columns["valid"], bool)[row]
    return np.where(found, np.asarray(columns[column], np.float64)[row], np.nan)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", action="append", default=[])
    parser.add_argument("--level", default="obvious")
    parser.add_argument("--points", type=int, default=20_000)
    args = parser.parse_args()
    names = [n for n in bases() if "channel_elevation" in bases()[n].faults and any(t in n for t in args.base or [""])]
    import pandas as pd

    pd.set_option("display.width", 250)
    rows = [measure(n, args.level, args.points) for n in names]
    print(pd.DataFrame(rows).to_string(float_format=lambda v: f"{v:.3g}"))


if __name__ == "__main__":
    main()
