"""Benchmark: ``range_calibration`` over a grid of range faults, on simulated ``hdl32``, ``vlp32c``
and ``vlp16`` pairs: the field's RMS magnitude after it over the fault-free pair's.

The pairs: ``tests/helpers/range_fault.py``'s (the paper's intersection seen twice from about
the same place, 3 m up, 2 cm range noise, different seeds, sensor 2 yawed 0.21 deg),
registered by the truth, scan 2 measured with ``range_scale`` in 0.995..1.005 and
``range_offset_m`` in -5..5 cm. Per case: the fitted scale and offset's errors, and the ratio
``rms after / rms of the fault-free pair`` (the issue's target: within 1.2), on the default grid
and on a grid of the same shape whose elevation edges fall between every channel of the three
sensors (``[-20.5, 19.5]`` deg; the default's edges at -20, -12, -4 and +4 deg are ``hdl32``
channels, -4 a ``vlp32c`` one). The fault-free pair's own field is given too (the ratio's
denominator), with ``range_calibration`` applied to it.

Run: ``python bench/range_faults.py [--sensors hdl32,vlp32c,vlp16] [--scales ...] [--offsets ...]``.
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace
from pathlib import Path

from lidarfield.analysis.field_stats import analyse_field
from lidarfield.field.grid import field_settings_from_config
from lidarfield.hypotheses import apply_step
from lidarfield.registration import register_pair
from timing import machine  # bench/timing.py

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from helpers.range_fault import OFF_CHANNEL_GRID, range_fault_scans  # noqa: E402 (the tests' pair)

GRIDS = {"default": {}, "off-channel": OFF_CHANNEL_GRID}


def rms(pair, grid: dict) -> float:
    return float(analyse_field(pair, field_settings_from_config(grid))[1]["rms_magnitude"])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sensors", default="hdl32,vlp32c,vlp16")
    parser.add_argument("--scales", default="0.995,0.998,1.0,1.002,1.005")
    parser.add_argument("--offsets", default="-0.05,-0.02,0.0,0.02,0.05", help="metres")
    args = parser.parse_args()
    print(machine())
    print(f"load average {os.getloadavg()[0]:.2f}")
    for name in args.sensors.split(","):

        def pair(scale: float = 1.0, offset: float = 0.0):
            return register_pair(*range_fault_scans(scale, offset, name), "truth")

        truth = pair()
        outcome = apply_step(truth, {"range_calibration": {}})
        calibrated = replace(truth, xyz2=outcome.xyz2)
        free = {g: rms(truth, settings) for g, settings in GRIDS.items()}
        print(f"\n## {name}: {len(truth.xyz1)} + {len(truth.xyz2)} points")
        print(
            "fault-free field rms: "
            + ", ".join(
                f"{g} {v * 100:.2f} cm (after range_calibration {rms(calibrated, GRIDS[g]) * 100:.2f})"
                for g, v in free.items()
            )
            + f"; fit on it: scale {outcome.fitted['scale']:.5f}, offset {outcome.fitted['offset_m'] * 1000:.1f} mm"
        )
        print(
            "| scale | offset (cm) | fitted scale - scale | fitted offset - offset (mm) | "
            + " | ".join(f"rms before / free, {g} | after / free, {g}" for g in GRIDS)
            + " |"
        )
        for scale in (float(s) for s in args.scales.split(",")):
            for offset in (float(o) for o in args.offsets.split(",")):
                if scale == 1.0 and offset == 0.0:
                    continue
                faulty = pair(scale, offset)
                outcome = apply_step(faulty, {"range_calibration": {}})
                fixed = replace(faulty, xyz2=outcome.xyz2)
                c = outcome.fitted
                cells = []
                for g, settings in GRIDS.items():
                    cells += [f"{rms(faulty, settings) / free[g]:.2f}", f"{rms(fixed, settings) / free[g]:.2f}"]
                errors = f"{c['scale'] - scale:+.5f} | {(c['offset_m'] - offset) * 1000:+.1f}"
                print(f"| {scale} | {offset * 100:g} | {errors} | " + " | ".join(cells) + " |", flush=True)
    print(f"\nload average {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
