"""The workflow's Snakemake profiles as Snakemake combines them.

Snakemake reads profiles/default (the workflow profile) even when the user names another
profile, and the workflow profile's keys win: a workstation setting there would silently
replace the cluster's own (as `latency-wait: 5` once replaced the SLURM profile's 60).
"""

from __future__ import annotations

import pytest
import yaml

from conftest import ROOT

PROFILES = ROOT / "profiles"


def profile(name: str) -> dict:
    return yaml.safe_load((PROFILES / name / "config.yaml").read_text())


def test_the_workstation_profile_contradicts_no_other_profile():
    workstation = profile("default")
    others = [path.parent.name for path in PROFILES.glob("*/config.yaml") if path.parent.name != "default"]
    assert others
    for name in others:
        settings = profile(name)
        clashes = {key for key in workstation if key in settings and settings[key] != workstation[key]}
        assert not clashes, f"profiles/default would override profiles/{name}: {sorted(clashes)}"


def test_the_slurm_profile_keeps_its_settings_beside_the_workstation_profile(tmp_path, monkeypatch, capsys):
    pytest.importorskip("snakemake_executor_plugin_slurm")
    from snakemake.cli import parse_args

    monkeypatch.chdir(tmp_path)
    _, args = parse_args(["--snakefile", str(ROOT / "Snakefile"), "--profile", str(PROFILES / "slurm")])
    assert "workflow specific profile" in capsys.readouterr().err  # profiles/default was read too
    assert args.executor == "slurm-allocation"
    assert args.latency_wait == 60
    assert args.slurm_allocation_status_command == "squeue"
    assert args.slurm_allocation_pass_command_as_script is True
    assert args.groups["mitigate"] == args.groups["field"] == args.groups["explorer_stage"] == "pair"
    assert args.groups["simulate"] == "scans"
