"""LAS and LAZ scans through laspy (LAZ with the lazrs backend).

Read: scaled x, y, z; ``intensity``; ``time`` from GPS time when the point format has it; and
every extra-bytes dimension under its own name. Written as LAS 1.4 (point format 6 when the
scan has ``time``, else 0 with extra bytes), coordinates scaled at 0.05 mm, LAZ-compressed for
``.laz``. An ``intensity`` that is not a whole number in 0..65535 cannot live in LAS's uint16
field: it is written to the extra dimension ``float_intensity`` and read back as
``intensity``.
"""

from __future__ import annotations

import logging
from contextlib import contextmanager
from pathlib import Path

import laspy
import numpy as np

from ...errors import InputError
from ...scan import Scan
from ...sensors.models import SensorModel
from ..atomic import atomic_path
from ..rows import scan_from_rows

SCALE_M = 0.00005  # coordinate resolution: 0.05 mm (error at most 0.025 mm)
_FLOAT_INTENSITY = "float_intensity"


@contextmanager
def _laspy_silenced():
    """laspy logs the errors it raises (a truncated LAZ: twice); the raised one is reported."""
    logger = logging.getLogger("laspy")
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        logger.setLevel(level)


def read_las(path: Path, index: int = 0, sensor: SensorModel | None = None) -> Scan:
    try:
        with _laspy_silenced():
            las = laspy.read(path)
        xyz = np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])
        attributes = {"intensity": np.asarray(las.intensity)}
        if "gps_time" in las.point_format.dimension_names:
            attributes["time"] = np.asarray(las.gps_time)
        for name in las.point_format.extra_dimension_names:
            attributes[name] = np.asarray(las[name])
    except (laspy.errors.LaspyException, ValueError, OSError, EOFError, RuntimeError) as e:  # lazrs: RuntimeError
        raise InputError(f"not a readable LAS/LAZ file ({e})", path) from None
    if _FLOAT_INTENSITY in attributes:
        attributes["intensity"] = attributes.pop(_FLOAT_INTENSITY)
    return scan_from_rows(xyz, attributes, path, sensor=sensor)


def write_las(scan: Scan, path: Path) -> None:
    attributes = dict(scan.attributes)
    time = attributes.pop("time", None)
    intensity = attributes.pop("intensity", None)
    if intensity is not None and not _fits_uint16(intensity):
        attributes[_FLOAT_INTENSITY], intensity = intensity, None
    header = laspy.LasHeader(point_format=6 if time is not None else 0, version="1.4")
    header.offsets = np.floor(scan.xyz.min(axis=0)) if len(scan) else np.zeros(3)
    header.scales = np.full(3, SCALE_M)
    extra = {name: np.asarray(values) for name, values in attributes.items()}
    header.add_extra_dims(
        [laspy.ExtraBytesParams(name=name, type=_las_type(values.dtype, name)) for name, values in extra.items()]
    )
    las = laspy.LasData(header)
    las.x, las.y, las.z = scan.xyz[:, 0], scan.xyz[:, 1], scan.xyz[:, 2]
    if intensity is not None:
        las.intensity = np.asarray(intensity).astype(np.uint16)
    if time is not None:
        las.gps_time = time
    for name, values in extra.items():
        las[name] = values.astype(_las_type(values.dtype, name))
    with atomic_path(path) as tmp, open(tmp, "wb") as stream:
        # laspy picks compression from a path's extension (and ignores do_compress for paths);
        # the temporary name does not end in .laz, so write to a stream and say it.
        las.write(stream, do_compress=path.suffix.lower() == ".laz")


def _fits_uint16(values: np.ndarray) -> bool:
    values = np.asarray(values)
    return bool(
        values.size == 0 or (np.all(values == np.round(values)) and values.min() >= 0 and values.max() <= 65535)
    )


def _las_type(dtype: np.dtype, name: str) -> np.dtype:
    if dtype.kind == "b":
        return np.dtype("u1")
    if dtype.kind not in "fiu":
        raise InputError(f"attribute {name!r} of type {dtype} cannot be written to LAS")
    return dtype
