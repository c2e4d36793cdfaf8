"""Issue 27's drive, defined once: the paper intersection seen by the 80-channel sensor 3 m up,
driving at 3 m/s round the crossing's centre (radius 2.5 m), 10 frames a second, rolling
shutter, 1 cm range noise. ``SIMULATION`` is its config entry (``bench/drive.py`` runs it through
the workflow); ``drive_pair`` its first pair, for the ring-normal tests and bench/ring_normals.py."""

from __future__ import annotations

from lidarfield.pair import RegisteredPair
from lidarfield.registration import register_pair
from lidarfield.sensors.models import PRESETS
from lidarfield.simulation.raycast import simulate_scan
from lidarfield.simulation.scene import load_scene
from lidarfield.simulation.trajectory import arc_trajectory

# 3 m/s round the crossing's centre, 10 frames a second: 0.3 m and 6.9 deg from frame to frame,
# every pose at least 3.1 m from every building, so a drive of any length sees the whole scene
# (a straight drive out of the 26 m scene would see less and less of it, and nothing past its range).
TRAJECTORY = {"center_xy": [0, 0], "radius_m": 2.5, "start_angle_rad": 0, "speed_mps": 3, "rate_hz": 10, "height_m": 3}
OPTIONS = {"rolling_shutter": True, "range_noise_m": 0.01}
SIMULATION = {"scene": "paper-intersection", "sensor": "paper-sim-80", "trajectory": TRAJECTORY, "options": OPTIONS}


def drive_pair() -> RegisteredPair:
    """Frames 0 and 1 (about 87,000 points each), registered by the truth."""
    scene, model = load_scene(SIMULATION["scene"]), PRESETS[SIMULATION["sensor"]]
    t = TRAJECTORY
    frames = arc_trajectory(
        t["center_xy"], t["radius_m"], t["start_angle_rad"], t["speed_mps"], t["rate_hz"], 2, t["height_m"]
    )
    scans = [
        simulate_scan(
            scene,
            model,
            frame.pose,
            time_s=k / t["rate_hz"],
            seed=k + 1,
            range_noise_m=OPTIONS["range_noise_m"],
            rolling_shutter=OPTIONS["rolling_shutter"],
            linear_velocity_mps=frame.linear_velocity_mps,
            angular_velocity_rps=frame.angular_velocity_rps,
        )
        for k, frame in enumerate(frames)
    ]
    return register_pair(scans[0], scans[1], "truth")
