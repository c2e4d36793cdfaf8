"""A small synthetic study folder that follows the output layout, for the tests and benchmarks.

The scene: a ground disc, two buildings and a car that moved between the scans, seen from
two sensor positions; the vehicle's own body returns near each sensor. Stage 1 removes points
within 3 m of their own sensor, stage 2 removes points above 10 deg elevation about the other
sensor. Fields and statistics come from ``lidarfield.field`` and ``lidarfield.analysis.field_stats``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from lidarfield.analysis.field_stats import analyse_field, summary_json_safe
from lidarfield.analysis.suggest import suggestions, write_suggestions
from lidarfield.field.file import field_meta, write_field
from lidarfield.field.grid import FieldSettings, SphericalGrid
from lidarfield.io.atomic import write_text
from lidarfield.io.parquet_table import write_table
from lidarfield.pair import RegisteredPair, write_pair
from lidarfield.storage.stage_points import CHANGES, change_columns, with_rows, write_changes
from lidarfield.study.summary import write_summary_table

SETTINGS = FieldSettings(SphericalGrid(36, 0.0, (-20.0, 20.0), 5), min_points=10)
# The candidates of each stage's "what to try next" (the pair has no sensor models, so no
# field_of_view; no outliers, the slowest to compute).
SUGGEST = [
    {"ego_vehicle": {"radius_m": 3.0, "box_m": None}},
    {"crop": {"min_range_m": 0.0, "max_range_m": 15.0, "box_m": None}},
]
HYPOTHESES = ("none", "ego_vehicle", "field_of_view")


def _box_surface(rng, centre, size, n) -> np.ndarray:
    """Points on the four walls of a box (no roof), uniformly by area."""
    c, (sx, sy, sz) = np.asarray(centre, float), size
    face = rng.integers(0, 4, n)
    t = rng.uniform(-0.5, 0.5, n)
    h = rng.uniform(0.0, sz, n)
    x = np.where(face < 2, (face - 0.5) * sx, t * sx)
    y = np.where(face < 2, t * sy, (face - 2.5) * sy)
    return np.column_stack([x + c[0], y + c[1], h + c[2]])


def _cloud(rng, origin, car_shift, n: int) -> np.ndarray:
    r = np.sqrt(rng.uniform(2.0**2, 22.0**2, n // 2))
    a = rng.uniform(0, 2 * np.pi, n // 2)
    ground = np.column_stack([r * np.cos(a), r * np.sin(a), np.full(n // 2, -1.8)])
    buildings = [
        _box_surface(rng, (10, 6, -1.8), (5, 8, 10), n // 6),
        _box_surface(rng, (-8, -9, -1.8), (7, 5, 10), n // 6),
    ]
    car = _box_surface(rng, (np.array([4.0, -5.0, -1.8]) + car_shift), (4.2, 1.8, 1.5), n // 12)
    ego = rng.normal(0, 0.6, (n // 12, 3)) * [1.5, 0.8, 0.3] + np.asarray(origin) + [0, 0, -0.8]
    return np.vstack([ground, *buildings, car, ego])


def synthetic_pair(seed: int = 0, n: int = 24000) -> RegisteredPair:
    rng = np.random.default_rng(seed)
    T = np.eye(4)
    T[:3, 3] = [1.0, 0.5, 0.0]
    xyz1 = _cloud(rng, (0, 0, 0), np.zeros(3), n)
    xyz2 = _cloud(rng, T[:3, 3], np.array([1.5, 0.3, 0.0]), n) + rng.normal(
        0, 0.02, (n // 2 + 2 * (n // 6) + 2 * (n // 12), 3)
    )
    return RegisteredPair(xyz1, xyz2, T, registration={"method": "truth", "fitness": 1.0, "converged": True})


def stats_row(
    pair_name: str,
    stage_id: str,
    level: int,
    hypothesis: str,
    pair: RegisteredPair,
    removed: tuple[int, int],
    statistics: dict,
) -> dict:
    """A stage's stats.json row, with its field's ``statistics`` as analyse_field gave them
    (not computed again: the randomness tests are most of a small field's time)."""
    return {
        "pair": pair_name,
        "stage": stage_id,
        "level": level,
        "hypothesis": hypothesis,
        "n1": len(pair.xyz1),
        "n2": len(pair.xyz2),
        "removed1": removed[0],
        "removed2": removed[1],
        **summary_json_safe(statistics),
        "registration_method": pair.registration.get("method"),
        "registration_fitness": pair.registration.get("fitness"),
    }


def _mitigate(pair: RegisteredPair, hypothesis: str) -> tuple[np.ndarray, np.ndarray]:
    """Keep-masks of both clouds for one of the toy hypotheses."""
    if hypothesis == "ego_vehicle":
        return (
            np.linalg.norm(pair.xyz1 - pair.origin1, axis=1) >= 3.0,
            np.linalg.norm(pair.xyz2 - pair.origin2, axis=1) >= 3.0,
        )
    if hypothesis == "field_of_view":

        def below(xyz, o):
            d = xyz - o
            return np.degrees(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1]))) <= 10.0

        return below(pair.xyz1, pair.origin2), below(pair.xyz2, pair.origin1)
    return np.ones(len(pair.xyz1), bool), np.ones(len(pair.xyz2), bool)


def write_synthetic_pair(
    pair_dir: str | Path, pair_name: str, seed: int = 0, levels: int = 3, n: int = 24000
) -> list[Path]:
    """Write a pair folder (stages 0..levels-1 and the pair summary); returns the stage folders."""
    pair_dir = Path(pair_dir)
    pair = synthetic_pair(seed, n)
    write_pair(pair_dir / "registered.parquet", pair)
    pair, stage_dirs, rows = with_rows(pair), [], []
    for level in range(levels):
        hypothesis = HYPOTHESES[level % len(HYPOTHESES)]
        keep1, keep2 = _mitigate(pair, hypothesis)
        stage_id = f"{level:02d}-{hypothesis}-{seed:04x}{level:04x}"
        stage_dir = pair_dir / "stages" / stage_id
        meta = {"stage": stage_id, "level": level, "hypothesis": hypothesis, "spec": {hypothesis: {}}}
        gone = pair.subset(~keep1, ~keep2)
        removed = gone.to_columns()
        removed["hypothesis"] = np.full(len(removed["cloud"]), hypothesis)
        changes = change_columns(pair, keep1, keep2, pair.subset(keep1, keep2))
        pair = pair.subset(keep1, keep2)
        previous = stage_dirs[-1].name if stage_dirs else None
        write_changes(stage_dir / CHANGES, changes, {**meta, "T_1_2": pair.T_1_2.tolist(), "previous": previous})
        write_table(stage_dir / "removed.parquet", removed, {**pair.metadata(), **meta})
        field, statistics = analyse_field(pair, SETTINGS)
        write_field(
            stage_dir / "field.parquet", field, field_meta(SETTINGS, summary_json_safe(statistics), stage=stage_id)
        )
        grid = SETTINGS.to_config()
        table = suggestions(pair, SETTINGS, SUGGEST, ".", grid)
        write_suggestions(stage_dir / "suggestions.parquet", table, stage_id, SUGGEST, grid)
        row = stats_row(pair_name, stage_id, level, hypothesis, pair, (len(gone.xyz1), len(gone.xyz2)), statistics)
        write_text(stage_dir / "stats.json", json.dumps(row))
        rows.append(row)
        stage_dirs.append(stage_dir)
    write_summary(pair_dir, rows)
    return stage_dirs


def write_summary(folder: Path, rows: list[dict]) -> None:
    """``summary.parquet`` and ``summary.csv`` of the rows, as the workflow writes them."""
    write_summary_table(rows, folder / "summary.parquet", folder / "summary.csv")


def write_synthetic_study(
    results_dir: str | Path, n_pairs: int = 2, levels: int = 3, n: int = 24000
) -> dict[str, list[Path]]:
    """A results folder of ``n_pairs`` pairs (named pair-00, pair-01, ...) and the study summary."""
    results_dir = Path(results_dir)
    pairs = {
        f"pair-{i:02d}": write_synthetic_pair(
            results_dir / f"pair-{i:02d}", f"pair-{i:02d}", seed=i, levels=levels, n=n
        )
        for i in range(n_pairs)
    }
    rows = [json.loads((d / "stats.json").read_text()) for dirs in pairs.values() for d in dirs]
    write_summary(results_dir, rows)
    return pairs


def _ring_clouds(rng, n: int, ring_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Two clouds of the same random directions and ranges about the origin; cloud 2 pushed
    ``ring_m`` outwards below -12 deg elevation (a ring) and its ranges jittered by 5 cm (along
    the ray, so that no point changes voxel: a voxel's vector is the push, not a membership change)."""
    az = rng.uniform(-np.pi, np.pi, n)
    el = np.radians(rng.uniform(-20.0, 20.0, n))
    r = rng.uniform(5.0, 30.0, n)
    direction = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    xyz1 = direction * r[:, None]
    push = np.where(np.degrees(el) < -12.0, ring_m, 0.0)
    xyz2 = direction * (r + push + rng.normal(0.0, 0.05, n))[:, None]
    return xyz1, xyz2


def write_field_study(results_dir: str | Path, n_pairs: int, levels: int = 3, n: int = 4000) -> dict[str, list[Path]]:
    """A results folder with only what the study level and the report read: per pair and
    stage ``field.parquet`` and ``stats.json`` (no points), and the study summary. Pair k's
    stage l has a ring of (k % 5 + 1) / 10 / 2^l m at the lowest elevations: hundreds of
    pairs in seconds, for the report's tests and benchmarks."""
    results_dir = Path(results_dir)
    pairs, rows = {}, []
    for k in range(n_pairs):
        name, rng = f"pair-{k:03d}", np.random.default_rng(k)
        dirs = []
        for level in range(levels):
            hypothesis = HYPOTHESES[level % len(HYPOTHESES)]
            stage_id = f"{level:02d}-{hypothesis}-{k:04x}{level:04x}"
            stage_dir = results_dir / name / "stages" / stage_id
            xyz1, xyz2 = _ring_clouds(rng, n, (k % 5 + 1) / 10 / 2**level)
            pair = RegisteredPair(
                xyz1, xyz2, np.eye(4), registration={"method": "truth", "fitness": 1.0, "converged": True}
            )
            field, statistics = analyse_field(pair, SETTINGS)
            write_field(
                stage_dir / "field.parquet", field, field_meta(SETTINGS, summary_json_safe(statistics), stage=stage_id)
            )
            row = stats_row(name, stage_id, level, hypothesis, pair, (level * 10, level * 12), statistics)
            write_text(stage_dir / "stats.json", json.dumps(row))
            rows.append(row)
            dirs.append(stage_dir)
        pairs[name] = dirs
    write_summary(results_dir, rows)
    return pairs
