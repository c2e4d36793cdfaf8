"""What every reader does last: drop rows without valid coordinates, count them, refuse empty scans."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..scan import Scan
from ..sensors.models import SensorModel


def scan_from_rows(
    xyz: np.ndarray,
    attributes: dict[str, np.ndarray],
    path: str | Path,
    *,
    sensor: SensorModel | None = None,
    pose: np.ndarray | None = None,
    dropped_before: int = 0,
) -> Scan:
    """A Scan of the rows whose three coordinates are finite; the others are counted as dropped.

    Raises ``InputError`` when the file holds no rows, or no row with valid coordinates.
    """
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    if len(xyz) == 0:
        raise InputError("empty scan: the file holds no points", path)
    valid = np.isfinite(xyz).all(axis=1)
    n_valid = int(valid.sum())
    if n_valid == 0:
        raise InputError(f"empty scan: all {len(xyz)} rows have NaN or infinite coordinates", path)
    if n_valid < len(xyz):
        xyz = xyz[valid]
        attributes = {name: np.asarray(values)[valid] for name, values in attributes.items()}
    return Scan(xyz, attributes, sensor, pose, str(path), dropped_before + len(valid) - n_valid)


def ring_major_rings(n_rows: int, sensor: SensorModel | None) -> np.ndarray | None:
    """Ring index of each row of an organised, ring-major file of ``sensor.channels`` x N rows.

    The ring is the row index of the organised image (row 0 is the first block of the file),
    as in the MATLAB arrays of the source data. None when the layout does not fit.
    """
    if sensor is None or n_rows == 0 or n_rows % sensor.channels:
        return None
    return np.repeat(np.arange(sensor.channels, dtype=np.uint16), n_rows // sensor.channels)


def file_key(path: Path) -> tuple[str, int, int]:
    """(resolved path, size, modification time): a cache key that changes when the file does."""
    stat = path.stat()
    return str(path.resolve()), stat.st_size, stat.st_mtime_ns
