"""The SLURM profile against a running SLURM cluster: a single node started on this machine
from Debian's packages by scripts/slurm-cluster.sh (root and apt-get needed; skipped, with the
reason, otherwise).

config/smoke.yaml runs through ``snakemake --profile profiles/slurm`` (only the partition set
on the command line, as a user would) and locally; the summaries must be identical. A study
whose mitigation raises must be reported failed within a minute of the failure, and the run
must exit non-zero.
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml

from conftest import ROOT

pytestmark = pytest.mark.slow

CLUSTER_SCRIPT = ROOT / "scripts" / "slurm-cluster.sh"
SMOKE = ROOT / "config" / "smoke.yaml"
SNAKEMAKE = [sys.executable, "-m", "snakemake", "--snakefile", str(ROOT / "Snakefile")]
SLURM = ["--profile", str(ROOT / "profiles" / "slurm"), "--default-resources", "slurm_partition=test"]
# slurm-cluster.sh's exit status when it cannot install or start SLURM on this machine at all.
CANNOT_RUN_HERE = 3

FAILING_PLUGIN = '''"""Fails on purpose: the failing job of the SLURM test."""


def remove(pair, params):
    raise RuntimeError("this hypothesis fails on purpose")
'''


def why_no_cluster() -> str | None:
    if sys.platform != "linux":
        return "a SLURM test cluster needs Linux"
    if os.geteuid() != 0:
        return "starting slurmd and munged needs root"
    if importlib.util.find_spec("snakemake_executor_plugin_slurm") is None:
        return "snakemake-executor-plugin-slurm is not installed (pip install -e '.[slurm]')"
    return None


@pytest.fixture(scope="module")
def slurm_env(tmp_path_factory):
    """The environment of a submit host of a freshly started single-node cluster."""
    reason = why_no_cluster()
    if reason:
        pytest.skip(reason)
    folder = tmp_path_factory.mktemp("slurm") / "cluster"
    start = subprocess.run([str(CLUSTER_SCRIPT), "start", str(folder)], capture_output=True, text=True)
    if start.returncode == CANNOT_RUN_HERE:
        pytest.skip(start.stderr.strip().splitlines()[-1])
    if start.returncode != 0:
        subprocess.run([str(CLUSTER_SCRIPT), "stop", str(folder)], capture_output=True)
        raise AssertionError(f"the test cluster did not start:\n{start.stderr}")
    try:
        yield {**os.environ, "SLURM_CONF": str(folder / "etc" / "slurm.conf")}
    finally:
        subprocess.run([str(CLUSTER_SCRIPT), "stop", str(folder)], check=True, capture_output=True)


def run_study(workdir: Path, config: Path, *args: str, env=None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*SNAKEMAKE, "--directory", str(workdir), "--configfile", str(config), *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=900,
    )


def submissions(log: str) -> int:
    return len(re.findall(r"has been submitted with SLURM jobid", log))


def test_the_smoke_study_through_slurm_matches_the_local_run(slurm_env, tmp_path):
    local = run_study(tmp_path / "local", SMOKE, "--cores", "2")
    assert local.returncode == 0, local.stderr
    cluster = run_study(tmp_path / "slurm", SMOKE, *SLURM, env=slurm_env)
    assert cluster.returncode == 0, cluster.stderr
    summary = Path("results/smoke/summary.csv")
    assert (tmp_path / "slurm" / summary).read_bytes() == (tmp_path / "local" / summary).read_bytes()
    # 4 scans, then one submission per pair for its whole chain, then one for the study-wide
    # jobs: 7 submissions for 32 jobs.
    assert submissions(cluster.stderr) == 7, cluster.stderr


def test_a_failing_job_is_reported_within_a_minute_and_the_run_fails(slurm_env, tmp_path):
    study = yaml.safe_load(SMOKE.read_text())
    study["pairs"] = {"shift": study["pairs"]["shift"]}
    study["hypotheses"] = [{"plugin": {"file": "fails.py", "function": "remove"}}]
    (tmp_path / "fails.py").write_text(FAILING_PLUGIN)
    config = tmp_path / "failing.yaml"
    config.write_text(yaml.safe_dump(study))

    reported_at: list[float] = []
    proc = subprocess.Popen(
        [*SNAKEMAKE, "--directory", str(tmp_path), "--configfile", str(config), *SLURM],
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
        env=slurm_env,
    )
    lines: list[str] = []

    def read() -> None:
        for line in proc.stderr:
            lines.append(line)
            if line.startswith("Error in rule") and not reported_at:
                reported_at.append(time.time())

    reader = threading.Thread(target=read)
    reader.start()
    code = proc.wait(timeout=600)
    reader.join()
    log = "".join(lines)
    assert code != 0, log
    assert reported_at, log
    # The mitigation's log is written until the job fails.
    failed_log = next((tmp_path / "results" / "smoke" / "logs" / "mitigate" / "shift").glob("01-plugin-*.log"))
    assert "fails on purpose" in failed_log.read_text()
    assert reported_at[0] - failed_log.stat().st_mtime < 60, log
    assert not list((tmp_path / "results" / "smoke").rglob("summary.csv"))
