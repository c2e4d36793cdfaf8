"""The summary contract: one row per stage (``stats.json``), gathered into a pair's or a
study's ``summary.parquet`` and ``summary.csv``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..analysis.tags import TAGS
from ..errors import InputError
from ..io.atomic import atomic_path, write_text
from ..pair import RegisteredPair
from ..sensors.fit import fit_warning
from ..storage.layout import level_of
from ..storage.stage_ids import canonical_json

if TYPE_CHECKING:
    import pandas as pd

# The summary contract's columns, in order (the statistics of field_stats follow them).
SUMMARY_COLUMNS = (
    "pair",
    "stage",
    "level",
    "hypothesis",
    "n1",
    "n2",
    "removed1",
    "removed2",
    "voxels_valid",
    "max_magnitude",
    "mean_magnitude",
    "rms_magnitude",
    "p95_magnitude",
    "paper_max_metric",
    "voxels_significant",
    "p_direction",
    "p_coherence",
    "verdict",
    *(f"energy_share_{tag}" for tag in TAGS),
)


def summary_row(pair_name: str, pair: RegisteredPair, meta: dict, removed_cloud: np.ndarray, statistics: dict) -> dict:
    """One row of the summary contract for a stage."""
    registration = meta.get("registration") or {}
    row = {
        "pair": pair_name,
        "stage": meta.get("stage"),
        "level": meta.get("level"),
        "hypothesis": meta.get("hypothesis"),
        "n1": len(pair.xyz1),
        "n2": len(pair.xyz2),
        "removed1": int(np.count_nonzero(removed_cloud == 1)),
        "removed2": int(np.count_nonzero(removed_cloud == 2)),
    }
    row.update({key: statistics.get(key) for key in SUMMARY_COLUMNS if key not in row})
    row.update({key: value for key, value in statistics.items() if key not in row})
    row["registration_method"] = registration.get("method")
    row["registration_fitness"] = registration.get("fitness")
    row["registration_converged"] = registration.get("converged")
    row["registration_warning"] = registration.get("warning", "")  # a column in every summary
    row["field_warning"] = field_warning(row)
    fits = meta.get("sensor_fit") or {}
    for k in ("1", "2"):
        row[f"sensor_outside{k}"] = (fits.get(k) or {}).get("outside")  # None: no sensor model
    row["sensor_warning"] = "; ".join(filter(None, (fit_warning(fits.get(k), f"scan {k}") for k in ("1", "2"))))
    row.update(correction_columns(meta))
    row.update(label_counts(pair))
    return row


# Where a pair's points carry the simulator's ``object`` labels (0: the static scene).
LABEL = "object"
LABEL_SCORES = ("moving_removed_share", "static_kept_share")  # against the pair's stage 0


def label_counts(pair: RegisteredPair) -> dict:
    """``moving_points`` and ``static_points``: a stage's survivors (both clouds) on a moving
    object (label > 0) and on the static scene (label 0; the sensor's own vehicle, < 0, is neither);
    {} when the points have no labels."""
    if LABEL not in pair.attributes1 and LABEL not in pair.attributes2:
        return {}
    labels = [
        np.asarray(a.get(LABEL, np.full(len(x), np.nan)))
        for a, x in ((pair.attributes1, pair.xyz1), (pair.attributes2, pair.xyz2))
    ]
    label = np.concatenate(labels)
    return {"moving_points": int(np.count_nonzero(label > 0)), "static_points": int(np.count_nonzero(label == 0))}


def with_label_scores(rows: list[dict]) -> list[dict]:
    """The rows of labelled pairs with, against their pair's stage 0 (the registered pair):
    ``moving_removed_share``, the share of the moving objects' points removed up to the stage,
    and ``static_kept_share``, the share of the static points kept (NaN where there are none)."""
    first = {row["pair"]: row for row in rows if row.get("level") == 0 and "moving_points" in row}
    for row in rows:
        start = first.get(row["pair"])
        if start is None or "moving_points" not in row:
            continue
        moving, static = start["moving_points"], start["static_points"]
        removed = 1 - row["moving_points"] / moving if moving else float("nan")
        row.update(zip(LABEL_SCORES, (removed, row["static_points"] / static if static else float("nan"))))
    return rows


# A correcting stage's columns: in every row (a removing stage: '' and 0).
CORRECTION_COLUMNS = (
    "correction",
    "displacement1_median_m",
    "displacement1_max_m",
    "displacement2_median_m",
    "displacement2_max_m",
)


def correction_columns(meta: dict) -> dict:
    """``correction`` (canonical JSON of what the stage fitted and applied, '' when it only
    removed) and the median and maximum distance each cloud's survivors moved (0 when not)."""
    correction = meta.get("correction")
    moved = meta.get("displacement") or {}
    columns = {"correction": "" if correction is None else canonical_json(correction)}
    for k in ("1", "2"):
        for stat in ("median", "max"):
            columns[f"displacement{k}_{stat}_m"] = float((moved.get(k) or {}).get(f"{stat}_m", 0.0))
    return columns


def field_warning(row: dict) -> str:
    """Why a stage's field has no valid voxel, in words ('' when it has one): its statistics
    are then NaN, which a reader of the summary should not have to decode."""
    if row["voxels_valid"]:
        return ""
    if not row["n1"] or not row["n2"]:
        empty = " and ".join(f"cloud {k}" for k in (1, 2) if not row[f"n{k}"])
        return f"no valid voxel: {empty} has no point left"
    return (
        f"no valid voxel: no voxel of the grid holds min_points of both clouds ({row['n1']} and {row['n2']} "
        "points): the clouds do not overlap on the grid, or are too sparse for it"
    )


def read_stats(stats_paths: list[str | Path], rematch_paths: list[str | Path] = ()) -> list[dict]:
    """The summary rows of the given ``stats.json`` files, each joined with the rematch columns
    of the ``rematch.parquet`` among ``rematch_paths`` in the same stage folder (the field and
    rematch jobs of a stage are independent; the summary brings them together)."""
    from ..analysis.rematch import rematch_row

    rematched = {Path(path).parent: rematch_row(path) for path in rematch_paths}
    rows = []
    for path in stats_paths:
        try:
            row = json.loads(Path(path).read_text())
        except ValueError as e:
            raise InputError(f"not valid JSON ({e})", path) from None
        # a stats.json written before the correction columns existed: a removing stage's values
        row.update({k: v for k, v in correction_columns({}).items() if k not in row})
        rows.append({**row, **rematched.get(Path(path).parent, {})})
    return with_label_scores(rows)


def write_summary(
    stats_paths: list[str | Path], out_parquet: str | Path, out_csv: str | Path, rematch_paths: list[str | Path] = ()
) -> None:
    """The summary table of the given ``stats.json`` rows (joined with their stages' rematch
    columns), as Parquet and CSV (lists as JSON)."""
    write_summary_table(read_stats(stats_paths, rematch_paths), out_parquet, out_csv)


def write_summary_table(rows: list[dict], out_parquet: str | Path, out_csv: str | Path) -> None:
    """Summary rows as Parquet and CSV (list columns as JSON in the CSV)."""
    import pandas as pd  # half a second to import: only the summary job needs it

    table = pd.DataFrame(rows)
    with atomic_path(out_parquet) as tmp:
        table.to_parquet(tmp, index=False)
    flat = table.copy()
    for column in flat.columns:
        if flat[column].map(lambda v: isinstance(v, list)).any():
            flat[column] = flat[column].map(json.dumps)
    write_text(out_csv, flat.to_csv(index=False))


def read_summary_frame(path: Path) -> pd.DataFrame:
    """A summary table (``.parquet`` or ``.csv``) with at least its 'pair' and 'stage' columns."""
    import pandas as pd

    if not path.is_file():
        raise InputError("file not found", path)
    reader = pd.read_csv if path.suffix == ".csv" else pd.read_parquet
    try:
        df = reader(path)
    except Exception as e:  # pyarrow and pandas raise many types for a bad file
        raise InputError(f"not a readable summary table ({e})", path) from None
    if not {"pair", "stage"} <= set(df.columns):
        raise InputError(f"summary table without 'pair' and 'stage' columns (has {list(df.columns)})", path)
    if "level" not in df.columns:
        df["level"] = [level_of(str(s)) or 0 for s in df["stage"]]
    return df
