"""Find the pairs, their stages and their summary rows in a results folder.

A results folder is either a study (``results/``: one folder per pair, each with ``stages/``)
or one pair (``lidarfield run --out DIR``: ``DIR/stages/`` itself). The summary decides which
stage folders belong to the study (old stages of other stack variants stay on disk); without
a summary every stage folder is taken, in the order of its ``{k:02d}-`` prefix.
"""

from __future__ import annotations

import json
from pathlib import Path

from ..errors import InputError
from ..storage.layout import level_of
from ..study.summary import read_stats, read_summary_frame

LIST_COLUMNS = ("rigid_translation_m", "rigid_information", "rigid_unconstrained")


def read_summary(folder: Path) -> list[dict] | None:
    """Rows of ``summary.parquet`` (or ``summary.csv``) in ``folder``; None when neither exists."""
    for name in ("summary.parquet", "summary.csv"):
        path = folder / name
        if path.is_file():
            return [_clean_row(r) for r in read_summary_frame(path).to_dict("records")]
    return None


def _clean_row(row: dict) -> dict:
    out = {}
    for k, v in row.items():
        if k in LIST_COLUMNS and isinstance(v, str):
            try:
                v = json.loads(v)
            except ValueError:
                pass
        elif hasattr(v, "tolist"):
            v = v.tolist()
        out[k] = v
    return out


def _by_level(stage_dir: Path) -> tuple[int, str]:
    level = level_of(stage_dir.name)
    return (-1 if level is None else level, stage_dir.name)


def discover(results_dir: str | Path) -> tuple[dict[str, list[Path]], list[dict]]:
    """``{pair: [stage folders in order]}`` and the summary rows of a results folder."""
    results_dir = Path(results_dir)
    if not results_dir.is_dir():
        raise InputError("results folder not found", results_dir)
    single_pair = (results_dir / "stages").is_dir()
    if single_pair:
        pair_dirs = {results_dir.name: results_dir}
    else:
        pair_dirs = {p.name: p for p in sorted(results_dir.iterdir()) if (p / "stages").is_dir()}
    if not pair_dirs:
        raise InputError("no pair folders (folders holding stages/) found", results_dir)

    study_rows = None if single_pair else read_summary(results_dir)
    pairs, rows = {}, []
    for name, pair_dir in pair_dirs.items():
        pair_rows = [r for r in study_rows if str(r["pair"]) == name] if study_rows else read_summary(pair_dir)
        if pair_rows:
            pair_rows = sorted(pair_rows, key=lambda r: float(r.get("level", 0)))
            stages = [pair_dir / "stages" / str(r["stage"]) for r in pair_rows]
            stages = [s for s in stages if s.is_dir()]
        else:
            stages = sorted((s for s in (pair_dir / "stages").iterdir() if s.is_dir()), key=_by_level)
            pair_rows = read_stats([d / "stats.json" for d in stages if (d / "stats.json").is_file()])
        for r in pair_rows:
            r.setdefault("pair", name)
        pairs[name] = stages
        rows += pair_rows
    return pairs, rows
