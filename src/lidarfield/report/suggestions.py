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
    "fitted",
    "energy reduction",
    "removed 1 / 2",
    "removed share / moved",
    "voxels emptied",
    "their energy",
    "max after (m)",
    "p95 after (m)",
)
PARAMS = HEADERS.index("params")  # a candidate's parameters, JSON: wrapped when the table is too wide
FITTED = HEADERS.index("fitted")  # what a correction fitted: wrapped too
EXPLAINER = (
    "Each candidate applied on its own to this stage's survivors. Energy reduction: 1 − energy after / "
    "energy before, Σ min(n1, n2)·|v|² over the voxels valid before and after; voxels emptied below "
    "min_points (and their share of the energy) are counted apart: their vectors vanish unexplained. "
    "A candidate that removes a large share of the points to shrink the field is not an explanation. "
    "A correction (realign) removes nothing: it moves points, so its row shows how far (median / max) "
    "and what it fitted; 'suggested by' names the tag whose share of the energy points to it "
    "(rigid → realign, radial → range_calibration)."
)


def read_suggestions(stage_dir: Path) -> list[dict] | None:
    """The rows of a stage's ``suggestions.parquet`` in rank order; None when it is absent."""
    path = Path(stage_dir) / FILE
    if not path.is_file():
        return None
    columns, _ = read_table(path, required=("rank", "hypothesis", "params", "energy_reduction"))
    rows = [dict(zip(columns, values)) for values in zip(*columns.values())]
    return sorted(rows, key=lambda r: int(r["rank"]))


def describe_fitted(fitted: str | dict | None) -> str:
    """What a correction fitted, short: ``t = (x, y, z) m`` and the rotation angle when it has
    realign's keys, otherwise its scalar values; ``""`` for nothing fitted."""
    if isinstance(fitted, str):
        fitted = json.loads(fitted) if fitted else {}
    if not fitted:
        return ""
    parts = []
    if isinstance(fitted.get("translation_m"), list):
        parts.append("t = (" + ", ".join(f"{v:.3f}" for v in fitted["translation_m"]) + ") m")
    if isinstance(fitted.get("angle_deg"), (int, float)):
        parts.append(f"rotation {fitted['angle_deg']:.3f}°")
    if not parts:
        parts = [
            f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}"
            for k, v in fitted.items()
            if isinstance(v, (int, float, str))
        ]
    return ", ".join(parts)


def suggested_by(row: dict) -> str:
    """``suggested by the rigid tag (63% of the energy)``, or ``""`` (no tag, or no energy in it)."""
    tag, share = row.get("suggested_by") or "", float(row.get("tag_share", float("nan")))
    if not tag or not share > 0:
        return ""
    return f"suggested by the {tag} tag ({100 * share:.0f}% of the energy)"


def _cells(row: dict) -> list:
    params = json.loads(row["params"]) if row["params"] else {}
    note = suggested_by(row)
    if row.get("corrects"):
        cost = f"moves {float(row['displacement_median_m']):.3f} / {float(row['displacement_max_m']):.3f} m"
    else:
        cost = _share(row["removed_share"])
    return [
        int(row["rank"]),
        row["hypothesis"] + (f" ({note})" if note else ""),
        json.dumps(params, separators=(", ", ": ")),
        describe_fitted(row.get("fitted")),
        _share(row["energy_reduction"]),
        f"{int(row['removed1']):,} / {int(row['removed2']):,}",
        cost,
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
        list(HEADERS), [_cells(r) for r in rows], text_columns=4, prose_columns=(PARAMS, FITTED)
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
        + table(["pair", "last stage", *HEADERS], body, text_columns=6, prose_columns=(2 + PARAMS, 2 + FITTED))
    )
