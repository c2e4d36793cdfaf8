"""Benchmark: ``realign`` against the tool's registrations on the real shared pairs, each started
0.3 m and 0.5 deg off the pair's reference pose (``tests/helpers/real_pairs.py`` defines the
pairs, the starts and the measure).

Per pair and method, from the reference itself and from each start: the median over scan 2's
points of ``|T p - T_ref p|`` (cm), ``T`` where the method lands; then the distance between
every two landings from the first start (the methods' spread, which with the references'
disagreement says what a reference is worth). ``realign`` runs as the suggestions run it: on the
pair registered at the start (a transform), with both sensor models, default parameters. The
registrations: ``register_pair`` with ``guess`` the start, default settings. ``--variants`` adds
realign's diagnostic variants (without the sensor models: no ring normals and no refit on the
shared points; 200 iterations; every point of cloud 2), and GICP, NDT and point-to-plane ICP on
the points both sensors could see with sensor 2 where ``realign`` lands (the points its refit
uses).

Run: ``OMP_NUM_THREADS=1 python bench/realign_real.py [--variants] [--pairs expd,hdl32,...]``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from timing import machine  # bench/timing.py

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("LIDARFIELD_DATA", ROOT.parent / "shared" / "data"))
sys.path.insert(0, str(ROOT / "tests"))
from helpers.real_pairs import (  # noqa: E402 (the tests' pairs)
    OFFSETS,
    PAIRS,
    REGISTRATIONS,
    point_distance_cm,
    real_pair,
    realigned,
    registered,
    shared_pair,
)


def runs(real, diagnose: bool) -> dict:
    """Each method's run by name: start pose -> landing pose."""
    out = {m: (lambda s, m=m: registered(real, m, s)) for m in REGISTRATIONS}
    out["realign"] = lambda s: realigned(real, s)
    if diagnose:
        out["realign, no models"] = lambda s: realigned(real, s, models=False)
        out["realign, 200 iterations"] = lambda s: realigned(real, s, {"max_iterations": 200})
        out["realign, all of cloud 2"] = lambda s: realigned(real, s, {"max_points": 10**7})
        for m in REGISTRATIONS[:3]:  # on what both sensors saw, as realign's refit
            out[f"{m} on the shared points"] = lambda s, m=m: registered(shared_pair(real, realigned(real, s)), m, s)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", action="store_true", help="add realign's diagnostic variants")
    parser.add_argument("--pairs", default=",".join(PAIRS), help=f"comma-separated, of: {', '.join(PAIRS)}")
    args = parser.parse_args()
    print(machine())
    print(f"load average {os.getloadavg()[0]:.2f}; OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}")
    starts = {"reference": np.eye(4), **OFFSETS}
    for name in args.pairs.split(","):
        real = real_pair(DATA, name)
        xyz2 = real.scan2.xyz
        print(f"\n## {real.name}: {len(real.scan1)} + {len(real.scan2)} points")
        if real.other_reference is not None:
            print(f"its two references: {point_distance_cm(real.other_reference, real.reference, xyz2):.2f} cm apart")
        print("| method | from " + " | from ".join(starts) + " | seconds (mean) |")
        landed = {}
        for method, run in runs(real, args.variants).items():
            cells, seconds = [], []
            for start_name, offset in starts.items():
                began = time.perf_counter()
                T = run(offset @ real.reference)
                seconds.append(time.perf_counter() - began)
                cells.append(f"{point_distance_cm(T, real.reference, xyz2):.2f}")
                if start_name == next(iter(OFFSETS)):
                    landed[method] = T
            print(f"| {method} | " + " | ".join(cells) + f" | {np.mean(seconds):.2f} |", flush=True)
        print("landings from the first start, cm apart:")
        for a in landed:
            print(f"  {a:28s}" + " ".join(f"{point_distance_cm(landed[a], landed[b], xyz2):6.2f}" for b in landed))
    print(f"\nload average {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
