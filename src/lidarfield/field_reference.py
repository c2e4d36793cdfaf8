"""A plain reference for the field kernel: pandas groupby over the voxel ids of ``grid.assign``.

Slow and obvious on purpose: the tests check ``field.discrepancy_field`` against it to 1e-9 and
the benchmark times the kernel against it.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .grid import FieldSettings


def discrepancy_field_reference(
    xyz1: np.ndarray, xyz2: np.ndarray, settings: FieldSettings, origin=(0.0, 0.0, 0.0)
) -> dict[str, np.ndarray]:
    """Same contract as ``field.discrepancy_field``, computed with a pandas groupby."""
    grid = settings.grid
    return field_from_voxel_ids_reference(grid.assign(xyz1, origin), xyz1, grid.assign(xyz2, origin), xyz2, settings)


def field_from_voxel_ids_reference(
    ids1: np.ndarray, xyz1: np.ndarray, ids2: np.ndarray, xyz2: np.ndarray, settings: FieldSettings
) -> dict[str, np.ndarray]:
    """Same contract as ``field.field_from_voxel_ids``, computed with a pandas groupby."""
    grid = settings.grid
    per_cloud = []
    for k, xyz, ids in ((1, xyz1, ids1), (2, xyz2, ids2)):
        frame = pd.DataFrame(np.asarray(xyz, dtype=np.float64), columns=["x", "y", "z"])
        frame["voxel"] = ids
        frame = frame[frame["voxel"] >= 0]
        grouped = frame.groupby("voxel").agg(
            **{f"n{k}": ("x", "size"), f"x{k}": ("x", "mean"), f"y{k}": ("y", "mean"), f"z{k}": ("z", "mean")}
        )
        per_cloud.append(grouped)
    table = per_cloud[0].join(per_cloud[1], how="outer").sort_index()
    table[["n1", "n2"]] = table[["n1", "n2"]].fillna(0).astype(np.int64)

    valid = (table["n1"] >= settings.min_points) & (table["n2"] >= settings.min_points)
    for out, a, b in (("u", "x2", "x1"), ("v", "y2", "y1"), ("w", "z2", "z1")):
        table[out] = table[a] - table[b]
        if settings.max_component_m is not None:
            valid &= table[out].abs() <= settings.max_component_m
    for out in ("u", "v", "w"):
        table.loc[~valid, out] = np.nan
    table["magnitude"] = np.sqrt(table["u"] ** 2 + table["v"] ** 2 + table["w"] ** 2)
    table["valid"] = valid

    voxel = table.index.to_numpy(dtype=np.int64)
    columns = {"voxel": voxel, **grid.bins(voxel)}
    for name in ("n1", "n2", "x1", "y1", "z1", "x2", "y2", "z2", "u", "v", "w", "magnitude", "valid"):
        columns[name] = table[name].to_numpy()
    return columns
