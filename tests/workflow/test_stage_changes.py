"""Stages stored as their changes, through Snakemake on the default study: the same summary and
fields as the code that stored every stage's survivors, and a deleted change file reruns its
stage and every later one (never a stage read from stale points)."""

from __future__ import annotations

import collections
import json
import re
import shutil
from pathlib import Path

import pytest

from conftest import ROOT
from helpers.fingerprint import differences, fingerprint
from helpers.workflow import snakemake

pytestmark = pytest.mark.slow

TARGET = "results/summary.parquet"  # every stage's field and summary row, no figures


def planned(workdir: Path, *targets: str) -> collections.Counter:
    """Rule name -> number of jobs a dry run for ``targets`` plans."""
    proc = snakemake(workdir, "--dry-run", "--cores", "1", *targets)
    text = proc.stdout + proc.stderr
    if "Nothing to be done" in text:
        return collections.Counter()
    counts = collections.Counter()
    for line in text.split("Job stats:", 1)[1].splitlines():
        match = re.match(r"^(\w+)\s+(\d+)\s*$", line.strip())
        if match and match.group(1) != "total":
            counts[match.group(1)] = int(match.group(2))
    return counts


@pytest.fixture(scope="module")
def default_study(tmp_path_factory) -> Path:
    workdir = tmp_path_factory.mktemp("default-study")
    shutil.copy(ROOT / "config" / "config.yaml", workdir / "study.yaml")
    snakemake(workdir, "--cores", "2", TARGET)
    return workdir


def test_the_default_study_has_the_summary_and_fields_of_the_survivor_copies(default_study):
    """tests/data/default_study.json: the digests main's code (295a3ef, every stage's survivors
    in a points.parquet) wrote for the default study (see tests/helpers/fingerprint.py)."""
    expected = json.loads((ROOT / "tests" / "data" / "default_study.json").read_text())
    assert differences(fingerprint(default_study / "results"), expected) == []


def test_a_deleted_change_file_reruns_its_stage_and_every_later_one(default_study):
    stages = sorted((default_study / "results" / "paper-sim" / "stages").iterdir())
    assert [s.name[:2] for s in stages] == ["00", "01", "02"]
    assert not (stages[0] / "changes.parquet").exists()  # stage 0 changes nothing
    stage0_field = stages[0] / "field.parquet"
    stage0_made = stage0_field.stat().st_mtime_ns
    stages = stages[1:]
    before = {s.name: (s / "changes.parquet").stat().st_mtime_ns for s in stages}
    deleted = stages[0] / "changes.parquet"
    deleted.unlink()
    # The summary alone is up to date (what it was made from has not changed): Snakemake makes
    # a missing intermediate file again only when asked for it, as it does for temp() files.
    assert planned(default_study, TARGET) == {}
    # Asked for: stage 1 again, and stage 2, which reads it, and their fields and the summary;
    # not stage 0's field, no other pair.
    again = str(deleted.relative_to(default_study))
    assert planned(default_study, again, TARGET) == {"mitigate": 2, "field": 2, "summary": 1}
    snakemake(default_study, "--cores", "2", again, TARGET)
    after = {s.name: (s / "changes.parquet").stat().st_mtime_ns for s in stages}
    assert all(after[s.name] > before[s.name] for s in stages)
    assert stage0_field.stat().st_mtime_ns == stage0_made
    expected = json.loads((ROOT / "tests" / "data" / "default_study.json").read_text())
    assert differences(fingerprint(default_study / "results"), expected) == []


def test_the_whole_default_study_runs_to_its_report(default_study):
    """`make run`'s target on the embedded default study, every job: each stage's suggestions
    (the corrections among them move points into voxels the field before had none in) and the
    report."""
    snakemake(default_study, "--cores", "2")
    results = default_study / "results"
    stages = sorted(results.glob("*/stages/*/"))
    assert stages and all((stage / "suggestions.parquet").is_file() for stage in stages)
    assert "<h2>What to try next</h2>" in (results / "report.html").read_text()
