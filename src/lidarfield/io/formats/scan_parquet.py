"""The scan Parquet contract: columns x, y, z (float64) plus attributes; metadata key
``lidarfield`` = {"sensor", "pose", "source", "dropped_invalid", "stamp_s", "sweep_motion",
"lidars"} (``lidars``: a multi-lidar rig, see :mod:`lidarfield.sensors.rig`; absent: one lidar)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import InputError, LidarfieldError
from ...scan import Scan
from ...sensors.models import SensorModel
from ...sensors.rig import check_lidar_ids, lidars_from_meta, lidars_to_meta
from ..parquet_table import read_table, write_table
from ..rows import scan_from_rows


def write_parquet(scan: Scan, path: Path) -> None:
    columns = {"x": scan.xyz[:, 0], "y": scan.xyz[:, 1], "z": scan.xyz[:, 2], **scan.attributes}
    write_table(path, columns, scan_metadata(scan))


def scan_metadata(scan: Scan) -> dict:
    """The metadata of the scan Parquet contract."""
    return {
        "sensor": None if scan.sensor is None else scan.sensor.to_dict(),
        "pose": None if scan.pose is None else np.asarray(scan.pose).tolist(),
        "source": scan.source,
        "dropped_invalid": int(scan.dropped_invalid),
        "stamp_s": scan.stamp_s,
        "sweep_motion": scan.sweep_motion,
        **({"lidars": lidars_to_meta(scan.lidars)} if scan.lidars else {}),
    }


def read_parquet(path: Path, index: int = 0, sensor: SensorModel | None = None) -> Scan:
    columns, meta = read_table(path, required=("x", "y", "z"))
    xyz = np.column_stack([columns.pop(a) for a in "xyz"])
    try:
        stored_sensor = SensorModel.from_dict(meta["sensor"]) if meta.get("sensor") else None
        pose = np.asarray(meta["pose"], dtype=np.float64).reshape(4, 4) if meta.get("pose") is not None else None
    except (LidarfieldError, ValueError, TypeError) as e:
        raise InputError(f"bad lidarfield metadata ({e})", path) from None
    scan = scan_from_rows(
        xyz,
        columns,
        path,
        sensor=sensor or stored_sensor,
        pose=pose,
        dropped_before=int(meta.get("dropped_invalid", 0)),
    )
    if meta.get("source"):
        scan.source = meta["source"]
    scan.stamp_s = meta.get("stamp_s")
    scan.sweep_motion = meta.get("sweep_motion")
    try:
        scan.lidars = lidars_from_meta(meta.get("lidars"))
        check_lidar_ids(scan.lidars, scan.attributes)
    except (LidarfieldError, ValueError, TypeError, KeyError) as e:
        raise InputError(f"bad lidarfield metadata: lidars ({e})", path) from None
    return scan
