"""PCL ``.pcd`` scans: ASCII, binary and binary_compressed (LZF) data; fields x, y, z plus
any scalar fields (``intensity``, ``ring``, ``time``, ...) kept as attributes.

Written as binary PCD with float64 coordinates (exact round trip) and each attribute in its
own type. The VIEWPOINT line is neither interpreted nor written (identity).
"""

from __future__ import annotations

import io
import struct
from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import InputError
from ...scan import Scan
from ...sensors.models import SensorModel
from ..atomic import atomic_path
from ..rows import scan_from_rows

_MAX_HEADER_LINES = 64


def read_pcd(path: Path, index: int = 0, sensor: SensorModel | None = None) -> Scan:
    raw = path.read_bytes()
    header, offset = _parse_header(raw, path)
    fields, dtype = _row_dtype(header, path)
    points = _points(header, path)
    kind = header["DATA"][0].lower()
    if kind == "ascii":
        rows = _ascii_rows(raw[offset:], dtype, points, path)
    elif kind == "binary":
        rows = _binary_rows(raw[offset:], dtype, points, path)
    elif kind == "binary_compressed":
        rows = _compressed_rows(raw[offset:], dtype, points, path)
    else:
        raise InputError(f"unknown PCD DATA kind {kind!r} (ascii, binary, binary_compressed)", path)
    missing = [a for a in "xyz" if a not in fields]
    if missing:
        raise InputError(f"PCD has no field(s) {missing}; fields are {fields}", path)
    xyz = np.column_stack([rows[a].astype(np.float64) for a in "xyz"])
    attributes = {
        name: rows[name].copy()
        for name in fields
        if name not in ("x", "y", "z") and not name.startswith("_") and rows.dtype[name].shape == ()
    }
    return scan_from_rows(xyz, attributes, path, sensor=sensor)


def write_pcd(scan: Scan, path: Path, data: str = "binary") -> None:
    """Binary (default) or ASCII PCD v0.7; x, y, z as float64, attributes in their own type."""
    columns = {"x": scan.xyz[:, 0], "y": scan.xyz[:, 1], "z": scan.xyz[:, 2]}
    columns.update({name: np.asarray(values) for name, values in scan.attributes.items()})
    types = {name: _pcd_type(values.dtype, name) for name, values in columns.items()}
    n = len(scan)
    header = "\n".join(
        [
            "# .PCD v0.7 - Point Cloud Data file format (lidarfield)",
            "VERSION 0.7",
            "FIELDS " + " ".join(columns),
            "SIZE " + " ".join(str(dtype.itemsize) for dtype in types.values()),
            "TYPE " + " ".join(_TYPE_LETTER[dtype.kind] for dtype in types.values()),
            "COUNT " + " ".join("1" for _ in columns),
            f"WIDTH {n}",
            "HEIGHT 1",
            "VIEWPOINT 0 0 0 1 0 0 0",
            f"POINTS {n}",
            f"DATA {data}",
            "",
        ]
    )
    rows = np.empty(n, dtype=list(types.items()))
    for name, values in columns.items():
        rows[name] = values
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as stream:
            stream.write(header.encode("ascii"))
            if data == "binary":
                stream.write(rows.tobytes())
            elif data == "ascii":
                frame = pd.DataFrame({name: rows[name] for name in columns})
                frame.to_csv(stream, sep=" ", header=False, index=False, float_format="%.17g")
            else:
                raise ValueError(f"PCD data kind {data!r} cannot be written (binary, ascii)")


# --- header ------------------------------------------------------------------------------
_TYPE_LETTER = {"f": "F", "i": "I", "u": "U", "b": "U"}


def _pcd_type(dtype: np.dtype, name: str) -> np.dtype:
    if dtype.kind == "b":
        return np.dtype("u1")
    if dtype.kind not in "fiu":
        raise InputError(f"attribute {name!r} of type {dtype} cannot be written to PCD")
    return dtype.newbyteorder("<")


def _parse_header(raw: bytes, path: Path) -> tuple[dict[str, list[str]], int]:
    header: dict[str, list[str]] = {}
    offset = 0
    for _ in range(_MAX_HEADER_LINES):
        end = raw.find(b"\n", offset)
        if end < 0:
            break
        line = raw[offset:end].decode("ascii", errors="replace").strip()
        offset = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        header[key.upper()] = values
        if key.upper() == "DATA":
            return header, offset
    raise InputError("not a PCD file: no DATA line in the header", path)


def _row_dtype(header: dict[str, list[str]], path: Path) -> tuple[list[str], np.dtype]:
    try:
        fields = header["FIELDS"]
        sizes = [int(s) for s in header["SIZE"]]
        types = [t.upper() for t in header["TYPE"]]
        counts = [int(c) for c in header.get("COUNT", ["1"] * len(fields))]
    except (KeyError, ValueError) as e:
        raise InputError(f"bad PCD header ({e})", path) from None
    if not len(fields) == len(sizes) == len(types) == len(counts):
        raise InputError("bad PCD header: FIELDS, SIZE, TYPE and COUNT differ in length", path)
    parts = []
    for name, size, kind, count in zip(fields, sizes, types, counts):
        if kind not in ("F", "I", "U") or size not in (1, 2, 4, 8):
            raise InputError(f"bad PCD header: field {name!r} has TYPE {kind} SIZE {size}", path)
        base = np.dtype(f"<{kind.lower()}{size}")
        parts.append((name, base) if count == 1 else (name, base, (count,)))
    names = [p[0] for p in parts]
    if len(set(names)) != len(names):  # PCL pads with repeated '_' fields: make them unique
        parts = [(f"_{i}" if p[0] == "_" else p[0], *p[1:]) for i, p in enumerate(parts)]
        names = [p[0] for p in parts]
    return names, np.dtype(parts)


def _points(header: dict[str, list[str]], path: Path) -> int:
    try:
        if "POINTS" in header:
            return int(header["POINTS"][0])
        return int(header["WIDTH"][0]) * int(header.get("HEIGHT", ["1"])[0])
    except (KeyError, ValueError, IndexError):
        raise InputError("bad PCD header: no POINTS (or WIDTH x HEIGHT)", path) from None


# --- data ----------------------------------------------------------------------------------
def _binary_rows(body: bytes, dtype: np.dtype, points: int, path: Path) -> np.ndarray:
    need = points * dtype.itemsize
    if len(body) < need:
        raise InputError(
            f"truncated binary PCD: {len(body)} bytes of point data, POINTS {points} x {dtype.itemsize}-byte rows "
            f"needs {need}",
            path,
        )
    return np.frombuffer(body, dtype=dtype, count=points)


def _ascii_rows(body: bytes, dtype: np.dtype, points: int, path: Path) -> np.ndarray:
    widths = [_width(dtype[name]) for name in dtype.names]
    try:
        table = pd.read_csv(io.BytesIO(body), sep=r"\s+", header=None, comment="#").to_numpy(np.float64)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, ValueError) as e:
        raise InputError(f"bad ASCII PCD data ({str(e).strip() or 'no rows'})", path) from None
    if table.shape != (points, sum(widths)):
        raise InputError(f"ASCII PCD data has shape {table.shape}, header says {points} x {sum(widths)}", path)
    rows = np.empty(points, dtype=dtype)
    column = 0
    for name, width in zip(dtype.names, widths):
        values = table[:, column : column + width]
        rows[name] = values[:, 0] if width == 1 else values
        column += width
    return rows


def _compressed_rows(body: bytes, dtype: np.dtype, points: int, path: Path) -> np.ndarray:
    if len(body) < 8:
        raise InputError("truncated binary_compressed PCD: no size words", path)
    compressed_size, size = struct.unpack("<II", body[:8])
    if len(body) < 8 + compressed_size:
        raise InputError(f"truncated binary_compressed PCD: {len(body) - 8} of {compressed_size} bytes", path)
    if size != points * dtype.itemsize:
        raise InputError(
            f"binary_compressed PCD holds {size} bytes, POINTS x row size is {points * dtype.itemsize}", path
        )
    try:
        plain = lzf_decompress(body[8 : 8 + compressed_size], size)
    except (IndexError, ValueError) as e:
        raise InputError(f"corrupt binary_compressed PCD data ({e})", path) from None
    # The decompressed data is column-major: all values of field 1, then field 2, ...
    rows = np.empty(points, dtype=dtype)
    start = 0
    for name in dtype.names:
        field = dtype[name]
        values = np.frombuffer(plain, dtype=field.base, count=points * _width(field), offset=start)
        rows[name] = values.reshape((points, *field.shape))
        start += points * field.itemsize
    return rows


def _width(field: np.dtype) -> int:
    """Values per point of a field (its COUNT)."""
    return int(np.prod(field.shape)) if field.shape else 1


def lzf_decompress(data: bytes, size: int) -> bytes:
    """LZF (liblzf) decompression, as PCL uses for binary_compressed data."""
    out = bytearray(size)
    i = o = 0
    while i < len(data):
        ctrl = data[i]
        i += 1
        if ctrl < 32:  # literal run of ctrl + 1 bytes
            length = ctrl + 1
            out[o : o + length] = data[i : i + length]
            i += length
        else:  # back reference
            length = ctrl >> 5
            if length == 7:
                length += data[i]
                i += 1
            ref = o - ((ctrl & 0x1F) << 8) - data[i] - 1
            i += 1
            length += 2
            if ref < 0:
                raise ValueError("back reference before the start")
            distance = o - ref
            if distance >= length:
                out[o : o + length] = out[ref : ref + length]
            else:  # overlapping copy repeats the last `distance` bytes
                pattern = bytes(out[ref:o])
                out[o : o + length] = (pattern * (length // distance + 1))[:length]
        o += length
    if o != size:
        raise ValueError(f"decompressed {o} bytes, expected {size}")
    return bytes(out)
