"""Studies through the SLURM profile against the same studies run locally, back to back: wall
times and their ratio, byte-identical summaries, and what each allocation cost.

The smoke study (config/smoke.yaml) and the 100-pair drive of bench/study_scale.py
(config/drive-100.yaml), each run locally (``--cores 2``, job worker on) and then through a copy
of profiles/slurm with only its partition line edited, as a user would. Starts a single-node
cluster with scripts/slurm-cluster.sh (root; see tests/workflow/test_slurm.py), or uses a
running one if SLURM_CONF is set (its partition: ``--partition``). Each run starts from an empty
folder. The allocations' start and end times are read from squeue while the run goes on.

    python bench/slurm_study.py                    # both studies
    python bench/slurm_study.py --study smoke
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import threading
import time
from datetime import datetime
from pathlib import Path

import yaml

from study_scale import study_config  # bench/study_scale.py
from timing import machine  # bench/timing.py

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from helpers.workflow import workflow_command  # noqa: E402 (the workflow's command, as the tests run it)

STUDIES = {"smoke": ROOT / "config" / "smoke.yaml", "drive-100": ROOT / "config" / "drive-100.yaml"}
PARTITION_LINE = 'slurm_partition: "your_partition"'


def user_profile(folder: Path, partition: str) -> Path:
    """A copy of profiles/slurm with its partition line edited."""
    text = (ROOT / "profiles" / "slurm" / "config.yaml").read_text()
    folder.mkdir(parents=True)
    (folder / "config.yaml").write_text(text.replace(PARTITION_LINE, f'slurm_partition: "{partition}"'))
    return folder


class Allocations:
    """The SLURM jobs' start and end times, read from ``squeue -t all`` every second."""

    def __init__(self, env: dict):
        self.env = env
        self.times: dict[str, tuple[str, str]] = {}
        self.earlier = {line.split()[0] for line in self.squeue()}  # jobs of earlier runs
        self.done = threading.Event()
        self.thread = threading.Thread(target=self.watch, daemon=True)

    def squeue(self) -> list[str]:
        return subprocess.run(
            ["squeue", "-h", "-t", "all", "-o", "%i %S %e %T"], capture_output=True, text=True, env=self.env
        ).stdout.splitlines()

    def watch(self) -> None:
        while not self.done.wait(1.0):
            for line in self.squeue():
                job, start, end, state = line.split()
                if state in ("COMPLETED", "FAILED") and job not in self.earlier:
                    self.times[job] = (start, end)

    def __enter__(self) -> Allocations:
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        time.sleep(2.0)  # the last allocation's end
        self.done.set()
        self.thread.join()

    def seconds(self) -> list[float]:
        return [
            (datetime.fromisoformat(end) - datetime.fromisoformat(start)).total_seconds()
            for start, end in self.times.values()
        ]


def timed_run(workdir: Path, config: Path, *args: str, env=None) -> float:
    workdir.mkdir(parents=True)
    study = study_config(config, None)
    (workdir / "study.yaml").write_text(yaml.safe_dump(study, sort_keys=False))
    start = time.perf_counter()
    with open(workdir / "snakemake.log", "w") as log:
        proc = subprocess.run(
            [*workflow_command(workdir, workdir / "study.yaml"), *args],
            stdout=log,
            stderr=subprocess.STDOUT,
            env=env,
        )
    if proc.returncode != 0:
        sys.exit(f"snakemake {' '.join(args)} failed in {workdir}: see {workdir / 'snakemake.log'}")
    return time.perf_counter() - start


def job_seconds(workdir: Path) -> float:
    """The summed wall time of the jobs the allocations' workers ran (their logs)."""
    total = 0.0
    for log in (workdir / "results" / "logs" / "workers").glob("slurm-*.log"):
        for line in log.read_text().splitlines():
            if "{'exit'" in line:
                total += float(line.split("}, ")[1].split(" s wall")[0])
    return total


def compare(name: str, tmp: Path, profile: Path, env: dict) -> None:
    config = STUDIES[name]
    local = timed_run(tmp / name / "local", config, "--cores", "2")
    with Allocations(env) as allocations:
        slurm = timed_run(tmp / name / "slurm", config, "--profile", str(profile), env=env)
    summary = Path("results") / "summary.csv"
    same = (tmp / name / "slurm" / summary).read_bytes() == (tmp / name / "local" / summary).read_bytes()
    walls = allocations.seconds()
    jobs = job_seconds(tmp / name / "slurm")
    print(f"{name}, local --cores 2:                {local:7.1f} s")
    print(f"{name}, through profiles/slurm:         {slurm:7.1f} s ({slurm / local:.2f}x local)")
    print(f"  summaries byte-identical: {same}")
    print(
        f"  {len(walls)} allocations, {sum(walls):.0f} s of allocation wall time in all "
        f"(each {min(walls):.0f}-{max(walls):.0f} s); their jobs' summed wall time {jobs:.0f} s"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--study", choices=("smoke", "drive-100", "both"), default="both")
    parser.add_argument("--partition", default="test", help="of a running cluster (SLURM_CONF set)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        cluster = None
        env = dict(os.environ)
        if "SLURM_CONF" not in env:
            cluster = tmp / "cluster"
            subprocess.run([str(ROOT / "scripts" / "slurm-cluster.sh"), "start", str(cluster)], check=True)
            env["SLURM_CONF"] = str(cluster / "etc" / "slurm.conf")
        profile = user_profile(tmp / "profile", args.partition)
        print(machine())
        try:
            for name in ("smoke", "drive-100") if args.study == "both" else (args.study,):
                compare(name, tmp, profile, env)
        finally:
            if cluster:
                subprocess.run([str(ROOT / "scripts" / "slurm-cluster.sh"), "stop", str(cluster)], check=True)


if __name__ == "__main__":
    main()
