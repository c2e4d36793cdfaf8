"""The simulator's calibration faults, checked (numpy only: a config's validation imports this,
and must not load Open3D).

The scene and the ray are the truth, the reported point the measurement: beam k fires at
``elevation_deg[k] + elevation_offsets_deg[k]`` and hits at the true range r; the point is
reported along the nominal elevation ``elevation_deg[k]`` at ``range_scale * r +
range_offset_m`` (see ``raycast.simulate_scan``).
"""

from __future__ import annotations

import numpy as np

from ..errors import ConfigError
from ..sensors.models import SensorModel


def checked_range_fault(scale, offset) -> tuple[float, float]:
    """A range scale (positive) and offset (finite) as floats, else a one-line ConfigError."""
    scale, offset = float(scale), float(offset)
    if not (np.isfinite(scale) and scale > 0 and np.isfinite(offset)):
        raise ConfigError(f"simulate: range scale must be positive and range offset finite; got {scale:g}, {offset:g}")
    return scale, offset


def checked_elevation_offsets(
    offsets, sensor: SensorModel, what: str = "simulate: elevation offsets"
) -> np.ndarray | None:
    """Per-channel elevation offsets (degrees) as an array, or None; one finite number per beam
    of ``sensor``, else a one-line ConfigError that starts with ``what``."""
    if offsets is None:
        return None
    try:
        values = np.asarray(offsets, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"{what}: must be numbers, got {offsets!r}") from None
    if values.ndim != 1 or len(values) != sensor.channels:
        raise ConfigError(
            f"{what}: need one value per beam of sensor {sensor.name} ({sensor.channels} beams), got {values.size}"
        )
    if not np.all(np.isfinite(values)):
        raise ConfigError(f"{what}: must be finite numbers")
    return values
