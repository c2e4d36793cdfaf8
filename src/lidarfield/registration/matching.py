"""Scan matching through Open3D: ICP (point-to-point, point-to-plane), GICP and NDT.

The estimate is the pose of sensor 2 in frame 1 (Open3D's source = scan 2, target = scan 1,
so its transformation maps scan-2 points into frame 1). Every method's quality is measured the
same way, by :func:`evaluate`, so fitness values compare across methods.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from .settings import MATCHING_METHODS

reg = o3d.pipelines.registration


@dataclass
class MatchResult:
    T: np.ndarray  # estimated pose of sensor 2 in frame 1
    failure: str | None = None  # Open3D's message when it refused to run


def point_cloud(xyz: np.ndarray, voxel_m: float, min_range_m: float) -> o3d.geometry.PointCloud:
    """An Open3D cloud of the points beyond ``min_range_m`` from their sensor, voxel-downsampled."""
    if min_range_m > 0:
        xyz = xyz[np.linalg.norm(xyz, axis=1) >= min_range_m]
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.ascontiguousarray(xyz, dtype=np.float64)))
    return cloud.voxel_down_sample(voxel_m) if voxel_m > 0 else cloud


def voxel_size(xyz1: np.ndarray, xyz2: np.ndarray, p: dict) -> float:
    """The voxel both clouds are downsampled with: ``voxel_m``, or less where the scene is near,
    no wider than ``voxel_deg`` seen from the sensors at the pair's median range.

    A voxel's centroid stands for the surfaces in it: at an edge, a corner, a curved surface or
    where it merges two rings it lies off them by up to half the voxel, and the two scans'
    voxels fall differently on the same surfaces. Seen from the sensor that blur is an angle,
    the voxel over the range, and the rotation fitted on the centroids inherits it. A fixed
    0.2 m is a degree at 11 m (a street) but 9 deg at 1.3 m (a sensor in a small room), where it
    also leaves a few hundred points (docs/registration.md)."""
    voxel_m = p["voxel_m"]
    if voxel_m == 0:
        return 0.0
    ranges = np.concatenate([np.linalg.norm(xyz, axis=1) for xyz in (xyz1, xyz2)])
    ranges = ranges[ranges >= p["min_range_m"]]
    if len(ranges) == 0:
        return float(voxel_m)
    return float(min(voxel_m, np.median(ranges) * np.radians(p["voxel_deg"])))


@dataclass
class Clouds:
    """Both clouds as a method needs them: scan 2 (source, its sensor frame) and scan 1 (target),
    downsampled by ``voxel_size``, and as the fitness is measured for every method (by the
    configured ``voxel_m``, so that fitness values compare across methods and pairs)."""

    source: o3d.geometry.PointCloud
    target: o3d.geometry.PointCloud
    model: o3d.geometry.PointCloud  # what the method matches against (NDT: every scan-1 point)
    voxel_m: float  # the voxel of source and target (``voxel_size``)
    scored_source: o3d.geometry.PointCloud  # what the fitness is measured on ...
    scored_target: o3d.geometry.PointCloud  # ... and against


def prepare(method: str, xyz1: np.ndarray, xyz2: np.ndarray, p: dict) -> Clouds:
    """Downsample both clouds and give them the normals the method uses, once for any number
    of runs from different guesses."""
    scored_source = point_cloud(xyz2, p["voxel_m"], p["min_range_m"])
    scored_target = point_cloud(xyz1, p["voxel_m"], p["min_range_m"])
    voxel_m = voxel_size(xyz1, xyz2, p) if method in MATCHING_METHODS else p["voxel_m"]
    if voxel_m == p["voxel_m"]:
        source, target = scored_source, scored_target
    else:
        source, target = (point_cloud(xyz, voxel_m, p["min_range_m"]) for xyz in (xyz2, xyz1))
    if method in ("icp_point_to_plane", "gicp"):
        # Point-to-plane needs target normals; Open3D's GICP builds its covariances from normals.
        search = o3d.geometry.KDTreeSearchParamHybrid(radius=p["normal_radius_m"], max_nn=p["normal_max_nn"])
        for cloud in (source, target):
            cloud.estimate_normals(search)
    # NDT models scan 1 with its own cells: give it every point, not the downsampled cloud.
    model = point_cloud(xyz1, 0.0, p["min_range_m"]) if method == "ndt" else target
    return Clouds(source, target, model, voxel_m, scored_source, scored_target)


def match(method: str, clouds: Clouds, guess: np.ndarray, p: dict) -> MatchResult:
    """Run ``method`` from ``guess``; Open3D refusing the input (too few points or NDT cells)
    gives the guess back with the reason instead of raising."""
    try:
        if method == "ndt":
            return MatchResult(_ndt(clouds.source, clouds.model, guess, p))
        return MatchResult(_icp_family(method, clouds.source, clouds.model, guess, p))
    except RuntimeError as e:
        return MatchResult(np.array(guess, dtype=np.float64), _open3d_message(e))


def _icp_family(method: str, source, target, guess: np.ndarray, p: dict) -> np.ndarray:
    criteria = reg.ICPConvergenceCriteria(p["relative_fitness"], p["relative_rmse"], p["max_iterations"])
    distance = p["max_correspondence_m"]
    if method == "icp":
        estimation = reg.TransformationEstimationPointToPoint()
    elif method == "icp_point_to_plane":
        estimation = reg.TransformationEstimationPointToPlane()
    else:
        estimation = reg.TransformationEstimationForGeneralizedICP(p["gicp_epsilon"])
        return reg.registration_generalized_icp(source, target, distance, guess, estimation, criteria).transformation
    return reg.registration_icp(source, target, distance, guess, estimation, criteria).transformation


def _ndt(source, target, guess: np.ndarray, p: dict) -> np.ndarray:
    """Coarse-to-fine NDT: one run per cell size of ``ndt_resolution_m``, each from the last."""
    T = np.array(guess, dtype=np.float64)
    for cell_m in p["ndt_resolution_m"]:
        option = reg.NormalDistributionsTransformOption(
            voxel_size=cell_m,
            min_points_per_voxel=p["ndt_min_points_per_voxel"],
            outlier_threshold=p["ndt_outlier_threshold"],
            max_iteration=p["max_iterations"],
        )
        T = np.asarray(reg.registration_ndt(source, target, option, T).transformation)
    return T


def evaluate(source, target, T: np.ndarray, distance_m: float) -> tuple[float, float | None]:
    """(fitness, inlier RMSE): the share of source points with a target point within
    ``distance_m`` once mapped by ``T``, and the RMS distance of those pairs (None without any:
    the metadata is JSON, which has no NaN)."""
    if len(source.points) == 0 or len(target.points) == 0 or not np.isfinite(T).all():
        return 0.0, None
    result = reg.evaluate_registration(source, target, distance_m, T)
    if result.fitness == 0:
        return 0.0, None
    # The RMSE from the pairs in source order: Open3D sums them in parallel, in an order that
    # changes its last digits from run to run, and the registered pair's files should not.
    pairs = np.asarray(result.correspondence_set)
    pairs = pairs[np.argsort(pairs[:, 0], kind="stable")]
    mapped = np.asarray(source.points)[pairs[:, 0]] @ T[:3, :3].T + T[:3, 3]
    squared = np.sum((mapped - np.asarray(target.points)[pairs[:, 1]]) ** 2, axis=1)
    return float(result.fitness), float(np.sqrt(np.mean(squared)))


def _open3d_message(error: RuntimeError) -> str:
    # Open3D wraps its messages in ANSI colour codes and a source location: keep the sentence.
    text = str(error).replace("\x1b[1;31m", "").replace("\x1b[0;m", "").strip()
    return text.rsplit(": ", 1)[-1] if ".cpp:" in text else text
