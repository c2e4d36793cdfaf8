"""Neighbour distances on disk, for every stage's ``outliers`` candidate.

The ``outliers`` candidate needs every point's k nearest neighbours, the expensive part of a
stage's suggestions. A stage's points are the previous stage's minus what it removed, so:

- ``{pair}/neighbours.parquet``: the registered pair's distances, searched once (the
  ``neighbours`` job). Columns: ``cloud``, then ``mean_k{k}`` and ``reach_k{k}`` for each
  neighbour count ``k``, in the registered pair's row order.
- ``{stage}/neighbour_changes.parquet``: what stage k changed in them, written by its suggest
  job. Stage k's distances are stage k-1's carried past what stage k removed
  (:func:`~lidarfield.hypotheses.outliers.after_removal`, exact): only the points whose
  neighbourhood reached a removed point are searched again, and only the rows whose
  distances came out different are kept here (columns ``cloud``, ``k``, ``row`` among the
  stage's points of that cloud, ``mean``, ``reach``).

A stage that moved a cloud (a correction, such as ``realign``) changes every distance of it
(not exactly: a rigid motion keeps them only up to rounding), so that cloud is searched anew
and its change is the whole distances.

So a stage's suggest job reads the pair's file and the changes of stages 1..k-1, and searches
only near what its own stage removed: an appended hypothesis costs what it removes, not what
the whole stack removed. The per-stage files hold only the changes: the distances are as large
as the points.
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
            columns[f"{name}_k{k}"] = np.concatenate(
                [
                    getattr(pair.neighbours[(cloud, k)], name)
                    if (cloud, k) in pair.neighbours
                    else np.full(sizes[cloud], np.nan)
                    for cloud in (1, 2)
                ]
            )
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


def carry_to_stage(
    pair: RegisteredPair,
    neighbours_path: str | Path,
    removed_paths: list[str | Path],
    change_paths: list[str | Path],
    moved: tuple[int, ...] | list[int] = (),
) -> dict[tuple[int, int], tuple[NeighbourDistances | None, NeighbourDistances]]:
    """Give ``pair`` (stage k's survivors) the registered pair's neighbour distances
    (``neighbours_path``), carried past stages 1..k-1 by their changes (``change_paths``) and
    past what stage k removed by a search near it. ``removed_paths``: the ``removed.parquet``
    of stages 1..k, in order (their ``row`` columns say where each removed point was among the
    previous stage's points). ``moved``: the clouds stage k moved (its points file's ``moved``),
    searched anew. Returns, by (cloud, k), the distances before stage k's search (stage k-1's
    kept rows; None where searched anew) and after it, for :func:`write_changes`."""
    if len(change_paths) != max(len(removed_paths) - 1, 0):
        raise ValueError(
            f"stage {len(removed_paths)} needs the changes of the {max(len(removed_paths) - 1, 0)} stages before it, "
            f"got {len(change_paths)}"
        )
    removed = [read_table(path, required=("cloud", "x", "y", "z"))[0] for path in removed_paths]
    if any("row" not in table for table in removed):  # written before the column existed
        log.info("a removed.parquet without its row column: the neighbour distances are searched again")
        return search_anew(pair, read_neighbours(neighbours_path))
    changes = [read_changes(path) for path in change_paths]
    carried = {}
    for (cloud, k), distances in read_neighbours(neighbours_path).items():
        for table, path, change in zip(removed, removed_paths, changes):  # stages 1..k-1
            distances = apply_change(
                kept(distances, removal_keep(table, cloud, len(distances), path)), change.get((cloud, k)), path
            )
        kept_xyz = pair.xyz1 if cloud == 1 else pair.xyz2
        if not removed:  # stage 0: the registered pair's own points
            if len(distances) != len(kept_xyz):
                raise InputError(
                    f"has {len(distances)} points in cloud {cloud}, not the stage's {len(kept_xyz)}", neighbours_path
                )
            carried[(cloud, k)] = (distances, distances)
            pair.neighbours[(cloud, k)] = distances
            continue
        table, path = removed[-1], removed_paths[-1]
        keep = removal_keep(table, cloud, len(distances), path)
        if np.count_nonzero(keep) != len(kept_xyz):
            raise InputError(
                f"has {len(distances)} points in cloud {cloud} before stage {len(removed)}, not its {len(kept_xyz)} "
                f"survivors "
                f"and {np.count_nonzero(~keep)} removed points",
                neighbours_path,
            )
        if cloud in moved:  # corrected coordinates: no distance carries over
            pair.neighbours[(cloud, k)] = neighbour_distances(kept_xyz, k)
            carried[(cloud, k)] = (None, pair.neighbours[(cloud, k)])
            continue
        mine = table["cloud"] == cloud
        xyz = np.empty((len(distances), 3))
        xyz[table["row"][mine]] = np.column_stack([table["x"][mine], table["y"][mine], table["z"][mine]])
        xyz[keep] = kept_xyz
        pair.neighbours[(cloud, k)] = after_removal(distances, xyz, keep)
        carried[(cloud, k)] = (kept(distances, keep), pair.neighbours[(cloud, k)])
    return carried


def search_anew(pair: RegisteredPair, registered: dict[tuple[int, int], NeighbourDistances]) -> dict:
    """The stage's distances for every (cloud, k) the pair's file has, by a new search (what
    :func:`carry_to_stage` returns: nothing carried, so every row is a change)."""
    searched = {}
    for cloud, k in registered:
        distances = pair.neighbours[(cloud, k)] = neighbour_distances(pair.xyz1 if cloud == 1 else pair.xyz2, k)
        searched[(cloud, k)] = (None, distances)
    return searched


def removal_keep(table: dict[str, np.ndarray], cloud: int, n: int, path: str | Path) -> np.ndarray:
    """Keep-mask over a cloud's ``n`` points of the stage before, from a ``removed.parquet``."""
    rows = table["row"][table["cloud"] == cloud]
    if len(rows) and (rows.min() < 0 or rows.max() >= n):
        raise InputError(f"row out of range for the previous stage's {n} points of cloud {cloud}", path)
    keep = np.ones(n, dtype=bool)
    keep[rows] = False
    return keep


def kept(distances: NeighbourDistances, keep: np.ndarray) -> NeighbourDistances:
    return NeighbourDistances(distances.k, distances.mean[keep], distances.reach[keep])


def apply_change(
    distances: NeighbourDistances, change: NeighbourDistances | tuple | None, path: str | Path
) -> NeighbourDistances:
    """Stage j's distances from stage j-1's kept rows and stage j's change: (rows, mean,
    reach), or whole distances where the stage searched anew or k changed."""
    if change is None:
        return distances
    if isinstance(change, NeighbourDistances):
        if len(change) != len(distances):
            raise InputError(f"has whole distances of {len(change)} points for a stage of {len(distances)}", path)
        return change
    rows, mean, reach = change
    if len(rows) and rows.max() >= len(distances):
        raise InputError(f"changes row {rows.max()} of a stage with {len(distances)} points", path)
    distances = NeighbourDistances(distances.k, distances.mean.copy(), distances.reach.copy())
    distances.mean[rows], distances.reach[rows] = mean, reach
    return distances


def write_changes(
    path: str | Path, carried: dict[tuple[int, int], tuple[NeighbourDistances | None, NeighbourDistances]]
) -> None:
    """``neighbour_changes.parquet`` of a stage: the rows whose distances differ from the
    previous stage's kept rows (every row where it searched anew or k changed), atomically."""
    columns = {name: [] for name in ("cloud", "k", "row", "mean", "reach")}
    whole = []  # (cloud, k, effective k) of the distances stored whole
    for (cloud, k), (before, after) in sorted(carried.items()):
        if before is None or before.k != after.k:
            rows = np.arange(len(after))
            whole.append([cloud, k, after.k])
        else:
            rows = np.flatnonzero((before.mean != after.mean) | (before.reach != after.reach))
        for name, values in (
            ("cloud", np.full(len(rows), cloud)),
            ("k", np.full(len(rows), k)),
            ("row", rows),
            ("mean", after.mean[rows]),
            ("reach", after.reach[rows]),
        ):
            columns[name].append(values)
    types = {"cloud": np.uint8, "k": np.int64, "row": np.int64, "mean": np.float64, "reach": np.float64}
    write_table(
        path,
        {
            name: np.concatenate(parts).astype(types[name]) if parts else np.zeros(0, types[name])
            for name, parts in columns.items()
        },
        {"whole": whole},
    )


def read_changes(path: str | Path) -> dict[tuple[int, int], NeighbourDistances | tuple]:
    """A stage's changes by (cloud, k): whole distances, or (rows, mean, reach)."""
    columns, meta = read_table(path, required=("cloud", "k", "row", "mean", "reach"))
    whole = {(int(cloud), int(k)): int(effective) for cloud, k, effective in meta.get("whole", [])}
    changes = {}
    for cloud, k in {(int(c), int(k)) for c, k in zip(columns["cloud"], columns["k"])} | set(whole):
        mine = (columns["cloud"] == cloud) & (columns["k"] == k)
        rows, mean, reach = columns["row"][mine], columns["mean"][mine], columns["reach"][mine]
        if (cloud, k) in whole:
            if not np.array_equal(rows, np.arange(len(rows))):
                raise InputError(f"whole distances of cloud {cloud}, k {k} are not every row in order", path)
            changes[(cloud, k)] = NeighbourDistances(whole[(cloud, k)], mean, reach)
        else:
            changes[(cloud, k)] = (rows, mean, reach)
    return changes
