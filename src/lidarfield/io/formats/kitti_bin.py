"""KITTI-style binary scans: little-endian float32 rows ``x, y, z, intensity``, no header."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import InputError
from ...scan import Scan
from ...sensors.models import SensorModel
from ..atomic import atomic_path
from ..rows import scan_from_rows

_ROW = np.dtype("<f4")
_COLUMNS = 4


def read_bin(path: Path, index: int = 0, sensor: SensorModel | None = None) -> Scan:
    size = path.stat().st_size
    row_bytes = _COLUMNS * _ROW.itemsize
    if size % row_bytes:
        raise InputError(
            f"size {size} bytes is not a whole number of {row_bytes}-byte rows (float32 x, y, z, intensity)",
            path,
        )
    values = np.fromfile(path, dtype=_ROW).reshape(-1, _COLUMNS)
    return scan_from_rows(values[:, :3], {"intensity": values[:, 3]}, path, sensor=sensor)


def write_bin(scan: Scan, path: Path) -> None:
    """float32 rows; intensity is 0 when the scan has none (the layout has no way to omit it)."""
    values = np.zeros((len(scan), _COLUMNS), dtype=_ROW)
    values[:, :3] = scan.xyz
    if "intensity" in scan.attributes:
        values[:, 3] = scan.attributes["intensity"]
    with atomic_path(path) as tmp:
        values.tofile(tmp)
