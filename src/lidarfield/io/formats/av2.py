"""Argoverse 2 lidar sweeps: ``sensors/lidar/<timestamp_ns>.feather`` of a sensor-dataset log.

A sweep is a Feather (Arrow IPC) table of both roof lidars' points, columns ``x, y, z``
(metres, in the *vehicle* frame, ``egovehicle``), ``intensity``, ``laser_number`` (0-31: the
up lidar's lasers, 32-63: the down lidar's) and ``offset_ns`` (each point's time, ns after the
sweep's timestamp, the file's name).

The reader keeps the points of ``lidars`` and writes them in ``frame``: the vehicle frame as
stored, or a lidar's own frame through ``T_frame_vehicle`` (the inverse of that lidar's pose in
the vehicle frame, which the log's calibration table gives). The dataset reader
(:mod:`lidarfield.datasets.av2`) passes all three options, so that an ingest job reads the
sweep file and nothing else; read on its own (``lidarfield info sweep.feather``), a sweep is
both lidars in the vehicle frame. Attributes: ``intensity``, ``ring`` (``laser_number`` as
stored: the down lidar's rings are 32-63) and ``time`` (``offset_ns`` in seconds after the
sweep's timestamp). With ``lidar_poses`` (each kept lidar's pose in ``frame``, which the
dataset reader gives from the calibration), the scan is a rig (:mod:`lidarfield.sensors.rig`): its
``lidars`` in the order of ``lidars``, each with the given sensor model (default ``vlp32c``),
and each point's ``lidar`` attribute its lidar's index there.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import InputError
from ...poses import apply_pose, rigid_pose
from ...scan import Scan
from ...sensors.models import PRESETS, SensorModel
from ...sensors.rig import LIDAR, Lidar
from ..rows import scan_from_rows

# lidar -> its laser_number range [first, last + 1) in a sweep
LIDARS = {"up_lidar": (0, 32), "down_lidar": (32, 64)}
FRAMES = ("up_lidar", "down_lidar", "egovehicle")
COLUMNS = ("x", "y", "z", "intensity", "laser_number", "offset_ns")
MODEL = "vlp32c"  # both lidars' model


def read_av2(
    path: Path,
    index: int = 0,
    sensor: SensorModel | None = None,
    *,
    frame: str = "egovehicle",
    lidars: list[str] | tuple[str, ...] = ("up_lidar", "down_lidar"),
    T_frame_vehicle: list | None = None,
    lidar_poses: dict[str, list] | None = None,
) -> Scan:
    """The points of ``lidars`` in ``frame`` (``T_frame_vehicle``: 4x4, vehicle to that frame;
    needed for a lidar frame, identity for ``egovehicle``); with ``lidar_poses`` (lidar name ->
    its 4x4 pose in ``frame``) a rig of those lidars."""
    transform = _frame_transform(frame, T_frame_vehicle, path)
    unknown = [name for name in lidars if name not in LIDARS]
    if unknown or not lidars:
        raise InputError(f"lidars {list(lidars)!r}: choose one or both of {list(LIDARS)}", path)
    if lidar_poses is not None and set(lidar_poses) != set(lidars):
        raise InputError(f"lidar_poses names {sorted(lidar_poses)}, not the lidars read {sorted(lidars)}", path)
    columns = feather_columns(path, COLUMNS, "an Argoverse 2 lidar sweep")
    laser = columns["laser_number"]
    if not (np.isfinite(laser).all() and (laser >= 0).all() and (laser < 64).all()):
        raise InputError("laser_number holds values outside 0..63 (0-31 up lidar, 32-63 down lidar)", path)
    laser = laser.astype(np.int64)
    keep = np.zeros(len(laser), dtype=bool)
    which = np.zeros(len(laser), dtype=np.uint8)
    for k, name in enumerate(lidars):
        first, end = LIDARS[name]
        mine = (laser >= first) & (laser < end)
        keep |= mine
        which[mine] = k
    if len(laser) and not keep.any():
        raise InputError(f"no point of {' or '.join(lidars)} in the sweep (laser_number ranges {LIDARS})", path)
    xyz = np.column_stack([np.asarray(columns[c], dtype=np.float64)[keep] for c in ("x", "y", "z")])
    if transform is not None:
        xyz = apply_pose(transform, xyz)
    attributes = {
        "intensity": columns["intensity"][keep],
        "ring": laser[keep].astype(np.uint16),
        "time": np.asarray(columns["offset_ns"], dtype=np.float64)[keep] / 1e9,  # one rounding, not two
    }
    if lidar_poses is None:
        return scan_from_rows(xyz, attributes, path, sensor=sensor)
    attributes[LIDAR] = which[keep]
    scan = scan_from_rows(xyz, attributes, path, sensor=sensor)
    model = sensor or PRESETS[MODEL]
    scan.lidars = tuple(Lidar(name, _rigid(lidar_poses[name], f"lidar_poses.{name}", path), model) for name in lidars)
    return scan


def _frame_transform(frame: str, T_frame_vehicle, path: Path) -> np.ndarray | None:
    if frame not in FRAMES:
        raise InputError(f"frame {frame!r}: one of {', '.join(FRAMES)}", path)
    if T_frame_vehicle is None:
        if frame != "egovehicle":
            raise InputError(
                f"frame {frame!r} needs T_frame_vehicle (vehicle to {frame}, from the log's calibration: "
                "read the sweep through its dataset, format av2)",
                path,
            )
        return None
    return _rigid(T_frame_vehicle, "T_frame_vehicle", path)


def _rigid(values, what: str, path: Path) -> np.ndarray:
    """A 4x4 rigid transform from ``values``; an InputError naming ``what`` otherwise."""
    T = np.asarray(values, dtype=np.float64)
    if T.shape != (4, 4):
        raise InputError(f"{what} is {T.shape}, not 4x4", path)
    try:
        return rigid_pose(T, path)
    except InputError as e:
        raise InputError(f"{what}: {str(e).removeprefix(f'{path}: ')}", path) from None


def feather_columns(
    path: Path, columns: tuple[str, ...], what: str, error=InputError, text: tuple[str, ...] = ()
) -> dict[str, np.ndarray]:
    """The ``columns`` of the Feather table ``path`` as numpy arrays, numbers except the ``text``
    ones; ``error`` (an InputError or a ConfigError) naming the file when it is missing,
    unreadable, lacks a column or holds something else in one."""
    import pyarrow as pa
    import pyarrow.feather as feather

    from ..parquet_table import numpy_array

    path = Path(path)
    if not path.is_file():
        raise error(f"{what}: file not found", path)
    try:
        table = feather.read_table(path)
    except (pa.ArrowException, OSError, ValueError) as e:
        raise error(f"{what}: not a readable Feather file ({e})", path) from None
    missing = [c for c in columns if c not in table.column_names]
    if missing:
        raise error(f"{what}: missing column(s) {missing}; has {table.column_names}", path)
    values = {c: numpy_array(table.column(c)) for c in columns}
    wrong = [c for c in columns if c not in text and values[c].dtype.kind not in "biuf"]
    if wrong:
        kinds = ", ".join(f"{c} is {table.schema.field(c).type}" for c in wrong)
        raise error(f"{what}: column(s) not numeric ({kinds})", path)
    return values
