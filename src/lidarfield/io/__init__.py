"""Reading and writing scans: one facade over one module per file format.

``read_scan(path)`` picks the format from the extension (or ``format=``), and returns a
:class:`~lidarfield.scan.Scan` in the sensor frame with rows of NaN or infinite coordinates
dropped and counted. Container formats (MATLAB cell arrays, Ouster recordings) hold several
scans: the reference ``path#k`` (0-based) selects scan k and ``scan_count(path)`` says how many
there are.
"""

from __future__ import annotations

import importlib
import re
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError
from ..scan import Scan
from ..sensors import SensorModel, sensor_model


@dataclass(frozen=True)
class ScanFormat:
    """A file format: its extensions and the module (imported on first use) that reads it.

    The module provides ``read_<name>(path, index, sensor) -> Scan``, optionally
    ``write_<name>(scan, path)`` and, for container formats, ``count_<name>(path) -> int``.
    """

    name: str
    extensions: tuple[str, ...]
    module: str
    writable: bool = True
    container: bool = False

    def function(self, verb: str):
        module = importlib.import_module(f"{__name__}.{self.module}")
        return getattr(module, f"{verb}_{self.name}")


FORMATS: dict[str, ScanFormat] = {
    f.name: f
    for f in (
        ScanFormat("pcd", (".pcd",), "pcd"),
        ScanFormat("ply", (".ply",), "ply"),
        ScanFormat("bin", (".bin",), "kitti_bin"),
        ScanFormat("txt", (".txt", ".xyz", ".asc"), "text"),
        ScanFormat("csv", (".csv",), "text"),
        ScanFormat("npy", (".npy",), "npy"),
        ScanFormat("parquet", (".parquet", ".pq"), "scan_parquet"),
        ScanFormat("las", (".las", ".laz"), "las"),
        ScanFormat("mat", (".mat",), "mat", writable=False, container=True),
        ScanFormat("ouster", (".pcap", ".osf"), "ouster", writable=False, container=True),
    )
}

_REFERENCE = re.compile(r"^(?P<path>.+)#(?P<index>\d+)$")


def known_formats() -> str:
    """The formats and their extensions, for error messages."""
    return ", ".join(f"{f.name} ({' '.join(f.extensions)})" for f in FORMATS.values())


def split_reference(reference: str | Path) -> tuple[Path, int | None]:
    """``'scans.mat#3'`` -> (Path('scans.mat'), 3); a plain path -> (path, None).

    A file whose real name ends in ``#digits`` is taken as it is.
    """
    text = str(reference)
    match = _REFERENCE.match(text)
    if match is None or Path(text).exists():
        return Path(text), None
    return Path(match["path"]), int(match["index"])


def scan_format(path: str | Path, format: str | None = None) -> ScanFormat:
    """The format named by ``format``, or the one of ``path``'s extension."""
    if format is not None:
        found = FORMATS.get(format.lower().lstrip("."))
        if found is None:
            found = next((f for f in FORMATS.values() if "." + format.lower().lstrip(".") in f.extensions), None)
        if found is None:
            raise InputError(f"unknown scan format {format!r}; known formats: {known_formats()}", path)
        return found
    suffix = Path(path).suffix.lower()
    for f in FORMATS.values():
        if suffix in f.extensions:
            return f
    raise InputError(
        f"unknown scan file extension {suffix or '(none)'!r}; known formats: {known_formats()} "
        "(or give the format explicitly)",
        path,
    )


def scan_count(reference: str | Path, format: str | None = None) -> int:
    """How many scans the file holds (1 for single-scan formats)."""
    path, _ = split_reference(reference)
    fmt = scan_format(path, format)
    _require_file(path)
    return fmt.function("count")(path) if fmt.container else 1


def read_scan(reference: str | Path, format: str | None = None, sensor: str | dict | SensorModel | None = None) -> Scan:
    """Read one scan from ``path`` or ``path#k`` (scan k of a container file, 0-based).

    ``sensor`` (a preset name, a YAML file, a dict or a model) is attached to the scan and
    overrides a model stored in the file. Raises ``InputError`` naming the file and the problem.
    """
    path, index = split_reference(reference)
    fmt = scan_format(path, format)
    _require_file(path)
    model = sensor_model(sensor)
    count = fmt.function("count")(path) if fmt.container else 1
    if index is None and count > 1:
        raise InputError(f"holds {count} scans: select one by appending #k to the path, k = 0..{count - 1}", path)
    index = 0 if index is None else index
    if index >= count:
        raise InputError(f"scan #{index} requested but the file holds {count} scan(s) (#0..#{count - 1})", path)
    scan = fmt.function("read")(path, index, model)
    if model is not None:
        scan.sensor = model
    return scan


def write_scan(scan: Scan, path: str | Path, format: str | None = None) -> None:
    """Write ``scan`` whole (or not at all) in the format of ``path``'s extension or ``format``."""
    path = Path(path)
    fmt = scan_format(path, format)
    if not fmt.writable:
        writable = ", ".join(f.name for f in FORMATS.values() if f.writable)
        raise InputError(f"format {fmt.name!r} is read-only; writable formats: {writable}", path)
    fmt.function("write")(scan, path)


def _require_file(path: Path) -> None:
    if not path.is_file():
        raise InputError("file not found" if not path.exists() else "not a file", path)


__all__ = ["FORMATS", "ScanFormat", "known_formats", "read_scan", "scan_count", "split_reference", "write_scan"]
