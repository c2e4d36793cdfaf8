"""Ouster recordings (``.pcap`` with its ``.json`` metadata beside it, or ``.osf``) through the
optional ``ouster-sdk`` package (``pip install lidarfield[ouster]``).

Each frame of the first sensor is one scan: ``path#k`` selects frame k. Points are in the
sensor frame (the SDK's XYZ look-up table); pixels without a return are dropped and counted.
Attributes: ``intensity`` (the REFLECTIVITY channel, as in Ouster's decoded KITTI-style bins),
``ring`` (the beam, row of the frame) and ``time`` (seconds since the frame's first column).
The sensor model comes from the recording's beam altitude angles.
"""

from __future__ import annotations

import warnings
from functools import lru_cache
from pathlib import Path

import numpy as np

from ...errors import InputError
from ...scan import Scan
from ...sensors.models import PRESETS, SensorModel
from ..rows import file_key, scan_from_rows

_INSTALL = "reading Ouster recordings needs the optional ouster-sdk package: pip install lidarfield[ouster]"


def count_ouster(path: Path) -> int:
    return _frame_count(*file_key(path))


def read_ouster(path: Path, index: int = 0, sensor: SensorModel | None = None) -> Scan:
    sdk = _sdk()
    source = _open(path)
    info = source.sensor_info[0]
    frame = next((f[0] for k, f in enumerate(source) if k == index), None)
    if frame is None:
        raise InputError(f"frame #{index} could not be decoded", path)
    ranges = frame.field(sdk.core.ChanField.RANGE)
    xyz = sdk.core.XYZLut(info)(ranges).reshape(-1, 3)
    xyz[ranges.reshape(-1) == 0] = np.nan  # no return
    rows, columns = ranges.shape
    stamps = np.asarray(frame.timestamp, dtype=np.int64)
    first = stamps[stamps > 0].min() if (stamps > 0).any() else 0
    attributes = {
        "intensity": frame.field(sdk.core.ChanField.REFLECTIVITY).reshape(-1).astype(np.float32),
        "ring": np.repeat(np.arange(rows, dtype=np.uint16), columns),
        "time": np.tile((stamps - first) * 1e-9, rows),
    }
    scan = scan_from_rows(xyz, attributes, path, sensor=sensor or _sensor_model(info))
    scan.source = f"{path}#{index}"
    return scan


def _sensor_model(info) -> SensorModel:
    """The recording's own beam elevations; ranges from the OS1-128 preset."""
    preset = PRESETS["os1-128"]
    return SensorModel(
        f"ouster-{str(info.prod_line).lower()}",
        tuple(float(a) for a in info.beam_altitude_angles),
        360.0 / info.format.columns_per_frame,
        preset.min_range_m,
        preset.max_range_m,
        info.format.fps if hasattr(info.format, "fps") else preset.rotation_hz,
    )


def _sdk():
    try:
        import ouster.sdk as sdk
        import ouster.sdk.core  # noqa: F401  (the submodule holding ChanField and XYZLut)
    except ImportError:
        raise InputError(_INSTALL) from None
    return sdk


def _open(path: Path):
    sdk = _sdk()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)
            return sdk.open_source(str(path), sensor_idx=0, index=True)
    except Exception as e:  # the SDK raises its own exception types for unreadable recordings
        detail = " ".join(str(e).split())
        raise InputError(
            f"ouster-sdk cannot open the recording (is its .json metadata beside it?): {detail}", path
        ) from None


@lru_cache(maxsize=32)
def _frame_count(path: str, size: int, mtime_ns: int) -> int:
    """Frames in a recording (cached by path, size and time: indexing reads the whole file)."""
    counts = _open(Path(path)).frames_num
    return int(counts[0] if isinstance(counts, (list, tuple)) else counts)
