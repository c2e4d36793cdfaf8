"""Lidar sensor models: the channel elevations, azimuth sampling, range limits and rotation rate.

A model travels with a scan (in its Parquet metadata) because the ``field_of_view`` hypothesis
needs the limits of the *other* sensor, and the simulator needs the beams.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..errors import ConfigError
from ..yaml_file import read_yaml


@dataclass(frozen=True)
class SensorModel:
    name: str
    elevation_deg: tuple[float, ...]  # one angle per channel (ring), degrees
    azimuth_resolution_deg: float = 0.2
    min_range_m: float = 0.0
    max_range_m: float = float("inf")
    rotation_hz: float = 10.0
    # Azimuth field of view as [start, end] degrees (counter-clockwise from +x); None = 360.
    azimuth_limits_deg: tuple[float, float] | None = None

    @property
    def elevation_limits_deg(self) -> tuple[float, float]:
        return float(min(self.elevation_deg)), float(max(self.elevation_deg))

    @property
    def firings_per_revolution(self) -> int:
        """Azimuth steps in a revolution: the resolution rounded to a whole number of steps
        (the simulator fires step j at ``360 j / n`` deg; Ouster columns are locked likewise)."""
        return max(1, int(round(360.0 / self.azimuth_resolution_deg)))

    @property
    def channels(self) -> int:
        return len(self.elevation_deg)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["elevation_deg"] = list(self.elevation_deg)
        if self.azimuth_limits_deg is not None:
            d["azimuth_limits_deg"] = list(self.azimuth_limits_deg)
        if not np.isfinite(self.max_range_m):
            d["max_range_m"] = None
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "SensorModel":
        known = {f for f in cls.__dataclass_fields__}
        unknown = set(d) - known
        if unknown:
            raise ConfigError(f"sensor model: unknown key(s) {sorted(unknown)}; expected {sorted(known)}")
        if "elevation_deg" not in d or "name" not in d:
            raise ConfigError("sensor model: needs at least 'name' and 'elevation_deg'")
        kw = dict(d)
        kw["elevation_deg"] = tuple(float(a) for a in d["elevation_deg"])
        if kw.get("max_range_m") is None:
            kw["max_range_m"] = float("inf")
        if kw.get("azimuth_limits_deg") is not None:
            kw["azimuth_limits_deg"] = tuple(float(a) for a in kw["azimuth_limits_deg"])
        return cls(**kw)


def _uniform(first_deg: float, step_deg: float, n: int) -> tuple[float, ...]:
    return tuple(round(first_deg + i * step_deg, 6) for i in range(n))


# Elevation tables from the manufacturers' manuals. The HDL-32E and the HDL-64E upper block are
# spaced in exact thirds of a degree (-30.67 = -92/3, +10.67 = 32/3, -8.33 = -25/3).
_HDL32_ELEVATION = _uniform(-92.0 / 3.0, 4.0 / 3.0, 32)
# Velodyne VLP-32C: the user manual's vertical angle of each laser ID 0..31, in laser-ID order
# (the firing order, not sorted: ring k is laser ID k, as Argoverse 2's laser_number counts
# them); -25..+15 deg, beams 1/3 deg apart near the horizon and sparser away from it.
_VLP32C_ELEVATION = tuple(
    float(a)
    for a in """
    -25 -1 -1.667 -15.639 -11.31 0 -0.667 -8.843 -7.254 0.333 -0.333 -6.148 -5.333 1.333 0.667 -4
    -4.667 1.667 1 -3.667 -3.333 3.333 2.333 -2.667 -3 7 4.667 -2.333 -2 15 10.333 -1.333
    """.split()
)
# Hesai Pandar40P: the default angle-correction table of Hesai's drivers (line 1..40), -25..+15
# deg, 1/3 deg apart from -6 to +2 deg and gaps of 3 to 6 deg at both edges (14 -> 19 -> 25
# below, 5 -> 8 -> 11 -> 15 above): a "gradient" layout.
_PANDAR40P_ELEVATION = tuple(
    float(a)
    for a in """
    15 11 8 5 3 2 1.67 1.33 1 0.67 0.33 0 -0.33 -0.67 -1 -1.33 -1.66 -2 -2.33 -2.67
    -3 -3.33 -3.67 -4 -4.33 -4.67 -5 -5.33 -5.67 -6 -7 -8 -9 -10 -11 -12 -13 -14 -19 -25
    """.split()
)
PRESETS: dict[str, SensorModel] = {
    # The source paper's simulated sensor: 80 channels 0.4 deg apart from -22 deg upward,
    # whole scan at one instant.
    "paper-sim-80": SensorModel("paper-sim-80", _uniform(-22.0, 0.4, 80), 0.2, 0.0, 200.0, 10.0),
    # Velodyne VLP-16: 16 channels 2 deg apart, -15..+15 deg, 100 m.
    "vlp16": SensorModel("vlp16", _uniform(-15.0, 2.0, 16), 0.2, 0.5, 100.0, 10.0),
    # Velodyne HDL-32E: 32 channels from -30.67 to +10.67 deg, 1.33 deg apart, 100 m.
    "hdl32": SensorModel("hdl32", _HDL32_ELEVATION, 0.16, 1.0, 100.0, 10.0),
    # Velodyne HDL-64E: upper block +2..-8.33 deg (1/3 deg steps), lower block -8.83..-24.33
    # deg (1/2 deg steps), 120 m. Azimuth: ~20,800 firings per laser per second, so 0.1728 deg
    # at 10 Hz (the datasheet's 0.09 deg holds at 5 Hz).
    "hdl64": SensorModel(
        "hdl64",
        _uniform(-24.33, 0.5, 32) + _uniform(-25.0 / 3.0, 1.0 / 3.0, 32),
        0.1728,
        0.9,
        120.0,
        10.0,
    ),
    # Velodyne VLP-32C: 32 channels, -25..+15 deg at the datasheet's non-uniform angles (ring =
    # laser ID), 200 m, 0.2 deg at 10 Hz; the datasheet gives no minimum range, so none is set.
    # Argoverse 2's two roof lidars are VLP-32Cs.
    "vlp32c": SensorModel("vlp32c", _VLP32C_ELEVATION, 0.2, 0.0, 200.0, 10.0),
    # Hesai Pandar40P: 40 channels, -25..+15 deg (the table above), 0.3..200 m, 0.2 deg at 10 Hz.
    "pandar40p": SensorModel("pandar40p", _PANDAR40P_ELEVATION, 0.2, 0.3, 200.0, 10.0),
    # Ouster OS1-128 (rev 7): 128 channels uniform over -22.5..+22.5 deg, 1024 columns at 10 Hz.
    "os1-128": SensorModel("os1-128", _uniform(-22.5, 45.0 / 127.0, 128), 360.0 / 1024, 0.3, 200.0, 10.0),
}


def sensor_model(spec: str | dict | SensorModel | None) -> SensorModel | None:
    """A sensor model from a preset name, a YAML file path, a dict, or a model."""
    if spec is None or isinstance(spec, SensorModel):
        return spec
    if isinstance(spec, dict):
        return SensorModel.from_dict(spec)
    if spec in PRESETS:
        return PRESETS[spec]
    path = Path(spec)
    if path.suffix in (".yaml", ".yml"):
        model = read_yaml(path, "sensor model")
        if not isinstance(model, dict):
            raise ConfigError("a sensor model is a mapping with at least 'name' and 'elevation_deg'", path)
        try:
            return SensorModel.from_dict(model)
        except ConfigError as e:
            raise ConfigError(str(e), path) from None
        except (TypeError, ValueError) as e:
            raise ConfigError(f"not a sensor model: {e}", path) from None
    raise ConfigError(f"unknown sensor {spec!r}; available presets: {', '.join(sorted(PRESETS))} (or a YAML file)")
