"""Snakemake's command line on the workflow: --config on top of the default study, --configfile
instead of it, and the commands that only read or print the workflow (a dry run, --lint, --dag,
--summary), which must write nothing and start no process."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from conftest import ROOT
from helpers.workflow import tiny_study, workflow_command, write_study

pytestmark = pytest.mark.slow

# Snakemake, reporting on stderr every process it (or the Snakefile) starts.
AUDITED_SNAKEMAKE = """import sys

def report(event, args):
    if event in ("subprocess.Popen", "os.posix_spawn", "os.exec", "os.fork", "os.system"):
        print("started:", event, repr(args), file=sys.stderr, flush=True)

sys.addaudithook(report)
from snakemake.cli import main
main()
"""


def with_default_study(workdir: Path) -> Path:
    """A working folder holding the default study where Snakemake looks for it."""
    (workdir / "config").mkdir(parents=True)
    shutil.copy(ROOT / "config" / "config.yaml", workdir / "config" / "config.yaml")
    return workdir


def dry_run(workdir: Path, *args: str) -> str:
    """A dry run's output with the shell commands of the jobs it plans."""
    proc = subprocess.run(
        [*workflow_command(workdir), "--dry-run", "--printshellcmds", *args],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout + proc.stderr


def planned_grids(output: str) -> list[dict]:
    """The --grid settings of the field jobs of a dry run's shell commands."""
    return [json.loads(grid) for grid in re.findall(r"lidarfield job field .*? --grid '([^']*)'", output)]


def test_config_keys_override_the_default_study(tmp_path):
    """`--config results=DIR grid={...}` (no --configfile) plans the default study, its results in
    DIR and its grid with only the given key changed."""
    default = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    output = dry_run(with_default_study(tmp_path), "--config", "results=run1", "grid={azimuth_bins: 18}")
    grids = planned_grids(output)
    # 9 pairs (paper-sim and the drive's 8) x 3 stages
    assert len(grids) == 9 * 3
    assert {json.dumps(grid, sort_keys=True) for grid in grids} == {json.dumps(grids[0], sort_keys=True)}
    assert grids[0]["azimuth_bins"] == 18
    for key in ("elevation_deg", "elevation_bins", "min_points", "kind"):
        assert grids[0][key] == default["grid"][key]
    assert "run1/paper-sim/report.html" in output
    assert "results/" not in output


def test_a_configfile_replaces_the_default_study(tmp_path):
    workdir = with_default_study(tmp_path)
    write_study(workdir, tiny_study())
    output = dry_run(workdir, "--configfile", str(workdir / "study.yaml"), "--config", "grid={min_points: 7}")
    grids = planned_grids(output)
    assert len(grids) == 2 * 3  # the tiny study's pairs and stages, none of the default's
    assert "paper-sim" not in output and "drive-000" not in output
    assert {grid["min_points"] for grid in grids} == {7}
    assert {grid["azimuth_bins"] for grid in grids} == {tiny_study()["grid"]["azimuth_bins"]}


@pytest.mark.parametrize("command", [["--dry-run"], ["--lint"], ["--dag"], ["--summary"]])
def test_reading_or_printing_the_workflow_writes_nothing_and_starts_no_process(tmp_path, command):
    """In a fresh folder: no results/ folder (no worker log, no socket) and no worker process;
    only Snakemake's own .snakemake/ and the processes Snakemake's plugins start."""
    workdir = tmp_path / "study"
    workdir.mkdir()
    write_study(workdir, tiny_study())
    proc = subprocess.run(
        [*workflow_command(workdir, workdir / "study.yaml", [sys.executable, "-c", AUDITED_SNAKEMAKE]), *command],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    started = [line for line in proc.stderr.splitlines() if line.startswith("started:")]
    assert started, "the audit hook saw no process at all: it would not see the worker's either"
    assert not [line for line in started if "lidarfield" in line or sys.executable in line]
    assert sorted(p.name for p in workdir.iterdir()) == [".snakemake", "study.yaml"]
