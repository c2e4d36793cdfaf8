"""Where a field job's CPU goes: the workflow's field job (``commands.jobs.field_stage``) on the
drive's first pair (``bench/drive.py``'s simulation and stack), run in this process, each of its
steps timed where the job calls it.

The drive's pair (frames 0 and 1, registered by the truth) and its stages 0-3 (``field_of_view``,
``shadow``, ``ego_vehicle``) are written as the workflow writes them (``stack_jobs``), then each
stage's field job is run again ``--repeat`` times with no previous stage's field to take (every
field computed). A step's time is its CPU time (user + system of this process) inclusive of the
steps it calls, the median over the runs of every stage; indented steps are inside the one
above. Run: python bench/field_job.py [--repeat R]
"""

from __future__ import annotations

import argparse
import importlib
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from drive import drive  # bench/drive.py
from timing import machine  # bench/timing.py

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from helpers.drive import drive_pair  # noqa: E402 (the drive's first pair, as the tests build it)
from lidarfield.commands import jobs  # noqa: E402
from lidarfield.pair import write_pair  # noqa: E402
from lidarfield.storage.stage_ids import stage_ids  # noqa: E402

# (module, function, depth): the steps timed, in the order a field job calls them
STEPS = (
    ("lidarfield.commands.jobs", "field_stage", 0),
    ("lidarfield.commands.jobs", "read_stage_points", 1),
    ("lidarfield.analysis.suggest", "points_digest", 1),
    ("lidarfield.commands.jobs", "analyse_field", 1),
    ("lidarfield.analysis.field_stats", "pair_field", 2),
    ("lidarfield.field.pair_field", "pair_binning", 3),
    ("lidarfield.field.pair_field", "shared_points", 3),
    ("lidarfield.field.free_space", "lidar_images", 4),
    ("lidarfield.field.free_space", "any_lidar", 4),
    ("lidarfield.field.pair_field", "field_from_voxel_ids", 3),
    ("lidarfield.analysis.field_stats", "field_rigid_part", 2),
    ("lidarfield.analysis.field_stats", "voxel_tags", 2),
    ("lidarfield.analysis.tags", "_near_fov_edge", 3),
    ("lidarfield.analysis.tags", "_near_a_sensor", 3),
    ("lidarfield.analysis.tags", "_on_depth_edge", 3),
    ("lidarfield.analysis.field_stats", "field_statistics", 2),
    ("lidarfield.analysis.field_stats", "randomness_tests", 3),
    ("lidarfield.commands.jobs", "write_field", 1),
)


def timed(spent: dict[str, list[float]], module, name: str) -> None:
    """Replace ``module.name`` by a wrapper adding each call's CPU time to ``spent[name]``."""
    function = getattr(module, name)

    def wrapper(*args, **kwargs):
        start = time.process_time()
        try:
            return function(*args, **kwargs)
        finally:
            spent[name][-1] += time.process_time() - start

    setattr(module, name, wrapper)


def stage_folders(root: Path) -> tuple[Path, list[dict], list[Path], dict]:
    """The drive's first pair written in ``root`` with its stages' changes and fields."""
    study = drive(1)
    steps, grid = study["hypotheses"], study["grid"]
    registered = root / "registered.parquet"
    write_pair(registered, drive_pair())
    folders = [root / "stages" / stage for stage in stage_ids({"pair": "drive-000"}, steps)]
    for folder in folders:
        folder.mkdir(parents=True)
    jobs.stack_jobs(registered, steps, folders, grid, "drive-000")
    return registered, steps, folders, grid


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=5, help="runs of each stage's field job")
    args = parser.parse_args()
    print(machine())
    modules = {name: importlib.import_module(name) for name in {module for module, _, _ in STEPS}}
    with tempfile.TemporaryDirectory(prefix="field-job-") as folder:
        registered, steps, folders, grid = stage_folders(Path(folder))
        spent: dict[str, list[float]] = defaultdict(list)
        for module, name, _ in STEPS:
            timed(spent, modules[module], name)
        changes = [f / "changes.parquet" for f in folders[1:]]
        for _ in range(args.repeat):
            for level, stage in enumerate(folders):
                for _, name, _ in STEPS:
                    spent[name].append(0.0)
                jobs.field_stage(
                    registered,
                    changes[:level],
                    stage / "removed.parquet" if level else None,
                    grid,
                    "drive-000",
                    Path(folder) / "field.parquet",
                    Path(folder) / "stats.json",
                    stage.name,
                )
    total = float(np.median(spent["field_stage"]))
    print(f"the drive's first pair, stages 0-{len(steps)}, {args.repeat} runs each: median CPU a field job")
    for _, name, depth in STEPS:
        median = float(np.median(spent[name]))
        print(f"{'  ' * depth}{name}: {median * 1e3:.1f} ms ({median / total:.0%})")


if __name__ == "__main__":
    main()
