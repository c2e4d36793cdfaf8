"""``neighbours.parquet``: a stage's outlier-candidate neighbour distances, for the next stage.

The suggest job of a stage searches every point's nearest neighbours for the ``outliers``
candidate; the next stage's points are these minus the few the next hypothesis removed, so
its suggest job carries them over (:func:`~lidarfield.hypotheses.outliers.after_removal`,
exact) instead of searching again. Columns: ``cloud``, then ``mean_k{k}`` and ``reach_k{k}``
for each neighbour count ``k`` the stage's candidates used (in the points file's row order).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..hypotheses.outliers import NeighbourDistances, after_removal
from ..io.parquet_table import read_table, write_table
from ..pair import RegisteredPair

log = logging.getLogger(__name__)


def write_neighbours(path: str | Path, pair: RegisteredPair, stage_id: str | None) -> None:
    """The neighbour distances the pair's clouds have (``pair.neighbours``), atomically."""
    sizes = {1: len(pair.xyz1), 2: len(pair.xyz2)}
    columns = {"cloud": np.repeat(np.array([1, 2], dtype=np.uint8), [sizes[1], sizes[2]])}
    for k in sorted({k for _, k in pair.neighbours}):
        for name in ("mean", "reach"):
            columns[f"{name}_k{k}"] = np.concatenate([
                getattr(pair.neighbours[(cloud, k)], name) if (cloud, k) in pair.neighbours else np.full(sizes[cloud], np.nan)
                for cloud in (1, 2)
            ])  # fmt: skip
    write_table(path, columns, {"stage": stage_id})


def read_neighbours(path: str | Path) -> dict[tuple[int, int], NeighbourDistances]:
    """The neighbour distances of a ``neighbours.parquet``, by (cloud, k)."""
    columns, _ = read_table(path, required=("cloud",))
    known = {}
    for name in columns:
        if not name.startswith("mean_k"):
            continue
        k = int(name.removeprefix("mean_k"))
        for cloud in (1, 2):
            rows = columns["cloud"] == cloud
            mean, reach = columns[name][rows], columns[f"reach_k{k}"][rows]
            if not np.isnan(mean).any():
                known[(cloud, k)] = NeighbourDistances(min(k, len(mean)), mean, reach)
    return known


def carry_from_previous(pair: RegisteredPair, previous_path: str | Path, removed_path: str | Path) -> None:
    """Give ``pair`` (a stage's survivors) the neighbour distances of the previous stage
    (``previous_path``), carried past the points this stage removed (``removed_path``, whose
    ``row`` column says where each was among the previous stage's points)."""
    removed, _ = read_table(removed_path, required=("cloud", "x", "y", "z"))
    if "row" not in removed:  # written before the column existed: search again
        log.info("%s has no row column: the neighbour distances are searched again", removed_path)
        return
    for (cloud, k), before in read_neighbours(previous_path).items():
        kept = pair.xyz1 if cloud == 1 else pair.xyz2
        mine = removed["cloud"] == cloud
        rows = removed["row"][mine]
        n = len(kept) + len(rows)
        if len(before) != n or (len(rows) and rows.max() >= n):
            log.warning("%s: %d points in cloud %d, the stage had %d: searched again", previous_path, len(before), cloud, n)
            continue
        keep = np.ones(n, dtype=bool)
        keep[rows] = False
        xyz = np.empty((n, 3))
        xyz[rows] = np.column_stack([removed["x"][mine], removed["y"][mine], removed["z"][mine]])
        xyz[keep] = kept
        pair.neighbours[(cloud, k)] = after_removal(before, xyz, keep)
