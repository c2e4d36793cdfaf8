""".pcap captures, which Velodyne and Ouster sensors share: told apart by their packets
(Velodyne data packets are 1206-byte UDP payloads) or, failing that, by the Ouster ``.json``
metadata beside the capture (a ``.json`` whose name begins the capture's, as ouster-sdk finds
it). Then read as :mod:`lidarfield.io.velodyne` or :mod:`lidarfield.io.ouster` reads them.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from ...errors import InputError
from ...scan import Scan
from ...sensors.models import SensorModel
from . import ouster, velodyne


def capture_vendor(path: Path) -> str:
    """``"velodyne"`` or ``"ouster"``; an ``InputError`` listing the packets for anything else."""
    if velodyne.is_velodyne(path):
        return "velodyne"
    if ouster_metadata(path) is not None:
        return "ouster"
    sizes = Counter(len(payload) for _, payload in velodyne.udp_payloads(path))
    listing = ", ".join(f"{size} bytes x {n}" for size, n in sizes.most_common(5)) or "no UDP packets"
    raise InputError(
        f"not a Velodyne capture (no 1206-byte data packets; UDP payloads: {listing}) and no Ouster "
        ".json metadata beside it",
        path,
    )


def ouster_metadata(path: Path) -> Path | None:
    """The Ouster sensor metadata beside a capture: the longest ``.json`` name that begins its name."""
    candidates = [p for p in path.parent.glob("*.json") if path.stem.startswith(p.stem)]
    return max(candidates, key=lambda p: len(p.stem)) if candidates else None


def count_pcap(path: Path, sensor: SensorModel | None = None) -> int:
    if capture_vendor(path) == "ouster":
        return ouster.count_ouster(path)
    return velodyne.count_velodyne(path, sensor)


def read_pcap(path: Path, index: int = 0, sensor: SensorModel | None = None) -> Scan:
    if capture_vendor(path) == "ouster":
        return ouster.read_ouster(path, index, sensor)
    return velodyne.read_velodyne(path, index, sensor)
