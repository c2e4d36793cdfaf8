"""Text scans: whitespace-separated columns (``.txt``, ``.xyz``) and CSV with a header.

Whitespace text: ``x y z [intensity [more ...]]`` per line, no header, ``#`` comments, and
``NaN NaN NaN`` rows for missing returns (the format of the ExpD VLP-16 files). When a sensor is
given and the file is organised (it keeps its no-return rows and has ``channels`` x N lines),
each row's ring is its block index, ring-major.

CSV: a header naming ``x, y, z`` (any case) and optional attribute columns (``intensity``,
``ring``, ``time`` or others); every numeric column other than x, y, z is kept.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import InputError
from ...scan import KNOWN_ATTRIBUTES, Scan
from ...sensors.models import SensorModel
from ..atomic import atomic_path
from ..rows import ring_major_rings, scan_from_rows

_EXACT = "%.17g"  # enough digits for float64 to round-trip exactly


def read_txt(path: Path, index: int = 0, sensor: SensorModel | None = None) -> Scan:
    table = _read_frame(path, sep=r"\s+", header=None, comment="#")
    if table.shape[1] < 3:
        raise InputError(f"needs at least 3 columns (x y z), found {table.shape[1]}", path)
    values = _numeric(table, path)
    attributes = {}
    if values.shape[1] > 3:
        attributes["intensity"] = values[:, 3]
    for column in range(4, values.shape[1]):
        attributes[f"column{column + 1}"] = values[:, column]
    xyz = values[:, :3]
    organised = not np.isfinite(xyz).all()
    rings = ring_major_rings(len(xyz), sensor) if organised else None
    if rings is not None:
        attributes["ring"] = rings
    return scan_from_rows(xyz, attributes, path, sensor=sensor)


def write_txt(scan: Scan, path: Path) -> None:
    """``x y z`` (plus ``intensity`` when present) per line, at full float64 precision."""
    columns = [scan.xyz]
    if "intensity" in scan.attributes:
        columns.append(np.asarray(scan.attributes["intensity"], dtype=np.float64)[:, None])
    with atomic_path(path) as tmp:
        np.savetxt(tmp, np.hstack(columns), fmt=_EXACT)


def read_csv(path: Path, index: int = 0, sensor: SensorModel | None = None) -> Scan:
    table = _read_frame(path, comment="#")
    by_lower = {str(name).strip().lower(): name for name in table.columns}
    missing = [axis for axis in "xyz" if axis not in by_lower]
    if missing:
        raise InputError(
            f"CSV header must name columns x, y, z; missing {missing}, header is {list(map(str, table.columns))}",
            path,
        )
    xyz = _numeric(table[[by_lower[a] for a in "xyz"]], path)
    attributes = {}
    for lower, name in by_lower.items():
        if lower in ("x", "y", "z") or not pd.api.types.is_numeric_dtype(table[name]):
            continue
        attributes[lower if lower in KNOWN_ATTRIBUTES else str(name).strip()] = table[name].to_numpy()
    return scan_from_rows(xyz, attributes, path, sensor=sensor)


def write_csv(scan: Scan, path: Path) -> None:
    """A header line ``x,y,z,<attributes>`` and one row per point (float64 written exactly)."""
    frame = pd.DataFrame({"x": scan.xyz[:, 0], "y": scan.xyz[:, 1], "z": scan.xyz[:, 2], **scan.attributes})
    with atomic_path(path) as tmp:
        frame.to_csv(tmp, index=False, float_format=_EXACT)


def _read_frame(path: Path, **options) -> pd.DataFrame:
    try:
        return pd.read_csv(path, **options)
    except pd.errors.EmptyDataError:
        raise InputError("empty scan: the file holds no points", path) from None
    except (pd.errors.ParserError, UnicodeDecodeError, ValueError) as e:
        raise InputError(f"not a readable text scan ({str(e).strip()})", path) from None


def _numeric(table: pd.DataFrame, path: Path) -> np.ndarray:
    try:
        return table.to_numpy(dtype=np.float64)
    except (ValueError, TypeError):
        raise InputError("non-numeric values where coordinates were expected", path) from None
