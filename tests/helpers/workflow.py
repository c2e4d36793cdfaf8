"""The tiny study and the Snakemake command of the workflow tests (tests/workflow/test_workflow.py,
tests/workflow/test_worker.py) and of the workflow benchmarks (bench/study_scale.py,
bench/slurm_study.py)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import yaml

from conftest import ROOT

SNAKEMAKE = [sys.executable, "-m", "snakemake"]  # this environment's

# A small sensor keeps the tiny study fast: 16 channels, 1 deg azimuth steps.
TINY_SENSOR = {"name": "tiny-16", "elevation_deg": [-22 + 2 * i for i in range(16)], "azimuth_resolution_deg": 1.0}


def tiny_study() -> dict:
    simulate = {"scene": "paper-intersection", "sensor": TINY_SENSOR, "pose1": [0, 0, 3, 0, 0, 0]}
    return {
        "pairs": {
            "shift": {"simulate": {**simulate, "pose2": [1, 1, 3, 0, 0, 0.05]}, "register": "truth"},
            "turn": {"simulate": {**simulate, "pose2": [0, 0, 3, 0, 0, 0.2]}, "register": "truth"},
        },
        "grid": {"azimuth_bins": 18, "elevation_deg": [-25, 12.5], "elevation_bins": 5, "min_points": 5},
        "hypotheses": [
            {"ego_vehicle": {"radius_m": 8.0}},
            {"field_of_view": {}},
        ],
        "plots": {"background_points": 2000, "interactive": False},
        # Not the default candidates: three check the rule; outliers' neighbour searches only add time.
        "suggest": [{"ego_vehicle": {}}, {"field_of_view": {}}, {"shadow": {}}],
    }


def workflow_command(
    workdir: Path, configfile: Path | None = None, program: list[str] = SNAKEMAKE, snakefile: Path = ROOT / "Snakefile"
) -> list[str]:
    """``program`` (Snakemake) running ``snakefile`` (this repository's) in ``workdir`` on
    ``configfile`` (None: Snakemake's own default, config/config.yaml in ``workdir``)."""
    command = [*program, "--snakefile", str(snakefile), "--directory", str(workdir)]
    return command if configfile is None else [*command, "--configfile", str(configfile)]


def snakemake(workdir: Path, *args: str, check: bool = True) -> subprocess.CompletedProcess:
    proc = subprocess.run(
        [*workflow_command(workdir, workdir / "study.yaml"), *args],
        capture_output=True,
        text=True,
    )
    if check and proc.returncode != 0:
        raise AssertionError(f"snakemake {' '.join(args)} failed:\n{proc.stdout}\n{proc.stderr}")
    return proc


def write_study(workdir: Path, study: dict) -> None:
    (workdir / "study.yaml").write_text(yaml.safe_dump(study, sort_keys=False))
