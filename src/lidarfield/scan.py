"""A single lidar scan: points in its sensor frame, per-point attributes, sensor model and pose."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .sensors.models import SensorModel
from .sensors.rig import Lidar, check_lidar_ids

# Attributes the contracts know; readers may add others (kept as they are). ``object`` is a
# simulated point's label: the moving object it hit, 0 for the static scene.
KNOWN_ATTRIBUTES = ("intensity", "ring", "time", "object", "lidar")
# The first word of a simulated scan's ``source`` (lidarfield.simulation.raycast): its pose is
# the simulation's, exact.
SIMULATED = "simulated"


def still_sweep() -> dict:
    """The ``sweep_motion`` of a scan whose points carry no motion (taken still, or de-skewed)."""
    return {"velocity_mps": [0.0, 0.0, 0.0], "angular_velocity_rps": [0.0, 0.0, 0.0]}


@dataclass
class Scan:
    xyz: np.ndarray  # (N, 3) float64, metres, sensor frame
    attributes: dict[str, np.ndarray] = field(default_factory=dict)  # each of length N
    sensor: SensorModel | None = None
    pose: np.ndarray | None = None  # 4x4 world-from-sensor, when known
    source: str | None = None  # where the scan came from (file path or simulation spec)
    dropped_invalid: int = 0  # rows dropped by the reader for NaN / infinite coordinates
    stamp_s: float | None = None  # when the scan was taken (s since the epoch; a bag's header stamp)
    # The sensor's motion during the sweep as recorded with the scan, the motion its points carry:
    # {"velocity_mps": [3], "angular_velocity_rps": [3]}, both in its sensor frame at the sweep
    # start (zero for a scan taken still or already de-skewed); None when unknown.
    sweep_motion: dict | None = None
    # The rig when several lidars measured the scan (see lidarfield.sensors.rig; the points'
    # ``lidar`` attribute names each point's); empty: one lidar at the frame's origin.
    lidars: tuple[Lidar, ...] = ()

    def __post_init__(self):
        self.xyz = np.ascontiguousarray(self.xyz, dtype=np.float64).reshape(-1, 3)
        for name, values in self.attributes.items():
            if len(values) != len(self.xyz):
                raise ValueError(f"attribute {name!r} has {len(values)} values for {len(self.xyz)} points")
        if self.pose is not None:
            self.pose = np.asarray(self.pose, dtype=np.float64).reshape(4, 4)
        self.lidars = tuple(self.lidars)
        check_lidar_ids(self.lidars, self.attributes)

    def __len__(self) -> int:
        return len(self.xyz)

    @property
    def simulated(self) -> bool:
        """Whether the simulator made it (its ``source`` says so): its pose is then exact."""
        return (self.source or "").split(" ", 1)[0] == SIMULATED

    def subset(self, mask: np.ndarray) -> "Scan":
        return Scan(
            self.xyz[mask],
            {k: v[mask] for k, v in self.attributes.items()},
            self.sensor,
            self.pose,
            self.source,
            self.dropped_invalid,
            self.stamp_s,
            self.sweep_motion,
            self.lidars,
        )
