"""The workflow's scan and registration jobs: a JSON spec from the config in, a Parquet file out.

Each job reads what the config resolved for it (:class:`lidarfield.config.ScanSpec`, the
pair's ``register`` setting) and writes its one output atomically, so a failed job leaves
nothing behind.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from .io import read_scan, write_scan
from .pair import write_pair
from .scan import Scan
from .sensor_fit import log_fit
from .sensors import sensor_model

log = logging.getLogger(__name__)


def simulated_scan(spec: dict) -> Scan:
    """Ray-cast one scan as a :class:`ScanSpec` of kind ``simulated`` describes it."""
    from .scene import load_scene
    from .simulate import simulate_scan

    return simulate_scan(
        load_scene(spec["scene"]),
        sensor_model(spec["sensor"]),
        np.asarray(spec["pose"], dtype=float),
        time_s=spec["time_s"],
        seed=spec["seed"],
        range_noise_m=spec["range_noise_m"],
        dropout=spec["dropout"],
        max_range_m=spec["max_range_m"],
        rolling_shutter=spec["rolling_shutter"],
        linear_velocity_mps=spec["velocity_mps"],
        angular_velocity_rps=spec["angular_velocity_rps"],
    )


def recorded_scan(spec: dict) -> Scan:
    """Read one recorded scan as a :class:`ScanSpec` of kind ``recorded`` describes it."""
    scan = read_scan(spec["path"], format=spec["format"], sensor=spec["sensor"], poses=spec.get("poses"))
    if spec["pose"] is not None:
        scan.pose = np.asarray(spec["pose"], dtype=float)
    return scan


def scan_job(kind: str, spec: dict, out: str | Path) -> None:
    scan = simulated_scan(spec) if kind == "simulated" else recorded_scan(spec)
    log.info("%s scan: %d points (%d invalid rows dropped) -> %s", kind, len(scan), scan.dropped_invalid, out)
    log_fit(scan, spec.get("path") or str(out))
    write_scan(scan, out)


def register_job(scan1: str | Path, scan2: str | Path, settings, out: str | Path) -> None:
    from .registration import register_pair

    pair = register_pair(read_scan(scan1), read_scan(scan2), settings)
    reg = pair.registration
    log.info("registration %s: %s", reg.get("method"), {k: v for k, v in reg.items() if k != "method"})
    if reg.get("warning"):
        log.warning("registration of %s to %s: %s", scan2, scan1, reg["warning"])
    write_pair(out, pair)
