"""A simulated drive through the whole workflow: cold, then after appending one hypothesis.

Runs ``snakemake`` on ``config/drive-100.yaml`` (100 pairs x 4 stages; ``--pairs N`` makes the
drive N pairs long) in a fresh folder, times the cold run and the rerun after appending one
hypothesis to the stack, and prints the mean wall time per job of each rule (from the
workflow's benchmark files), with the job worker on, off (every job its own process, as on a
cluster), or both in turn. ``--plan-pairs N`` also times ``snakemake -n`` of an N-pair drive.

    python bench/study_scale.py                                   # 100 pairs, worker on
    python bench/study_scale.py --config config/config.yaml --worker both   # the default study
    python bench/study_scale.py --pairs 20 --scheduler ilp        # against Snakemake's ILP
    python bench/study_scale.py --plan-only --plan-pairs 1000     # planning a 1,000-pair drive
    python bench/study_scale.py --pairs 20 --schedulers           # ILP vs greedy: Snakemake's own cost
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from study_time import job_seconds  # bench/study_time.py
from timing import machine  # bench/timing.py

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from helpers.workflow import workflow_command  # noqa: E402 (the workflow's command, as the tests run it)

APPENDED = {"ego_vehicle": {"radius_m": 4.1}}


def study_config(config: Path, pairs: int | None) -> dict:
    """The study of ``config`` with its results in ``results`` of the run's folder, and its
    first sequence ``pairs`` pairs long when given."""
    study = yaml.safe_load(config.read_text())
    study["results"] = "results"
    if pairs is not None:
        sequence = next(iter(study["sequences"].values()))
        sequence["simulate"]["trajectory"]["frames"] = pairs + 1
    return study


def snakemake(workdir: Path, worker: str, extra: list[str]) -> tuple[float, float]:
    """One workflow run in ``workdir``: (wall seconds, CPU seconds of all its processes)."""
    env = (
        {**os.environ, "LIDARFIELD_WORKER": "off"}
        if worker == "off"
        else {k: v for k, v in os.environ.items() if k != "LIDARFIELD_WORKER"}
    )
    command = [*workflow_command(workdir, workdir / "study.yaml"), *extra]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    with open(workdir / "snakemake.log", "a") as log:
        proc = subprocess.run(command, stdout=log, stderr=subprocess.STDOUT, env=env)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        sys.exit(f"snakemake {' '.join(extra)} failed in {workdir}: see {workdir / 'snakemake.log'}")
    return wall, (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)


def per_rule(results: Path, since: float = 0.0) -> dict[str, list[float]]:
    """Job wall seconds by rule, of the benchmark files written after ``since`` (epoch s)."""
    return {rule: times for rule, times in job_seconds(results, since).items() if times}


def print_rules(title: str, by_rule: dict[str, list[float]]) -> None:
    total = sum(sum(t) for t in by_rule.values())
    print(f"  {title}: {sum(len(t) for t in by_rule.values())} jobs, {total:.1f} s of job time")
    for rule, times in sorted(by_rule.items(), key=lambda kv: -sum(kv[1])):
        print(f"    {rule:<12} {len(times):>5} jobs  mean {sum(times) / len(times):6.2f} s  {sum(times) / total:6.1%}")


def cold_and_append(config: Path, pairs: int | None, worker: str, workdir: Path, extra: list[str]) -> None:
    workdir.mkdir(parents=True)
    study = study_config(config, pairs)
    (workdir / "study.yaml").write_text(yaml.safe_dump(study, sort_keys=False))
    cold, cold_cpu = snakemake(workdir, worker, extra)
    print(f"worker {worker}: cold {cold:.1f} s wall ({cold_cpu:.1f} s CPU)")
    print_rules("cold run", per_rule(workdir / "results"))

    study["hypotheses"].append(APPENDED)
    (workdir / "study.yaml").write_text(yaml.safe_dump(study, sort_keys=False))
    since = time.time()
    rerun, rerun_cpu = snakemake(workdir, worker, extra)
    print(
        f"worker {worker}: appending {APPENDED} reruns in {rerun:.1f} s wall ({rerun_cpu:.1f} s CPU), "
        f"{rerun / cold:.1%} of cold"
    )
    print_rules("rerun", per_rule(workdir / "results", since))


def scheduler_cost(workdir: Path) -> None:
    """Snakemake's own cost of running the finished study's DAG under each scheduler: every
    job "run" by touching its outputs (``--touch --forceall``), so only scheduling is left."""
    for scheduler in ("ilp", "greedy"):
        wall, cpu = snakemake(workdir, "off", ["--touch", "--forceall", "--cores", "2", "--scheduler", scheduler])
        print(f"scheduler {scheduler}: all jobs touched in {wall:.1f} s wall, {cpu:.1f} s CPU")


def plan(config: Path, pairs: int, workdir: Path) -> None:
    workdir.mkdir(parents=True)
    (workdir / "study.yaml").write_text(yaml.safe_dump(study_config(config, pairs), sort_keys=False))
    wall, cpu = snakemake(workdir, "on", ["--dry-run", "--quiet", "--cores", "2"])
    print(f"planning {pairs} pairs (snakemake -n): {wall:.1f} s wall, {cpu:.1f} s CPU")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--config", type=Path, default=ROOT / "config" / "drive-100.yaml")
    parser.add_argument("--pairs", type=int, help="the drive's length in pairs (default: the config's)")
    parser.add_argument("--worker", choices=("on", "off", "both"), default="on")
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument("--scheduler", choices=("greedy", "ilp"), help="default: the profile's (greedy)")
    parser.add_argument("--plan-pairs", type=int, help="also time snakemake -n of a drive this long")
    parser.add_argument("--plan-only", action="store_true", help="only the planning")
    parser.add_argument(
        "--schedulers", action="store_true", help="then compare the ILP and greedy schedulers' own cost"
    )
    parser.add_argument("--workdir", type=Path, help="where the runs go (default: a new temporary folder)")
    args = parser.parse_args()
    workdir = args.workdir or Path(tempfile.mkdtemp(prefix="study-scale-"))
    extra = ["--cores", str(args.cores)] + (["--scheduler", args.scheduler] if args.scheduler else [])
    print(machine())
    print(f"{args.config.name}, {args.pairs or 'its'} pairs, in {workdir}")
    if not args.plan_only:
        for worker in ("on", "off") if args.worker == "both" else (args.worker,):
            cold_and_append(args.config, args.pairs, worker, workdir / f"worker-{worker}", extra)
        if args.schedulers:
            scheduler_cost(workdir / f"worker-{'off' if args.worker == 'off' else 'on'}")
    if args.plan_pairs or args.plan_only:
        plan(args.config, args.plan_pairs or args.pairs or 1000, workdir / "plan")


if __name__ == "__main__":
    main()
