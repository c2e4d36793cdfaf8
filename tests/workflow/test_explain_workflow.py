"""The explain target of a study: one pair's, every pair's, and the study report's section on it."""

from __future__ import annotations

import json

import pytest

from helpers.workflow import snakemake, tiny_study, write_study
from lidarfield.study.config import load_config

pytestmark = pytest.mark.slow

# The shifted pair's truth (sensor 2 at (1, 1) m, turned 0.05 rad) with 0.3 m more along x.
OFF_TRUTH = """0.998750260395 -0.049979169271 0 1.3
0.049979169271 0.998750260395 0 1
0 0 1 0
0 0 0 1
"""


def test_the_explain_target_and_the_study_report(tmp_path):
    """`snakemake explain` writes each pair's folder; the study report, built after it, shows the
    stack found per pair and how often each hypothesis was chosen, and depends on it from then
    on (nothing left to do after; explaining one pair again rebuilds the report). The shifted
    pair is registered 0.3 m off the truth, which the candidates (the tiny study's and realign)
    can explain: registered by the truth its field reads random (on its surfaces, what the
    change of viewpoint moves is within them)."""
    study = tiny_study()
    study["plots"]["figures"] = ["field_top"]
    (tmp_path / "shift-off.txt").write_text(OFF_TRUTH)
    study["pairs"]["shift"]["register"] = {"transform": "shift-off.txt"}
    study["suggest"].append({"realign": {}})
    write_study(tmp_path, study)
    snakemake(tmp_path, "--cores", "2", "results/shift/explain/explain.html")
    assert not (tmp_path / "results" / "turn" / "explain").exists()  # one pair: only its own
    snakemake(tmp_path, "--cores", "2", "explain")
    records = {}
    for pair in ("shift", "turn"):
        folder = tmp_path / "results" / pair / "explain"
        records[pair] = json.loads((folder / "explain.json").read_text())
        assert {"stack.yaml", "steps.csv", "explain.html", "figures"} <= {p.name for p in folder.iterdir()}
        loaded = load_config(folder / "stack.yaml", tmp_path, require_pairs=False)
        assert loaded.hypotheses == records[pair]["stack"]
        # the tiny study's candidates only (its suggest list), each at most once
        names = [next(iter(step)) for step in records[pair]["stack"]]
        assert set(names) <= {"ego_vehicle", "field_of_view", "shadow", "realign"} and len(set(names)) == len(names)
    assert records["shift"]["stack"], "the shifted pair's field has something the candidates explain"

    snakemake(tmp_path, "--cores", "2")
    report = (tmp_path / "results" / "report.html").read_text()
    assert "What explain found" in report
    for pair, record in records.items():
        names = " → ".join(next(iter(step)) for step in record["stack"]) or "(none)"
        assert f'href="{pair}/explain/explain.html"' in report and names in report
    assert "pairs that chose it" in report
    assert "Nothing to be done" in (lambda p: p.stdout + p.stderr)(snakemake(tmp_path, "--dry-run", "--cores", "1"))
