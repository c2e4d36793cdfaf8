"""The file-level stages shared by ``lidarfield run`` and the Snakemake workflow.

Each function reads its inputs from files and writes its outputs whole (atomically), in the
layout of the design: per stage ``points.parquet``, ``removed.parquet``, ``field.parquet`` and
``stats.json`` (one summary row), ``suggestions.parquet`` (what to try next), and per pair
``neighbours.parquet`` (what every stage's suggestions carry over), ``summary.parquet`` / ``summary.csv``.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from .errors import ConfigError, InputError
from .field import field_meta, write_field
from .analysis.field_stats import analyse_field, summary_json_safe
from .grid import field_settings_from_config
from .io import read_scan, write_scan
from .io.atomic import atomic_path, write_text
from .io.parquet_table import read_table, write_table
from .pair import RegisteredPair, read_pair, write_pair
from .sensor_fit import fit_warning, log_fit
from .stack import Stage, apply_stack, initial_stage, next_stage
from .stages import stage_ids
from .analysis.neighbour_file import write_neighbours
from .analysis.suggest import suggestions, write_suggestions
from .analysis.tags import TAGS

log = logging.getLogger(__name__)

# The summary contract's columns, in order (the statistics of field_stats follow them).
SUMMARY_COLUMNS = (
    "pair", "stage", "level", "hypothesis", "n1", "n2", "removed1", "removed2", "voxels_valid",
    "max_magnitude", "mean_magnitude", "rms_magnitude", "p95_magnitude", "paper_max_metric",
    "voxels_significant", "p_direction", "p_coherence", "verdict", *(f"energy_share_{tag}" for tag in TAGS),
)  # fmt: skip
# Marks a folder written by ``lidarfield run``: only such a folder (or an empty one) is reused.
RUN_MARKER = ".lidarfield-run.json"


# --- one stage ------------------------------------------------------------------------------


def write_stage(stage: Stage, stage_id: str, points_out: str | Path, removed_out: str | Path) -> None:
    """The stage's survivors and removed points, each file with the stage's metadata."""
    meta = stage.metadata(stage_id)
    write_pair(points_out, stage.pair, meta)
    write_table(removed_out, stage.removed_columns(), {**stage.removed.metadata(), **meta})


def mitigate_stage(
    points_in: str | Path,
    step: dict | None,
    stage_id: str,
    level: int,
    points_out: str | Path,
    removed_out: str | Path,
    base_dir: str | Path = ".",
    study_grid: dict | None = None,
) -> None:
    """Stage ``level``: apply ``step`` to the points of ``points_in`` (the previous stage's, or
    the registered pair for stage 0, where ``step`` is None and nothing is removed)."""
    pair, _ = read_pair(points_in)
    stage = initial_stage(pair) if step is None else next_stage(pair, step, level, base_dir, study_grid)
    log.info("stage %s: removed %d + %d points", stage_id, stage.removed1, stage.removed2)
    write_stage(stage, stage_id, points_out, removed_out)


def field_stage(
    points_path: str | Path,
    removed_path: str | Path,
    grid_section: dict,
    pair_name: str,
    field_out: str | Path,
    stats_out: str | Path,
) -> dict:
    """The field of a stage's survivors and its summary row (``stats.json``); returns the row."""
    pair, meta = read_pair(points_path)
    removed, _ = read_table(removed_path, columns=("cloud",))
    settings = field_settings_from_config(grid_section)
    columns, statistics = analyse_field(pair, settings)
    statistics = summary_json_safe(statistics)
    write_field(field_out, columns, field_meta(settings, statistics, stage=meta.get("stage")))
    row = summary_row(pair_name, pair, meta, removed["cloud"], statistics)
    write_text(stats_out, json.dumps(row, indent=1) + "\n")
    return row


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
    return row


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
    from .analysis.rematch import rematch_row

    rematched = {Path(path).parent: rematch_row(path) for path in rematch_paths}
    rows = []
    for path in stats_paths:
        try:
            row = json.loads(Path(path).read_text())
        except ValueError as e:
            raise InputError(f"not valid JSON ({e})", path) from None
        rows.append({**row, **rematched.get(Path(path).parent, {})})
    return rows


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


# --- one pair, whole stack ------------------------------------------------------------------


def registration_settings(register: str | None = None, transform: str | Path | None = None) -> str | dict:
    """The register setting of ``--register METHOD`` / ``--transform FILE`` (identity if neither)."""
    if register is not None and transform is not None:
        raise ConfigError("give either a registration method or a transform file, not both")
    if transform is not None:
        return {"transform": str(transform)}
    if register in (None, "identity", "truth"):
        return register or "identity"
    return {"method": register}


def check_out_dir(out_dir: str | Path) -> Path:
    """``out_dir`` if it is new, empty, or written by an earlier ``lidarfield run``."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError("the output folder is a file", out_dir)
    if out_dir.is_dir() and any(out_dir.iterdir()) and not (out_dir / RUN_MARKER).is_file():
        raise InputError(
            f"the output folder is not empty and was not written by lidarfield run (no {RUN_MARKER}); "
            "choose a new or empty folder",
            out_dir,
        )
    return out_dir


def run_pair(
    scan1: str | Path,
    scan2: str | Path,
    config_path: str | Path,
    out_dir: str | Path,
    register: str | None = None,
    transform: str | Path | None = None,
    sensor: str | None = None,
    poses: dict | None = None,
) -> list[dict]:
    """One pair through the whole stack of a study config, without Snakemake.

    ``poses`` ({"topic", "frame"}) takes both scans' poses from a topic of their ROS bag.

    Everything that can fail on the user's input (config, scans, registration, every
    hypothesis) runs before the first file is written, so a failure leaves no stage output.
    Returns the summary rows of all stages (also in ``out_dir/summary.parquet`` and ``.csv``).
    """
    from .config import load_config

    out_dir = check_out_dir(out_dir)
    study = load_config(config_path, require_pairs=False)
    settings = registration_settings(register, transform)
    scans = [read_scan(path, sensor=sensor, poses=poses) for path in (scan1, scan2)]
    for path, scan in zip((scan1, scan2), scans):
        log.info("read %s: %d points (%d invalid rows dropped)", path, len(scan), scan.dropped_invalid)
        log_fit(scan, str(path))
    from .registration import register_pair  # imports Open3D: only where a pair is registered

    pair = register_pair(scans[0], scans[1], settings)
    reg = pair.registration
    log.info("registered by %s: fitness %.3f, converged %s", reg.get("method"), reg.get("fitness", float("nan")), reg.get("converged"))
    candidates = [study.candidates(level) for level in range(len(study.hypotheses) + 1)]
    field_settings = field_settings_from_config(study.grid)
    stages, tables = [], []
    for stage in apply_stack(pair, study.hypotheses, study.base_dir, study.grid):
        log.info("stage %d (%s): removed %d + %d points", stage.level, stage.name, stage.removed1, stage.removed2)
        stages.append(stage)
        # Candidates run before any file is written too (a plugin candidate can fail).
        tables.append(suggestions(stage.pair, field_settings, candidates[stage.level], study.base_dir, study.grid, study.suggest is None))

    # The same inputs as a config pair {scan1, scan2, sensor, register}: equal stage ids.
    scan_specs = [{"path": str(p), "format": None, "sensor": sensor, "pose": None} for p in (scan1, scan2)]
    if poses is not None:
        scan_specs = [{**spec, "poses": poses} for spec in scan_specs]
    inputs = {"scan1": scan_specs[0], "scan2": scan_specs[1], "register": settings}
    ids = stage_ids(inputs, study.hypotheses, study.base_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    run = {
        "scan1": str(scan1), "scan2": str(scan2), "config": str(config_path), "register": settings, "sensor": sensor,
        "poses": poses,
    }  # fmt: skip
    write_text(out_dir / RUN_MARKER, json.dumps({**run, "stages": ids}, indent=1) + "\n")
    write_scan(scans[0], out_dir / "scan1.parquet")
    write_scan(scans[1], out_dir / "scan2.parquet")
    write_pair(out_dir / "registered.parquet", pair)
    write_neighbours(out_dir / "neighbours.parquet", pair)  # what stage 0's suggestions searched
    pair_name = out_dir.resolve().name
    folders = [out_dir / "stages" / stage_id for stage_id in ids]
    for stage, stage_id, folder, table in zip(stages, ids, folders, tables):
        write_stage(stage, stage_id, folder / "points.parquet", folder / "removed.parquet")
        field_stage(
            folder / "points.parquet", folder / "removed.parquet", study.grid, pair_name,
            folder / "field.parquet", folder / "stats.json",
        )  # fmt: skip
        write_suggestions(folder / "suggestions.parquet", table, stage_id, candidates[stage.level], study.grid)
        if study.rematch:
            from .analysis.rematch import rematch_stage

            rematch_stage(folder / "points.parquet", study.rematch, folder / "rematch.parquet")
    stats = [folder / "stats.json" for folder in folders]
    rematched = [folder / "rematch.parquet" for folder in folders] if study.rematch else []
    write_summary(stats, out_dir / "summary.parquet", out_dir / "summary.csv", rematched)
    return read_stats(stats, rematched)
