"""Issue 38's guard: what makes "what to try next" cheaper leaves its ranking as it was, on the
default study's pair, the drive's and the real shared pairs (the reference and how it is
written: tests/helpers/suggestion_ranking.py)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from helpers.real_pairs import PAIRS
from helpers.suggestion_ranking import SCORE_TOLERANCE, SIMULATED, ranking

REFERENCE = json.loads((Path(__file__).resolve().parents[1] / "data" / "suggestion_ranking.json").read_text())


def fits_pose(row: dict) -> bool:
    return '"with_pose":true' in row["params"]


def assert_same_ranking(name: str, rows: list[dict]) -> None:
    """The reference's ranking of the candidates offered: on the simulated pairs, whose pose is
    the simulation's truth, those fitted with the pose are no longer run (analysis.suggest)."""
    expected = [r for r in REFERENCE[name] if not (name in SIMULATED and fits_pose(r))]
    fitted_with_pose = [r for r in rows if fits_pose(r)]
    if name in SIMULATED:
        assert fitted_with_pose == []
    else:
        assert fitted_with_pose
    assert [(r["hypothesis"], r["params"]) for r in rows] == [(r["hypothesis"], r["params"]) for r in expected]
    for row, before in zip(rows, expected):
        if before["score"] is None:
            assert row["score"] is None, row
        else:
            assert row["score"] == pytest.approx(before["score"], abs=SCORE_TOLERANCE), row


def test_the_reference_holds_every_case_and_both_kinds_of_candidate():
    assert set(REFERENCE) == {*SIMULATED, *PAIRS}
    rows = [row for case in REFERENCE.values() for row in case]
    assert {"realign", "deskew", "range_calibration", "outliers", "moving_objects"} <= {r["hypothesis"] for r in rows}
    assert any(fits_pose(r) for r in rows)


@pytest.mark.parametrize("name", SIMULATED)
def test_the_simulated_pairs_rank_their_candidates_as_before(name):
    assert_same_ranking(name, ranking(name))


@pytest.mark.parametrize("name", PAIRS)
def test_the_real_pairs_rank_their_candidates_as_before(shared_data, name):
    assert_same_ranking(name, ranking(name, shared_data))
