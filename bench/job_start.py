"""Where one workflow job's time goes: process start and imports, against the work itself.

Re-runs one finished job of each rule of a study (its shell command, as Snakemake recorded it
in ``.snakemake/metadata``) in turn as a plain process (``LIDARFIELD_WORKER=off``, how every
job ran before the worker, and how jobs run on a cluster) and through the pre-imported
worker, interleaved so that both see the same machine load, and prints the median wall time
of each and their ratio; then the packages that take longest to import in each plain job
(``python -X importtime``).

Run after a study, in its folder: python bench/job_start.py [WORKDIR] [--repeat 5]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path

from timing import machine  # bench/timing.py

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
from lidarfield.runner import server as worker  # noqa: E402

HEAVY = (
    "numpy",
    "pyarrow",
    "pandas",
    "matplotlib",
    "open3d",
    "scipy",
    "trimesh",
    "plotly",
    "yaml",
    "jsonschema",
    "lidarfield",
)


def one_job_per_rule(workdir: Path) -> dict[str, str]:
    """``{rule: shell command}`` of the first recorded job of each rule, run as a plain process
    (``python -m lidarfield``, so that a pyenv or conda shim's own start is left out)."""
    jobs: dict[str, str] = {}
    for record in sorted((workdir / ".snakemake" / "metadata").iterdir()):
        meta = json.loads(record.read_text())
        if meta.get("shellcmd", "").startswith("lidarfield job") and meta["rule"] not in jobs:
            jobs[meta["rule"]] = f"{sys.executable} -m " + meta["shellcmd"]
    return jobs


def timed(command: str, workdir: Path, env: dict) -> float:
    start = time.perf_counter()
    subprocess.run(command, shell=True, cwd=workdir, env=env, check=True)
    return time.perf_counter() - start


def import_times(command: str, workdir: Path) -> dict[str, float]:
    """Cumulative import seconds of the top-level packages of ``HEAVY`` in one plain run."""
    env = {**os.environ, "LIDARFIELD_WORKER": "off"}
    stderr = subprocess.run(
        command.replace(" -m lidarfield", " -X importtime -m lidarfield").split(" > ")[0],
        shell=True,
        cwd=workdir,
        env=env,
        capture_output=True,
        text=True,
    ).stderr
    seconds: dict[str, float] = defaultdict(float)
    for line in stderr.splitlines():
        match = re.match(r"import time:\s+\d+ \|\s+(\d+) \| (\s*)(\S+)", line)
        if match and match.group(3) in HEAVY:
            seconds[match.group(3)] = max(seconds[match.group(3)], int(match.group(1)) / 1e6)
    return seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "workdir", type=Path, nargs="?", default=Path("."), help="where the study ran (holds .snakemake/)"
    )
    parser.add_argument("--results", default="results")
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    jobs = one_job_per_rule(args.workdir)
    print(machine())
    os.chdir(args.workdir)
    thread_env = {name: "1" for name in worker.THREAD_VARS}  # as Snakemake runs a 1-thread job
    plain_env = {**os.environ, **thread_env, "LIDARFIELD_WORKER": "off"}
    worker.start(args.results)
    try:
        worked_env = {**os.environ, **thread_env}
        timed(next(iter(jobs.values())), args.workdir, worked_env)  # waits for the worker's imports
        times = defaultdict(lambda: defaultdict(list))
        for _ in range(args.repeat):
            for rule, command in jobs.items():
                times[rule]["plain"].append(timed(command, args.workdir, plain_env))
                times[rule]["worker"].append(timed(command, args.workdir, worked_env))
    finally:
        worker.stop()
    print(f"median wall time of one job, of {args.repeat} runs each, interleaved:")
    print(f"{'rule':<12} {'plain s':>8} {'worker s':>9} {'ratio':>6}")
    for rule in jobs:
        plain, forked = (statistics.median(times[rule][k]) for k in ("plain", "worker"))
        print(f"{rule:<12} {plain:>8.2f} {forked:>9.2f} {forked / plain:>6.2f}")
    print("imports of the plain job (cumulative s, python -X importtime):")
    for rule, command in jobs.items():
        seconds = import_times(command, args.workdir)
        print(
            f"{rule:<12} " + ", ".join(f"{name} {s:.2f}" for name, s in sorted(seconds.items(), key=lambda kv: -kv[1]))
        )


if __name__ == "__main__":
    main()
