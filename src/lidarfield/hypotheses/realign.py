"""``realign``: re-estimate the rigid transform of cloud 2 onto cloud 1 from the survivors, and apply it.

A correcting hypothesis: it removes nothing, and moves cloud 2. Point-to-plane ICP (Open3D, as
the registration uses it), source = cloud 2, target = cloud 1: every point of cloud 1 and at most
``max_points`` of cloud 2, a random subset drawn with a fixed seed (both clouds voxel-downsampled
first if ``voxel_m`` > 0; not by default), normals of cloud 1 from its neighbours within
``normal_radius_m``, starting from the identity (the pair is already registered: what is fitted
is the correction). With both sensor models known (and the pair not registered by ``identity``,
which does not say where sensor 2 was), two things more, each measured on the simulated ego-car
pair of ``tests/unit/test_explain.py`` (VLP-16s 1 m apart, 2 m up, registered by the truth, its
carried body removed), where the plain fit stopped 0.80 deg pitched:

- where a point's neighbours hold one ring of the sensor, its normal comes from its rings
  (``ring_normals``): a single ring's thinnest direction is across the ray, not the surface's
  normal, and such normals on the ground pull a pair taken from two places into a pitch (0.18
  deg with ring normals);
- the fit is then refined, from where it stopped, on the points both sensors could see at that
  pose (``field.free_space.shared_points``): what only one sensor saw (past a corner, beyond
  the other's lowest beam) has no counterpart, and its nearest neighbours pull the fit (0.009
  deg and 3 mm with both; on the method's simulated pair registered 0.3 m off, 0.0005 deg and
  0.1 mm instead of 0.011 deg and 3.4 mm). The recorded figures are the refined fit's.

The fitted transform ``T``
(a point ``p`` of cloud 2 becomes ``R p + t``) is applied to every point of cloud 2 and to
sensor 2's pose (``T_1_2`` becomes ``T @ T_1_2``), so later stages and figures see the
corrected pose. ``T``'s rotation vector and translation are rounded to 1e-9 (rad, m), so that a
rerun writes the same files (Open3D's parallel sums vary in the last digits).

What it records (the stage's ``correction``): ``translation_m`` (t, frame 1), ``rotation_deg``
(the rotation vector of R, axis times angle, in degrees, about frame 1's x, y, z: for small
rotations its z is the yaw), ``angle_deg`` (its norm), their standard errors
``translation_se_m`` and ``rotation_se_deg``, ``fitness`` (share of the cloud-2 points in the
fit with a cloud-1 point within ``max_correspondence_m``), ``inlier_rmse_m``,
``correspondences``, ``sigma_m`` and ``parameters`` (6). All are computed from ICP's own correspondences, those
Open3D finds after its last update (a second search at ``T`` found the same ones, as a test
checks, for a tenth of realign's time). The standard errors are the point-to-plane least
squares' at ``T``: with one residual ``r_i = n_i . (T s_i - q_i)`` per correspondence and its
Jacobian ``[(T s_i) x n_i, n_i]`` for a small rotation and translation applied after ``T``, the
covariance is ``sigma^2 (J^T J)^-1`` with ``sigma^2 = sum r_i^2 / (m - 6)``, propagated to ``t``
to first order. They are those of the points the fit used: on a subset of ``m`` of cloud 2's
``n`` points about ``sqrt(n / m)`` times those of a fit on all of them (1.73 to 1.76 times for
5,000 of 15,318 points), as the subset's fit is that much less certain. They treat the
residuals as independent, which neighbouring points of a scan are not quite (a subset's points,
farther apart, less so): read them as a lower bound.

Why not downsampled by default: a downsampling voxel's centroid moves with which of the scan's
points fall in it (the same partial-volume effect as the field's means), and that biases the
fit. Measured on the simulated intersection (two VLP-16 samplings, 2 cm noise, 0.5 deg of yaw
added): with 0.2 m voxels the fit stops 0.005 deg and 0.9 mm from the truth (four of its own
standard errors; the field after it is ``patterned``), with 0.1 m voxels 0.003 deg and 1.4 mm,
on all points 0.0015 deg and 0.4 mm from either start (the field after it ``random``), for
0.06 s instead of 0.02 s. A random subset of cloud 2's own points has no such bias: it only adds
noise, which its standard errors measure; cloud 1 keeps every point, so the correspondences and
normals stay at full resolution.

Why at most 20,000 points of cloud 2: ICP's time grows with the source's points, its accuracy
hardly does beyond a few thousand, and a VLP-16 scan (12,000 to 16,000 points) is still fitted
on all of them, as before. What is left is mostly cloud 1's normals (about 70% of the time on a
pair of 55,000-point scans), which a full-resolution target needs. The second fit's target,
the points both sensors saw, takes them from the first's (``Target.subset``): a point's
neighbours' normal and its one-ring test depend only on the points within
``normal_radius_m``, so only the kept points that near to a dropped one are found again, the
same to the bit as made afresh (tested on simulated and real scans); on the drive of
``bench/drive.py`` that is 27% of them. Measured figures: the hypotheses page of the docs and
``bench/RESULTS.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import HypothesisError
from ..field.free_space import shared_points
from ..pair import RegisteredPair
from ..poses import skew
from .outcome import Outcome
from .params import doc
from .ring_normals import one_ring_after_removal, ring_normals, witnessed_one_ring

MIN_POINTS = 10  # per downsampled cloud, and correspondences: 6 unknowns and a residual's sigma
# Above this share of the kept points within twice normal_radius_m of a dropped one (the points
# the recomputed normals come from), a target's subset takes Open3D's normals of all its points:
# as fast, the same result (Target.subset; measured 2026-11-28, serially: at 62% the subset cost
# 0.70 of a fresh target on the OS1-128 frames, at 98% 1.08 on ExpD and at 99.9% 1.03 on the
# HDL-32E pair, when both parts of the normals were found again for all points there).
LOCAL_SHARE_MAX = 0.8


@dataclass(frozen=True)
class Params:
    max_correspondence_m: float = field(
        default=1.0, metadata=doc("ICP ignores pairs of points farther apart than this (m)")
    )
    voxel_m: float = field(
        default=0.0, metadata=doc("both clouds are voxel-downsampled to this size first (m; 0: not, the default)")
    )
    max_points: int = field(
        default=20000, metadata=doc("at most this many points of cloud 2 in the fit (a random subset, fixed seed)")
    )
    max_iterations: int = field(default=50, metadata=doc("ICP iterations at most"))
    normal_radius_m: float = field(
        default=1.0, metadata=doc("cloud 1's normals from its points within this radius (m)")
    )
    normal_max_nn: int = field(default=30, metadata=doc("... and at most this many of them"))
    field_refinement: bool = field(
        default=True,
        metadata=doc(
            "follow ICP with the field's own rigid fit of its surfaces' normal parts (needs both sensor models)"
        ),
    )

    def __post_init__(self):
        if not self.max_correspondence_m > 0 or self.voxel_m < 0 or self.max_iterations < 1:
            raise ValueError(
                f"need max_correspondence_m > 0, voxel_m >= 0 and max_iterations >= 1, got "
                f"{self.max_correspondence_m}, {self.voxel_m} and {self.max_iterations}"
            )
        if self.max_points < MIN_POINTS:
            raise ValueError(f"need max_points >= {MIN_POINTS}, got {self.max_points}")
        if not self.normal_radius_m > 0 or self.normal_max_nn < 3:
            raise ValueError(
                f"need normal_radius_m > 0 and normal_max_nn >= 3, got {self.normal_radius_m} and {self.normal_max_nn}"
            )


def realign(pair: RegisteredPair, params: Params) -> Outcome:
    """Cloud 2 moved by point-to-plane ICP onto cloud 1, sensor 2's pose with it; nothing removed.
    With both sensor models and origins known, refined on the points both sensors could see."""
    target = Target.of(pair.xyz1, pair.sensor1, params)
    T, result, source = _icp(target.cloud, pair.xyz2, params, np.eye(4))
    if pair.sensor1 is not None and pair.sensor2 is not None and (pair.registration or {}).get("method") != "identity":
        # What only one sensor saw has no counterpart to match; where the sensors were is known
        # (an identity registration does not say) once the first fit has brought them close.
        moved = pair.with_cloud2(pair.xyz2 @ T[:3, :3].T + T[:3, 3], T @ pair.T_1_2)  # cloud 1's images kept
        shared1, shared2 = shared_points(moved)
        target = target.subset(pair.xyz1, shared1, pair.sensor1, params)
        T, result, source = _icp(target.cloud, pair.xyz2[shared2], params, T)
    # ICP's correspondences are those at its final transform (Open3D searches them after the last
    # update); T is that transform rounded to 1e-9, so only a nearest-neighbour tie that close
    # could tell them apart.
    pairs = np.asarray(result.correspondence_set).reshape(-1, 2)
    if len(pairs) < MIN_POINTS:
        raise HypothesisError(
            f"realign: too few correspondences: {len(pairs)} cloud-2 points have a cloud-1 point within "
            f"max_correspondence_m = {params.max_correspondence_m} m, it needs at least {MIN_POINTS}"
        )
    pairs = pairs[np.argsort(pairs[:, 0], kind="stable")]  # source order: sums independent of Open3D's threads
    mapped = np.asarray(source.points)[pairs[:, 0]] @ T[:3, :3].T + T[:3, 3]
    refinement = np.eye(4)
    if params.field_refinement and pair.sensor1 is not None and pair.sensor2 is not None:  # both scan patterns
        refinement = _field_refinement(pair.with_cloud2(pair.xyz2 @ T[:3, :3].T + T[:3, 3], T @ pair.T_1_2))
        T = _rounded(refinement @ T)
    fitted = {
        **_fitted(
            T, mapped, np.asarray(target.cloud.points)[pairs[:, 1]], np.asarray(target.cloud.normals)[pairs[:, 1]]
        ),
        "fitness": float(result.fitness),
        "correspondences": len(pairs),
        "method": "icp_point_to_plane",
        "field_refinement": _fitted_transform(refinement),
        "parameters": 6,  # a rigid motion's: what fitting it to noise alone explains (analysis.suggest)
    }
    keep1, keep2 = np.ones(len(pair.xyz1), dtype=bool), np.ones(len(pair.xyz2), dtype=bool)
    xyz2 = pair.xyz2 @ T[:3, :3].T + T[:3, 3]
    return Outcome(keep1, keep2, xyz2=xyz2, T_1_2=T @ pair.T_1_2, fitted=fitted)


def _field_refinement(pair: RegisteredPair) -> np.ndarray:
    """The 4x4 correction of cloud 2 that the field of the ICP-fitted pair still asks for: its
    surfaces' normal parts fitted by generalised least squares (``field_normal_part_fit``)
    on the default grid; the identity where the field has too few surfaces."""
    from ..field.grid import FieldSettings, SphericalGrid
    from ..field.pair_field import pair_field
    from ..field.rigid_fit import field_normal_part_fit

    fit = field_normal_part_fit(pair_field(pair, FieldSettings(SphericalGrid()))[0])
    T = np.eye(4)
    if np.all(np.isfinite(fit.rotation)) and np.all(np.isfinite(fit.translation)):
        T[:3, :3], T[:3, 3] = fit.rotation, fit.translation
    return T


@dataclass(frozen=True)
class Target:
    """Cloud 1 as ICP's target: ``cloud`` (Open3D, voxel-downsampled if ``voxel_m``) with its
    normals, from its neighbours within ``normal_radius_m`` and, with sensor 1's model and no
    downsampling, from its rings where its neighbours hold one ring (``ring_normals``). Without
    downsampling it keeps what its normals were made of, so that a subset's are found again
    only where they can differ (``subset``): ``surface``, the neighbours' normals,
    ``one_ring``, the points given their rings', and ``witness``, the other points' neighbour
    on another ring (``witnessed_one_ring``; both None without sensor 1's model)."""

    cloud: object
    surface: np.ndarray | None = None
    one_ring: np.ndarray | None = None
    witness: np.ndarray | None = None

    @classmethod
    def of(cls, xyz1: np.ndarray, sensor1, params: Params) -> "Target":
        from ..registration.matching import point_cloud

        cloud = point_cloud(xyz1, params.voxel_m, 0.0)
        _require_points(len(cloud.points), 1, params)
        surface = _surface_normals(cloud, params)
        if params.voxel_m > 0:  # its points are voxels': no rings, no subset of them
            return cls(cloud)
        one_ring, witness = (
            (None, None)
            if sensor1 is None
            else witnessed_one_ring(xyz1, sensor1.elevation_deg, *_neighbourhood(params))
        )
        return cls._with_normals(cloud, surface, one_ring, witness, sensor1, params)

    @classmethod
    def _with_normals(cls, cloud, surface: np.ndarray, one_ring, witness, sensor1, params: Params) -> "Target":
        import open3d as o3d

        normals = surface
        if one_ring is not None:
            xyz = np.asarray(cloud.points)
            normals = ring_normals(xyz, surface, sensor1.elevation_deg, *_neighbourhood(params), one_ring=one_ring)
        cloud.normals = o3d.utility.Vector3dVector(normals)
        return cls(cloud, surface, one_ring, witness)

    def subset(self, xyz1: np.ndarray, keep: np.ndarray, sensor1, params: Params) -> "Target":
        """``Target.of`` the points ``keep`` of ``xyz1``, the cloud it was made of, the same to the bit:
        a point's neighbours' normal and one-ring test depend only on the points within
        ``normal_radius_m``, so they are found again only for the kept points that near to a
        dropped one: the normals from the kept points near enough to be their neighbours (from
        all, above ``LOCAL_SHARE_MAX``), the test among all kept points where a point's witness
        was dropped (``one_ring_after_removal``); the rings' normals, which reach farther along
        a ring, are found again for all."""
        from ..registration.matching import point_cloud

        if self.surface is None:  # downsampled: made again from the kept points
            return Target.of(xyz1[keep], sensor1, params)
        kept, dropped = xyz1[keep], xyz1[~keep]
        _require_points(len(kept), 1, params)
        surface, one_ring, witness = self.surface[keep], self.one_ring, self.witness
        cloud = point_cloud(kept, 0.0, 0.0)
        near = np.zeros(0, dtype=np.int64)
        if len(dropped):
            from scipy.spatial import cKDTree

            radius = params.normal_radius_m * (1 + 1e-9) + 1e-12  # a tie at the radius counts as near
            distance, _ = cKDTree(dropped).query(kept, k=1, distance_upper_bound=2 * radius)
            local = np.flatnonzero(distance <= 2 * radius)  # holds every neighbour of a near point
            near = np.flatnonzero(distance <= radius)
            if len(local) > LOCAL_SHARE_MAX * len(kept):
                surface = _surface_normals(cloud, params)
            elif len(near):
                local_normals = _surface_normals(point_cloud(kept[local], 0.0, 0.0), params)
                surface[near] = local_normals[distance[local] <= radius]
        if one_ring is not None:
            one_ring, witness = one_ring_after_removal(
                one_ring, witness, keep, kept, near, sensor1.elevation_deg, *_neighbourhood(params)
            )
        return Target._with_normals(cloud, surface, one_ring, witness, sensor1, params)


def _surface_normals(cloud, params: Params) -> np.ndarray:
    """(N, 3) Open3D's normals of ``cloud``'s points from their neighbours, set on it too."""
    import open3d as o3d

    search = o3d.geometry.KDTreeSearchParamHybrid(radius=params.normal_radius_m, max_nn=params.normal_max_nn)
    cloud.estimate_normals(search)
    return np.asarray(cloud.normals).copy()


def _neighbourhood(params: Params) -> tuple[float, int]:
    """The normals' neighbourhood: its radius and how many neighbours at most."""
    return params.normal_radius_m, params.normal_max_nn


def _icp(target, xyz2: np.ndarray, params: Params, start: np.ndarray):
    """(T, ICP's result, source): point-to-plane ICP of at most ``max_points`` of ``xyz2`` onto
    the Open3D cloud ``target`` (with normals) from ``start``."""
    import open3d as o3d  # only where a stage realigns

    from ..registration.matching import point_cloud

    reg = o3d.pipelines.registration
    source = _sample(point_cloud(xyz2, params.voxel_m, 0.0), params.max_points)
    _require_points(len(source.points), 2, params)
    criteria = reg.ICPConvergenceCriteria(1e-6, 1e-6, params.max_iterations)
    estimation = reg.TransformationEstimationPointToPlane()
    result = reg.registration_icp(source, target, params.max_correspondence_m, start, estimation, criteria)
    return _rounded(np.array(result.transformation, dtype=np.float64)), result, source


def _require_points(count: int, number: int, params: Params) -> None:
    """A HypothesisError where cloud ``number`` has too few points (``count``) to fit."""
    if count < MIN_POINTS:
        raise HypothesisError(
            f"realign: too few points: cloud {number} has {count}"
            + (f" after {params.voxel_m} m voxels" if params.voxel_m else "")
            + f", it needs at least {MIN_POINTS}"
        )


def _fitted(T: np.ndarray, mapped: np.ndarray, target: np.ndarray, normals: np.ndarray) -> dict:
    """The transform's translation and rotation vector, and their standard errors (see the module)."""

    residuals = np.einsum("ij,ij->i", mapped - target, normals)
    J = np.hstack([np.cross(mapped, normals), normals])  # d r / d (rotation, translation) applied after T
    m = len(residuals)
    sigma2 = float(residuals @ residuals) / (m - 6)
    information = J.T @ J
    try:
        covariance = sigma2 * np.linalg.inv(information)
    except np.linalg.LinAlgError:
        covariance = np.full((6, 6), np.nan)
    return {
        **transform_record(T, covariance),
        "inlier_rmse_m": float(np.sqrt(np.mean(np.sum((mapped - target) ** 2, axis=1)))),
        "sigma_m": float(np.sqrt(sigma2)),
    }


def transform_record(T: np.ndarray, covariance: np.ndarray, about: np.ndarray | None = None) -> dict:
    """A fitted transform ``T`` of cloud 2 (frame 1) as recorded: its translation, rotation
    vector and angle (``_fitted_transform``) and their standard errors, from ``covariance``
    (6x6: a small rotation vector w, rad, then a translation v, m) of the motion that, applied
    after ``T``, turns by w about the point ``about`` (frame 1; the origin when None) and moves
    by v. Every correction that fits sensor 2's pose records it so (``realign``, ``deskew`` and
    ``range_calibration`` with ``with_pose``)."""
    pivot = np.zeros(3) if about is None else np.asarray(about, dtype=np.float64)
    # T's translation t after that motion, to first order: t + w x (t - pivot) + v
    A = np.hstack([-skew(T[:3, 3] - pivot), np.eye(3)])
    translation_cov = A @ covariance @ A.T

    def se(values: np.ndarray, scale: float = 1.0) -> list | None:
        values = np.sqrt(np.clip(np.diag(values), 0, None)) * scale
        return [float(v) for v in values] if np.isfinite(values).all() else None  # singular: unknown

    return {
        **_fitted_transform(T),
        "translation_se_m": se(translation_cov),
        "rotation_se_deg": se(covariance[:3, :3], float(np.degrees(1.0))),
    }


def _fitted_transform(T: np.ndarray) -> dict:
    """A transform's translation, rotation vector (degrees) and angle."""
    from scipy.spatial.transform import Rotation

    rotvec = Rotation.from_matrix(T[:3, :3]).as_rotvec()
    return {
        "translation_m": [float(v) for v in T[:3, 3]],
        "rotation_deg": [float(v) for v in np.degrees(rotvec)],
        "angle_deg": float(np.degrees(np.linalg.norm(rotvec))),
    }


def _sample(cloud, max_points: int):
    """At most ``max_points`` of ``cloud``'s points, a random subset in their order, the same on
    every run (a fixed seed)."""
    if len(cloud.points) <= max_points:
        return cloud
    rows = np.random.default_rng(0).choice(len(cloud.points), max_points, replace=False)
    return cloud.select_by_index(np.sort(rows).tolist())


def _rounded(T: np.ndarray) -> np.ndarray:
    """``T`` with its rotation vector and translation rounded to 1e-9 (rad, m): Open3D's parallel
    sums change the last digits of its estimate from run to run, and a rerun should write the
    same files. (1e-9 rad moves a point 100 m away by 0.1 um.)"""
    from scipy.spatial.transform import Rotation

    rounded = np.eye(4)
    rounded[:3, :3] = Rotation.from_rotvec(np.round(Rotation.from_matrix(T[:3, :3]).as_rotvec(), 9)).as_matrix()
    rounded[:3, 3] = np.round(T[:3, 3], 9)
    return rounded
