"""``field_of_view``: remove the points of each cloud that the *other* sensor could not have seen.

Cloud 1 is expressed in sensor 2's frame (``T_1_2``, rotation included) and tested against
sensor 2's limits; cloud 2 against sensor 1's limits in frame 1. A point is dropped when its
elevation ``atan2(z, hypot(x, y))`` is strictly below or above the sensor's elevation limits
(the lowest and highest channel of its model, or ``elevation_deg``), widened by ``margin_deg``.
Where the model has them (or the parameters give them), points outside the range limits
``[min_range_m, max_range_m]`` and the azimuth sector are dropped by the same rule. A scan of
several lidars (:mod:`lidarfield.sensors.rig`) sees what any of its lidars sees: a point is kept
when it is inside the limits of one of them, about that lidar's own origin and axes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import NotApplicableError
from ..pair import RegisteredPair
from ..sensors.models import SensorModel
from ..sensors.rig import LidarView
from .geometry import in_sensor_frame
from .params import doc


@dataclass(frozen=True)
class Params:
    elevation_deg: tuple[float, float] | None = field(
        default=None,
        metadata=doc(
            "[lo, hi] elevation limits for both sensors (null: each sensor model's lowest and highest channel)"
        ),
    )
    range_m: tuple[float, float] | None = field(
        default=None,
        metadata=doc("[min, max] range limits for both sensors (null: the sensor models' range limits, if any)"),
    )
    azimuth_deg: tuple[float, float] | None = field(
        default=None,
        metadata=doc(
            "[start, end] azimuth sector, counter-clockwise from +x, for both sensors (null: the models' sector, or "
            "360 deg)"
        ),
    )
    margin_deg: float = field(
        default=0.0, metadata=doc("widen the angular limits by this much on each side (negative: narrow them)")
    )

    def __post_init__(self):
        if self.elevation_deg is not None and not self.elevation_deg[0] < self.elevation_deg[1]:
            raise ValueError(f"elevation_deg must be [lo, hi] with lo < hi, got {list(self.elevation_deg)}")
        if self.range_m is not None and not 0 <= self.range_m[0] < self.range_m[1]:
            raise ValueError(f"range_m must be [min, max] with 0 <= min < max, got {list(self.range_m)}")


@dataclass(frozen=True)
class Limits:
    """What one sensor can see: elevation [lo, hi] deg, range [min, max] m, azimuth sector or None."""

    elevation_deg: tuple[float, float]
    range_m: tuple[float, float] = (0.0, math.inf)
    azimuth_deg: tuple[float, float] | None = None


def sensor_limits(model: SensorModel | None, params: Params, lidar: str) -> Limits:
    """The limits of a lidar ("sensor 1", a rig's lidar): the parameters where given, else its model."""
    if params.elevation_deg is None and model is None:
        raise NotApplicableError(
            f"field_of_view: {lidar} has no sensor model, so its elevation limits are unknown: "
            "give the sensor (--sensor, or 'sensor' in the pair's config) or field_of_view's elevation_deg"
        )
    elevation = params.elevation_deg or model.elevation_limits_deg
    if params.range_m is not None:
        range_m = params.range_m
    else:
        range_m = (0.0, math.inf) if model is None else (model.min_range_m, model.max_range_m)
    azimuth = params.azimuth_deg or (None if model is None else model.azimuth_limits_deg)
    return Limits(tuple(elevation), tuple(range_m), azimuth)


# A point on a limit is inside it. A simulated channel lies exactly on its sensor's limit, and
# the rounding of a frame change (1e-15 rad) must not push half of that ring out.
BOUNDARY_TOLERANCE_DEG = 1e-9


def visible(xyz: np.ndarray, limits: Limits, margin_deg: float = 0.0) -> np.ndarray:
    """Mask of the points (in the sensor's frame) inside its limits; boundaries are inside.

    The elevation test ``lo <= atan2(z, h) <= hi`` is done as ``tan(lo) h <= z <= tan(hi) h``
    (h >= 0), and the range test on squared ranges: no trigonometry per point.
    """
    x, y, z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    margin_deg = margin_deg + BOUNDARY_TOLERANCE_DEG
    horizontal2 = x * x + y * y
    horizontal = np.sqrt(horizontal2)
    lo, hi = limits.elevation_deg
    keep = np.ones(len(xyz), dtype=bool)
    if lo - margin_deg > -90.0:
        keep &= z >= math.tan(math.radians(lo - margin_deg)) * horizontal
    if hi + margin_deg < 90.0:
        keep &= z <= math.tan(math.radians(hi + margin_deg)) * horizontal
    r_min, r_max = limits.range_m
    if r_min > 0 or math.isfinite(r_max):
        r2 = horizontal2 + z * z
        keep &= (r2 >= r_min * r_min) & (r2 <= r_max * r_max)
    if limits.azimuth_deg is not None:
        start, end = limits.azimuth_deg
        width = (end - start) % 360.0 + 2 * margin_deg
        if width < 360.0:
            offset = (np.degrees(np.arctan2(y, x)) - (start - margin_deg)) % 360.0
            keep &= offset <= width
    return keep


def field_of_view(pair: RegisteredPair, params: Params) -> tuple[np.ndarray, np.ndarray]:
    """Keep-masks: cloud 1 against the limits of scan 2's lidars, cloud 2 against scan 1's."""
    keep2 = seen_by(pair.xyz2, pair.lidars(1), params)  # sensor 1's missing model is the first error
    return seen_by(pair.xyz1, pair.lidars(2), params), keep2


def seen_by(xyz: np.ndarray, lidars: list[LidarView], params: Params) -> np.ndarray:
    """Mask of the points (frame 1) inside the limits of any of ``lidars``."""
    keep = np.zeros(len(xyz), dtype=bool)
    for lidar in lidars:
        limits = sensor_limits(lidar.sensor, params, lidar.name)
        keep |= visible(in_sensor_frame(xyz, lidar.pose), limits, params.margin_deg)
    return keep
