"""The study level: what a whole drive shows, as tables (Parquet first; figures come from them).

- ``voxels``: per stage level and voxel of the study's grid (in sensor 1's frame, so a voxel is
  the same direction from the vehicle in every pair), over the pairs: how many hold points,
  how many have a valid vector, the median vector and magnitude, and the share of pairs where
  the voxel's magnitude exceeds that pair-stage's median magnitude.
- ``hypotheses``: per hypothesis of the stack and pair, the change it made: max, p95 and rms
  magnitude before (the previous stage) and after, and the points it removed.
- ``pairs``: the pairs ranked by what remains at their last stage (p95 magnitude, largest first).

Fields are read one stage level at a time and only their voxel, vector and validity columns,
so memory grows with pairs x valid voxels of one level, not with the whole study.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.atomic import atomic_path
from ..io.parquet_table import read_table, write_table
from ..storage.layout import level_of
from .summary import read_summary_frame

log = logging.getLogger(__name__)

FIELD_READ = ("voxel", "u", "v", "w", "magnitude", "valid")
MEDIANS = (("u", "u_median"), ("v", "v_median"), ("w", "w_median"), ("magnitude", "magnitude_median"))
METRICS = ("max_magnitude", "p95_magnitude", "rms_magnitude")


@dataclass(frozen=True)
class StageField:
    """One stage's field file of the study."""

    pair: str
    level: int
    hypothesis: str
    path: Path


def stage_name(stage_id: str) -> str:
    """The hypothesis name of a stage id ``{k:02d}-{name}-{hash8}``."""
    return stage_id.split("-", 1)[-1].rsplit("-", 1)[0]


def stage_field(path: str | Path) -> StageField:
    """The field file ``.../{pair}/stages/{stage}/field.parquet`` of the study layout."""
    path = Path(path)
    stage_dir = path.parent
    level = level_of(stage_dir.name)
    if level is None or stage_dir.parent.name != "stages":
        raise InputError("not a field of the study layout ({pair}/stages/{k:02d}-{name}-{hash}/field.parquet)", path)
    return StageField(stage_dir.parent.parent.name, level, stage_name(stage_dir.name), path)


def group_medians(keys: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The sorted unique keys and the median of the values of each (one sort, no Python loop)."""
    order = np.lexsort((values, keys))
    k, v = keys[order], values[order]
    starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]]) if len(k) else np.zeros(0, int)
    counts = np.diff(np.r_[starts, len(k)])
    return k[starts], 0.5 * (v[starts + (counts - 1) // 2] + v[starts + counts // 2])


def _level_voxels(fields: list[StageField]) -> dict[str, np.ndarray]:
    """The voxels table of one stage level (``fields``: that level's field of every pair)."""
    present, valid_parts = [], []
    for f in fields:
        columns, _ = read_table(f.path, columns=FIELD_READ)
        present.append(np.asarray(columns["voxel"], dtype=np.int64))
        valid = np.asarray(columns["valid"], dtype=bool) & np.isfinite(columns["magnitude"])
        part = {k: np.asarray(columns[k])[valid] for k in ("voxel", "u", "v", "w", "magnitude")}
        magnitude = part["magnitude"].astype(np.float64)
        # above: the voxel's magnitude exceeds the median magnitude of this pair-stage's valid voxels
        part["above"] = magnitude > np.median(magnitude) if len(magnitude) else np.zeros(0, bool)
        valid_parts.append(part)
    voxels, with_points = np.unique(np.concatenate(present), return_counts=True)
    valid = {k: np.concatenate([p[k] for p in valid_parts]) for k in valid_parts[0]}
    out = {
        "voxel": voxels,
        "pairs": np.full(len(voxels), len(fields), dtype=np.int64),
        "pairs_with_points": with_points.astype(np.int64),
    }
    index = np.searchsorted(voxels, valid["voxel"])
    out["pairs_valid"] = np.bincount(index, minlength=len(voxels)).astype(np.int64)
    for column, name in MEDIANS:
        keys, medians = group_medians(valid["voxel"], valid[column].astype(np.float64))
        out[name] = np.full(len(voxels), np.nan)
        out[name][np.searchsorted(voxels, keys)] = medians
    above = np.bincount(index, weights=valid["above"], minlength=len(voxels))
    with np.errstate(invalid="ignore", divide="ignore"):
        out["share_above_pair_median"] = np.where(out["pairs_valid"] > 0, above / out["pairs_valid"], np.nan)
    return out


def study_voxels(fields: list[StageField]) -> dict[str, np.ndarray]:
    """The voxels table of the study: one row per stage level and voxel holding points in any pair."""
    if not fields:
        raise InputError("no field files to summarise")
    levels = sorted({f.level for f in fields})
    parts = []
    for level in levels:
        at_level = [f for f in fields if f.level == level]
        part = _level_voxels(at_level)
        names = sorted({f.hypothesis for f in at_level})
        part = {
            "level": np.full(len(part["voxel"]), level, dtype=np.int64),
            "hypothesis": np.full(len(part["voxel"]), "/".join(names), dtype=object),
            **part,
        }
        parts.append(part)
        log.info("level %02d (%s): %d pairs, %d voxels", level, "/".join(names), len(at_level), len(part["voxel"]))
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def field_grid(path: str | Path) -> dict:
    """The grid config stored in a field file's metadata."""
    _, meta = read_table(path, columns=("voxel",))
    return meta.get("grid") or {}


def voxels_table(fields: list[StageField]) -> tuple[dict[str, np.ndarray], dict]:
    """The voxels table with the grid's bin columns after ``voxel``, and the grid (from the
    first field's metadata: every field of a study is on the study's grid)."""
    from ..field.grid import grid_from_config

    table = study_voxels(fields)
    grid = field_grid(fields[0].path)
    if grid:
        bins = grid_from_config(grid).bins(table["voxel"])
        table = {
            "level": table["level"],
            "hypothesis": table["hypothesis"],
            "voxel": table["voxel"],
            **bins,
            **{k: v for k, v in table.items() if k not in ("level", "hypothesis", "voxel")},
        }
    table["hypothesis"] = table["hypothesis"].astype(str)
    return table, grid


def write_study_voxels(field_paths: list[str | Path], out: str | Path) -> Path:
    """``voxels.parquet`` of the given field files of the study layout (the grid in its metadata)."""
    fields = [stage_field(p) for p in field_paths]
    table, grid = voxels_table(fields)
    write_table(out, table, {"grid": grid, "pairs": len({f.pair for f in fields})})
    return Path(out)


# --- from the summary table -----------------------------------------------------------------


def hypothesis_changes(summary):
    """Per hypothesis (stage level >= 1) and pair: max, p95 and rms magnitude before and after,
    and the points it removed (``removed_share``: of the points that entered the stage)."""
    import pandas as pd

    s = summary.sort_values(["pair", "level"])
    before = s.groupby("pair")[[*METRICS, "n1", "n2"]].shift(1)
    out = pd.DataFrame(
        {"pair": s["pair"], "level": s["level"].astype(int), "stage": s["stage"], "hypothesis": s["hypothesis"]}
    )
    for metric in METRICS:
        out[f"{metric}_before"] = before[metric].astype(float)
        out[f"{metric}_after"] = s[metric].astype(float)
    out["removed1"] = s["removed1"].astype(int)
    out["removed2"] = s["removed2"].astype(int)
    entered = before["n1"] + before["n2"]
    out["removed_share"] = (out["removed1"] + out["removed2"]) / entered
    return out[out["level"] >= 1].reset_index(drop=True)


def rank_pairs(summary):
    """One row per pair at its last stage, ranked by its p95 magnitude (rank 1: the most left)."""
    s = summary.sort_values(["pair", "level"])
    first = s.groupby("pair").head(1).set_index("pair")
    last = s.groupby("pair").tail(1).set_index("pair")
    keep = ["stage", "level", "hypothesis", *METRICS, "voxels_valid"]
    keep += [
        c for c in ("voxels_significant", "verdict", "registration_converged", "registration_warning") if c in last
    ]
    out = last[keep].copy()
    out["p95_magnitude_stage0"] = first["p95_magnitude"].astype(float)
    out = out.sort_values(["p95_magnitude", "max_magnitude"], ascending=False, na_position="last").reset_index()
    out.insert(0, "rank", np.arange(1, len(out) + 1))
    return out


def write_study_tables(summary_path: str | Path, hypotheses_out: str | Path, pairs_out: str | Path) -> None:
    """``hypotheses.parquet`` and ``pairs.parquet`` from the study's ``summary.parquet``."""
    summary = read_summary_frame(Path(summary_path))
    for table, out in ((hypothesis_changes(summary), hypotheses_out), (rank_pairs(summary), pairs_out)):
        with atomic_path(out) as tmp:
            table.to_parquet(tmp, index=False)


# --- all of them -------------------------------------------------------------------------------


@dataclass
class StudyTables:
    """The study level's tables (pandas DataFrames) and the study's grid."""

    summary: object
    voxels: object | None  # None: no field files were at hand
    hypotheses: object
    pairs: object
    grid: dict


def read_study_tables(summary_path: str | Path, study_dir: str | Path) -> StudyTables:
    """The tables the workflow wrote: ``summary.parquet`` and ``study/*.parquet``."""
    import pandas as pd

    study_dir = Path(study_dir)
    read = {}
    for name in ("voxels", "hypotheses", "pairs"):
        path = study_dir / f"{name}.parquet"
        if not path.is_file():
            raise InputError("file not found", path)
        try:
            read[name] = pd.read_parquet(path)
        except Exception as e:  # pyarrow raises many types for a bad file
            raise InputError(f"not a readable Parquet file ({e})", path) from None
    _, meta = read_table(study_dir / "voxels.parquet", columns=("voxel",))
    return StudyTables(
        read_summary_frame(Path(summary_path)),
        read["voxels"],
        read["hypotheses"],
        read["pairs"],
        meta.get("grid") or {},
    )


def compute_study_tables(pairs: dict[str, list[Path]], summary_rows: list[dict]) -> StudyTables:
    """The tables of a results folder computed in memory (``lidarfield report`` on any folder):
    ``pairs`` maps each pair to its stage folders (``lidarfield.report.discover``)."""
    import pandas as pd

    summary = pd.DataFrame(summary_rows)
    if "level" not in summary:
        summary["level"] = [level_of(str(s)) or 0 for s in summary["stage"]]
    summary["level"] = summary["level"].astype(int)
    fields = [
        StageField(name, level_of(d.name) or 0, stage_name(d.name), d / "field.parquet")
        for name, dirs in pairs.items()
        for d in dirs
        if (d / "field.parquet").is_file()
    ]
    voxels, grid = (None, {})
    if fields:
        table, grid = voxels_table(fields)
        voxels = pd.DataFrame(table)
    return StudyTables(summary, voxels, hypothesis_changes(summary), rank_pairs(summary), grid)
