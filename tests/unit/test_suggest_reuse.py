"""A stage whose points are those of a stage already suggested for reuses its suggestion rows
(issue 38: an appended hypothesis that changes nothing costs no candidate run): the same table,
the same ranking, as running every candidate again, on the default study's pair and the real
shared pairs; any change of the points, pose, grid or code gives another ``points_digest``, and
rows written by other code are not reused."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

import lidarfield
from helpers.real_pairs import pair_at, real_pair
from lidarfield.analysis import suggest
from lidarfield.analysis.suggest import (
    PACKAGE,
    candidate_steps,
    code_digest,
    points_digest,
    rows_by_candidate,
    source_digest,
    suggestions,
)
from lidarfield.commands.jobs import simulated_scan, suggest_stage
from lidarfield.field.grid import field_settings_from_config
from lidarfield.io.parquet_table import read_metadata
from lidarfield.pair import RegisteredPair, write_pair
from lidarfield.registration import register_pair
from lidarfield.study.config import load_config
from lidarfield.study.stack import apply_stack

ROOT = Path(__file__).resolve().parents[2]
# a crop that keeps every point of a scan: the appended stage has the points of the one before
KEEP_ALL = {"crop": {"max_range_m": 10_000}}


def assert_same_table(fresh: dict, reused: dict) -> None:
    assert list(reused["hypothesis"]) == list(fresh["hypothesis"])  # the ranking
    for name, values in fresh.items():
        np.testing.assert_array_equal(reused[name], values, err_msg=name)


def appended_tables(pair: RegisteredPair, stack: list[dict], grid: dict) -> tuple[dict, dict]:
    """The suggestions of ``stack`` + ``KEEP_ALL``'s last stage, run anew and with the rows of
    the stage before reused (as the workflow's job and ``lidarfield run`` reuse them)."""
    settings = field_settings_from_config(grid)
    *_, before, after = apply_stack(pair, [*stack, KEEP_ALL], ".", grid)
    assert after.removed1 == after.removed2 == 0
    assert points_digest(after.pair, grid) == points_digest(before.pair, grid)
    earlier = suggestions(before.pair, settings, candidate_steps(None, stack, ".", grid), ".", grid, True)
    candidates = candidate_steps(None, [*stack, KEEP_ALL], ".", grid)
    fresh = suggestions(after.pair, settings, candidates, ".", grid, True)
    reused = suggestions(after.pair, settings, candidates, ".", grid, True, rows_by_candidate(earlier))
    assert "crop" in earlier["hypothesis"] and "crop" not in reused["hypothesis"]
    return fresh, reused


def test_the_default_study_pair_gets_the_same_ranked_candidates_reused():
    study = load_config(ROOT / "config" / "config.yaml", ROOT)
    spec = study.pairs["paper-sim"]
    pair = register_pair(simulated_scan(spec.scan1.spec), simulated_scan(spec.scan2.spec), spec.register)
    fresh, reused = appended_tables(pair, study.hypotheses, study.grid_section)
    assert len(fresh["hypothesis"]) >= 5  # the removals left and the corrections, all run
    assert_same_table(fresh, reused)


@pytest.mark.parametrize("name", ["hdl32", "os1 0->1", "expd"])
def test_the_real_pairs_get_the_same_ranked_candidates_reused(shared_data, name):
    pair = pair_at(real_pair(shared_data, name))
    grid = load_config(ROOT / "config" / "config.yaml", ROOT).grid_section
    fresh, reused = appended_tables(pair, [{"ego_vehicle": {}}], grid)
    assert "realign" in fresh["hypothesis"]
    assert_same_table(fresh, reused)


def test_the_points_digest_changes_with_a_point_the_pose_or_the_grid():
    rng = np.random.default_rng(3)
    pair = RegisteredPair(rng.normal(size=(500, 3)), rng.normal(size=(400, 3)), attributes1={"ring": np.arange(500)})
    grid = {"kind": "spherical", "azimuth_bins": 36}
    digest = points_digest(pair, grid)
    same = RegisteredPair(pair.xyz1.copy(), pair.xyz2.copy(), attributes1={"ring": np.arange(500)})
    assert points_digest(same, grid) == digest
    keep = np.ones(500, dtype=bool)
    keep[17] = False
    moved = pair.xyz2.copy()
    moved[3, 0] += 1e-9
    posed = np.eye(4)
    posed[0, 3] = 0.01
    others = [
        points_digest(pair.subset(keep, np.ones(400, dtype=bool)), grid),
        points_digest(RegisteredPair(pair.xyz1, moved, attributes1=pair.attributes1), grid),
        points_digest(RegisteredPair(pair.xyz1, pair.xyz2, posed, attributes1=pair.attributes1), grid),
        points_digest(RegisteredPair(pair.xyz1, pair.xyz2, attributes1={"ring": np.arange(500) % 7}), grid),
        points_digest(pair, {**grid, "azimuth_bins": 72}),
        points_digest(pair, grid, code="another version"),
    ]
    assert len({digest, *others}) == len(others) + 1


def test_the_suggest_job_reuses_the_rows_of_a_sibling_stage_with_the_same_points(tmp_path, caplog, monkeypatch):
    """Two stage folders of one pair on the same points (stage 0 under two ids, as a stack
    edited back and forth leaves them): the second job reads the first one's rows, runs no
    candidate and writes the table the first one computed; a third one by other code (as after
    an edit of a hypothesis) runs every candidate."""
    rng = np.random.default_rng(5)
    xyz1 = rng.uniform(-20, 20, size=(3000, 3))
    write_pair(tmp_path / "registered.parquet", RegisteredPair(xyz1, xyz1 + rng.normal(0, 0.02, size=xyz1.shape)))
    grid = {"kind": "spherical", "azimuth_bins": 12, "elevation_deg": [-60, 60], "elevation_bins": 3}
    candidates = candidate_steps([{"crop": {"max_range_m": 25}}, {"outliers": {}}], [], ".", grid)
    stages = tmp_path / "pair" / "stages"
    first = suggest_stage(
        tmp_path / "registered.parquet", [], "00-none-aaaaaaaa", candidates, grid, stages / "a" / "s.parquet"
    )
    with caplog.at_level(logging.INFO, logger="lidarfield.analysis.suggest"):
        second = suggest_stage(
            tmp_path / "registered.parquet", [], "00-none-bbbbbbbb", candidates, grid, stages / "b" / "s.parquet"
        )
    assert "all 2 candidates reused" in caplog.text
    assert first["removed1"][list(first["hypothesis"]).index("crop")] > 0  # a row that ran, not a no-op
    assert_same_table(first, second)
    # the same points after an edit of the code: the rows are computed again, not reused
    caplog.clear()
    monkeypatch.setattr(suggest, "code_digest", lambda: "the code after an edit")
    with caplog.at_level(logging.INFO, logger="lidarfield.analysis.suggest"):
        third = suggest_stage(
            tmp_path / "registered.parquet", [], "00-none-cccccccc", candidates, grid, stages / "c" / "s.parquet"
        )
    assert "reused" not in caplog.text and "reusing" not in caplog.text
    assert read_metadata(stages / "c" / "s.parquet")["points"] != read_metadata(stages / "a" / "s.parquet")["points"]
    assert_same_table(first, third)  # the code did not change really: the same rows


def test_the_code_digest_changes_with_an_edit_of_a_module_or_the_version(tmp_path):
    """A copy of the package's hypotheses and suggest module: the same files give the same
    digest wherever they are; a byte more in one module, a module more or another version, another."""
    sources = [*sorted((PACKAGE / "hypotheses").glob("*.py")), PACKAGE / "analysis" / "suggest.py"]
    copies = []
    for name in ("a", "b"):
        for path in sources:
            copy = tmp_path / name / path.relative_to(PACKAGE)
            copy.parent.mkdir(parents=True, exist_ok=True)
            copy.write_bytes(path.read_bytes())
        copies.append(tmp_path / name)
    digest = source_digest(copies[0], "0.1.0")
    assert source_digest(copies[1], "0.1.0") == digest
    assert code_digest() == source_digest(PACKAGE, lidarfield.__version__) != digest  # the whole package
    (copies[1] / "README.txt").write_text("not a module")
    assert source_digest(copies[1], "0.1.0") == digest
    edited = copies[1] / "hypotheses" / "outliers.py"
    edited.write_bytes(edited.read_bytes() + b"\n")
    others = [source_digest(copies[1], "0.1.0"), source_digest(copies[0], "0.1.1")]
    (copies[0] / "hypotheses" / "extra.py").write_text("")
    others.append(source_digest(copies[0], "0.1.0"))
    assert len({digest, *others}) == len(others) + 1
