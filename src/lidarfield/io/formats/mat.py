"""Organised scans in a MATLAB v5 file: a cell array (``pc`` in the ExpD data) of
rings x columns x 3 arrays, NaN where there was no return. The ring of a point is its row.

``path#k`` selects cell k (0-based, column-major as MATLAB numbers cells); a file holding one
rings x columns x 3 numeric array is one scan.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
import scipy.io

from ...errors import InputError
from ...scan import Scan
from ...sensors.models import SensorModel
from ..rows import file_key, scan_from_rows


def count_mat(path: Path) -> int:
    return len(_organised_scans(path))


def read_mat(path: Path, index: int = 0, sensor: SensorModel | None = None) -> Scan:
    image = _organised_scans(path)[index]
    rings, columns, _ = image.shape
    ring = np.repeat(np.arange(rings, dtype=np.uint16), columns)
    scan = scan_from_rows(image.reshape(-1, 3), {"ring": ring}, path, sensor=sensor)
    scan.source = f"{path}#{index}"
    return scan


def _organised_scans(path: Path) -> list[np.ndarray]:
    return _load(*file_key(path))


@lru_cache(maxsize=4)
def _load(name: str, size: int, mtime_ns: int) -> list[np.ndarray]:
    """The organised arrays of the file's one cell array (or one numeric array); cached because
    a sequence reads the same file once per scan."""
    path = Path(name)
    try:
        variables = {k: v for k, v in scipy.io.loadmat(path).items() if not k.startswith("__")}
    except (ValueError, TypeError, OSError, NotImplementedError) as e:
        raise InputError(f"not a readable MATLAB v5 file ({e})", path) from None
    if "pc" in variables:
        variables = {"pc": variables["pc"]}
    if len(variables) != 1:
        raise InputError(f"expected one variable (a cell array of scans), found {sorted(variables)}", path)
    ((name, value),) = variables.items()
    cells = list(value.ravel(order="F")) if value.dtype == object else [value]
    for k, cell in enumerate(cells):
        if not (isinstance(cell, np.ndarray) and cell.ndim == 3 and cell.shape[2] == 3 and cell.dtype.kind in "fiu"):
            shape = getattr(cell, "shape", type(cell).__name__)
            raise InputError(f"{name}{{{k + 1}}} is not a rings x columns x 3 numeric array (found {shape})", path)
    return [np.asarray(cell, dtype=np.float64) for cell in cells]
