"""Where the points of a registered pair are as seen from either sensor."""

from __future__ import annotations

import numpy as np

from ..pair import RegisteredPair
from ..poses import in_sensor_frame


def sensor_pose(pair: RegisteredPair, sensor: int) -> np.ndarray:
    """4x4 pose of sensor 1 or 2 in frame 1."""
    if sensor not in (1, 2):
        raise ValueError(f"sensor must be 1 or 2, got {sensor!r}")
    return np.eye(4) if sensor == 1 else pair.T_1_2


def own_frame_points(pair: RegisteredPair) -> tuple[np.ndarray, np.ndarray]:
    """Each cloud in its own sensor's frame."""
    return pair.xyz1, in_sensor_frame(pair.xyz2, pair.T_1_2)


def near_in_own_frames(
    pair: RegisteredPair, candidates: tuple[np.ndarray, np.ndarray], radius_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """Per cloud, which of its ``candidates`` (masks) have a point of the other cloud within
    ``radius_m`` once each cloud is in its own sensor's frame: what stays put with the sensor."""
    own = own_frame_points(pair)
    near = []
    for k in (0, 1):
        mask = np.zeros(len(own[k]), dtype=bool)
        if candidates[k].any() and len(own[1 - k]):
            tree = cloud_tree(pair, 2 - k, own_frame=True)
            distance, _ = tree.query(own[k][candidates[k]], distance_upper_bound=radius_m)
            mask[candidates[k]] = np.isfinite(distance)
        near.append(mask)
    return near[0], near[1]


def cloud_tree(pair: RegisteredPair, cloud: int, own_frame: bool = False):
    """SciPy's k-d tree of cloud 1 or 2, in frame 1 or in its own sensor's frame, made once per
    pair (``RegisteredPair.remembered``): ``shadow``, ``moving_objects`` and the carried body
    ask for the same. For distances only: which of equally near points a query names depends
    on how the tree was built."""
    from scipy.spatial import cKDTree

    def make():
        xyz = own_frame_points(pair)[cloud - 1] if own_frame else (pair.xyz1 if cloud == 1 else pair.xyz2)
        return cKDTree(xyz)

    return pair.remembered(("own-frame tree" if own_frame else "tree", cloud), make, (cloud,))


def elevation_deg(xyz: np.ndarray) -> np.ndarray:
    return np.degrees(np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1])))


def inside_box(xyz: np.ndarray, box: tuple[float, ...]) -> np.ndarray:
    """Points inside the closed box [xmin, xmax, ymin, ymax, zmin, zmax]."""
    lo, hi = np.asarray(box[0::2]), np.asarray(box[1::2])
    return np.all((xyz >= lo) & (xyz <= hi), axis=1)


def check_box(box: tuple[float, ...] | None, name: str = "box_m") -> None:
    """ValueError unless ``box`` is None or [xmin, xmax, ymin, ymax, zmin, zmax] with min <= max."""
    if box is not None and any(lo > hi for lo, hi in zip(box[0::2], box[1::2])):
        raise ValueError(f"{name}: expected [xmin, xmax, ymin, ymax, zmin, zmax] with each min <= max, got {list(box)}")
