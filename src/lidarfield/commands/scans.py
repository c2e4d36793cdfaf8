"""The commands on two scan files, without Snakemake: ``lidarfield run`` (one pair through the
whole stack of a study config: the same jobs as the workflow's, in one process, into one
folder), ``lidarfield explain`` (the explain loop on the pair, its folder written),
``lidarfield field`` (the pair's field and its summary) and ``lidarfield register`` (the
registered pair, or the transform of an aligned copy)."""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..analysis.stopping_rule import explain_settings
from ..analysis.suggest import points_digest, rows_by_candidate, suggestions, write_suggestions
from ..errors import ConfigError, InputError
from ..io import read_scan, write_scan
from ..io.atomic import write_text
from ..pair import RegisteredPair, write_pair
from ..scan import Scan
from ..sensors.fit import log_fit
from ..storage.stage_ids import stage_ids
from ..storage.stage_points import CHANGES
from ..study.explain_loop import Explanation, explain_pair
from ..study.pairs import recorded_scan_spec
from ..study.stack import apply_stack
from ..study.summary import read_stats, write_summary
from ..threads import usable_threads
from .jobs import field_stage, rematch_stage, write_stage

if TYPE_CHECKING:  # the config's schema and validator load only where a config is read
    from ..study.config import Study

log = logging.getLogger(__name__)

# Mark a folder written by ``lidarfield run`` / ``explain``: only such a folder (or an empty
# one) is reused.
RUN_MARKER = ".lidarfield-run.json"
EXPLAIN_MARKER = ".lidarfield-explain.json"


def registration_settings(register: str | None = None, transform: str | Path | None = None) -> str | dict:
    """The register setting of ``--register METHOD`` / ``--transform FILE`` (identity if neither)."""
    if register is not None and transform is not None:
        raise ConfigError("give either a registration method or a transform file, not both")
    if transform is not None:
        return {"transform": str(transform)}
    if register in (None, "identity", "truth"):
        return register or "identity"
    return {"method": register}


def check_out_dir(out_dir: str | Path, marker: str = RUN_MARKER, command: str = "lidarfield run") -> Path:
    """``out_dir`` if it is new, empty, or written by an earlier ``command`` (it holds ``marker``)."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError("the output folder is a file", out_dir)
    if out_dir.is_dir() and any(out_dir.iterdir()) and not (out_dir / marker).is_file():
        raise InputError(
            f"the output folder is not empty and was not written by {command} (no {marker}); "
            "choose a new or empty folder",
            out_dir,
        )
    return out_dir


def read_and_register(
    scan1: str | Path, scan2: str | Path, settings: str | dict, sensor: str | None = None, poses: dict | None = None
) -> tuple[list[Scan], RegisteredPair]:
    """Both scans read (``sensor``: their sensor model; ``poses``: from a topic of their ROS bag)
    and registered by ``settings`` (``registration_settings``): what ``lidarfield run`` and
    ``lidarfield explain`` start from."""
    scans = [read_scan(path, sensor=sensor, poses=poses) for path in (scan1, scan2)]
    for path, scan in zip((scan1, scan2), scans):
        log.info("read %s: %d points (%d invalid rows dropped)", path, len(scan), scan.dropped_invalid)
        log_fit(scan.xyz, scan.sensor, str(path))
    from ..registration import register_pair  # imports Open3D: only where a pair is registered

    pair = register_pair(scans[0], scans[1], settings)
    reg = pair.registration
    log.info(
        "registered by %s: fitness %.3f, converged %s",
        reg.get("method"),
        reg.get("fitness", float("nan")),
        reg.get("converged"),
    )
    return scans, pair


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
    from ..study.config import load_config

    out_dir = check_out_dir(out_dir)
    study = load_config(config_path, require_pairs=False)
    settings = registration_settings(register, transform)
    scans, pair = read_and_register(scan1, scan2, settings, sensor, poses)
    candidates = [study.candidates(level) for level in range(len(study.hypotheses) + 1)]
    stages, tables, digests = [], [], []
    for stage in apply_stack(pair, study.hypotheses, study.base_dir, study.grid_section):
        log.info("stage %d (%s): removed %d + %d points", stage.level, stage.name, stage.removed1, stage.removed2)
        stages.append(stage)
        digests.append(points_digest(stage.pair, study.grid_section))
        # a stage with the points of the one before (its hypothesis changed nothing) reuses its rows
        known = rows_by_candidate(tables[-1]) if len(digests) > 1 and digests[-2] == digests[-1] else {}
        # Candidates run before any file is written too (a plugin candidate can fail).
        tables.append(
            suggestions(
                stage.pair,
                study.grid,
                candidates[stage.level],
                study.base_dir,
                study.grid_section,
                study.suggest is None,
                known,
            )
        )

    # The same inputs as a config pair {scan1, scan2, sensor, register}: equal stage ids.
    scan_specs = [recorded_scan_spec(str(path), sensor=sensor, poses=poses) for path in (scan1, scan2)]
    inputs = {"scan1": scan_specs[0], "scan2": scan_specs[1], "register": settings}
    ids = stage_ids(inputs, study.hypotheses, study.base_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    run = {
        "scan1": str(scan1),
        "scan2": str(scan2),
        "config": str(config_path),
        "register": settings,
        "sensor": sensor,
        "poses": poses,
    }
    write_text(out_dir / RUN_MARKER, json.dumps({**run, "stages": ids}, indent=1) + "\n")
    write_scan(scans[0], out_dir / "scan1.parquet")
    write_scan(scans[1], out_dir / "scan2.parquet")
    write_pair(out_dir / "registered.parquet", pair)
    pair_name = out_dir.resolve().name
    folders = [out_dir / "stages" / stage_id for stage_id in ids]
    changes = [folder / CHANGES for folder in folders]  # stage 0's is never written: it changes nothing
    for stage, stage_id, folder, table in zip(stages, ids, folders, tables):
        level = stage.level
        removed = folder / "removed.parquet" if level else None
        if level:
            write_stage(stage, stage_id, ids[level - 1] if level > 1 else None, changes[level], removed)
        field_stage(
            out_dir / "registered.parquet",
            changes[1 : level + 1],
            removed,
            study.grid_section,
            pair_name,
            folder / "field.parquet",
            folder / "stats.json",
            stage_id,
            folders[level - 1] / "field.parquet" if level else None,
        )
        write_suggestions(
            folder / "suggestions.parquet", table, stage_id, candidates[level], study.grid_section, digests[level]
        )
        if study.rematch:
            rematch_stage(
                out_dir / "registered.parquet",
                changes[1 : level + 1],
                stage_id,
                study.rematch,
                folder / "rematch.parquet",
            )
    stats = [folder / "stats.json" for folder in folders]
    rematched = [folder / "rematch.parquet" for folder in folders] if study.rematch else []
    write_summary(stats, out_dir / "summary.parquet", out_dir / "summary.csv", rematched)
    return read_stats(stats, rematched)


def explain_scans(
    scan1: str | Path,
    scan2: str | Path,
    config_path: str | Path | None,
    out_dir: str | Path,
    register: str | None = None,
    transform: str | Path | None = None,
    sensor: str | None = None,
    poses: dict | None = None,
) -> Explanation:
    """``lidarfield explain``: two scans read and registered as ``lidarfield run`` does, the loop
    on the grid, ``suggest`` and ``explain`` settings of the config (the schema's defaults
    without one; its ``hypotheses`` are not used), and the explanation's folder written."""
    from ..study.config import load_config, validate_config

    out_dir = check_out_dir(out_dir, EXPLAIN_MARKER, "lidarfield explain")
    study = validate_config({}, require_pairs=False) if config_path is None else load_config(config_path, None, False)
    settings = registration_settings(register, transform)
    with stage_figures(study, out_dir) as figures:  # the drawing process starts while the scans are registered
        _, pair = read_and_register(scan1, scan2, settings, sensor, poses)
        out_dir.mkdir(parents=True, exist_ok=True)  # marked first: the figures are drawn as the loop goes
        run = {
            "scan1": str(scan1),
            "scan2": str(scan2),
            "config": config_path and str(config_path),
            "register": settings,
        }
        write_text(out_dir / EXPLAIN_MARKER, json.dumps({**run, "sensor": sensor, "poses": poses}, indent=1) + "\n")
        return explain_into(pair, study, out_dir, figures)


def stage_figures(study: Study, out_dir: Path):
    """``out_dir``'s stage figures (``report.explanation.StageFigures``): drawn by a second
    process while the loop goes on when more than one core is usable (``usable_threads``)."""
    from ..report.explanation import StageFigures  # the figures: matplotlib, only here

    return StageFigures(out_dir.resolve().name, study.grid, out_dir, study.config["plots"], usable_threads() > 1)


def explain_into(pair: RegisteredPair, study: Study, out_dir: Path, figures=None) -> Explanation:
    """The loop on a registered pair (``explain_with_study``) and its folder written into
    ``out_dir``, each stage's figures drawn as soon as it is decided (``figures``: a
    ``stage_figures`` of ``out_dir`` already started; None: one made here)."""
    from ..report.explanation import write_explanation

    if figures is None:
        with stage_figures(study, out_dir) as figures:
            return explain_into(pair, study, out_dir, figures)
    explanation = explain_with_study(pair, study, out_dir.resolve().name, on_stage=figures)
    plots = study.config["plots"]
    write_explanation(explanation, study.grid, study.grid_section, out_dir, plots, figures.paths)
    return explanation


def explain_with_study(
    pair: RegisteredPair, study: Study, pair_name: str, on_stage: Callable[[list], None] | None = None
) -> Explanation:
    """The loop on a registered pair with a study config's grid, ``suggest`` and ``explain``
    settings (``on_stage``: ``explain_pair``'s): what ``lidarfield explain`` runs once it has
    registered the scans, and what the diagnosis benchmark runs on each case."""
    return explain_pair(
        pair,
        study.grid,
        study.grid_section,
        explain_settings(study.config["explain"]),
        study.suggest,
        study.base_dir,
        pair_name,
        on_stage,
    )


def field_of_scans(
    scan1: str | Path,
    scan2: str | Path,
    grid_section: dict,
    out: Path,
    format: str | None = None,
    transform: str | Path | None = None,
    pose2: str | None = None,
) -> dict:
    """``lidarfield field``: the field of scan 1 and scan 2 moved by ``transform`` (a pose file)
    or ``pose2`` (a pose string; identity without either), written with its summary into
    ``out``; returns the summary."""
    from ..analysis.field_stats import analyse_field, summary_json_safe
    from ..field.file import field_meta, write_field
    from ..field.grid import field_settings_from_config
    from ..io.pose_files import read_pose
    from ..poses import apply_pose, parse_pose_arg
    from ..sensors.rig import LIDAR

    # Everything that can fail on the user's input happens before the first file is written.
    settings = field_settings_from_config(grid_section)
    T_1_2 = np.eye(4)
    if transform is not None:
        T_1_2 = read_pose(transform)
    elif pose2 is not None:
        T_1_2 = parse_pose_arg(pose2)
    scans = read_scan(scan1, format=format), read_scan(scan2, format=format)
    for path, scan in zip((scan1, scan2), scans):
        if len(scan.xyz) == 0:
            raise InputError("holds no valid point", path)
    if out.exists() and not out.is_dir():
        raise InputError("--out exists and is not a folder", out)

    xyz2 = apply_pose(T_1_2, scans[1].xyz)
    # the sensors too: their scan patterns are part of each vector's sampling noise; a rig's
    # lidars (each point's own) are what could see what
    pair = RegisteredPair(
        scans[0].xyz,
        xyz2,
        T_1_2,
        scans[0].sensor,
        scans[1].sensor,
        {LIDAR: scans[0].attributes[LIDAR]} if scans[0].lidars else {},
        {LIDAR: scans[1].attributes[LIDAR]} if scans[1].lidars else {},
        lidars1=scans[0].lidars,
        lidars2=scans[1].lidars,
    )
    columns, statistics = analyse_field(pair, settings)
    summary = {
        "scan1": str(scan1),
        "scan2": str(scan2),
        "n1": len(scans[0].xyz),
        "n2": len(xyz2),
        "out_of_grid1": len(scans[0].xyz) - int(columns["n1"].sum()),
        "out_of_grid2": len(xyz2) - int(columns["n2"].sum()),
        "T_1_2": T_1_2.tolist(),
        **field_meta(settings, statistics),
    }
    write_field(out / "field.parquet", columns, summary_json_safe(summary))
    write_text(out / "summary.json", json.dumps(summary_json_safe(summary), indent=2, allow_nan=False) + "\n")
    return summary


def register_scans(
    scan1: str | Path,
    scan2: str | Path,
    settings: str | dict,
    out: str | Path,
    format: str | None = None,
    sensor: str | None = None,
    poses: list | None = None,
) -> RegisteredPair:
    """``lidarfield register``: scan 2 in scan 1's frame by ``settings`` (the poses, where given,
    replacing the scans' own), written to ``out``; returns the pair."""
    from ..registration import register_pair

    scans = [read_scan(path, format=format, sensor=sensor) for path in (scan1, scan2)]
    for scan, pose in zip(scans, poses or (None, None)):
        if pose is not None:
            scan.pose = pose
    pair = register_pair(*scans, settings)
    write_pair(out, pair)
    return pair


def transform_from_aligned(original: Path, aligned: Path, out: Path) -> tuple[np.ndarray, np.ndarray, float]:
    """``lidarfield register --from-aligned``: the translation mapping ``original`` onto its
    aligned copy row for row, written as a transform file; returns it, the rows' offsets and
    their spread (m)."""
    from ..registration import read_xyz_rows, translation_from_aligned_copy, translation_offsets, write_transform

    rows_original, rows_aligned = read_xyz_rows(original), read_xyz_rows(aligned)
    T = translation_from_aligned_copy(rows_original, rows_aligned)
    offsets = translation_offsets(rows_original, rows_aligned)
    spread = float(np.abs(offsets - T[:3, 3]).max())
    comment = (
        f"pose of the sensor of {original.name} in the frame of {aligned.name}: the translation mapping "
        f"it onto {aligned.name} row for row\n{len(offsets)} rows, offsets spread {spread:.3g} m"
    )
    write_transform(out, T, comment)
    return T, offsets, spread
