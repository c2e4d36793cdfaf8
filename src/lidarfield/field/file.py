"""The field file (``field.parquet``): the kernel's columns, with the grid, the validity rules
and the field's statistics in its metadata. The surface columns (``nx, ny, nz, planarity``)
are optional on reading: files written before them lack them."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.parquet_table import read_table, write_table
from .grid import FieldSettings
from .kernel import GRID_COLUMNS, VALUE_COLUMNS


def write_field(path: str | Path, columns: dict[str, np.ndarray], meta: dict | None = None) -> None:
    """Write the field Parquet (atomically); ``meta`` goes under the ``lidarfield`` key."""
    write_table(path, columns, meta)


def read_field(path: str | Path) -> tuple[dict[str, np.ndarray], dict]:
    """Read a field Parquet: its columns and its metadata; InputError if columns are missing."""
    columns, meta = read_table(path, required=("voxel", *VALUE_COLUMNS))
    kind = "cartesian" if "ix" in columns else "spherical"
    missing = [c for c in GRID_COLUMNS[kind] if c not in columns]
    if missing:
        raise InputError(f"field Parquet lacks grid column(s) {missing}", path)
    return columns, meta


def field_meta(settings: FieldSettings, statistics: dict, **extra) -> dict:
    """The field Parquet metadata of the layout: grid config (with the edges the field used,
    where the statistics give them: ``field.channels``), validity rules, statistics, plus
    ``extra`` (e.g. ``stage=...``)."""
    grid = settings.grid
    if statistics.get("elevation_edges_deg") is not None:  # the pair's channel-aware edges
        grid = grid.with_edges(statistics["elevation_edges_deg"], statistics["azimuth_edges_deg"])
    return {
        "grid": grid.to_config(),
        "min_points": int(settings.min_points),
        "max_component_m": settings.max_component_m,
        "z_min": float(settings.z_min),
        "statistics": statistics,
        **extra,
    }
