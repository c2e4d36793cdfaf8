"""The workflow's jobs, file in, file out, one function per ``lidarfield job``: a scan
(simulated or recorded), the registered pair, a stage's changes (mitigate), its field with its
summary row, its suggestions and its rematch; the pair's and the study's figures and pages; a
pair's explanation.

Each job reads what the config resolved for it (a scan spec, the pair's ``register``
setting, one stack entry, the grid) and writes its outputs whole and atomically, so a failed
job leaves nothing behind. ``lidarfield run`` calls the same functions for one pair.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from ..analysis.field_stats import analyse_field, summary_json_safe
from ..field.file import field_meta, read_field, write_field
from ..field.grid import field_settings_from_config
from ..io import read_scan, write_scan
from ..io.atomic import write_text
from ..io.parquet_table import read_metadata, read_table, write_table
from ..pair import read_pair, write_pair
from ..poses import apply_pose, invert_pose
from ..scan import Scan
from ..sensors.fit import log_fit
from ..sensors.models import sensor_model
from ..sensors.rig import LIDAR, rig_of_spec
from ..storage.stage_points import CHANGES, read_stage_points, write_changes
from ..study.stack import Stage, next_stage
from ..study.summary import summary_row

log = logging.getLogger(__name__)


def simulated_scan(spec: dict) -> Scan:
    """Ray-cast one scan as a :class:`ScanSpec` of kind ``simulated`` describes it."""
    from ..simulation.raycast import simulate_scan
    from ..simulation.scene import load_scene

    return simulate_scan(
        load_scene(spec["scene"]),
        sensor_model(spec["sensor"]),
        np.asarray(spec["pose"], dtype=float),
        time_s=spec["time_s"],
        seed=spec["seed"],
        range_noise_m=spec["range_noise_m"],
        dropout=spec["dropout"],
        max_range_m=spec["max_range_m"],
        rolling_shutter=spec["rolling_shutter"],
        linear_velocity_mps=spec["velocity_mps"],
        angular_velocity_rps=spec["angular_velocity_rps"],
        # calibration faults: in the spec only when set (study.pairs keeps older specs unchanged)
        range_scale=spec.get("range_scale", 1.0),
        range_offset_m=spec.get("range_offset_m", 0.0),
        elevation_offsets_deg=spec.get("elevation_offsets_deg"),
    )


def recorded_scan(spec: dict) -> Scan:
    """Read one recorded scan as a :class:`ScanSpec` of kind ``recorded`` describes it."""
    scan = read_scan(
        spec["path"], format=spec["format"], sensor=spec["sensor"], poses=spec.get("poses"), options=spec.get("options")
    )
    if spec["pose"] is not None:
        scan.pose = np.asarray(spec["pose"], dtype=float)
    if spec.get("stamp_s") is not None:
        scan.stamp_s = spec["stamp_s"]
    if spec.get("sweep_motion") is not None:
        scan.sweep_motion = spec["sweep_motion"]
    if spec.get("lidars"):
        scan.lidars, scan.attributes[LIDAR] = rig_of_spec(spec["lidars"], scan.attributes, len(scan), spec["path"])
    return scan


def scan_job(kind: str, spec: dict, out: str | Path) -> None:
    scan = simulated_scan(spec) if kind == "simulated" else recorded_scan(spec)
    log.info("%s scan: %d points (%d invalid rows dropped) -> %s", kind, len(scan), scan.dropped_invalid, out)
    log_fit(scan.xyz, scan.sensor, spec.get("path") or str(out))
    write_scan(scan, out)


def register_job(scan1: str | Path, scan2: str | Path, settings, out: str | Path) -> None:
    from ..registration import register_pair

    pair = register_pair(read_scan(scan1), read_scan(scan2), settings)
    reg = pair.registration
    log.info("registration %s: %s", reg.get("method"), {k: v for k, v in reg.items() if k != "method"})
    if reg.get("warning"):
        log.warning("registration of %s to %s: %s", scan2, scan1, reg["warning"])
    write_pair(out, pair)


def write_stage(
    stage: Stage, stage_id: str, previous: str | None, changes_out: str | Path, removed_out: str | Path
) -> None:
    """The stage's changes (what it removed and moved, sensor 2's pose after it and the
    ``previous`` stage's id) and its removed points, each file with the stage's metadata."""
    meta = stage.metadata(stage_id)
    write_changes(changes_out, stage.changes, {"T_1_2": stage.pair.T_1_2.tolist(), "previous": previous, **meta})
    write_table(removed_out, stage.removed_columns(), {**stage.removed.metadata(), **meta})


def mitigate_stage(
    registered: str | Path,
    changes_in: list[str | Path],
    step: dict,
    stage_id: str,
    level: int,
    changes_out: str | Path,
    removed_out: str | Path,
    base_dir: str | Path = ".",
    study_grid: dict | None = None,
) -> None:
    """Stage ``level`` >= 1: apply ``step`` to the points of the previous stage (the registered
    pair with ``changes_in``, the changes of stages 1..level-1). Stage 0 changes nothing and has
    no job: its points are the registered pair."""
    pair, meta = read_stage_points(registered, changes_in)
    stage = next_stage(pair, step, level, base_dir, study_grid)
    log.info("stage %s: removed %d + %d points", stage_id, stage.removed1, stage.removed2)
    if stage.correction is not None:
        log.info("stage %s: corrected, %s", stage_id, stage.correction_json())
    write_stage(stage, stage_id, meta.get("stage") if changes_in else None, changes_out, removed_out)


def field_stage(
    registered: str | Path,
    changes: list[str | Path],
    removed_path: str | Path | None,
    grid_section: dict,
    pair_name: str,
    field_out: str | Path,
    stats_out: str | Path,
    stage_id: str | None = None,
    previous: str | Path | None = None,
) -> dict:
    """The field of a stage's points (the registered pair with ``changes``, those of stages
    1..k) and its summary row (``stats.json``); returns the row. Stage 0 (no changes, its id
    ``stage_id``) has no removed points (``removed_path`` None). ``previous``: the stage
    before's ``field.parquet``, whose columns and statistics are taken as they are when it was
    computed from the same points, grid and code (``points_digest``: its hypothesis removed and
    moved nothing)."""
    from ..analysis.suggest import points_digest

    pair, meta = read_stage_points(registered, changes, stage_id)
    removed = {"cloud": np.zeros(0, np.uint8)}
    if removed_path is not None:
        removed, _ = read_table(removed_path, columns=("cloud",))
    settings = field_settings_from_config(grid_section)
    digest = points_digest(pair, grid_section)
    previous_meta = read_metadata(previous) if previous is not None else {}
    if previous_meta.get("points") == digest:
        log.info("the field of %s: the same points, grid and code", previous)
        columns, statistics = read_field(previous)[0], previous_meta["statistics"]
    else:
        columns, statistics = analyse_field(pair, settings)
        statistics = summary_json_safe(statistics)
    write_field(field_out, columns, field_meta(settings, statistics, stage=meta.get("stage"), points=digest))
    row = summary_row(pair_name, pair, meta, removed["cloud"], statistics)
    write_text(stats_out, json.dumps(row, indent=1) + "\n")
    return row


def stack_jobs(
    registered: str | Path,
    steps: list[dict],
    folders: list[Path],
    grid_section: dict,
    pair_name: str,
    base_dir: str | Path = ".",
) -> list[Path]:
    """A stack's stages through the workflow's jobs, in the order it runs them: stage 0's field
    (the registered pair), then each step's mitigate and field jobs. ``folders``: stage 0's and
    each step's folder, named by its stage id. Returns the changes files of stages 1..N."""
    changes = []
    for level, folder in enumerate(folders):
        removed = None
        if level:  # stage 0 changes nothing: it has no mitigate job
            removed = folder / "removed.parquet"
            mitigate_stage(
                registered,
                changes,
                steps[level - 1],
                folder.name,
                level,
                folder / CHANGES,
                removed,
                base_dir,
                grid_section,
            )
            changes.append(folder / CHANGES)
        field_stage(
            registered,
            changes,
            removed,
            grid_section,
            pair_name,
            folder / "field.parquet",
            folder / "stats.json",
            folder.name,
            folders[level - 1] / "field.parquet" if level else None,
        )
    return changes


def suggest_stage(
    registered: str | Path,
    changes: list[str | Path],
    stage_id: str,
    candidates: list[dict],
    grid_section: dict,
    out: str | Path,
    base_dir: str | Path = ".",
    defaults: bool = False,
) -> dict[str, np.ndarray]:
    """``suggestions.parquet`` of a stage (the registered pair with ``changes``, those of stages
    1..k; stage 0 takes its keys from ``stage_id``); returns the table. The rows of another stage
    of the pair with the same points (``out``'s sibling stage folders) are reused."""
    from ..analysis.suggest import points_digest, stored_rows, suggestions, write_suggestions

    pair, meta = read_stage_points(registered, changes, stage_id)
    digest = points_digest(pair, grid_section)
    out = Path(out)
    siblings = sorted(p for p in out.parent.parent.glob(f"*/{out.name}") if p != out)
    known = stored_rows(siblings, digest)
    settings = field_settings_from_config(grid_section)
    table = suggestions(pair, settings, candidates, base_dir, grid_section, defaults, known)
    write_suggestions(out, table, meta.get("stage"), candidates, grid_section, digest)
    return table


def rematch_stage(
    registered: str | Path, changes: list[str | Path], stage_id: str, settings: dict, out: str | Path
) -> dict[str, np.ndarray]:
    """Rematch a stage's survivors (the registered pair with ``changes``) and write
    ``rematch.parquet``; returns the table."""
    from ..analysis.rematch import reference_pose, rematch

    pair, meta = read_stage_points(registered, changes, stage_id)
    reference, kind = reference_pose(meta)
    # The survivors of scan 2 are in frame 1 by the study's T_1_2: back to sensor 2's frame.
    xyz2_sensor = apply_pose(invert_pose(pair.T_1_2), pair.xyz2)
    log.info(
        "rematch stage %s: %d + %d points, reference: %s", meta.get("stage"), len(pair.xyz1), len(xyz2_sensor), kind
    )
    table = rematch(pair.xyz1, xyz2_sensor, reference, settings)
    out_meta = {
        "stage": meta.get("stage"),
        "level": meta.get("level"),
        "hypothesis": meta.get("hypothesis"),
        "reference": kind,
        "reference_T_1_2": reference.tolist(),
        "settings": settings,
    }
    write_table(out, table, out_meta)
    return table


def plot_pair_job(stats: list[str | Path], rematched: list[str | Path], out: str | Path) -> None:
    """The pair's figures across its stages (and its rematch figure in a rematch study)."""
    from ..plots import plot_pair
    from ..study.summary import read_stats

    plot_pair(read_stats(stats), out)
    if rematched:
        from ..plots.rematch import plot_pair_rematch

        plot_pair_rematch(rematched, out)


def study_figures_job(summary: str | Path, study_dir: str | Path, out: str | Path) -> None:
    """The study level's figures, from the summary and the study tables."""
    from ..plots.study import plot_study
    from ..study.tables import read_study_tables

    t = read_study_tables(summary, study_dir)
    plot_study(t.summary, t.voxels, t.hypotheses, t.pairs, t.grid, out)


def pair_report_job(
    pair_name: str,
    stage_dirs: list[str | Path],
    stats: list[str | Path],
    rematched: list[str | Path],
    suggestion_files: list[str | Path],
    plots: dict,
    figures: bool,
    on_demand: str | None,
    max_mb: float,
    out: str | Path,
) -> None:
    """A pair's page, beside the study overview; suggestions shown for the stages whose
    ``suggestions.parquet`` is given."""
    from ..report import write_pair_page
    from ..study.summary import read_stats

    write_pair_page(
        pair_name,
        stage_dirs,
        read_stats(stats, rematched),
        out,
        plots,
        figures,
        overview_href="../report.html",
        on_demand=on_demand,
        max_mb=max_mb,
        suggested={Path(p).parent.name for p in suggestion_files},
    )


def report_job(
    config: dict,
    summary: str | Path,
    study_dir: str | Path,
    figures: str | Path,
    plotted: list[str],
    suggestion_files: list[str | Path],
    explanations: list[str | Path],
    out: str | Path,
) -> None:
    """The study overview: its tables, figures, the pairs' last-stage suggestions
    (``.../{pair}/stages/{stage}/suggestions.parquet``) and what explain found."""
    from ..report import write_overview
    from ..report.explanation import read_explanations
    from ..study.tables import read_study_tables

    tables = read_study_tables(summary, study_dir)
    last_stages = {Path(p).parents[2].name: Path(p).parent for p in suggestion_files}
    explained = read_explanations(explanations)
    write_overview(config, tables, out, figures, set(plotted), last_stages, explained=explained)


def explain_job(
    points: str | Path,
    pair_name: str,
    grid_section: dict,
    suggest: list[dict] | None,
    explain: dict,
    plots: dict | None,
    out_dir: str | Path,
):
    """A study pair's explain target: the loop on its registered pair, its folder written;
    returns the explanation."""
    from ..analysis.stopping_rule import explain_settings
    from ..report.explanation import write_explanation
    from ..study.explain_loop import explain_pair

    pair, _ = read_pair(points)
    settings = field_settings_from_config(grid_section)
    explanation = explain_pair(pair, settings, grid_section, explain_settings(explain), suggest, ".", pair_name)
    write_explanation(explanation, settings, grid_section, out_dir, plots)
    return explanation
