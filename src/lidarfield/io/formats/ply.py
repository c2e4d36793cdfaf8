"""PLY scans (ASCII, binary little- and big-endian): the ``vertex`` element's x, y, z, and its
other scalar properties as attributes. CloudCompare's ``scalar_`` prefix is dropped, so its
``scalar_intensity`` becomes ``intensity``.

Written as binary little-endian with double coordinates (exact round trip) and each
attribute in its own type.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import InputError
from ...scan import Scan
from ...sensors.models import SensorModel
from ..atomic import atomic_path
from ..rows import scan_from_rows

_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
_NAMES = {code: name for name, code in _TYPES.items() if not name[-1].isdigit()}  # char, uchar, ... double
_ENDIAN = {"binary_little_endian": "<", "binary_big_endian": ">", "ascii": "<"}


@dataclass
class _Element:
    name: str
    count: int
    properties: list[tuple[str, str]]  # (name, numpy type code); list properties have type "list"


def read_ply(path: Path, index: int = 0, sensor: SensorModel | None = None) -> Scan:
    raw = path.read_bytes()
    encoding, elements, offset = _parse_header(raw, path)
    position = next((i for i, e in enumerate(elements) if e.name == "vertex"), None)
    if position is None:
        raise InputError("PLY file has no vertex element", path)
    vertex = elements[position]
    if any(kind == "list" for _, kind in vertex.properties) or any(
        kind == "list" for e in elements[:position] for _, kind in e.properties
    ):
        raise InputError("PLY list properties before or in the vertex element are not supported", path)
    dtype = np.dtype([(name, _ENDIAN[encoding] + kind) for name, kind in vertex.properties])
    if encoding == "ascii":
        skip = sum(e.count for e in elements[:position])
        rows = _ascii_rows(raw[offset:], skip, vertex.count, dtype, path)
    else:
        start = offset + sum(e.count * _fixed_size(e, encoding) for e in elements[:position])
        need = vertex.count * dtype.itemsize
        if len(raw) - start < need:
            raise InputError(
                f"truncated PLY: {len(raw) - start} bytes of vertex data, {vertex.count} vertices need {need}", path
            )
        rows = np.frombuffer(raw, dtype=dtype, count=vertex.count, offset=start)
    names = [name for name, _ in vertex.properties]
    missing = [a for a in "xyz" if a not in names]
    if missing:
        raise InputError(f"PLY vertex has no propert(ies) {missing}; has {names}", path)
    xyz = np.column_stack([rows[a].astype(np.float64) for a in "xyz"])
    attributes = {
        name.removeprefix("scalar_"): rows[name].astype(rows.dtype[name].newbyteorder("="))
        for name in names
        if name not in ("x", "y", "z")
    }
    return scan_from_rows(xyz, attributes, path, sensor=sensor)


def write_ply(scan: Scan, path: Path) -> None:
    """Binary little-endian PLY: double x, y, z and one property per attribute."""
    columns = {"x": scan.xyz[:, 0], "y": scan.xyz[:, 1], "z": scan.xyz[:, 2]}
    columns.update({name: np.asarray(values) for name, values in scan.attributes.items()})
    dtype = np.dtype([(name, _ply_code(values.dtype, name)) for name, values in columns.items()])
    rows = np.empty(len(scan), dtype=dtype)
    for name, values in columns.items():
        rows[name] = values
    lines = ["ply", "format binary_little_endian 1.0", "comment lidarfield scan", f"element vertex {len(scan)}"]
    lines += [f"property {_NAMES[dtype[name].str[1:]]} {name}" for name in dtype.names]
    lines += ["end_header", ""]
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as stream:
            stream.write("\n".join(lines).encode("ascii"))
            stream.write(rows.tobytes())


def _ply_code(dtype: np.dtype, name: str) -> str:
    code = "u1" if dtype.kind == "b" else dtype.str[1:]
    if code not in _NAMES:
        raise InputError(f"attribute {name!r} of type {dtype} cannot be written to PLY")
    return "<" + code


def _parse_header(raw: bytes, path: Path) -> tuple[str, list[_Element], int]:
    end = raw.find(b"end_header")
    if not raw.startswith(b"ply") or end < 0:
        raise InputError("not a PLY file (no 'ply' magic or no end_header)", path)
    offset = raw.find(b"\n", end) + 1
    encoding = None
    elements: list[_Element] = []
    try:
        for line in raw[:end].decode("ascii").splitlines()[1:]:
            words = line.split()
            if not words or words[0] in ("comment", "obj_info"):
                continue
            if words[0] == "format":
                encoding = words[1]
            elif words[0] == "element":
                elements.append(_Element(words[1], int(words[2]), []))
            elif words[0] == "property":
                kind = "list" if words[1] == "list" else _TYPES[words[1]]
                elements[-1].properties.append((words[-1], kind))
    except (UnicodeDecodeError, IndexError, KeyError, ValueError) as e:
        raise InputError(f"bad PLY header ({type(e).__name__}: {e})", path) from None
    if encoding not in _ENDIAN:
        raise InputError(f"unknown PLY format {encoding!r} (ascii, binary_little_endian, binary_big_endian)", path)
    return encoding, elements, offset


def _fixed_size(element: _Element, encoding: str) -> int:
    return np.dtype([(n, _ENDIAN[encoding] + k) for n, k in element.properties]).itemsize


def _ascii_rows(body: bytes, skip: int, count: int, dtype: np.dtype, path: Path) -> np.ndarray:
    try:
        table = pd.read_csv(io.BytesIO(body), sep=r"\s+", header=None, skiprows=skip, nrows=count).to_numpy(np.float64)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, ValueError) as e:
        raise InputError(f"bad ASCII PLY data ({str(e).strip() or 'no rows'})", path) from None
    if table.shape != (count, len(dtype.names)):
        raise InputError(
            f"ASCII PLY vertex data has shape {table.shape}, header says {count} x {len(dtype.names)}", path
        )
    rows = np.empty(count, dtype=dtype)
    for column, name in enumerate(dtype.names):
        rows[name] = table[:, column]
    return rows
