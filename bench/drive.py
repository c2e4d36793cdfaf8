"""A simulated drive through the whole workflow, as issue 27 measured it: cold, then after
appending one hypothesis; old code against new in the same run.

The drive: the paper's intersection, N pairs of consecutive frames (rolling shutter, 1 cm range
noise, ``register: truth``), stack ``field_of_view``, ``shadow``, ``ego_vehicle``, default
figures and suggestions. For each code tree given (``--code``, a checkout with its ``src`` and
``Snakefile``; default: this one) it runs ``snakemake --cores 2`` in a fresh folder and prints,
for the cold run and for the rerun after appending ``crop`` (``--append outliers``: a hypothesis
that removes points): wall time, the CPU user and system time of every process it started, the
largest process's peak memory, and the bytes and files the run left; per rule, the jobs' time
(Snakemake's benchmark files) and CPU time (the job worker's log); then the planning time of
``snakemake -n`` for the drive. Each tree's jobs import
its own ``src`` (PYTHONPATH), so two trees compare in one run:

    python bench/drive.py --pairs 100 --code /work/main --code .      # old, then new
    python bench/drive.py --pairs 1000                                 # this tree only
    python bench/drive.py --plan-only --pairs 5000                     # planning only
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import yaml

from study_time import job_seconds  # bench/study_time.py
from timing import machine  # bench/timing.py

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from helpers.drive import SIMULATION  # noqa: E402 (the drive, defined once with the tests' pair of it)
from helpers.workflow import workflow_command  # noqa: E402 (the workflow's command, as the tests run it)

# what an append adds: a crop beyond the drive's points (it removes none), or one that removes some
APPENDED = {"crop": {"max_range_m": 60}, "outliers": {}}
TIME = "/usr/bin/time"  # GNU time


def drive(pairs: int) -> dict:
    return {
        "results": "results",
        "sequences": {
            "drive": {
                "simulate": {**SIMULATION, "trajectory": {**SIMULATION["trajectory"], "frames": pairs + 1}},
                "register": "truth",
            }
        },
        "grid": {"kind": "spherical", "azimuth_bins": 36, "elevation_deg": [-22.5, 15], "elevation_bins": 5},
        "hypotheses": [
            {"field_of_view": {}},
            {"shadow": {"jump_m": 1.0, "min_points": 30, "origins": [1, 2]}},
            {"ego_vehicle": {}},
        ],
    }


@dataclass
class Run:
    wall_s: float
    user_s: float
    system_s: float
    peak_mb: float  # the largest process's resident peak
    bytes: int  # left in the folder
    files: int


def folder_size(folder: Path) -> tuple[int, int]:
    sizes = [p.stat().st_size for p in folder.rglob("*") if p.is_file() and not p.is_symlink()]
    return sum(sizes), len(sizes)


def snakemake(code: Path, workdir: Path, *args: str) -> Run:
    """One snakemake run of ``code``'s workflow in ``workdir``."""
    env = {**os.environ, "PYTHONPATH": str(code / "src")}
    command = [*workflow_command(workdir, workdir / "study.yaml", snakefile=code / "Snakefile"), "--cores", "2", *args]
    bytes_before, files_before = folder_size(workdir)
    # GNU time: the CPU of snakemake and every process it waited for (the job worker waits for
    # the jobs it forks), and the largest one's peak resident memory, for this run alone
    usage = workdir / "time.txt"
    start = time.perf_counter()
    with open(workdir / "snakemake.log", "a") as log:
        proc = subprocess.run(
            [TIME, "-f", "%U %S %M", "-o", str(usage), *command], stdout=log, stderr=subprocess.STDOUT, env=env
        )
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        sys.exit(f"snakemake {' '.join(args)} failed in {workdir}: see {workdir / 'snakemake.log'}")
    user, system, peak_kb = usage.read_text().split()[-3:]
    usage.unlink()
    size, files = folder_size(workdir)
    return Run(wall, float(user), float(system), int(peak_kb) / 1024, size - bytes_before, files - files_before)


def row(label: str, run: Run) -> str:
    return (
        f"| {label} | {run.wall_s:.1f} s | {run.user_s:.1f} s | {run.system_s:.1f} s | {run.peak_mb:.0f} MB "
        f"| {run.bytes / 1e9:.2f} GB | {run.files:,} |"
    )


def per_rule(by_rule: dict[str, list[float]], what: str) -> str:
    total = sum(sum(t) for t in by_rule.values())
    parts = sorted(((sum(t), rule, len(t)) for rule, t in by_rule.items()), reverse=True)
    # every rule: seconds, share, jobs and seconds a job (the per-rule figures of bench/RESULTS.md)
    return f"{total:.0f} s of {what}: " + ", ".join(
        f"{rule} {s:.1f} s {s / total:.0%} ({n}, {s / n:.2f} s)" for s, rule, n in parts
    )


def job_time(results: Path, since: float = 0.0) -> str:
    return per_rule(job_seconds(results, since), "job time")


WORKER_JOB = re.compile(r"job \d+ ([\w-]+): .*?, [\d.]+ s wall, ([\d.]+) s CPU")


def jobs_cpu(results: Path) -> str:
    """The jobs' CPU time per rule, from the last run's lines of the job worker's log (one line a
    job, after the worker's first): less sensitive to the machine's load than wall time."""
    log = results / "logs" / "worker.log"
    lines = log.read_text().splitlines() if log.is_file() else []
    start = max((i for i, line in enumerate(lines) if "imports took" in line), default=len(lines))
    by_rule: dict[str, list[float]] = defaultdict(list)
    for match in filter(None, map(WORKER_JOB.search, lines[start:])):
        by_rule[match[1].replace("-", "_")].append(float(match[2]))
    return per_rule(by_rule, "jobs' CPU") if by_rule else "no job worker's log"


def bench(code: Path, pairs: int, workdir: Path, plan_only: bool, appended: str = "crop") -> list[str]:
    workdir.mkdir(parents=True)
    study = drive(pairs)
    (workdir / "study.yaml").write_text(yaml.safe_dump(study, sort_keys=False))
    plan = snakemake(code, workdir, "--dry-run", "--quiet")
    rows = [row(f"{code.name}: plan (`snakemake -n`)", plan)]
    if plan_only:
        return rows
    cold = snakemake(code, workdir)
    rows.append(row(f"{code.name}: cold", cold))
    print(f"  {code.name} cold: {job_time(workdir / 'results')}", flush=True)
    print(f"  {code.name} cold: {jobs_cpu(workdir / 'results')}", flush=True)
    study["hypotheses"].append({appended: APPENDED[appended]})
    (workdir / "study.yaml").write_text(yaml.safe_dump(study, sort_keys=False))
    since = time.time()
    rows.append(row(f"{code.name}: appending `{appended}`", snakemake(code, workdir)))
    print(f"  {code.name} append: {job_time(workdir / 'results', since)}", flush=True)
    print(f"  {code.name} append: {jobs_cpu(workdir / 'results')}", flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--pairs", type=int, default=100, help="the drive's length in pairs")
    parser.add_argument("--code", type=Path, action="append", help="a code tree to run (repeat: in turn)")
    parser.add_argument("--plan-only", action="store_true", help="only snakemake -n")
    parser.add_argument("--workdir", type=Path, help="where the runs go (default: a new temporary folder)")
    parser.add_argument("--append", choices=sorted(APPENDED), default="crop", help="the hypothesis appended")
    args = parser.parse_args()
    workdir = args.workdir or Path(tempfile.mkdtemp(prefix="drive-"))
    print(machine())
    print(f"drive of {args.pairs} pairs x 4 stages, in {workdir}", flush=True)
    rows = []
    for index, code in enumerate(args.code or [ROOT]):
        folder = workdir / f"{index}-{code.resolve().name}"
        rows += bench(code.resolve(), args.pairs, folder, args.plan_only, args.append)
    print("| run | wall | CPU user | CPU system | peak memory | bytes left | files left |")
    print("|---|---|---|---|---|---|---|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
