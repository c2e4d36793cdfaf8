"""``outliers``: Open3D's statistical outlier removal, on each cloud separately.

A point is removed when its mean distance to its ``nb_neighbors`` nearest neighbours exceeds
the cloud's mean of that distance by more than ``std_ratio`` standard deviations.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..pair import RegisteredPair
from .params import doc


@dataclass(frozen=True)
class Params:
    nb_neighbors: int = field(default=20, metadata=doc("neighbours in each point's mean distance"))
    std_ratio: float = field(default=2.0, metadata=doc("standard deviations above the mean beyond which a point is removed"))

    def __post_init__(self):
        if self.nb_neighbors < 1 or not self.std_ratio > 0:
            raise ValueError(f"need nb_neighbors >= 1 and std_ratio > 0, got {self.nb_neighbors} and {self.std_ratio}")


def statistical_inliers(xyz: np.ndarray, nb_neighbors: int, std_ratio: float) -> np.ndarray:
    """Keep-mask of Open3D's ``remove_statistical_outlier`` on one cloud."""
    keep = np.zeros(len(xyz), dtype=bool)
    if len(xyz) <= nb_neighbors:
        return ~keep  # too few points for the statistic: nothing is an outlier
    import open3d as o3d  # slow to import: only when this hypothesis runs

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))
    _, index = cloud.remove_statistical_outlier(nb_neighbors=nb_neighbors, std_ratio=std_ratio)
    keep[np.asarray(index, dtype=np.int64)] = True
    return keep


def outliers(pair: RegisteredPair, params: Params) -> tuple[np.ndarray, np.ndarray]:
    """Keep-masks of the statistical inliers of each cloud."""
    return (
        statistical_inliers(pair.xyz1, params.nb_neighbors, params.std_ratio),
        statistical_inliers(pair.xyz2, params.nb_neighbors, params.std_ratio),
    )
