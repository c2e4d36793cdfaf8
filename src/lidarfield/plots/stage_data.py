"""A stage folder, loaded for its figures: its survivors, what it removed and its field.

A stage folder holds ``changes.parquet`` (what the stage removed and moved: with the registered
pair and the changes of the stages before it, its survivors; see
:mod:`lidarfield.storage.stage_points`), ``removed.parquet`` (points this stage removed, with a
``hypothesis`` column) and ``field.parquet`` (one row per voxel); see the shared layout.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..defaults import default
from ..errors import InputError
from ..io.parquet_table import read_table
from ..pair import RegisteredPair
from ..storage.layout import level_of
from ..storage.stage_points import read_stage_points, stage_files

FIELD_COLUMNS = ("voxel", "n1", "n2", "x1", "y1", "z1", "x2", "y2", "z2", "u", "v", "w", "magnitude", "valid")

SUBSAMPLE_SEED = 0


@dataclass
class VectorField:
    """The valid vectors of a stage's field: tails (mean1), vectors (mean2 - mean1), magnitudes."""

    tails: np.ndarray  # (M, 3)
    vectors: np.ndarray  # (M, 3)
    magnitude: np.ndarray  # (M,)
    columns: dict[str, np.ndarray]  # the valid rows of every field column
    meta: dict

    @property
    def max_magnitude(self) -> float:
        return float(self.magnitude.max()) if len(self.magnitude) else 0.0

    @property
    def z_min(self) -> float:
        return float(self.meta.get("z_min") or default("grid", "z_min"))  # a field written before z_min was stored

    @property
    def significant(self) -> np.ndarray:
        """|z| >= z_min per vector (all True for a field written before z existed)."""
        if "z" not in self.columns:
            return np.ones(len(self.magnitude), dtype=bool)
        with np.errstate(invalid="ignore"):
            return np.abs(np.asarray(self.columns["z"], dtype=np.float64)) >= self.z_min

    def faded_label(self) -> str:
        faded = np.count_nonzero(~self.significant)
        return f"faded: |z| < {self.z_min:g}, within sampling noise ({faded} of {len(self.magnitude)})"


@dataclass
class StageData:
    """One stage folder, loaded."""

    path: Path
    pair: RegisteredPair  # the survivors of this stage
    points_meta: dict
    removed: dict[str, np.ndarray]  # removed.parquet columns (empty arrays for stage 0)
    field: VectorField

    @property
    def stage_id(self) -> str:
        return str(self.points_meta.get("stage") or self.field.meta.get("stage") or self.path.name)

    @property
    def level(self) -> int:
        level = self.points_meta.get("level")
        if level is None:
            level = level_of(self.stage_id) or 0
        return int(level)

    @property
    def hypothesis(self) -> str:
        return str(self.points_meta.get("hypothesis") or ("none" if self.level == 0 else "?"))

    @property
    def label(self) -> str:
        return f"stage {self.level:02d} {self.hypothesis}"


def read_vector_field(path: str | Path) -> VectorField:
    """The valid rows of a field Parquet file (contract columns required)."""
    return vector_field(*read_table(path, required=FIELD_COLUMNS))


def vector_field(columns: dict[str, np.ndarray], meta: dict) -> VectorField:
    """The valid rows of a field's columns (those of ``field.parquet``) and its metadata."""
    valid = np.asarray(columns["valid"], dtype=bool) & np.isfinite(columns["magnitude"])
    columns = {k: np.asarray(v)[valid] for k, v in columns.items()}
    tails = np.column_stack([columns["x1"], columns["y1"], columns["z1"]]).astype(np.float64)
    vectors = np.column_stack([columns["u"], columns["v"], columns["w"]]).astype(np.float64)
    return VectorField(tails, vectors, columns["magnitude"].astype(np.float64), columns, meta)


def load_stage(stage_dir: str | Path, points: tuple[str | Path, Sequence[str | Path]] | None = None) -> StageData:
    """Read a stage folder; a missing or malformed file raises InputError naming it. ``points``:
    the pair's ``registered.parquet`` and the ``changes.parquet`` of stages 1..k (found from the
    results' layout when None)."""
    stage_dir = Path(stage_dir)
    if not stage_dir.is_dir():
        raise InputError("stage folder not found", stage_dir)
    field = read_vector_field(stage_dir / "field.parquet")
    pair, points_meta = read_stage_points(*(points or stage_files(stage_dir)), stage_id=stage_dir.name)
    removed_path = stage_dir / "removed.parquet"
    if removed_path.exists():
        removed, _ = read_table(removed_path, required=("cloud", "x", "y", "z"))
    else:
        removed = {"cloud": np.zeros(0, np.uint8), "x": np.zeros(0), "y": np.zeros(0), "z": np.zeros(0)}
    return StageData(stage_dir, pair, points_meta, removed, field)


def subsample(xyz: np.ndarray, n: int, seed: int = SUBSAMPLE_SEED) -> np.ndarray:
    """At most ``n`` rows of ``xyz``, chosen with a fixed seed (same figure on every run)."""
    if len(xyz) <= n:
        return xyz
    rng = np.random.default_rng(seed)
    return xyz[np.sort(rng.choice(len(xyz), size=n, replace=False))]


def removed_xyz(removed: dict[str, np.ndarray], cloud: int) -> np.ndarray:
    mask = np.asarray(removed["cloud"]) == cloud
    return np.column_stack([removed["x"][mask], removed["y"][mask], removed["z"][mask]]).astype(np.float64)


def background(pair: RegisteredPair, n: int) -> np.ndarray:
    """Both clouds together, subsampled to at most ``n`` points."""
    return subsample(np.vstack([pair.xyz1, pair.xyz2]), n)


def sensor_origins(pair: RegisteredPair) -> dict[int, np.ndarray]:
    return {1: pair.origin1, 2: pair.origin2}
