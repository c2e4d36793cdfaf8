"""The ranked "what to try next" of the default study's pairs and the real shared pairs, as a
reference: issue 38's guard that making the suggestions cheaper leaves their ranking as it was.

``tests/data/suggestion_ranking.json`` holds, per case, the candidates in rank order (name and
parameters) and each one's whitened reduction beyond its null, written with

    python tests/helpers/suggestion_ranking.py tests/data/suggestion_ranking.json [shared data folder]

``tests/unit/test_suggest_ranking.py`` checks the code of today against it: the same order,
and each score within ``SCORE_TOLERANCE`` (the scores are fits: a cheaper exact path moves them
by rounding, an approximation by more). History: written 2026-11-28 by main at 4a3d731, before
``realign`` reused cloud 1's normals in its second fit.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from helpers.drive import drive_pair
from helpers.real_pairs import PAIRS, pair_at, real_pair
from lidarfield.analysis.suggest import candidate_steps, suggestions
from lidarfield.commands.jobs import simulated_scan
from lidarfield.field.grid import field_settings_from_config
from lidarfield.pair import RegisteredPair
from lidarfield.registration import register_pair
from lidarfield.study.config import load_config
from lidarfield.study.stack import apply_stack

ROOT = Path(__file__).resolve().parents[2]
# how far a candidate's whitened reduction beyond its null may move (of the field's whitened
# energy): far above rounding; the order is held apart, exactly (several candidates of a real
# pair lie closer together than this)
SCORE_TOLERANCE = 0.01
# the drive of bench/drive.py: its stack, at its last stage
DRIVE_STACK = [
    {"field_of_view": {}},
    {"shadow": {"jump_m": 1.0, "min_points": 30, "origins": [1, 2]}},
    {"ego_vehicle": {}},
]
SIMULATED = ("paper-sim", "drive")


def default_grid() -> dict:
    return load_config(ROOT / "config" / "config.yaml", ROOT).grid_section


def case_pair(name: str, data: Path | None) -> tuple[RegisteredPair, list[dict]]:
    """A case's pair and the stack applied before its suggestions: the default study's pair
    with its stack, the drive's first pair with the drive's, a real pair registered by its
    reference with ``ego_vehicle``."""
    if name == "paper-sim":
        study = load_config(ROOT / "config" / "config.yaml", ROOT)
        spec = study.pairs["paper-sim"]
        pair = register_pair(simulated_scan(spec.scan1.spec), simulated_scan(spec.scan2.spec), spec.register)
        return pair, study.hypotheses
    if name == "drive":
        return drive_pair(), DRIVE_STACK
    return pair_at(real_pair(data, name)), [{"ego_vehicle": {}}]


def ranking(name: str, data: Path | None = None) -> list[dict]:
    """The suggestions of a case's last stage, in rank order: each candidate's ``hypothesis``,
    ``params`` and ``score`` (whitened reduction beyond its fitted null; None where undefined)."""
    pair, stack = case_pair(name, data)
    grid = default_grid()
    *_, last = apply_stack(pair, stack, ".", grid)
    table = suggestions(
        last.pair, field_settings_from_config(grid), candidate_steps(None, stack, ".", grid), ".", grid, True
    )
    scores = table["whitened_reduction"] - table["fitted_null"]
    return [
        {"hypothesis": str(h), "params": str(p), "score": float(s) if np.isfinite(s) else None}
        for h, p, s in zip(table["hypothesis"], table["params"], scores)
    ]


def main(out: str, data: str | None = None) -> None:
    names = [*SIMULATED, *(PAIRS if data else ())]
    rankings = {}
    for name in names:
        rankings[name] = ranking(name, Path(data) if data else None)
        print(name, [row["hypothesis"] for row in rankings[name]], flush=True)
    Path(out).write_text(json.dumps(rankings, indent=1) + "\n")


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT / "tests"))
    main(*sys.argv[1:])
