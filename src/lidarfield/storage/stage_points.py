"""A stage's points, stored as what the stage changed: the registered pair is kept once.

Stage k's points are the registered pair with the changes of stages 1..k applied in order.
Stage 0 applies no hypothesis and changes nothing: its points are the registered pair and its
folder has no changes file (nor ``removed.parquet``). Each later stage folder holds
``changes.parquet``, one row per point the stage changed:

- ``cloud`` (1 or 2) and ``row``: the point's row among its cloud's points in the registered
  pair (the ``row`` attribute every stage's points carry);
- ``removed``: True for a point the stage removed; False for a survivor it moved;
- ``x, y, z``: a moved survivor's corrected coordinates in frame 1 (NaN for a removed point:
  its coordinates as they were are in the stage's ``removed.parquet``).

A removing stage writes its removed rows only; a correcting one also the survivors whose
coordinates it changed, never the unchanged ones. The file's metadata is the stage's (``stage``,
``level``, ``hypothesis``, ``spec``, and a correcting stage's ``correction``, ``moved``,
``displacement``) with ``T_1_2``: sensor 2's pose in frame 1 after the stage, and
``previous``: the id of the stage whose changes come before its own (None for stage 1: only
the registered pair comes before it; a results folder written before stage 0 lost its file
names stage 0 there, whose file is empty).
:func:`read_stage_points` is the one reader: the workflow's jobs, ``lidarfield run``, the
figures and the Python API all read a stage's points through it; :func:`stage_files` finds
what it reads for a stage folder of a study's (or ``lidarfield run``'s) results.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.parquet_table import read_metadata, read_table, write_table
from ..pair import RegisteredPair, read_pair
from .layout import level_of

CHANGES = "changes.parquet"  # the file of a stage folder that holds what the stage changed
NO_MITIGATION = "none"  # the hypothesis name of stage 0, which changes nothing
ROW = "row"  # the points' attribute: each point's row among its cloud's points in the registered pair
COLUMNS = ("cloud", ROW, "removed", "x", "y", "z")


def with_rows(pair: RegisteredPair) -> RegisteredPair:
    """``pair`` with the ``row`` attribute (0..N-1 per cloud) if it has none; its neighbour
    distances are shared (same points, same order)."""
    if ROW in pair.attributes1 and ROW in pair.attributes2:
        return pair
    return RegisteredPair(
        pair.xyz1,
        pair.xyz2,
        pair.T_1_2,
        pair.sensor1,
        pair.sensor2,
        {**pair.attributes1, ROW: np.arange(len(pair.xyz1), dtype=np.int64)},
        {**pair.attributes2, ROW: np.arange(len(pair.xyz2), dtype=np.int64)},
        pair.registration,
        pair.sensor_fit,
        pair.sweeps,
        pair.lidars1,
        pair.lidars2,
        neighbours=pair.neighbours,
    )


def change_columns(
    before: RegisteredPair, keep1: np.ndarray, keep2: np.ndarray, after: RegisteredPair
) -> dict[str, np.ndarray]:
    """The change rows of a stage that kept ``keep1``/``keep2`` of ``before`` and left ``after``
    (its survivors, as corrected): the removed rows, then the survivors whose coordinates
    differ from what they were. Rows are ``before``'s ``row`` attribute (0..N-1 without one)."""
    parts = []
    for cloud, keep, xyz_before, xyz_after, attributes in (
        (1, keep1, before.xyz1, after.xyz1, before.attributes1),
        (2, keep2, before.xyz2, after.xyz2, before.attributes2),
    ):
        rows = attributes.get(ROW, np.arange(len(xyz_before), dtype=np.int64))
        gone = rows[~keep]
        parts.append((cloud, gone, True, np.full((len(gone), 3), np.nan)))
        moved = np.any(xyz_after != xyz_before[keep], axis=1)
        parts.append((cloud, rows[keep][moved], False, xyz_after[moved]))
    xyz = np.vstack([p[3] for p in parts])
    return {
        "cloud": np.concatenate([np.full(len(p[1]), p[0], np.uint8) for p in parts]),
        ROW: np.concatenate([p[1] for p in parts]).astype(np.int64),
        "removed": np.concatenate([np.full(len(p[1]), p[2]) for p in parts]).astype(bool),
        "x": xyz[:, 0],
        "y": xyz[:, 1],
        "z": xyz[:, 2],
    }


def write_changes(path: str | Path, columns: dict[str, np.ndarray], meta: dict) -> None:
    """A stage's ``changes.parquet`` (atomically); ``meta`` holds ``T_1_2`` and the stage's keys."""
    if "T_1_2" not in meta:
        raise ValueError("a stage's changes need T_1_2 in their metadata")
    write_table(path, columns, meta)


def apply_changes(kept: list[np.ndarray], xyz: list[np.ndarray], columns: dict[str, np.ndarray], path: Path) -> None:
    """One stage's change rows applied in place to ``kept`` (per cloud, which of the registered
    pair's points are left) and ``xyz`` (per cloud, their coordinates); ``path`` names the file
    in errors."""
    clouds, rows = np.asarray(columns["cloud"]), np.asarray(columns[ROW])
    removed = np.asarray(columns["removed"], dtype=bool)
    for index, cloud in enumerate((1, 2)):
        for what, mine in (("removes", removed), ("moves", ~removed)):
            wanted = rows[(clouds == cloud) & mine]
            there = (wanted >= 0) & (wanted < len(kept[index]))
            there[there] = kept[index][wanted[there]]
            if not there.all():
                raise InputError(
                    f"cloud {cloud}: {what} row {int(wanted[~there][0])}, which the stages before it do not have "
                    "(a change file of another pair or stack?)",
                    path,
                )
            if what == "removes":
                kept[index][wanted] = False
            else:
                moved = (clouds == cloud) & mine
                xyz[index][wanted] = np.column_stack([columns[axis][moved] for axis in "xyz"])


def stage_zero_keys(stage_id: str | None) -> dict:
    """The stage keys of stage 0 (``stage_id``), as a later stage's changes file holds its own."""
    return {"stage": stage_id, "level": 0, "hypothesis": NO_MITIGATION, "spec": None}


def read_stage_points(
    registered: str | Path, changes: Sequence[str | Path], stage_id: str | None = None
) -> tuple[RegisteredPair, dict]:
    """Stage k's points and their metadata: the ``registered.parquet`` of a pair with the
    ``changes.parquet`` of its stages 1..k applied in order (``changes[-1]`` is stage k's).

    The metadata is the registered pair's with stage k's keys over it (``stage``, ``level``,
    ``hypothesis``, ``T_1_2``, ...), as a file of the survivors would hold. No changes: stage 0,
    the registered pair (numbered by ``row``), with stage 0's keys when ``stage_id`` names it."""
    pair, meta = read_pair(registered)  # arrays of its own: moved in place
    pair = with_rows(pair)
    kept = [np.ones(len(pair.xyz1), dtype=bool), np.ones(len(pair.xyz2), dtype=bool)]
    xyz, stage_meta = [pair.xyz1, pair.xyz2], {}
    for path in map(Path, changes):
        columns, stage_meta = read_table(path, required=COLUMNS)
        if "T_1_2" not in stage_meta:
            raise InputError("not a stage's changes file (no T_1_2 in its lidarfield metadata)", path)
        apply_changes(kept, xyz, columns, path)
    if stage_meta:
        pair.T_1_2 = np.asarray(stage_meta["T_1_2"], dtype=np.float64)
    elif stage_id is not None:
        stage_meta = stage_zero_keys(stage_id)
    return pair.subset(*kept), {**meta, **stage_meta}


def stage_files(stage_dir: str | Path) -> tuple[Path, list[Path]]:
    """The ``registered.parquet`` and the ``changes.parquet`` of stages 1..k that stage folder
    ``stage_dir`` (``{pair}/stages/{stage}``) reads, following each stage's ``previous``; none
    for stage 0."""
    stage_dir = Path(stage_dir)
    registered = stage_dir.parent.parent / "registered.parquet"
    if level_of(stage_dir.name) == 0 and not (stage_dir / CHANGES).exists():
        return registered, []
    changes = [stage_dir / CHANGES]
    while (previous := read_metadata(changes[0]).get("previous")) is not None:
        changes.insert(0, stage_dir.parent / previous / CHANGES)
    return registered, changes
