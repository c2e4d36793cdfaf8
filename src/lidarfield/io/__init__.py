"""Reading and writing scans: one facade over one module per file format.

``read_scan(path)`` picks the format from the extension (or ``format=``), and returns a
:class:`~lidarfield.scan.Scan` in the sensor frame with rows of NaN or infinite coordinates
dropped and counted. Container formats (MATLAB cell arrays, Ouster recordings, ROS bags) hold
several scans: the reference ``path#k`` (0-based) selects scan k and ``scan_count(path)`` says
how many there are. A ROS bag with several PointCloud2 topics needs the topic:
``path#/topic#k``. A ROS 2 bag is a folder (holding ``metadata.yaml``).
"""

from __future__ import annotations

import importlib
import re
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

from ..errors import InputError
from ..scan import Scan
from ..sensors.models import SensorModel, sensor_model
from .rosbag.bag import is_bag_folder


@dataclass(frozen=True)
class ScanFormat:
    """A file format: its extensions and the module (imported on first use) that reads it.

    The module provides ``read_<name>(path, index, sensor) -> Scan``, optionally
    ``write_<name>(scan, path)`` and, for container formats, ``count_<name>(path) -> int``.
    Formats with ``topics`` (ROS bags) take the topic as a last argument of both; formats whose
    decoding depends on the sensor (``sensor_decodes``: raw captures) get it in ``count`` too.
    """

    name: str
    extensions: tuple[str, ...]
    module: str
    writable: bool = True
    container: bool = False
    topics: bool = False
    sensor_decodes: bool = False

    def function(self, verb: str):
        module = importlib.import_module(f"{__name__}.{self.module}")
        return getattr(module, f"{verb}_{self.name}")


FORMATS: dict[str, ScanFormat] = {
    f.name: f
    for f in (
        ScanFormat("pcd", (".pcd",), "formats.pcd"),
        ScanFormat("ply", (".ply",), "formats.ply"),
        ScanFormat("bin", (".bin",), "formats.kitti_bin"),
        ScanFormat("txt", (".txt", ".xyz", ".asc"), "formats.text"),
        ScanFormat("csv", (".csv",), "formats.text"),
        ScanFormat("npy", (".npy",), "formats.npy"),
        ScanFormat("parquet", (".parquet", ".pq"), "formats.scan_parquet"),
        ScanFormat("las", (".las", ".laz"), "formats.las"),
        ScanFormat("mat", (".mat",), "formats.mat", writable=False, container=True),
        ScanFormat("pcap", (".pcap",), "formats.pcap", writable=False, container=True, sensor_decodes=True),
        ScanFormat("ouster", (".osf",), "formats.ouster", writable=False, container=True),
        ScanFormat("velodyne", (), "formats.velodyne", writable=False, container=True, sensor_decodes=True),
        ScanFormat("rosbag", (".bag", ".mcap", ".db3"), "rosbag.reader", writable=False, container=True, topics=True),
        # dataset sweeps (lidarfield.datasets): named by the dataset reader, not by extension
        ScanFormat("av2", (".feather",), "formats.av2", writable=False),
        ScanFormat("nuscenes", (), "formats.nuscenes_bin", writable=False),
    )
}

_REFERENCE = re.compile(r"^(?P<path>.+?)(?:#(?P<topic>/[^#]*))?(?:#(?P<index>\d+))?$")


class ScanReference(NamedTuple):
    """A scan of a file: ``path``, ``path#k`` or (ROS bags) ``path#/topic#k`` / ``path#/topic``."""

    path: Path
    index: int | None = None
    topic: str | None = None


def known_formats() -> str:
    """The formats and their extensions, for error messages."""
    return ", ".join(f"{f.name} ({' '.join(f.extensions)})" for f in FORMATS.values())


def split_reference(reference: str | Path) -> ScanReference:
    """``'scans.mat#3'`` -> (Path('scans.mat'), 3, None); ``'drive.bag#/points#2'`` ->
    (Path('drive.bag'), 2, '/points'); a plain path -> (path, None, None).

    A file whose real name ends in ``#digits`` is taken as it is.
    """
    text = str(reference)
    match = _REFERENCE.match(text)
    if match is None or Path(text).exists() or not (match["index"] or match["topic"]):
        return ScanReference(Path(text))
    index = None if match["index"] is None else int(match["index"])
    return ScanReference(Path(match["path"]), index, match["topic"])


def scan_format(path: str | Path, format: str | None = None) -> ScanFormat:
    """The format named by ``format``, or the one of ``path``'s extension (a folder holding
    ``metadata.yaml`` is a ROS 2 bag)."""
    if format is not None:
        found = FORMATS.get(format.lower().lstrip("."))
        if found is None:
            found = next((f for f in FORMATS.values() if "." + format.lower().lstrip(".") in f.extensions), None)
        if found is None:
            raise InputError(f"unknown scan format {format!r}; known formats: {known_formats()}", path)
        return found
    if is_bag_folder(Path(path)):
        return FORMATS["rosbag"]
    suffix = Path(path).suffix.lower()
    for f in FORMATS.values():
        if suffix in f.extensions:
            return f
    raise InputError(
        f"unknown scan file extension {suffix or '(none)'!r}; known formats: {known_formats()} "
        "(or give the format explicitly)",
        path,
    )


def scan_count(reference: str | Path, format: str | None = None, sensor: str | dict | SensorModel | None = None) -> int:
    """How many scans the file holds (1 for single-scan formats; a bag's topic: its messages; a
    Velodyne capture: its whole rotations, decoded as ``sensor`` when given)."""
    reference = split_reference(reference)
    fmt = _checked_format(reference, format)
    return _count(fmt, reference, sensor_model(sensor))


def read_scan(
    reference: str | Path,
    format: str | None = None,
    sensor: str | dict | SensorModel | None = None,
    poses: dict | None = None,
    options: dict | None = None,
) -> Scan:
    """Read one scan from ``path``, ``path#k`` (scan k of a container file, 0-based) or, for a
    ROS bag, ``path#/topic#k``.

    ``sensor`` (a preset name, a YAML file, a dict or a model) is attached to the scan and
    overrides a model stored in the file. ``poses`` (ROS bags only: ``{"topic": ..., "frame":
    ...}``) gives the scan the pose of that topic at its header stamp. ``options`` are the
    format reader's own keyword arguments (an Argoverse 2 sweep: its frame and lidars). Raises
    ``InputError`` naming the file and the problem.
    """
    reference = split_reference(reference)
    path = reference.path
    fmt = _checked_format(reference, format)
    model = sensor_model(sensor)
    count = _count(fmt, reference, model)
    if reference.index is None and count > 1:
        raise InputError(f"holds {count} scans: select one by appending #k to the path, k = 0..{count - 1}", path)
    index = 0 if reference.index is None else reference.index
    if index >= count:
        raise InputError(f"scan #{index} requested but the file holds {count} scan(s) (#0..#{count - 1})", path)
    if poses is not None and not fmt.topics:
        raise InputError(f"poses from a topic need a ROS bag, not a {fmt.name} file", path)
    bag = (reference.topic, poses) if fmt.topics else ()
    reader = fmt.function("read")
    if options and not set(options) <= set(_parameters(reader)):
        raise InputError(f"the {fmt.name} reader takes no option(s) {sorted(options)}", path)
    scan = reader(path, index, model, *bag, **(options or {}))
    if model is not None:
        scan.sensor = model
    return scan


def _parameters(function) -> list[str]:
    import inspect  # only for readers given options: most jobs never need it

    return list(inspect.signature(function).parameters)


def _checked_format(reference: ScanReference, format: str | None) -> ScanFormat:
    """The reference's format, once its file (or bag folder) is known to exist."""
    fmt = scan_format(reference.path, format)
    if not (reference.path.is_file() or fmt.topics and is_bag_folder(reference.path)):
        raise InputError("file not found" if not reference.path.exists() else "not a file", reference.path)
    if reference.topic is not None and not fmt.topics:
        raise InputError(f"a {fmt.name} file has no topics (#{reference.topic} given)", reference.path)
    return fmt


def _count(fmt: ScanFormat, reference: ScanReference, sensor: SensorModel | None) -> int:
    if not fmt.container:
        return 1
    extra = (reference.topic,) if fmt.topics else (sensor,) if fmt.sensor_decodes else ()
    return fmt.function("count")(reference.path, *extra)


def write_scan(scan: Scan, path: str | Path, format: str | None = None) -> None:
    """Write ``scan`` whole (or not at all) in the format of ``path``'s extension or ``format``."""
    path = Path(path)
    fmt = scan_format(path, format)
    if not fmt.writable:
        writable = ", ".join(f.name for f in FORMATS.values() if f.writable)
        raise InputError(f"format {fmt.name!r} is read-only; writable formats: {writable}", path)
    fmt.function("write")(scan, path)


__all__ = [
    "FORMATS",
    "ScanFormat",
    "ScanReference",
    "known_formats",
    "read_scan",
    "scan_count",
    "split_reference",
    "write_scan",
]
