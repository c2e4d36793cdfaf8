"""nuScenes lidar sweeps (``samples/LIDAR_TOP/*.pcd.bin``, ``sweeps/LIDAR_TOP/*.pcd.bin``):
little-endian float32 rows ``x, y, z, intensity, ring``, no header, in the LIDAR_TOP sensor
frame. The extension says ``.bin`` (a KITTI file reads 4 columns): the dataset reader names
the format, or give ``format: nuscenes``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import InputError
from ...scan import Scan
from ...sensors.models import SensorModel
from ..rows import scan_from_rows

_ROW = np.dtype("<f4")
_COLUMNS = 5
_MAX_RING = np.iinfo(np.uint16).max


def read_nuscenes(path: Path, index: int = 0, sensor: SensorModel | None = None) -> Scan:
    size = path.stat().st_size
    row_bytes = _COLUMNS * _ROW.itemsize
    if size % row_bytes:
        raise InputError(
            f"size {size} bytes is not a whole number of {row_bytes}-byte rows "
            "(nuScenes: float32 x, y, z, intensity, ring)",
            path,
        )
    values = np.fromfile(path, dtype=_ROW).reshape(-1, _COLUMNS)
    valid = np.isfinite(values[:, :3]).all(axis=1)
    ring = values[valid, 4]
    if len(ring) and not (np.isfinite(ring).all() and (ring >= 0).all() and (ring <= _MAX_RING).all()):
        raise InputError("column 5 (ring) holds values that are not ring indices: not a nuScenes lidar file?", path)
    rings = np.zeros(len(values), dtype=np.uint16)
    rings[valid] = np.rint(ring).astype(np.uint16)
    return scan_from_rows(values[:, :3], {"intensity": values[:, 3], "ring": rings}, path, sensor=sensor)
