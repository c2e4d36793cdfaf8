"""The first pair of issue 27's drive (bench/drive.py): the paper intersection seen by the
80-channel sensor 3 m up, driving at 3 m/s round the crossing's centre (radius 2.5 m), 10 frames
a second, rolling shutter, 1 cm range noise; for the ring-normal tests and bench/ring_normals.py."""

from __future__ import annotations

from lidarfield.pair import RegisteredPair
from lidarfield.registration import register_pair
from lidarfield.sensors.models import PRESETS
from lidarfield.simulation.raycast import simulate_scan
from lidarfield.simulation.scene import load_scene
from lidarfield.simulation.trajectory import arc_trajectory

RATE_HZ = 10.0


def drive_pair() -> RegisteredPair:
    """Frames 0 and 1 (about 87,000 points each), registered by the truth."""
    scene, model = load_scene("paper-intersection"), PRESETS["paper-sim-80"]
    frames = arc_trajectory([0, 0], 2.5, 0.0, 3.0, RATE_HZ, 2, 3.0)
    scans = [
        simulate_scan(
            scene,
            model,
            frame.pose,
            time_s=k / RATE_HZ,
            seed=k + 1,
            range_noise_m=0.01,
            rolling_shutter=True,
            linear_velocity_mps=frame.linear_velocity_mps,
            angular_velocity_rps=frame.angular_velocity_rps,
        )
        for k, frame in enumerate(frames)
    ]
    return register_pair(scans[0], scans[1], "truth")
