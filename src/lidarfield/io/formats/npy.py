"""NumPy ``.npy`` scans: an (N, 3+) numeric array ``x, y, z [, intensity, ...]`` or a structured
array with fields ``x, y, z`` and any numeric attribute fields."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import InputError
from ...scan import Scan
from ...sensors.models import SensorModel
from ..atomic import atomic_path
from ..rows import scan_from_rows


def read_npy(path: Path, index: int = 0, sensor: SensorModel | None = None) -> Scan:
    try:
        array = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as e:
        raise InputError(f"not a readable .npy array ({e})", path) from None
    if array.dtype.names:
        return _structured(array, path, sensor)
    if array.ndim != 2 or array.shape[1] < 3 or not np.issubdtype(array.dtype, np.number):
        raise InputError(f"needs a numeric N x 3+ array (x, y, z, ...), found shape {array.shape} {array.dtype}", path)
    attributes = {}
    if array.shape[1] > 3:
        attributes["intensity"] = array[:, 3]
    for column in range(4, array.shape[1]):
        attributes[f"column{column + 1}"] = array[:, column]
    return scan_from_rows(array[:, :3], attributes, path, sensor=sensor)


def write_npy(scan: Scan, path: Path) -> None:
    """A structured array with fields x, y, z (float64) and every attribute in its own dtype."""
    dtype = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    dtype += [(name, np.asarray(values).dtype) for name, values in scan.attributes.items()]
    array = np.empty(len(scan), dtype=dtype)
    for axis, name in enumerate("xyz"):
        array[name] = scan.xyz[:, axis]
    for name, values in scan.attributes.items():
        array[name] = values
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as stream:  # a file object: np.save would append .npy to the name
            np.save(stream, array, allow_pickle=False)


def _structured(array: np.ndarray, path: Path, sensor: SensorModel | None) -> Scan:
    missing = [a for a in "xyz" if a not in array.dtype.names]
    if missing or array.ndim != 1:
        raise InputError(f"structured array needs 1-D fields x, y, z; has {list(array.dtype.names)}", path)
    xyz = np.column_stack([array[a] for a in "xyz"])
    attributes = {
        name: array[name]
        for name in array.dtype.names
        if name not in ("x", "y", "z") and np.issubdtype(array.dtype[name], np.number) and not array.dtype[name].shape
    }
    return scan_from_rows(xyz, attributes, path, sensor=sensor)
