"""The Snakemake workflow, run through Snakemake itself on a tiny study.

One full run, then dry runs that check which jobs each kind of config change plans: the
content-addressed stage ids must rerun exactly what a change touches.
"""

from __future__ import annotations

import collections
import os
import re
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pandas as pd
import pytest

from conftest import ROOT
from helpers.workflow import snakemake, tiny_study, workflow_command, write_study

pytestmark = pytest.mark.slow

SUMMARY_TARGET = "results/summary.parquet"  # every stage's field and the summary, no figures

PLUGIN_SOURCE = '''"""Keeps points above a height: a plugin for the workflow tests."""
import numpy as np


def remove(pair, params):
    return pair.xyz1[:, 2] > params["min_z_m"], pair.xyz2[:, 2] > params["min_z_m"]
'''


def planned_jobs(workdir: Path) -> collections.Counter:
    """Rule name -> number of jobs a dry run plans."""
    proc = snakemake(workdir, "--dry-run", "--cores", "1")
    text = proc.stdout + proc.stderr
    if "Nothing to be done" in text:
        return collections.Counter()
    table = text.split("Job stats:", 1)[1]
    counts = collections.Counter()
    for line in table.splitlines():
        match = re.match(r"^(\w+)\s+(\d+)\s*$", line.strip())
        if match and match.group(1) not in ("total", "all"):  # all: the target rule, no work
            counts[match.group(1)] = int(match.group(2))
    return counts


def planned_after(workdir: Path, edit) -> collections.Counter:
    """The jobs a dry run plans after ``edit(study)``; the study is restored afterwards."""
    study = tiny_study()
    edit(study)
    write_study(workdir, study)
    try:
        return planned_jobs(workdir)
    finally:
        write_study(workdir, tiny_study())


@pytest.fixture(scope="module")
def study_dir(tmp_path_factory) -> Path:
    """A workdir where the tiny study has run to completion once."""
    workdir = tmp_path_factory.mktemp("tiny-study")
    (workdir / "hypotheses").mkdir()
    (workdir / "hypotheses" / "high.py").write_text(PLUGIN_SOURCE)
    write_study(workdir, tiny_study())
    snakemake(workdir, "--cores", "2")
    return workdir


def test_full_run_writes_every_stage_and_the_report(study_dir):
    summary = pd.read_parquet(study_dir / "results" / "summary.parquet")
    assert sorted(summary["pair"].unique()) == ["shift", "turn"]
    assert sorted(summary["level"].unique()) == [0, 1, 2]
    assert list(summary.sort_values(["pair", "level"])["hypothesis"][:3]) == ["none", "ego_vehicle", "field_of_view"]
    for pair in ("shift", "turn"):
        rows = summary[summary["pair"] == pair].set_index("level")
        assert rows.loc[1, "removed1"] > 0 and rows.loc[1, "removed2"] > 0  # the ground ring at 7.4 m < 8 m
        assert rows.loc[2, "n1"] == rows.loc[1, "n1"] - rows.loc[2, "removed1"]
        assert rows.loc[0, "voxels_valid"] > 0
    # field_of_view: the shifted sensor sees other parts of the scene; the turned one, on the
    # same spot, sees all that the other sees.
    levels = summary.set_index(["pair", "level"])
    assert levels.loc[("shift", 2), "removed1"] > 0 and levels.loc[("shift", 2), "removed2"] > 0
    assert levels.loc[("turn", 2), "removed1"] == 0 and levels.loc[("turn", 2), "removed2"] == 0
    for pair, stage in zip(summary["pair"], summary["stage"]):
        assert stage in (study_dir / "results" / pair / "report.html").read_text()
    csv = pd.read_csv(study_dir / "results" / "summary.csv")
    assert len(csv) == len(summary) == 6
    # What to try next, per stage, from the config's candidates.
    for pair, stage in zip(summary["pair"], summary["stage"]):
        table = pd.read_parquet(study_dir / "results" / pair / "stages" / stage / "suggestions.parquet")
        assert sorted(table["hypothesis"]) == ["ego_vehicle", "field_of_view", "shadow"]
        assert list(table["rank"]) == [1, 2, 3]


def test_full_run_writes_the_study_level_and_a_page_per_pair(study_dir):
    results = study_dir / "results"
    voxels = pd.read_parquet(results / "study" / "voxels.parquet")
    assert sorted(voxels["level"].unique()) == [0, 1, 2] and (voxels["pairs"] == 2).all()
    assert len(pd.read_parquet(results / "study" / "hypotheses.parquet")) == 2 * 2
    assert sorted(pd.read_parquet(results / "study" / "pairs.parquet")["pair"]) == ["shift", "turn"]
    assert {p.name for p in (results / "study" / "figures").glob("*.png")} == {
        "heatmap.png",
        "hypotheses.png",
        "all_pairs.png",
        "voxels_00.png",
        "voxels_01.png",
        "voxels_02.png",
    }
    overview = (results / "report.html").read_text()
    for pair in ("shift", "turn"):
        assert f'href="{pair}/report.html"' in overview
        page = (results / pair / "report.html").read_text()
        assert "field_3d.html" not in page or "interactive 3-D view" in page
        assert page.count("field from above</figcaption>") == 3 and 'class="missing"' not in page
        # the explorer: the pair's points (the sample, the rest) and one data file per stage, loaded by the page
        stages = sorted(p.name for p in (results / pair / "stages").iterdir())
        explorer = sorted(p.name for p in (results / pair / "explorer").iterdir())
        assert explorer == sorted(["points.js", "rest.js", *(f"{s}.js" for s in stages)])
        assert all(f'"explorer/{name}"' in page for name in explorer)  # the explorer's spec lists them


def test_unchanged_config_plans_nothing(study_dir):
    assert planned_jobs(study_dir) == collections.Counter()


def test_appending_a_hypothesis_plans_one_stage_per_pair(study_dir):
    jobs = planned_after(study_dir, lambda s: s["hypotheses"].append({"crop": {"max_range_m": 40.0}}))
    assert jobs == {
        "mitigate": 2,
        "field": 2,
        "suggest": 2,
        "plot_stage": 2,
        "explorer_stage": 2,
        "plot_pair": 2,
        "summary": 1,
        "study_voxels": 1,
        "study_tables": 1,
        "study_figures": 1,
        "pair_report": 2,
        "report": 1,
    }


def test_editing_hypothesis_two_replans_stage_two_only(study_dir):
    jobs = planned_after(study_dir, lambda s: s["hypotheses"].__setitem__(1, {"field_of_view": {"margin_deg": 1.0}}))
    assert jobs == {
        "mitigate": 2,
        "field": 2,
        "suggest": 2,
        "plot_stage": 2,
        "explorer_stage": 2,
        "plot_pair": 2,
        "summary": 1,
        "study_voxels": 1,
        "study_tables": 1,
        "study_figures": 1,
        "pair_report": 2,
        "report": 1,
    }


def test_editing_the_grid_replans_only_fields_plots_and_report(study_dir):
    jobs = planned_after(study_dir, lambda s: s["grid"].update(azimuth_bins=36))
    assert jobs == {
        "field": 6,
        "suggest": 6,
        "plot_stage": 6,
        "explorer_stage": 6,
        "plot_pair": 2,
        "summary": 1,
        "study_voxels": 1,
        "study_tables": 1,
        "study_figures": 1,
        "pair_report": 2,
        "report": 1,
    }


def test_changing_the_candidates_replans_only_the_suggestions(study_dir):
    planned = planned_after(study_dir, lambda s: s.update(suggest=[{"outliers": {"nb_neighbors": 8}}]))
    assert planned == {"suggest": 6, "pair_report": 2, "report": 1}


def test_choosing_the_plotted_pairs_replans_only_their_pages(study_dir):
    assert planned_after(study_dir, lambda s: s["plots"].update(pairs=["shift"])) == {"pair_report": 1, "report": 1}
    assert planned_after(study_dir, lambda s: s["plots"].update(pairs="none")) == {"pair_report": 2, "report": 1}


def test_a_pair_left_out_of_plots_pairs_gets_its_figures_on_demand(study_dir):
    """Without its stage figures on disk, the pair's page with them plans their plot jobs."""
    results = study_dir / "results"
    figures = sorted((results / "turn" / "stages").glob("*/figures"))
    for d in figures:
        d.rename(d.with_name("figures.away"))
    study = tiny_study()
    study["plots"]["pairs"] = ["shift"]
    write_study(study_dir, study)
    try:
        default = planned_jobs(study_dir)
        proc = snakemake(study_dir, "--dry-run", "--cores", "1", "results/turn/stages.html")
    finally:
        for d in figures:
            d.with_name("figures.away").rename(d)
        write_study(study_dir, tiny_study())
    assert "plot_stage" not in default  # the study itself does not draw them
    assert re.search(r"^plot_stage\s+3\s*$", proc.stdout, re.M) and re.search(
        r"^pair_report\s+1\s*$", proc.stdout, re.M
    )


def test_a_pair_left_out_of_suggest_pairs_gets_no_suggest_job(study_dir):
    """Without turn's last-stage suggestions on disk: the default (every pair of a small study)
    plans its suggest job; suggest_pairs without it (and plots.pairs without it) plans none,
    and its page and the overview are rewritten without them."""
    results = study_dir / "results"
    last = sorted((results / "turn" / "stages").iterdir())[-1] / "suggestions.parquet"
    last.rename(last.with_name("suggestions.away"))
    try:
        left_out = planned_after(
            study_dir, lambda s: s.update(suggest_pairs=["shift"], plots={**s["plots"], "pairs": ["shift"]})
        )
        default = planned_after(study_dir, lambda s: s["plots"].update(pairs=["shift"]))
    finally:
        last.with_name("suggestions.away").rename(last)
    assert left_out == {"pair_report": 1, "report": 1}
    assert default == {"suggest": 1, "pair_report": 1, "report": 1}


def test_asking_for_rematch_plans_rematch_jobs_and_what_reads_them(study_dir):
    # The field jobs do not depend on rematching: only the summary, pair figures and report rerun.
    planned = planned_after(study_dir, lambda s: s.update(rematch={"methods": ["icp"], "trials": 1}))
    assert (
        planned["rematch"] == 6
        and planned["summary"] == 1
        and planned["plot_pair"] == 2
        and planned["pair_report"] == 2
    )
    assert not {"simulate", "register", "mitigate", "field", "suggest", "plot_stage"} & set(planned)


def test_editing_a_plugin_source_replans_its_stage_and_later(study_dir):
    study = tiny_study()
    # plugin as stage 1, field_of_view as stage 2: run it once, then edit the plugin's source.
    study["hypotheses"][0] = {"plugin": {"file": "hypotheses/high.py", "function": "remove", "params": {"min_z_m": -1}}}
    write_study(study_dir, study)
    try:
        snakemake(study_dir, "--cores", "2")
        plugin = study_dir / "hypotheses" / "high.py"
        plugin.write_text(PLUGIN_SOURCE + "\n# edited: same rule, new source\n")
        jobs = planned_jobs(study_dir)
    finally:
        write_study(study_dir, tiny_study())
    assert jobs == {
        "mitigate": 4,
        "field": 4,
        "suggest": 4,
        "plot_stage": 4,
        "explorer_stage": 4,
        "plot_pair": 2,
        "summary": 1,
        "study_voxels": 1,
        "study_tables": 1,
        "study_figures": 1,
        "pair_report": 2,
        "report": 1,
    }


@pytest.mark.parametrize(
    "edit, expected",
    [
        (lambda s: s.update(colour="red"), "colour"),
        (lambda s: s["grid"].update(azimuth_bins="many"), "grid.azimuth_bins"),
        (lambda s: s["hypotheses"].append({"wishful_thinking": {}}), "wishful_thinking"),
        (lambda s: s["pairs"].update(real={"scan1": "missing1.pcd", "scan2": "missing2.pcd"}), "missing1.pcd"),
        (
            lambda s: s["pairs"]["shift"]["simulate"].update(sensor={"name": "x"}),
            "needs at least 'name' and 'elevation_deg'",
        ),
    ],
    ids=["unknown-key", "wrong-type", "unknown-hypothesis", "missing-file", "sensor-without-elevations"],
)
def test_invalid_config_is_one_line_before_any_job(tmp_path, edit, expected):
    study = tiny_study()
    edit(study)
    write_study(tmp_path, study)
    # A dry run, as a user checks a config; a run goes through the same validation first.
    proc = snakemake(tmp_path, "--cores", "1", "--dry-run", check=False)
    assert proc.returncode == 2
    # Snakemake's own first line names the profile it reads; then the message alone, without
    # the stack frames of common.smk and the package.
    printed = [
        line
        for line in (proc.stdout + proc.stderr).splitlines()
        if not line.startswith("Using workflow specific profile")
    ]
    assert len(printed) == 1 and printed[0].startswith(f"lidarfield: error: {tmp_path / 'study.yaml'}: "), printed
    assert expected in printed[0]
    assert not (tmp_path / "results").exists()


def test_failed_job_leaves_no_output_and_keep_going_finishes_the_rest(tmp_path):
    # A truncated KITTI .bin (not a whole number of float32 x 4 rows) fails its ingest job.
    (tmp_path / "broken.bin").write_bytes(b"\x00" * 18)
    (tmp_path / "good.bin").write_bytes(b"\x00" * 16)
    study = tiny_study()
    study["pairs"]["broken"] = {"scan1": "broken.bin", "scan2": "good.bin"}
    write_study(tmp_path, study)
    # Up to the summary (every pair's stages): what the other pairs finish is their stats, not
    # their figures and suggestions (test_full_run_writes_every_stage_and_the_report).
    proc = snakemake(tmp_path, "--cores", "2", "--keep-going", SUMMARY_TARGET, check=False)
    assert proc.returncode != 0
    results = tmp_path / "results"
    assert not (results / "scans" / "recorded" / "broken-1.parquet").exists()
    assert not any(results.glob("scans/recorded/.*part"))
    for pair in ("shift", "turn"):
        assert len(list((results / pair / "stages").glob("*/stats.json"))) == 3
    log = (results / "logs" / "ingest" / "broken-1.log").read_text()
    assert "broken.bin" in log


def test_snakemake_lint_and_snakefmt_are_clean(tmp_path):
    write_study(tmp_path, tiny_study())
    lint = snakemake(tmp_path, "--lint", check=False)
    assert lint.returncode == 0, lint.stdout + lint.stderr
    assert "Lints for" not in lint.stdout + lint.stderr
    if shutil.which("snakefmt") is None:
        pytest.fail("snakefmt is a test dependency: pip install -e '.[test]'")
    fmt = subprocess.run(
        ["snakefmt", "--check", "Snakefile", "workflow/rules"], cwd=ROOT, capture_output=True, text=True
    )
    assert fmt.returncode == 0, fmt.stdout + fmt.stderr


# --- the same study twice, and after a killed run --------------------------------------------


def outputs(workdir: Path) -> dict[str, bytes]:
    """Every Parquet file and stats.json of a study's results, by path relative to results/."""
    results = workdir / "results"
    return {
        str(p.relative_to(results)): p.read_bytes()
        for p in sorted(results.rglob("*"))
        if p.suffix == ".parquet" or p.name == "stats.json"
    }


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory) -> dict[str, bytes]:
    workdir = tmp_path_factory.mktemp("first-run")
    write_study(workdir, tiny_study())
    snakemake(workdir, "--cores", "2", SUMMARY_TARGET)
    return outputs(workdir)


def test_two_runs_of_a_study_write_byte_identical_files(uninterrupted, tmp_path):
    write_study(tmp_path, tiny_study())
    snakemake(tmp_path, "--cores", "2", SUMMARY_TARGET)
    again = outputs(tmp_path)
    assert sum(name.endswith("field.parquet") for name in again) == 6 and "summary.parquet" in again
    assert again.keys() == uninterrupted.keys()
    assert [name for name in again if again[name] != uninterrupted[name]] == []


def test_a_rerun_after_a_killed_run_and_unlock_gives_the_same_files(uninterrupted, tmp_path):
    write_study(tmp_path, tiny_study())
    command = workflow_command(tmp_path, tmp_path / "study.yaml")
    run = subprocess.Popen(
        [*command, "--cores", "1", SUMMARY_TARGET],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:  # kill -9 Snakemake and its running job once the first stage has started
        deadline = time.monotonic() + 600
        while not list(tmp_path.glob("results/*/stages/00-*")) and run.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)
        assert run.poll() is None, "the study finished before it could be killed"
    finally:
        os.killpg(run.pid, signal.SIGKILL)
        run.wait()
    refused = snakemake(tmp_path, "--cores", "2", SUMMARY_TARGET, check=False)
    assert refused.returncode != 0 and "Directory cannot be locked" in refused.stdout + refused.stderr
    snakemake(tmp_path, "--unlock")
    snakemake(tmp_path, "--cores", "2", SUMMARY_TARGET)
    recovered = outputs(tmp_path)
    assert recovered.keys() == uninterrupted.keys()
    assert [name for name in recovered if recovered[name] != uninterrupted[name]] == []
