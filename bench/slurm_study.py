"""The smoke study (config/smoke.yaml) through the SLURM profile against the same study run
locally: wall times and their ratio, measured in the same run.

Starts a single-node cluster with scripts/slurm-cluster.sh (root; see tests/workflow/test_slurm.py),
or uses a running one if SLURM_CONF is set. Each run starts from an empty folder.

    python bench/slurm_study.py
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from timing import machine  # bench/timing.py

ROOT = Path(__file__).resolve().parents[1]
SNAKEMAKE = [sys.executable, "-m", "snakemake", "--snakefile", str(ROOT / "Snakefile")]
SMOKE = ROOT / "config" / "smoke.yaml"


def timed_run(workdir: Path, *args: str, env=None) -> float:
    start = time.perf_counter()
    subprocess.run(
        [*SNAKEMAKE, "--directory", str(workdir), "--configfile", str(SMOKE), *args],
        check=True,
        capture_output=True,
        env=env,
    )
    return time.perf_counter() - start


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        cluster = None
        env = dict(os.environ)
        if "SLURM_CONF" not in env:
            cluster = tmp / "cluster"
            subprocess.run([str(ROOT / "scripts" / "slurm-cluster.sh"), "start", str(cluster)], check=True)
            env["SLURM_CONF"] = str(cluster / "etc" / "slurm.conf")
        try:
            local = timed_run(tmp / "local", "--cores", "2")
            slurm = timed_run(
                tmp / "slurm",
                "--profile",
                str(ROOT / "profiles" / "slurm"),
                "--default-resources",
                "slurm_partition=test",
                env=env,
            )
        finally:
            if cluster:
                subprocess.run([str(ROOT / "scripts" / "slurm-cluster.sh"), "stop", str(cluster)], check=True)
    print(machine())
    print(f"smoke study, local --cores 2:        {local:.1f} s")
    print(f"smoke study through profiles/slurm:      {slurm:.1f} s ({slurm / local:.2f}x local)")


if __name__ == "__main__":
    main()
