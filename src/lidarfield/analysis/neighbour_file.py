"""``{pair}/neighbours.parquet``: the registered pair's neighbour distances, for every stage's
``outliers`` candidate.

The ``outliers`` candidate needs every point's k nearest neighbours, the expensive part of a
stage's suggestions. A stage's points are the registered pair's minus what the stack removed
so far, so the pair's distances are searched once (the ``neighbours`` job) and each stage's
suggest job carries them past the points its stages removed
(:func:`~lidarfield.hypotheses.outliers.after_removal`, exact). Columns: ``cloud``, then
``mean_k{k}`` and ``reach_k{k}`` for each neighbour count ``k``, in the registered pair's row
order. One file per pair rather than per stage: the distances are as large as the points.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..hypotheses.outliers import NeighbourDistances, after_removal, neighbour_distances
from ..io.parquet_table import read_table, write_table
from ..pair import RegisteredPair, read_pair

log = logging.getLogger(__name__)


def write_neighbours(path: str | Path, pair: RegisteredPair) -> None:
    """The neighbour distances the pair's clouds have (``pair.neighbours``), atomically."""
    sizes = {1: len(pair.xyz1), 2: len(pair.xyz2)}
    columns = {"cloud": np.repeat(np.array([1, 2], dtype=np.uint8), [sizes[1], sizes[2]])}
    for k in sorted({k for _, k in pair.neighbours}):
        for name in ("mean", "reach"):
            columns[f"{name}_k{k}"] = np.concatenate([
                getattr(pair.neighbours[(cloud, k)], name) if (cloud, k) in pair.neighbours else np.full(sizes[cloud], np.nan)
                for cloud in (1, 2)
            ])  # fmt: skip
    write_table(path, columns, {"points": sizes})


def read_neighbours(path: str | Path) -> dict[tuple[int, int], NeighbourDistances]:
    """The neighbour distances of a ``neighbours.parquet``, by (cloud, k)."""
    columns, _ = read_table(path, required=("cloud",))
    known = {}
    for name in columns:
        if name.startswith("mean_k"):
            k = int(name.removeprefix("mean_k"))
            for cloud in (1, 2):
                rows = columns["cloud"] == cloud
                mean, reach = columns[name][rows], columns[f"reach_k{k}"][rows]
                if not np.isnan(mean).any():
                    known[(cloud, k)] = NeighbourDistances(min(k, len(mean)), mean, reach)
    return known


def neighbours_job(points_path: str | Path, ks: list[int], out: str | Path) -> None:
    """``{pair}/neighbours.parquet`` of a registered pair, for each neighbour count in ``ks``."""
    pair, _ = read_pair(points_path)
    for k in ks:
        for cloud, xyz in ((1, pair.xyz1), (2, pair.xyz2)):
            pair.neighbours[(cloud, k)] = neighbour_distances(xyz, k)
    write_neighbours(out, pair)


def carry_from_registered(pair: RegisteredPair, neighbours_path: str | Path, removed_paths: list[str | Path]) -> None:
    """Give ``pair`` (stage k's survivors) the registered pair's neighbour distances
    (``neighbours_path``) carried past what stages 1..k removed (their ``removed.parquet``, in
    order; each ``row`` column says where a point was among the previous stage's points)."""
    removed = [read_table(path, required=("cloud", "x", "y", "z"))[0] for path in removed_paths]
    if any("row" not in table for table in removed):  # written before the column existed
        log.info("a removed.parquet without its row column: the neighbour distances are searched again")
        return
    for (cloud, k), registered in read_neighbours(neighbours_path).items():
        kept_xyz = pair.xyz1 if cloud == 1 else pair.xyz2
        n = len(registered)
        if n != len(kept_xyz) + sum(np.count_nonzero(table["cloud"] == cloud) for table in removed):
            raise InputError(f"has {n} points in cloud {cloud}, not the stages' survivors and removed points", neighbours_path)
        xyz = np.empty((n, 3))
        survivors = np.arange(n)  # each survivor's row among the registered pair's
        for table, path in zip(removed, removed_paths):
            mine = table["cloud"] == cloud
            rows = table["row"][mine]
            if len(rows) and (rows.min() < 0 or rows.max() >= len(survivors)):
                raise InputError(f"row out of range for the previous stage's {len(survivors)} points of cloud {cloud}", path)
            xyz[survivors[rows]] = np.column_stack([table["x"][mine], table["y"][mine], table["z"][mine]])
            survivors = np.delete(survivors, rows)
        xyz[survivors] = kept_xyz
        keep = np.zeros(n, dtype=bool)
        keep[survivors] = True
        pair.neighbours[(cloud, k)] = after_removal(registered, xyz, keep)
