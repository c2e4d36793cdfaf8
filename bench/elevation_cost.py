"""Benchmark: what ``elevation_calibration`` as a default candidate costs ``explain`` (issue 36).

On zoo cases (a control and ``channel_elevation`` at each level, per base pair), ``explain`` as
``lidarfield explain`` runs it without a config, with the default candidates and with them less
``elevation_calibration``, in turn in one process (the CPU time of each, ``time.process_time``),
and what each proposed. Run: ``python bench/elevation_cost.py [--base NAME ...] [--points N]``.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from helpers.fault_zoo import CONTROL, LEVELS, Case, default_study, faulted_pair, load_base  # noqa: E402
from lidarfield.commands.scans import explain_with_study  # noqa: E402
from lidarfield.hypotheses import BUILTINS  # noqa: E402

NAME = "elevation_calibration"


def explain_cpu(pair, name: str, with_it: bool) -> tuple[float, str]:
    """CPU seconds of explain on the pair, with or without the candidate, and its stack."""
    entry = BUILTINS[NAME]
    if not with_it:
        del BUILTINS[NAME]
    try:
        start = time.process_time()
        explanation = explain_with_study(pair, default_study(), name)
        return time.process_time() - start, " > ".join(row["hypothesis"] for row in explanation.steps)
    finally:
        BUILTINS[NAME] = entry


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", action="append", default=[])
    parser.add_argument("--points", type=int, default=20_000)
    args = parser.parse_args()
    logging.disable(logging.WARNING)
    warnings.simplefilter("ignore")
    total = {True: 0.0, False: 0.0}
    for base_name in args.base:
        base = load_base(base_name, args.points)
        for case in [Case(base_name, CONTROL, "")] + [Case(base_name, "channel_elevation", lv) for lv in LEVELS]:
            pair = faulted_pair(base, case)
            runs = {with_it: explain_cpu(pair, case.name, with_it) for with_it in (False, True)}
            for with_it, (cpu, _) in runs.items():
                total[with_it] += cpu
            (cpu_without, stack_without), (cpu_with, stack_with) = runs[False], runs[True]
            print(f"{case.name}: without {cpu_without:.2f} s [{stack_without}], with {cpu_with:.2f} s [{stack_with}]")
    print(f"total CPU: without {total[False]:.1f} s, with {total[True]:.1f} s, ratio {total[True] / total[False]:.3f}")


if __name__ == "__main__":
    main()
