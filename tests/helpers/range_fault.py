"""The range-fault pair of ``tests/unit/test_range_calibration.py`` and ``bench/range_faults.py``:
the paper's intersection seen twice by one sensor model from about the same place, 3 m up."""

from __future__ import annotations

from lidarfield.poses import pose_from_xyzrpy
from lidarfield.scan import Scan
from lidarfield.sensors.models import PRESETS
from lidarfield.simulation.raycast import simulate_scan
from lidarfield.simulation.scene import load_scene

POSES = ([0, 0, 3, 0, 0, 0], [0, 0, 3, 0, 0, 0.0037])
# A grid of the default's shape whose elevation edges fall between the channels of vlp16, hdl32
# and vlp32c (the default's -20, -12, -4 and +4 deg are hdl32 channels, -4 a vlp32c one).
OFF_CHANNEL_GRID = {"kind": "spherical", "azimuth_bins": 36, "elevation_deg": [-20.5, 19.5], "elevation_bins": 5}


def range_fault_scans(scale: float = 1.0, offset: float = 0.0, sensor: str = "vlp16") -> list[Scan]:
    """Two independent samplings (2 cm range noise, different seeds), sensor 2 yawed 0.21 deg so
    that its rays interleave with sensor 1's, scan 2 measuring ``scale * r + offset``."""
    scene, model = load_scene("paper-intersection"), PRESETS[sensor]
    return [
        simulate_scan(scene, model, pose_from_xyzrpy(POSES[0]), seed=1, range_noise_m=0.02),
        simulate_scan(
            scene,
            model,
            pose_from_xyzrpy(POSES[1]),
            seed=2,
            range_noise_m=0.02,
            range_scale=scale,
            range_offset_m=offset,
        ),
    ]
