"""The study level and the overview of a study of many pairs: the voxels table against a pandas
groupby over the same field files (same run), the other tables, the figures, and the
overview's size. The study is synthetic (fields and summary rows only, no points).

Run: python bench/study_level.py [n_pairs (1000)] [levels (4)]
"""

from __future__ import annotations

import resource
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

from lidarfield.plots.study import plot_study
from lidarfield.report import write_overview
from lidarfield.study.tables import read_study_tables, write_study_tables, write_study_voxels
from timing import machine  # bench/timing.py

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the tests' synthetic study
from helpers.synthetic_study import write_field_study  # noqa: E402


def pandas_voxels(fields: list[Path]) -> pd.DataFrame:
    """The voxel medians the plain way: every field read whole into one frame, then groupby."""
    frames = []
    for path in fields:
        df = pd.read_parquet(path)
        df["pair"], df["level"] = path.parents[2].name, int(path.parent.name[:2])
        frames.append(df)
    valid = pd.concat(frames, ignore_index=True).query("valid")
    return valid.groupby(["level", "voxel"])[["u", "v", "w", "magnitude"]].median()


def timed(label: str, function):
    start = time.perf_counter()
    result = function()
    seconds = time.perf_counter() - start
    print(f"{label}: {seconds:.2f} s", flush=True)
    return seconds, result


def main() -> None:
    n_pairs = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    levels = int(sys.argv[2]) if len(sys.argv) > 2 else 4
    print(machine())
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        timed(
            f"synthetic study of {n_pairs} pairs x {levels} stages",
            lambda: write_field_study(root, n_pairs, levels, n=3000),
        )
        fields = sorted(root.glob("*/stages/*/field.parquet"))
        ours, _ = timed(
            f"voxels.parquet from {len(fields)} field files",
            lambda: write_study_voxels(fields, root / "study" / "voxels.parquet"),
        )
        plain, _ = timed("the same medians by a pandas groupby of whole fields", lambda: pandas_voxels(fields))
        print(f"ratio pandas / ours: {plain / ours:.2f}")
        timed(
            "hypotheses.parquet and pairs.parquet",
            lambda: write_study_tables(
                root / "summary.parquet", root / "study" / "hypotheses.parquet", root / "study" / "pairs.parquet"
            ),
        )
        tables = read_study_tables(root / "summary.parquet", root / "study")
        timed(
            "study figures",
            lambda: plot_study(
                tables.summary, tables.voxels, tables.hypotheses, tables.pairs, tables.grid, root / "study" / "figures"
            ),
        )
        _, out = timed("overview", lambda: write_overview({}, tables, root / "report.html", root / "study" / "figures"))
        print(f"overview: {out.stat().st_size / 1e6:.2f} MB for {n_pairs} pairs")
        print(f"peak memory of this process: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3:.0f} MB")


if __name__ == "__main__":
    main()
