"""Objects in a cloud: the ground under them, and the connected components of their voxels.

:func:`heights_above_ground` fits a ground plane; :func:`off_ground` keeps what stands on it
(and an object's foot); :func:`connected_voxels` labels the objects on a voxel grid
(:func:`voxel_grid`, one grid for both clouds of a pair) and is tested against the plain
flood fill :func:`connected_voxels_reference`; :func:`overlapping_objects` finds the objects
that share voxels with others.
"""

from __future__ import annotations

import itertools

import numpy as np

# The ground plane is fitted to the points within these bands (m) of it, narrowing: the first
# guess is a 0.25 m layer of the lower half of the cloud (``ground_layer``), layers slid by 5 cm.
_GROUND_BANDS_M = (1.0, 0.5, 0.25)
_LAYER_M = 0.25
_LAYER_STEP_M = 0.05
_GROUND_SAMPLE = 100_000


def ground_layer(z: np.ndarray) -> float:
    """The height of the ground's layer among heights ``z`` (the lower half of a cloud): the
    lowest 0.25 m layer that holds at least half as many points as the densest one, or the
    densest layer within a layer above it. The ground is the lowest extensive surface; it need
    not be the densest: in a street canyon a lidar whose channels crowd near the horizon (a
    VLP-32C) puts more points on the walls' band at its own height than on the ground. Layers
    slide by 5 cm, so that a flat ground is not split between two."""
    z = np.sort(z)
    starts = np.arange(z[0] - _LAYER_M, z[-1] + _LAYER_STEP_M, _LAYER_STEP_M)
    counts = np.searchsorted(z, starts + _LAYER_M) - np.searchsorted(z, starts)
    lowest = int(np.flatnonzero(counts >= counts.max() / 2)[0])
    near = slice(lowest, lowest + int(round(_LAYER_M / _LAYER_STEP_M)) + 1)
    return float(starts[near][np.argmax(counts[near])] + _LAYER_M / 2)


def heights_above_ground(xyz: np.ndarray) -> np.ndarray:
    """Each point's height above a plane ``z = a x + b y + c`` fitted by least squares to the
    ground: first the ground's layer of the lower half of the cloud (:func:`ground_layer`), then
    the points within 1, 0.5 and 0.25 m of the plane so far; fitted on every k-th point of a
    large cloud (at most ``_GROUND_SAMPLE``: a plane has three parameters)."""
    if len(xyz) < 3:
        return np.full(len(xyz), np.inf)
    sample = xyz[:: max(1, len(xyz) // _GROUND_SAMPLE)]
    z = sample[:, 2]
    plane = np.array([0.0, 0.0, ground_layer(z[z <= np.median(z)])])
    design = np.column_stack([sample[:, 0], sample[:, 1], np.ones(len(z))])
    for band in _GROUND_BANDS_M:
        near = np.abs(z - design @ plane) < band
        if np.count_nonzero(near) < 3:
            break
        plane, *_ = np.linalg.lstsq(design[near], z[near], rcond=None)
    return xyz[:, 2] - (xyz[:, 0] * plane[0] + xyz[:, 1] * plane[1] + plane[2])


def voxel_grid(clouds: list[np.ndarray], voxel_m: float) -> list[np.ndarray]:
    """Integer voxel coordinates of the points of each cloud on one grid (the same voxel in
    both clouds has the same coordinates), from 1 up: 0 and the top stay free for neighbours."""
    voxels = [np.floor(xyz / voxel_m).astype(np.int64) for xyz in clouds]
    occupied = [v for v in voxels if len(v)]
    low = np.min([v.min(axis=0) for v in occupied], axis=0) if occupied else np.zeros(3, np.int64)
    return [v - low + 1 for v in voxels]


def packed(voxels: np.ndarray, size: np.ndarray) -> np.ndarray:
    """One int64 key per voxel of a grid of ``size`` (each coordinate below its size)."""
    return voxels @ np.array([size[1] * size[2], size[2], 1])


def off_ground(xyz: np.ndarray, voxels: np.ndarray, ground_height_m: float) -> np.ndarray:
    """Mask of the points that belong to objects: higher than ``ground_height_m`` above the
    ground, and the lower points of an object's foot, those in a voxel column that also holds
    a point between ``ground_height_m`` and twice that (a car's lowest strip, not the ground
    under a canopy)."""
    height = heights_above_ground(xyz)
    standing = height >= ground_height_m
    if not len(xyz):
        return standing
    column = voxels[:, 0] * (int(voxels[:, 1].max()) + 1) + voxels[:, 1]
    foot = np.unique(column[standing & (height < 2 * ground_height_m)])
    low = ~standing
    standing[low] = np.isin(column[low], foot)
    return standing


# Half of the 26 neighbours of a voxel: each edge of the voxel graph is found once.
_HALF_NEIGHBOURS = [d for d in itertools.product((-1, 0, 1), repeat=3) if d > (0, 0, 0)]


def connected_voxels(voxels: np.ndarray) -> np.ndarray:
    """Object label of each point (its voxel's coordinates, from 1 up): the connected
    component (26 neighbours) of its voxel among the occupied ones; labels 0..K-1, in no
    particular order."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if len(voxels) == 0:
        return np.zeros(0, dtype=np.int64)
    size = voxels.max(axis=0) + 2
    occupied, voxel_of_point = np.unique(packed(voxels, size), return_inverse=True)
    first, second = [], []
    for step in _HALF_NEIGHBOURS:
        neighbour = occupied + int(packed(np.array(step), size))
        at = np.minimum(np.searchsorted(occupied, neighbour), len(occupied) - 1)
        found = np.flatnonzero(occupied[at] == neighbour)
        first.append(found)
        second.append(at[found])
    first, second = np.concatenate(first), np.concatenate(second)
    graph = coo_matrix((np.ones(len(first), np.int8), (first, second)), shape=(len(occupied),) * 2)
    _, component = connected_components(graph, directed=False)
    return component[voxel_of_point.ravel()].astype(np.int64)


def connected_voxels_reference(voxels: np.ndarray) -> np.ndarray:
    """Reference of :func:`connected_voxels`: a flood fill over the occupied voxels, each
    voxel compared with all others (Chebyshev distance 1 = neighbours)."""
    occupied, voxel_of_point = np.unique(voxels, axis=0, return_inverse=True)
    label = np.full(len(occupied), -1)
    for seed in range(len(occupied)):
        if label[seed] >= 0:
            continue
        label[seed], stack = label.max() + 1, [seed]
        while stack:
            voxel = stack.pop()
            fresh = (np.abs(occupied - occupied[voxel]).max(axis=1) <= 1) & (label < 0)
            label[fresh] = label[seed]
            stack.extend(np.flatnonzero(fresh))
    return label[voxel_of_point.ravel()]


def overlapping_objects(objects: np.ndarray, keys: np.ndarray, removed_keys: np.ndarray, share: float) -> np.ndarray:
    """Mask of the points of the objects (labels ``objects``, < 0: ground) at least ``share``
    of whose voxels (``keys``, one per point) are among ``removed_keys`` (the voxels of the
    objects removed from the other cloud)."""
    on_object = np.flatnonzero(objects >= 0)
    out = np.zeros(len(objects), dtype=bool)
    if not len(on_object) or not len(removed_keys):
        return out
    span = int(keys.max()) + 1
    distinct = np.unique(objects[on_object] * span + keys[on_object])  # each (object, voxel) once
    label, key = distinct // span, distinct % span
    voxels = np.bincount(label)
    shared = np.bincount(label, weights=np.isin(key, removed_keys), minlength=len(voxels))
    out[on_object] = (shared >= share * voxels)[objects[on_object]] & (shared > 0)[objects[on_object]]
    return out
