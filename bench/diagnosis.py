"""Benchmark: how well does ``lidarfield explain`` diagnose? The fault zoo (issue 36).

Every case is a pair with one known adversity, or none (``tests/helpers/fault_zoo.py``: real
scans of ../shared/data and simulated scenes seen by every preset, faults injected at three
levels); ``explain`` runs on it as ``lidarfield explain`` does without a config, and the case
records what it proposed first, its stack, the verdict at each step and whether the fault was
named (docs/diagnosis.md says which hypothesis names which fault).

Writes to ``--out`` (default ``diagnosis-results``): ``cases.parquet`` (one row per case),
``confusion.md`` and ``confusion.html`` (per sensor, fault x first proposal, and the overall
rates) and ``rates.png`` (the share named by fault and level).

Run: ``python bench/diagnosis.py [--slice small|full] [--base TEXT ...] [--real-pose reference|registered]
[--out DIR] [--points N] [--jobs N]`` (``make diagnosis`` runs the full zoo; ``--base real-hdl32
--base canyon-apart`` only the base pairs whose names hold one of the texts; ``--real-pose
registered`` registers the real base pairs by the tool's GICP from their reference poses, once
per base pair, before the faults).
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import time
import warnings
from multiprocessing import Pool
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from helpers.fault_zoo import (  # noqa: E402
    CONTROL,
    FAULTS,
    LEVELS,
    REAL_POSES,
    UNRATED,
    run_case,
    zoo,
)
from timing import machine  # noqa: E402 (bench/timing.py)

POINTS = 20_000  # per cloud: the whole zoo in under 15 minutes on 2 cores
VISIBLE = ("visible", "obvious")
CORRECTIONS = ("realign", "range_calibration", "deskew", "elevation_calibration")


def run_base(task: tuple[list, int]) -> list[dict]:
    """One base pair's cases, in a worker (it loads the pair once)."""
    logging.disable(logging.WARNING)
    warnings.simplefilter("ignore")
    cases, points = task
    return [run_case(case, points) for case in cases]


def progress(done: int, total: int, start: float) -> None:
    elapsed = time.perf_counter() - start
    left = elapsed / done * (total - done) if done else float("nan")
    bar = "#" * round(30 * done / total)
    print(f"\r[{bar:<30}] {done}/{total} cases, {elapsed:5.0f} s, about {left:4.0f} s left", end="", file=sys.stderr)


def run(slice_name: str, points: int, jobs: int, bases: list[str], real_pose: str) -> pd.DataFrame:
    cases = [case for case in zoo(slice_name, real_pose) if not bases or any(text in case.base for text in bases)]
    if not cases:
        sys.exit(f"no base pair of the {slice_name} zoo holds {' or '.join(bases)}")
    by_base: dict[str, list] = {}
    for case in cases:
        by_base.setdefault(case.base, []).append(case)
    tasks = [(group, points) for group in by_base.values()]
    rows, start = [], time.perf_counter()
    progress(0, len(cases), start)
    with Pool(jobs) as pool:
        for done in pool.imap_unordered(run_base, tasks):
            rows += done
            progress(len(rows), len(cases), start)
    print(file=sys.stderr)
    order = {case.name: k for k, case in enumerate(cases)}
    table = pd.DataFrame(rows).sort_values("case", key=lambda c: c.map(order)).reset_index(drop=True)
    for column in ("named", "named_strict", "named_displacement"):  # a case not built (its error said) named nothing
        table[column] = table[column].fillna(False).astype(bool)
    return table


def rates(table: pd.DataFrame) -> pd.DataFrame:
    """Per sensor, per source (real, simulated) and in all: the share of faulted cases at the visible levels whose first
    proposal names the fault (also strictly, and at the barely visible level), and of controls
    read right. The faults left out of the rates (``UNRATED``) are left out of the faulted shares."""
    ok = table[table["error"] == ""]
    nameable = ok[ok["fault"].map(lambda f: f != CONTROL and f not in UNRATED)]
    out = []
    groups = [("sensor", name) for name in sorted(set(ok["sensor"]))] + [("source", "real"), ("source", "simulated")]
    for column, sensor in [*groups, ("source", "all")]:
        chosen = (ok[column] == sensor) | (sensor == "all")
        part, controls = nameable[chosen[nameable.index]], ok[chosen & (ok["fault"] == CONTROL)]
        seen = part[part["level"].isin(VISIBLE)]
        barely = part[part["level"] == "barely"]
        out.append(
            {
                "sensor": sensor,
                "visible cases": len(seen),
                "named first (visible, obvious)": seen["named"].mean(),
                "strictly first": seen["named_strict"].mean(),
                "named first (barely)": barely["named"].mean(),
                "random after the correction": corrected(seen),
                "controls": len(controls),
                "controls right": controls["named"].mean(),
            }
        )
    return pd.DataFrame(out)


def corrected(part: pd.DataFrame) -> float:
    """Of the cases whose first step is the correction that names the fault (realign,
    range_calibration, deskew, elevation_calibration), the share whose field reads random after it."""
    fixed = part[part["named"] & part["first"].isin(CORRECTIONS)]
    return (fixed["verdict_after_first"] == "random").mean() if len(fixed) else np.nan


def confusion(part: pd.DataFrame) -> pd.DataFrame:
    """Fault x first proposal (``proposal``: what the pair holds by construction passed over),
    counts over every level, and the controls."""
    first = part["proposal"].replace("", "(nothing)")
    faults = [f for f in (CONTROL, *FAULTS) if f in set(part["fault"])]
    table = pd.crosstab(part["fault"], first).reindex(faults).fillna(0).astype(int)
    table["named"] = part.groupby("fault")["named"].sum().reindex(faults).astype(int)
    return table


def percent(x: float) -> str:
    return "-" if not np.isfinite(x) else f"{100 * x:.0f}%"


def write_outputs(table: pd.DataFrame, out: Path, header: str) -> None:
    out.mkdir(parents=True, exist_ok=True)
    table.to_parquet(out / "cases.parquet", index=False)
    summary = rates(table)
    formatted = summary.copy()
    shares = ("named first (visible, obvious)", "strictly first", "named first (barely)", "random after the correction")
    for column in (*shares, "controls right"):
        formatted[column] = formatted[column].map(percent)
    ok = table[table["error"] == ""]
    md, html = [header, "", "## Overall", "", formatted.to_markdown(index=False)], [f"<p>{header}</p>"]
    html += ["<h2>Overall</h2>", formatted.to_html(index=False)]
    for sensor, part in ok.groupby("sensor"):
        matrix = confusion(part)
        md += ["", f"## {sensor}", "", matrix.to_markdown()]
        html += [f"<h2>{sensor}</h2>", matrix.to_html()]
    failed = table[table["error"] != ""]
    if len(failed):
        md += ["", "## Cases not built", ""] + [f"- {r.case}: {r.error}" for r in failed.itertuples()]
    (out / "confusion.md").write_text("\n".join(md) + "\n")
    (out / "confusion.html").write_text("<!doctype html><meta charset=utf-8>\n" + "\n".join(html) + "\n")
    rates_figure(ok, out / "rates.png")


def rates_figure(table: pd.DataFrame, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    faulted = table[table["fault"] != CONTROL]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), sharey=True)
    for ax, source in zip(axes, ("real", "simulated")):
        part = faulted[faulted["source"] == source]
        for k, fault in enumerate(FAULTS):
            share = part[part["fault"] == fault].groupby("level")["named"].mean().reindex(LEVELS)
            if share.notna().any():
                style = {"color": plt.cm.tab20(k / len(FAULTS)), "marker": "os^vD"[k % 5]}
                ax.plot(LEVELS, 100 * share.values, label=fault, **style)
        ax.set_title(f"{source} base pairs ({len(part)} faulted cases)")
        ax.set_xlabel("fault level (magnitudes per fault: docs/diagnosis.md)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("first proposal names the fault (% of cases)")
    axes[0].set_ylim(-5, 105)
    axes[1].legend(loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--slice", choices=("small", "full"), default="full")
    parser.add_argument("--base", action="append", default=[], help="only the base pairs whose names hold this text")
    parser.add_argument(
        "--real-pose",
        choices=REAL_POSES,
        default=REAL_POSES[0],
        help="register the real base pairs by their reference poses (default), or by the tool's GICP from them",
    )
    parser.add_argument("--out", type=Path, default=Path("diagnosis-results"))
    parser.add_argument("--points", type=int, default=POINTS, help=f"per cloud, at most (default {POINTS:,})")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    parser.add_argument("--tables-from", type=Path, help="a cases.parquet: write its tables and figure, run nothing")
    args = parser.parse_args()
    if args.tables_from:
        table = pd.read_parquet(args.tables_from)
        write_outputs(table, args.out, f"{len(table)} cases of {args.tables_from}")
        return
    start = time.perf_counter()
    table = run(args.slice, args.points, args.jobs, args.base, args.real_pose)
    wall = time.perf_counter() - start
    chosen = "".join(f", bases holding {text}" for text in args.base)
    header = (
        f"{len(table)} cases ({args.slice} zoo{chosen}, real base pairs registered by {args.real_pose} poses), "
        f"at most {args.points:,} points per cloud, "
        f"{args.jobs} workers: "
        f"{wall:.0f} s wall, {table['cpu_seconds'].sum():.0f} s of CPU in the cases (faults, registration, explain); "
        f"{machine()}, load average {os.getloadavg()[0]:.1f} at the end"
    )
    write_outputs(table, args.out, header)
    print(header)
    print((args.out / "confusion.md").read_text().split("## ", 2)[1])


if __name__ == "__main__":
    main()
