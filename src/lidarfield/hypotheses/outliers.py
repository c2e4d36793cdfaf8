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
a removed point are searched again, and the result is exactly a new search's. A cloud a stage
moved as a whole (``realign``) keeps its neighbours (:func:`after_rigid_move`): their distances
are measured again at the new places, as a search measures them, and only the points whose
(k+1)-th neighbour came too near to tell are searched again.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..pair import RegisteredPair
from ..threads import usable_threads
from .params import doc
from .survivors import survivor_rows


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


@dataclass(frozen=True)
class NeighbourDistances:
    """Per point of one cloud, over its ``k`` nearest points (itself included)."""

    k: int
    mean: np.ndarray  # mean distance: the outlier score
    reach: np.ndarray  # distance to the k-th: no point closer than this is outside the k
    index: np.ndarray  # (N, k) the k nearest, nearest first (rows of the cloud, int32: half the memory)
    beyond: np.ndarray  # no point outside the k is nearer than this (the (k+1)-th's distance, or less)

    def __len__(self) -> int:
        return len(self.mean)


def neighbour_distances(xyz: np.ndarray, k: int, workers: int | None = None) -> NeighbourDistances:
    """The ``k`` nearest neighbours' mean distance and reach of every point, by a full search
    (the plain reference of :func:`after_removal`); ``k`` is capped at the cloud's size."""
    xyz = np.asarray(xyz, dtype=np.float64)
    k = min(k, len(xyz))
    if k == 0:
        return NeighbourDistances(0, np.zeros(0), np.zeros(0), np.zeros((0, 0), np.int32), np.zeros(0))
    return NeighbourDistances(k, *_search(xyz, xyz, k, workers))


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
    removed = xyz_before[~keep]
    if len(removed) == 0:
        return before
    # the survivors' neighbours, numbered among the survivors (right where none was removed)
    index = survivor_rows(keep)[before.index[keep]]
    carried = [before.mean[keep], before.reach[keep], index, before.beyond[keep]]
    if len(kept):
        _search_again(carried, kept, _reaches(kept, carried[1], removed, workers), before.k, workers)
    return NeighbourDistances(before.k, *carried)


def after_rigid_move(before: NeighbourDistances, xyz_after: np.ndarray, drift_m: float = 0.0, workers=None):
    """The neighbour distances of a cloud's points moved together (the same rows) to
    ``xyz_after``, each at most ``drift_m`` from where one rigid motion took it: equal to
    :func:`neighbour_distances` of ``xyz_after``, bit for bit. Such a move changes a distance by
    at most twice the drift (and rounding), so where a point's k-th distance, measured again at
    the new places as a search measures it, stays nearer than its ``beyond`` less that, its k
    are still its k nearest; the others are searched again."""
    xyz_after = np.asarray(xyz_after, dtype=np.float64)
    if before.k == 0 or len(before.index) == 0:
        return before
    distance = np.empty(before.index.shape)
    for j, column in enumerate(before.index.T):  # one neighbour at a time: no (N, k, 3) array
        delta = xyz_after - xyz_after[column]
        distance[:, j] = np.sqrt(delta[:, 0] * delta[:, 0] + delta[:, 1] * delta[:, 1] + delta[:, 2] * delta[:, 2])
    index = before.index.copy()
    unsorted = np.flatnonzero(np.any(distance[:, 1:] < distance[:, :-1], axis=1))  # rounding swapped near ties
    if len(unsorted):
        order = np.argsort(distance[unsorted], axis=1, kind="stable")
        distance[unsorted] = np.take_along_axis(distance[unsorted], order, axis=1)
        index[unsorted] = np.take_along_axis(index[unsorted], order, axis=1)
    margin = 2 * drift_m + MOVE_ROUNDING_M
    carried = [_mean(distance), distance[:, -1].copy(), index, before.beyond - margin]
    _search_again(carried, xyz_after, ~(distance[:, -1] < carried[3]), before.k, workers)
    return NeighbourDistances(before.k, *carried)


# A rigid motion computed in floating point keeps a distance between points up to ~1e-13 m
# (coordinates of hundreds of metres): far inside this.
MOVE_ROUNDING_M = 1e-9


def _search_again(carried: list, cloud: np.ndarray, rows: np.ndarray, k: int, workers: int | None) -> None:
    """``carried`` (mean, reach, index, beyond) with the points ``rows`` (a mask) searched anew
    in ``cloud``."""
    rows = np.flatnonzero(rows)
    if len(rows):
        for values, found in zip(carried, _search(cloud, cloud[rows], k, workers)):
            values[rows] = found


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


def _search(cloud: np.ndarray, points: np.ndarray, k: int, workers: int | None):
    """Mean and k-th distance from each of ``points`` to its ``k`` nearest in ``cloud``, those
    k (rows of ``cloud``, nearest first) and the distance of the next (inf where none)."""
    from scipy.spatial import cKDTree  # a third of a second: only when this hypothesis runs

    found = min(k + 1, len(cloud))
    # An unbalanced tree (split at the midpoint) builds and answers faster on scans; exact all the same.
    distances, index = cKDTree(cloud, balanced_tree=False).query(points, k=found, workers=_workers(workers))
    distances, index = distances.reshape(len(points), found), index.reshape(len(points), found)
    beyond = distances[:, k] if found > k else np.full(len(points), np.inf)
    return _mean(distances[:, :k]), distances[:, k - 1].copy(), index[:, :k].astype(np.int32), beyond


def _mean(distances: np.ndarray) -> np.ndarray:
    """Each row's mean, summed nearest first, one neighbour at a time, as Open3D does: numpy's
    pairwise row sum rounds differently, which moves scores at the threshold by an ulp."""
    total = np.zeros(len(distances))
    for column in distances.T:
        total += column
    return total / distances.shape[1]


def _workers(workers: int | None) -> int:
    return workers or usable_threads()


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
    """A cloud's neighbour distances, memoised on the pair (``pair.neighbours``): searched, or
    carried from the stage before when first asked for (``CarriedDistances``)."""
    known = pair.neighbours.get((cloud, k))
    if known is None:
        known = pair.neighbours[(cloud, k)] = neighbour_distances(pair.xyz1 if cloud == 1 else pair.xyz2, k)
    elif isinstance(known, CarriedDistances):
        known = pair.neighbours[(cloud, k)] = known.distances()
    return known


@dataclass(frozen=True)
class CarriedDistances:
    """A cloud's neighbour distances carried from the stage before (``before``, of the points
    ``xyz_before``) to its points ``keep``, moved as a whole to ``moved_to`` (None: not moved):
    found when first asked for, by the candidate that asks, not between two steps."""

    before: NeighbourDistances | CarriedDistances
    xyz_before: np.ndarray
    keep: np.ndarray
    moved_to: np.ndarray | None = None
    drift_m: float = 0.0

    def distances(self) -> NeighbourDistances:
        before = self.before.distances() if isinstance(self.before, CarriedDistances) else self.before
        carried = after_removal(before, self.xyz_before, self.keep)
        return carried if self.moved_to is None else after_rigid_move(carried, self.moved_to, self.drift_m)


def carry_neighbours(
    before: RegisteredPair, keep1: np.ndarray, keep2: np.ndarray, after: RegisteredPair, moved: tuple[int, ...] = ()
) -> None:
    """Give ``after`` (``before``'s survivors) every neighbour distance ``before`` has, carried
    by :func:`after_removal` when asked for; for the clouds in ``moved`` (by a correction) then
    by :func:`after_rigid_move` where the cloud moved as a whole with sensor 2's pose (cloud 2)
    or stayed (cloud 1), to ``RIGID_DRIFT_M``; else not (searched anew when asked for)."""
    for (cloud, k), distances in before.neighbours.items():
        xyz, keep = (before.xyz1, keep1) if cloud == 1 else (before.xyz2, keep2)
        if cloud not in moved:
            after.neighbours[(cloud, k)] = CarriedDistances(distances, xyz, keep)
            continue
        now = after.xyz1 if cloud == 1 else after.xyz2
        T = after.T_1_2 @ np.linalg.inv(before.T_1_2) if cloud == 2 else np.eye(4)
        drift = np.linalg.norm(now - (xyz[keep] @ T[:3, :3].T + T[:3, 3]), axis=1)
        if len(drift) and drift.max() <= RIGID_DRIFT_M:
            after.neighbours[(cloud, k)] = CarriedDistances(distances, xyz, keep, now, float(drift.max()))


# A moved cloud whose points lie this near where one rigid motion (sensor 2's change of pose)
# takes them keeps its neighbours (``after_rigid_move``); realign's lie within rounding of it.
RIGID_DRIFT_M = 1e-6


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
