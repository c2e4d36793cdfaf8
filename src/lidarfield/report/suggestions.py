"""The report's "what to try next": a stage's suggestion table, and the study's best next steps."""

from __future__ import annotations

import json
from pathlib import Path

from ..errors import InputError
from ..io.parquet_table import read_table
from .page import esc, table

FILE = "suggestions.parquet"
HEADERS = (
    "rank",
    "hypothesis",
    "params",
    "energy reduction",
    "removed 1 / 2",
    "removed share",
    "voxels emptied",
    "their energy",
    "max after (m)",
    "p95 after (m)",
)
PARAMS = HEADERS.index("params")  # a candidate's parameters, JSON: wrapped when the table is too wide
EXPLAINER = (
    "Each candidate applied on its own to this stage's survivors. Energy reduction: 1 − energy after / "
    "energy before, Σ min(n1, n2)·|v|² over the voxels valid before and after; voxels emptied below "
    "min_points (and their share of the energy) are counted apart: their vectors vanish unexplained. "
    "A candidate that removes a large share of the points to shrink the field is not an explanation."
)


def read_suggestions(stage_dir: Path) -> list[dict] | None:
    """The rows of a stage's ``suggestions.parquet`` in rank order; None when it is absent."""
    path = Path(stage_dir) / FILE
    if not path.is_file():
        return None
    columns, _ = read_table(path, required=("rank", "hypothesis", "params", "energy_reduction"))
    rows = [dict(zip(columns, values)) for values in zip(*columns.values())]
    return sorted(rows, key=lambda r: int(r["rank"]))


def _cells(row: dict) -> list:
    params = json.loads(row["params"]) if row["params"] else {}
    return [
        int(row["rank"]),
        row["hypothesis"],
        json.dumps(params, separators=(", ", ": ")),
        _share(row["energy_reduction"]),
        f"{int(row['removed1']):,} / {int(row['removed2']):,}",
        _share(row["removed_share"]),
        int(row["voxels_invalidated"]),
        _share(row["energy_invalidated"]),
        float(row["max_after"]),
        float(row["p95_after"]),
    ]


def _share(value) -> str:
    value = float(value)
    return "" if value != value else f"{100 * value:.1f}%"


def stage_suggestions(stage_dir: Path) -> str:
    """A stage's "what to try next" table, or a note that it is missing."""
    try:
        rows = read_suggestions(stage_dir)
    except InputError as e:
        return f'<p class="missing">what to try next: {esc(e)}</p>'
    if rows is None:
        return f'<p class="missing">what to try next: not computed ({FILE} missing)</p>'
    return f'<p class="note"><b>What to try next.</b> {esc(EXPLAINER)}</p>' + table(
        list(HEADERS), [_cells(r) for r in rows], text_columns=3, prose_columns=(PARAMS,)
    )


def study_suggestions(pairs: dict[str, list[Path]], best: int = 3) -> str:
    """Per pair, the best ``best`` candidates at its last stage: the study's next steps."""
    body = []
    for name, stage_dirs in pairs.items():
        if not stage_dirs:
            continue
        try:
            rows = read_suggestions(stage_dirs[-1]) or []
        except InputError:
            rows = []
        for row in rows[:best]:
            body.append([name, stage_dirs[-1].name, *_cells(row)])
    if not body:
        return '<p class="note">No suggestions were computed.</p>'
    return (
        '<p class="note">Per pair, the best candidates on the survivors of its last stage (the full '
        "tables are in each pair's section).</p>"
        + table(["pair", "last stage", *HEADERS], body, text_columns=5, prose_columns=(2 + PARAMS,))
    )
