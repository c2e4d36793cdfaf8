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
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from ..pair import RegisteredPair
from .params import doc


@dataclass(frozen=True)
class Params:
    nb_neighbors: int = field(default=20, metadata=doc("neighbours in each point's mean distance (the point itself included)"))
    std_ratio: float = field(default=2.0, metadata=doc("standard deviations above the mean beyond which a point is removed"))

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


def mean_neighbour_distances(xyz: np.ndarray, nb_neighbors: int, workers: int = 1) -> np.ndarray:
    """Each point's mean distance to its ``nb_neighbors`` nearest points (itself included)."""
    from scipy.spatial import cKDTree  # a third of a second: only when this hypothesis runs

    k = min(nb_neighbors, len(xyz))
    # An unbalanced tree (split at the midpoint) builds and answers faster on scans; exact all the same.
    distances, _ = cKDTree(xyz, balanced_tree=False).query(xyz, k=k, workers=workers)
    # Summed nearest first, one neighbour at a time, as Open3D does: numpy's pairwise row sum
    # rounds differently, which moves scores at the threshold by an ulp.
    total = np.zeros(len(xyz))
    for column in distances.reshape(len(xyz), k).T:
        total += column
    return total / k


def statistical_inliers(xyz: np.ndarray, nb_neighbors: int, std_ratio: float, workers: int | None = None) -> np.ndarray:
    """Keep-mask of Open3D's ``remove_statistical_outlier`` on one cloud (see the module)."""
    if len(xyz) <= nb_neighbors:
        return np.ones(len(xyz), dtype=bool)  # too few points for the statistic: nothing is an outlier
    scores = mean_neighbour_distances(np.asarray(xyz, dtype=np.float64), nb_neighbors, workers or neighbour_threads())
    return open3d_threshold(scores, std_ratio)


def open3d_threshold(scores: np.ndarray, std_ratio: float) -> np.ndarray:
    """Open3D's keep rule on the scores (sums in point order: ``add.accumulate`` is sequential)."""
    positive = scores > 0
    mean = np.add.accumulate(np.where(positive, scores, 0.0))[-1] / len(scores)
    squares = np.add.accumulate(np.where(positive, (scores - mean) * (scores - mean), 0.0))[-1]
    with np.errstate(invalid="ignore", divide="ignore"):  # one point: 0 / 0, nothing kept, as Open3D
        threshold = mean + std_ratio * np.sqrt(squares / (len(scores) - 1))
    return positive & (scores < threshold)


def outliers(pair: RegisteredPair, params: Params) -> tuple[np.ndarray, np.ndarray]:
    """Keep-masks of the statistical inliers of each cloud."""
    return (
        statistical_inliers(pair.xyz1, params.nb_neighbors, params.std_ratio),
        statistical_inliers(pair.xyz2, params.nb_neighbors, params.std_ratio),
    )
