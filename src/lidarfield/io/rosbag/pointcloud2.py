"""Decode ``sensor_msgs/PointCloud2`` data as drivers publish it: any field layout and padding.

A PointCloud2 is ``height`` rows of ``width`` points, each row ``row_step`` bytes long, each
point ``point_step`` bytes, the fields at the byte offsets the message lists (``count`` values
each, of the ROS datatypes 1..8), little- or big-endian. Drivers pad their points: the Ouster
driver's point is 48 bytes (x, y, z, pad, intensity, t, reflectivity, ring, ambient, range),
the Velodyne driver's 22 (x, y, z, intensity, ring, time).

x, y, z become the coordinates; every other scalar field becomes an attribute under its own
name, except the Ouster driver's ``t`` (integer nanoseconds since the scan began), which
becomes ``time`` in seconds as the scan contract has it. Fields with ``count`` > 1 (arrays per
point) are skipped. Rows are kept as they are (NaN rows are dropped later, as for every
format); note that some drivers mark "no return" in organised clouds by (0, 0, 0), not NaN.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

# sensor_msgs/PointField datatypes
DATATYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
TYPE_NAMES = {1: "int8", 2: "uint8", 3: "int16", 4: "uint16", 5: "int32", 6: "uint32", 7: "float32", 8: "float64"}


class PointField(NamedTuple):
    name: str
    offset: int
    datatype: int
    count: int = 1


class CloudLayoutError(ValueError):
    """The message's fields, steps and data do not describe a readable cloud."""


def cloud_dtype(fields: list[PointField], point_step: int, big_endian: bool) -> np.dtype:
    """The structured dtype of one point (scalar fields; padding left out by offsets)."""
    order = ">" if big_endian else "<"
    names, formats, offsets = [], [], []
    for f in fields:
        if f.datatype not in DATATYPES:
            raise CloudLayoutError(f"field {f.name!r} has unknown datatype {f.datatype}")
        size = np.dtype(DATATYPES[f.datatype]).itemsize * max(f.count, 1)
        if f.offset < 0 or f.offset + size > point_step:
            raise CloudLayoutError(
                f"field {f.name!r} (offset {f.offset}, {size} bytes) lies outside the {point_step}-byte point"
            )
        if f.count != 1 or f.name in names:
            continue
        names.append(f.name)
        formats.append(order + DATATYPES[f.datatype])
        offsets.append(f.offset)
    return np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": point_step})


def decode_cloud(
    fields: list[PointField],
    height: int,
    width: int,
    point_step: int,
    row_step: int,
    big_endian: bool,
    data: np.ndarray | bytes,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """(xyz (N, 3) float64, attributes) of a PointCloud2's points, rows in order.

    Raises ``CloudLayoutError`` when the layout is not readable (no x, y, z; fields beyond the
    point; data shorter than height x row_step).
    """
    missing = [a for a in "xyz" if a not in {f.name for f in fields}]
    if missing:
        raise CloudLayoutError(f"no {', '.join(missing)} field (fields: {', '.join(f.name for f in fields) or 'none'})")
    if point_step <= 0 or width * point_step > row_step:
        raise CloudLayoutError(f"point_step {point_step} x width {width} does not fit the row_step {row_step}")
    data = np.frombuffer(data, dtype=np.uint8)
    if len(data) < height * row_step:
        raise CloudLayoutError(f"data holds {len(data)} bytes, fewer than height {height} x row_step {row_step}")
    dtype = cloud_dtype(fields, point_step, big_endian)
    # Rows may end in padding (row_step > width * point_step): view each row separately.
    rows = np.lib.stride_tricks.as_strided(data, shape=(height, width * point_step), strides=(row_step, 1))
    points = np.ascontiguousarray(rows).view(dtype).reshape(-1)
    xyz = np.column_stack([points[a].astype(np.float64) for a in "xyz"])
    attributes = {}
    for name in dtype.names:
        if name in ("x", "y", "z"):
            continue
        values = points[name].astype(points[name].dtype.newbyteorder("="))
        if name == "t" and values.dtype.kind in "iu":
            name, values = "time", values * 1e-9
        attributes[name] = values
    return xyz, attributes


def encode_cloud(xyz: np.ndarray, attributes: dict[str, np.ndarray], dtype: np.dtype) -> bytes:
    """The data of a PointCloud2 of one row in the layout ``dtype`` (padding zero): the inverse
    of :func:`decode_cloud`, for writing bags of real scans (tests, benchmarks)."""
    points = np.zeros(len(xyz), dtype=dtype)
    for k, axis in enumerate("xyz"):
        points[axis] = xyz[:, k]
    for name, values in attributes.items():
        points[name] = values
    return points.tobytes()
