"""``outliers``: statistical outlier removal (Open3D's rule), on each cloud separately.

A point's score is its mean distance to its ``nb_neighbors`` nearest points of its own cloud,
the point itself included (at distance 0), as Open3D's ``remove_statistical_outlier`` counts
them. A point is kept when its score is above 0 and strictly below mean + ``std_ratio`` * std
of the scores. Open3D's quirks are kept so that the keep-masks are the same as its own: the
mean and the std (Bessel-corrected) sum only the scores above 0 but divide by the number of
all points, and a point whose neighbours all coincide with it (score 0) is removed. A cloud of
no more than ``nb_neighbors`` points keeps every point (too few for the statistic; Open3D
would average over the whole cloud instead).

The neighbours come from ``scipy.spatial.cKDTree`` (Open3D is not imported), on as many
threads as the job's ``OMP_NUM_THREADS`` says (Snakemake and the workflow's worker set it to
the rule's ``threads``), or on every core the process may use.

The search is the expensive part (0.15 s per 50,000 points), and the stages of a stack each
search again clouds that differ from the stage before by the few points it removed. So the
neighbour distances of a cloud are kept (:class:`NeighbourDistances`, memoised on the pair) and
carried to its survivors by :func:`after_removal`: only the points whose neighbourhood reached
a removed point are searched again, and the result is exactly a new search's.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from ..pair import RegisteredPair
from .params import doc


@dataclass(frozen=True)
class Params:
    nb_neighbors: int = field(
        default=20, metadata=doc("neighbours in each point's mean distance (the point itself included)")
    )
    std_ratio: float = field(
        default=2.0, metadata=doc("standard deviations above the mean beyond which a point is removed")
    )

    def __post_init__(self):
        if self.nb_neighbors < 1 or not self.std_ratio > 0:
            raise ValueError(f"need nb_neighbors >= 1 and std_ratio > 0, got {self.nb_neighbors} and {self.std_ratio}")


def neighbour_threads() -> int:
    """Threads for the neighbour search: ``OMP_NUM_THREADS`` if set, else the usable cores."""
    try:
        threads = int(os.environ.get("OMP_NUM_THREADS", ""))
    except ValueError:
        threads = 0
    return threads if threads > 0 else len(os.sched_getaffinity(0))


@dataclass(frozen=True)
class NeighbourDistances:
    """Per point of one cloud, over its ``k`` nearest points (itself included)."""

    k: int
    mean: np.ndarray  # mean distance: the outlier score
    reach: np.ndarray  # distance to the k-th: no point closer than this is outside the k

    def __len__(self) -> int:
        return len(self.mean)


def neighbour_distances(xyz: np.ndarray, k: int, workers: int | None = None) -> NeighbourDistances:
    """The ``k`` nearest neighbours' mean distance and reach of every point, by a full search
    (the plain reference of :func:`after_removal`); ``k`` is capped at the cloud's size."""
    xyz = np.asarray(xyz, dtype=np.float64)
    k = min(k, len(xyz))
    if k == 0:
        return NeighbourDistances(0, np.zeros(0), np.zeros(0))
    mean, reach = _search(xyz, xyz, k, workers)
    return NeighbourDistances(k, mean, reach)


def after_removal(
    before: NeighbourDistances, xyz_before: np.ndarray, keep: np.ndarray, workers: int | None = None
) -> NeighbourDistances:
    """The neighbour distances of ``xyz_before[keep]``, from those of ``xyz_before``: equal to
    :func:`neighbour_distances` of the survivors, bit for bit.

    A survivor farther from every removed point than its reach keeps all its k neighbours:
    same points, same distances, same sum. Only the others are searched again, among the
    survivors. (Ties at the reach count as reached: searched again, never wrong.)
    """
    xyz_before = np.asarray(xyz_before, dtype=np.float64)
    keep = np.asarray(keep, dtype=bool)
    kept = xyz_before[keep]
    if before.k == 0 or len(kept) < before.k:  # fewer points than neighbours: k changes
        return neighbour_distances(kept, before.k, workers)
    mean, reach = before.mean[keep], before.reach[keep]
    removed = xyz_before[~keep]
    if len(removed) == 0 or len(kept) == 0:
        return NeighbourDistances(before.k, mean, reach)
    reached = _reaches(kept, reach, removed, workers)
    if reached.any():
        mean, reach = mean.copy(), reach.copy()
        mean[reached], reach[reached] = _search(kept, kept[reached], before.k, workers)
    return NeighbourDistances(before.k, mean, reach)


def _reaches(points: np.ndarray, reach: np.ndarray, others: np.ndarray, workers: int | None) -> np.ndarray:
    """Whether each point has one of ``others`` within its ``reach`` (or just beyond: a tie
    must count). The points are asked in tiers of reach, each search bounded by its tier's
    largest: bounded by the cloud's largest reach (an isolated point's, metres), the search
    for the nearest of ``others`` explores most of their tree for every point."""
    from scipy.spatial import cKDTree

    tree = cKDTree(others, balanced_tree=False)
    reach = reach * (1 + 1e-9) + 1e-12
    reached = np.zeros(len(points), dtype=bool)
    lower = -np.inf
    for upper in np.quantile(reach, [0.5, 0.9, 0.99, 0.999, 1.0]):
        tier = (reach > lower) & (reach <= upper)
        if tier.any():
            distance, _ = tree.query(
                points[tier], k=1, distance_upper_bound=np.nextafter(upper, np.inf), workers=_workers(workers)
            )
            reached[tier] = distance <= reach[tier]
        lower = upper
    return reached


def _search(cloud: np.ndarray, points: np.ndarray, k: int, workers: int | None) -> tuple[np.ndarray, np.ndarray]:
    """Mean and k-th distance from each of ``points`` to its ``k`` nearest in ``cloud``."""
    from scipy.spatial import cKDTree  # a third of a second: only when this hypothesis runs

    # An unbalanced tree (split at the midpoint) builds and answers faster on scans; exact all the same.
    distances, _ = cKDTree(cloud, balanced_tree=False).query(points, k=k, workers=_workers(workers))
    distances = distances.reshape(len(points), k)
    # Summed nearest first, one neighbour at a time, as Open3D does: numpy's pairwise row sum
    # rounds differently, which moves scores at the threshold by an ulp.
    total = np.zeros(len(points))
    for column in distances.T:
        total += column
    return total / k, distances[:, -1].copy()


def _workers(workers: int | None) -> int:
    return workers or neighbour_threads()


def statistical_inliers(
    xyz: np.ndarray,
    nb_neighbors: int,
    std_ratio: float,
    workers: int | None = None,
    distances: NeighbourDistances | None = None,
) -> np.ndarray:
    """Keep-mask of Open3D's ``remove_statistical_outlier`` on one cloud (see the module);
    ``distances``: the cloud's, when already known."""
    if len(xyz) <= nb_neighbors:
        return np.ones(len(xyz), dtype=bool)  # too few points for the statistic: nothing is an outlier
    if distances is None:
        distances = neighbour_distances(xyz, nb_neighbors, workers)
    return open3d_threshold(distances.mean, std_ratio)


def open3d_threshold(scores: np.ndarray, std_ratio: float) -> np.ndarray:
    """Open3D's keep rule on the scores (sums in point order: ``add.accumulate`` is sequential)."""
    positive = scores > 0
    mean = np.add.accumulate(np.where(positive, scores, 0.0))[-1] / len(scores)
    squares = np.add.accumulate(np.where(positive, (scores - mean) * (scores - mean), 0.0))[-1]
    with np.errstate(invalid="ignore", divide="ignore"):  # one point: 0 / 0, nothing kept, as Open3D
        threshold = mean + std_ratio * np.sqrt(squares / (len(scores) - 1))
    return positive & (scores < threshold)


def cloud_neighbour_distances(pair: RegisteredPair, cloud: int, k: int) -> NeighbourDistances:
    """A cloud's neighbour distances, memoised on the pair (``pair.neighbours``)."""
    known = pair.neighbours.get((cloud, k))
    if known is None:
        known = pair.neighbours[(cloud, k)] = neighbour_distances(pair.xyz1 if cloud == 1 else pair.xyz2, k)
    return known


def carry_neighbours(
    before: RegisteredPair, keep1: np.ndarray, keep2: np.ndarray, after: RegisteredPair, skip: tuple[int, ...] = ()
) -> None:
    """Give ``after`` (``before``'s survivors) every neighbour distance ``before`` has, carried
    by :func:`after_removal`, except for the clouds in ``skip`` (moved by a correction: their
    distances are searched anew when asked for)."""
    for (cloud, k), distances in before.neighbours.items():
        if cloud in skip:
            continue
        xyz, keep = (before.xyz1, keep1) if cloud == 1 else (before.xyz2, keep2)
        after.neighbours[(cloud, k)] = after_removal(distances, xyz, keep)


def outliers(pair: RegisteredPair, params: Params) -> tuple[np.ndarray, np.ndarray]:
    """Keep-masks of the statistical inliers of each cloud."""
    return tuple(
        statistical_inliers(
            xyz,
            params.nb_neighbors,
            params.std_ratio,
            distances=cloud_neighbour_distances(pair, cloud, params.nb_neighbors),
        )
        for cloud, xyz in ((1, pair.xyz1), (2, pair.xyz2))
    )
