"""The SLURM profile against a running SLURM cluster: a single node started on this machine
from Debian's packages by scripts/slurm-cluster.sh (root and apt-get needed; skipped, with the
reason, otherwise).

config/smoke.yaml runs through a copy of ``profiles/slurm`` with only its partition line edited,
as a user would, and locally; the summaries must be identical. A study whose mitigation raises
for one of its two pairs must fail with that job's log shown, leave no job worker or socket on
the node, and complete when rerun once the mitigation is mended.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
import yaml

from conftest import ROOT
from helpers.workflow import workflow_command

pytestmark = pytest.mark.slow

CLUSTER_SCRIPT = ROOT / "scripts" / "slurm-cluster.sh"
SMOKE = ROOT / "config" / "smoke.yaml"
PROFILE = ROOT / "profiles" / "slurm" / "config.yaml"
# The profile's partition line, and what the test cluster's partition makes it.
PARTITION_LINE = 'slurm_partition: "your_partition"'
TEST_PARTITION_LINE = 'slurm_partition: "test"'
# slurm-cluster.sh's exit status when it cannot install or start SLURM on this machine at all.
CANNOT_RUN_HERE = 3

# Fails for the pair whose scans are more than 0.5 m apart (smoke's "shift", not "turn");
# FAILS_FOR_NONE mends it.
FAILING_PLUGIN = '''"""The failing job of the SLURM test."""

import numpy as np

FAILS_BEYOND_M = {limit}


def remove(pair, params):
    if np.linalg.norm(pair.T_1_2[:3, 3]) > FAILS_BEYOND_M:
        raise RuntimeError("this hypothesis fails on purpose")
    return np.ones(len(pair.xyz1), dtype=bool), np.ones(len(pair.xyz2), dtype=bool)
'''
FAILS_FOR_SHIFT, FAILS_FOR_NONE = 0.5, 1e9


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


@pytest.fixture
def slurm_profile(tmp_path) -> list[str]:
    """The options naming a copy of profiles/slurm whose partition line says the test cluster's."""
    text = PROFILE.read_text()
    assert text.count(PARTITION_LINE) == 1
    folder = tmp_path / "profile"
    folder.mkdir()
    (folder / "config.yaml").write_text(text.replace(PARTITION_LINE, TEST_PARTITION_LINE))
    return ["--profile", str(folder)]


def run_study(workdir: Path, config: Path, *args: str, env=None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*workflow_command(workdir, config), *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=900,
    )


def submissions(log: str) -> int:
    return len(re.findall(r"has been submitted with SLURM jobid", log))


def test_the_smoke_study_through_slurm_matches_the_local_run(slurm_env, slurm_profile, tmp_path):
    local = run_study(tmp_path / "local", SMOKE, "--cores", "2")
    assert local.returncode == 0, local.stderr
    cluster = run_study(tmp_path / "slurm", SMOKE, *slurm_profile, env=slurm_env)
    assert cluster.returncode == 0, cluster.stderr
    summary = Path("results/smoke/summary.csv")
    assert (tmp_path / "slurm" / summary).read_bytes() == (tmp_path / "local" / summary).read_bytes()
    # One allocation for the 4 scans, one for both pairs' chains, one for the study-wide jobs.
    assert submissions(cluster.stderr) == 3, cluster.stderr
    # Each allocation's jobs ran on its job worker: one log line a job. 4 scans; a pair's
    # registration, stage 1's mitigate, 2 stages' field, suggest and figures, its figures and page,
    # its explorer's points and 2 stages' explorer data (13, twice);
    # the summary, the three study-level jobs and the overview (5).
    worker_logs = sorted((tmp_path / "slurm" / "results" / "smoke" / "logs" / "workers").glob("slurm-*.log"))
    assert len(worker_logs) == 3
    assert sum(log.read_text().count(": {'exit': 0}") for log in worker_logs) == 4 + 2 * 13 + 5


def workers_on(node_tmp: Path) -> list[str]:
    """The command lines of the running job workers whose socket is in ``node_tmp``."""
    found = []
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            argv = cmdline.read_bytes().decode(errors="replace").split("\0")
        except OSError:
            continue
        if "lidarfield.runner.server" in argv and any(a.startswith(str(node_tmp)) for a in argv):
            found.append(" ".join(argv))
    return found


@pytest.fixture
def node_tmp():
    """The allocations' node-local folder (sbatch passes the environment on), short: the worker's
    socket lies in it, and under pytest-xdist ``tmp_path`` is too deep for a socket's 107 bytes
    (then no worker starts, as in an allocation whose TMPDIR is that deep)."""
    folder = Path(tempfile.mkdtemp(prefix="lf-node-"))
    yield folder
    shutil.rmtree(folder, ignore_errors=True)


def test_a_failing_job_fails_with_its_log_and_the_rerun_completes(slurm_env, slurm_profile, tmp_path, node_tmp):
    study = yaml.safe_load(SMOKE.read_text())
    study["hypotheses"] = [{"plugin": {"file": "fails.py", "function": "remove"}}]
    (tmp_path / "fails.py").write_text(FAILING_PLUGIN.format(limit=FAILS_FOR_SHIFT))
    config = tmp_path / "failing.yaml"
    config.write_text(yaml.safe_dump(study))
    env = {**slurm_env, "TMPDIR": str(node_tmp)}

    failed = run_study(tmp_path, config, *slurm_profile, env=env)
    assert failed.returncode != 0, failed.stderr
    assert "Error in rule mitigate" in failed.stderr
    results = tmp_path / "results" / "smoke"
    failed_log = next((results / "logs" / "mitigate" / "shift").glob("01-plugin-*.log"))
    assert "fails on purpose" in failed_log.read_text()
    # The job's own log, printed into its allocation's SLURM log, which the run shows.
    assert failed.stderr.count("this hypothesis fails on purpose") >= 1, failed.stderr
    assert not (results / "summary.csv").exists()
    # The batch's other pair ran to its end in the allocation, whatever the run then kept of it.
    pair_worker_log = next(
        log for log in (results / "logs" / "workers").glob("slurm-*.log") if "pair-report" in log.read_text()
    )
    assert pair_worker_log.read_text().count("pair-report: {'exit': 0}") == 1
    # ... and Snakemake removed the failed batch's outputs: the rerun runs it again.
    assert not (results / "turn" / "registered.parquet").exists()
    assert not list(node_tmp.iterdir())
    assert not workers_on(node_tmp)

    (tmp_path / "fails.py").write_text(FAILING_PLUGIN.format(limit=FAILS_FOR_NONE))
    rerun = run_study(tmp_path, config, *slurm_profile, env=env)
    assert rerun.returncode == 0, rerun.stderr
    summary = (results / "summary.csv").read_text()
    assert "shift" in summary and "turn" in summary
    assert not list(node_tmp.iterdir())
    assert not workers_on(node_tmp)
