"""``range_calibration``: fit a range scale and offset of one cloud about its own sensor, and apply it.

A correcting hypothesis: it removes nothing, and moves the points of the chosen cloud (``cloud``,
1 or 2) along their own lines of sight. The model is the simulator's range fault: a sensor that
measures ``r = scale * r_true + offset``; a point at measured range ``r`` in unit direction ``u``
about its sensor origin ``o`` (its own lidar's, in a multi-lidar scan) is corrected to
``o + (r - offset) / scale * u``. Sensor 2's pose is not changed (the correction is not rigid).

The fit: a sample of at most ``max_points`` points of the chosen cloud (evenly spaced rows), each
paired with the nearest point ``q`` of the other cloud (SciPy's k-d tree) and that point's
normal ``n`` (the smallest-eigenvalue direction of the covariance of its ``normal_k`` nearest
neighbours in the other cloud; neighbourhoods that are not planar, a line along one scan line,
are not used). With ``alpha = 1 / scale`` and ``beta = offset / scale`` the point-to-plane residual
``n . (o + (alpha r - beta) u - q)`` is linear in ``(alpha, beta)``: each iteration solves the
weighted linear least squares, with Huber weights (k = 1.345 times the residuals' MAD scale),
then pairs the corrected sample anew, until no corrected range of the sample changes by more
than 0.1 mm (or ``max_iterations``). Pairs farther apart than ``max_correspondence_m`` are not used.

``per_ring: true`` fits one offset per ring and one common scale: ``r = scale * r_true +
offset_ring``, a per-laser range calibration (each laser of a spinning lidar has its own range
offset, calibrated at the factory to a centimetre or so). The ring is the cloud's ``ring``
attribute, else the channel of the sensor model nearest each point's elevation
(``cloud_channels``). A ring with fewer than ``MIN_RING_POINTS`` points
in the fit shares one pooled offset.

What it records (the stage's ``correction``): ``cloud``, ``scale``, ``offset_m``, their standard
errors ``scale_se``, ``offset_se_m``, ``points`` (pairs used in the last solve),
``residual_rms_m`` (their point-to-plane residuals' RMS), ``sigma_m`` (the weighted residuals'
standard deviation), ``iterations``, ``converged`` (false where ``max_iterations`` stopped it
first: the fit is where its last iteration left it), ``parameters`` (how many it fitted: 2, or
1 + the offsets); with ``per_ring``, ``ring_offsets_m`` and ``ring_offsets_se_m`` (by ring, as text) and
``offset_m`` their mean over the rings; with ``with_pose``, ``pose``: the fitted rigid
transform ``T`` of cloud 2 in frame 1 (a point ``p`` becomes ``R p + t``), recorded as
``realign`` records its own (``translation_m`` is ``T``'s, not the motion of sensor 2's origin),
with ``translation_se_m`` and ``rotation_se_deg``, and ``calibration_seen``: whether the scale or
the offset is ``MIN_CALIBRATION_SIGNIFICANCE`` (3) standard errors off (1 and 0). Where neither
is, the joint fit is the pose alone, which ``realign`` fits (and its 2 parameters more than
realign's explain a few units of noise, which can rank it first on a pure misregistration): it
would name a range error it does not see, so ``suggest`` ranks it last and the stopping rule
never applies it. The standard errors are ``sigma^2 (J^T W J)^-1`` of the
last solve, carried from ``(alpha, beta)`` to ``(scale, offset)`` to first order. They treat
neighbouring residuals as independent, which on a scan they are not quite: read them as lower
bounds.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np

from ..errors import HypothesisError
from ..field.free_space import directions, nearest_channel, sensor_channels
from ..pair import RegisteredPair
from ..poses import in_sensor_frame, rotation_from_vector
from .outcome import Outcome
from .params import doc
from .realign import transform_record
from .survivors import survivor_rows

MIN_POINTS = 20  # pairs in the fit, and points of each cloud
MIN_RING_POINTS = 30  # a ring's own offset needs this many pairs
HUBER_K = 1.345
TOLERANCE_M = 1e-4  # converged when no corrected range of the sample changes by more
# A calibration fitted with the pose names a range error only where the calibration itself is
# off by this many of its standard errors (scale from 1 or offset from 0): ``calibration_seen``.
MIN_CALIBRATION_SIGNIFICANCE = 3.0


@dataclass(frozen=True)
class PlaneFit:
    """The parameters of a fit that pairs a cloud's points with the other cloud's planes: this
    one's and ``elevation_calibration``'s."""

    max_correspondence_m: float = field(
        default=0.5, metadata=doc("pairs of points farther apart than this are not used (m)")
    )
    max_points: int = field(default=20000, metadata=doc("at most this many points of the cloud in the fit"))
    normal_k: int = field(default=12, metadata=doc("the other cloud's normals from this many nearest points"))
    max_iterations: int = field(default=20, metadata=doc("pairing and solving iterations at most"))
    cloud: int = field(default=2, metadata=doc("the cloud calibrated against the other cloud's planes: 1 or 2"))

    def __post_init__(self):
        if self.cloud not in (1, 2):
            raise ValueError(f"need cloud 1 or 2, got {self.cloud}")
        if not self.max_correspondence_m > 0 or self.max_points < MIN_POINTS or self.max_iterations < 1:
            raise ValueError(
                f"need max_correspondence_m > 0, max_points >= {MIN_POINTS} and max_iterations >= 1, got "
                f"{self.max_correspondence_m}, {self.max_points} and {self.max_iterations}"
            )
        if self.normal_k < 3:
            raise ValueError(f"need normal_k >= 3, got {self.normal_k}")


@dataclass(frozen=True)
class Params(PlaneFit):
    per_ring: bool = field(
        default=False, metadata=doc("one range offset per ring (the cloud's ring attribute), one common scale")
    )
    max_scale_change: float = field(
        default=0.05, metadata=doc("a fitted scale further than this from 1 is no range calibration (an error)")
    )
    max_offset_m: float = field(
        default=1.0, metadata=doc("a fitted offset larger than this is no range calibration (an error, m)")
    )
    with_pose: bool = field(
        default=False,
        metadata=doc("fit sensor 2's pose (a rigid motion about its origin) together with the calibration (cloud 2)"),
    )

    def __post_init__(self):
        super().__post_init__()
        if self.with_pose and self.cloud != 2:
            raise ValueError("with_pose fits sensor 2's pose: it needs cloud 2")
        if not self.max_scale_change > 0 or not self.max_offset_m > 0:
            raise ValueError(
                f"need max_scale_change > 0 and max_offset_m > 0, got {self.max_scale_change} and {self.max_offset_m}"
            )


class Planes:
    """The other cloud's planes: its k-d tree, and its points' normals (from ``normal_k``
    neighbours) computed where asked. Shared by the fits of one stage (``planes_of``): several
    threads may pair at once, each point's normal is computed alone (the same values whoever
    computes it first), and only its reading and writing are locked. Each normal's
    neighbourhood is kept (``neighbours``: its ``normal_k`` nearest, -1 where unknown or where
    a search may pick another), so that the next stage's planes can take the normal over
    (``carried_planes``)."""

    def __init__(self, other: np.ndarray, normal_k: int):
        from scipy.spatial import cKDTree

        self.other, self.normal_k = other, normal_k
        self.tree = cKDTree(other, balanced_tree=False, compact_nodes=False)  # faster to build, as fast to query
        self.normals = np.full((len(other), 3), np.nan)
        self.neighbours = np.full((len(other), normal_k), -1, dtype=np.int32)
        self.lock = threading.Lock()

    def pair(self, points: np.ndarray, max_distance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The rows of ``points`` whose nearest point ``q`` of the other cloud is within
        ``max_distance`` and on a plane, with ``n`` (that plane's normal) and ``q``."""
        distance, nearest = self.tree.query(points, distance_upper_bound=max_distance)
        return self.on_planes(np.isfinite(distance), nearest)

    def on_planes(self, paired: np.ndarray, nearest: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``pair``'s answer from each row's nearest point (``nearest``, used where ``paired``)."""
        index = nearest[paired]
        needed = np.unique(index)
        with self.lock:
            missing = needed[np.isnan(self.normals[needed, 0])]
        found, around = _normals(self.other, self.tree, missing, self.normal_k)  # outside the lock: the costly part
        with self.lock:
            self.normals[missing], self.neighbours[missing] = found, around
            n = self.normals[index]
        planar = np.isfinite(n).all(axis=1)
        return np.flatnonzero(paired)[planar], n[planar], self.other[index[planar]]


def carried_planes(before: Planes, other: np.ndarray, keep: np.ndarray) -> Planes:
    """The planes of ``other``, which is ``before.other[keep]``, given every normal of
    ``before`` whose neighbourhood was kept whole: the same as computed anew, bit for bit.
    Removing points brings no other point nearer, so a point whose ``normal_k`` nearest all
    stay, each strictly nearer than the next and than any other point (``_normals``), has
    them still, in the same order: the same covariance, the same normal. The others are
    computed when asked."""
    planes = Planes(other, before.normal_k)
    rows = np.flatnonzero(keep)  # each survivor's row before
    with before.lock:
        around, normals = before.neighbours[rows], before.normals[rows]
    known = np.flatnonzero(around[:, 0] >= 0)
    whole = known[keep[around[known]].all(axis=1)]
    planes.normals[whole] = normals[whole]
    planes.neighbours[whole] = survivor_rows(keep)[around[whole]]
    return planes


@dataclass(frozen=True)
class CarriedPlanes:
    """The planes of ``other`` (the points ``keep`` of ``before``'s cloud), made from
    ``before`` (``carried_planes``) when first asked for: by the fit that asks, not between two
    steps."""

    before: Planes | CarriedPlanes
    other: np.ndarray
    keep: np.ndarray

    def planes(self) -> Planes:
        before = self.before.planes() if isinstance(self.before, CarriedPlanes) else self.before
        return carried_planes(before, self.other, self.keep)


class Pairing:
    """``Planes.pair`` for the same rows of points moved again and again (a fit's iterations),
    the same answer for less: a row is searched again only where its move since it was last
    searched could change it. Searched, a row records its nearest and second-nearest distances
    ``d1``, ``d2`` (to ``max_distance + MARGIN_M``); moved by ``delta`` since, its nearest point
    is still the nearest if ``d2 - d1 > 2 delta`` (no other point can have come closer), and it
    is still paired (or not) if ``d1`` is more than ``delta`` from ``max_distance`` (one with
    nothing within the margin while it moved less than the margin). Exact: the same rows, points
    and normals as a search of every row each time (a test compares them)."""

    MARGIN_M = 0.1  # searched this far beyond max_distance, to know how far an unpaired row is

    def __init__(self, planes: Planes, max_distance: float):
        self.planes, self.max_distance = planes, max_distance
        self.anchor = self.nearest = self.d1 = self.d2 = None

    def __call__(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self.anchor is None:
            redo = np.arange(len(points))
            self.anchor = np.empty_like(points)
            self.nearest = np.empty(len(points), dtype=np.int64)
            self.d1, self.d2 = np.empty(len(points)), np.empty(len(points))
        else:
            delta = np.linalg.norm(points - self.anchor, axis=1) * (1 + 1e-9) + 1e-12  # rounding: err on searching
            near = self.d1 < self.max_distance
            same_side = np.abs(self.d1 - self.max_distance) > delta
            kept = np.where(
                np.isinf(self.d1),  # nothing within reach: still unpaired while it moved less than the margin
                delta < self.MARGIN_M,
                same_side & (~near | (self.d2 - self.d1 > 2 * delta)),
            )
            redo = np.flatnonzero(~kept)
        if len(redo):
            self._search(points, redo)
        return self.planes.on_planes(self.d1 < self.max_distance, self.nearest)

    def _search(self, points: np.ndarray, rows: np.ndarray) -> None:
        reach = self.max_distance + self.MARGIN_M
        distance, nearest = self.planes.tree.query(points[rows], k=2, distance_upper_bound=reach)
        d1, d2, first = distance[:, 0], np.minimum(distance[:, 1], reach), nearest[:, 0]
        tie = np.flatnonzero(d1 == d2)  # equally near (a repeated point): the nearest as Planes.pair's search picks it
        if len(tie):
            first[tie] = self.planes.tree.query(points[rows[tie]], distance_upper_bound=self.max_distance)[1]
        self.anchor[rows], self.nearest[rows], self.d1[rows], self.d2[rows] = points[rows], first, d1, d2


def planes_of(other: np.ndarray, normal_k: int) -> Planes:
    """The planes of ``other``: those made for the same array object and ``normal_k`` while it
    lives (``SHARED_PLANES``), or carried to it from the stage before (``carry_planes``), else
    new ones. A stage's candidates pair the same cloud with its planes three times
    (``range_calibration`` alone and with the pose, ``elevation_calibration``): its tree is
    built, and each normal computed, once."""
    key = (id(other), normal_k)
    with SHARED_PLANES_LOCK:
        known = SHARED_PLANES.get(key)
        if isinstance(known, Planes) and known.other is other:
            return known
        carried = isinstance(known, CarriedPlanes) and known.other is other
        planes = known.planes() if carried else Planes(other, normal_k)
        SHARED_PLANES.clear()  # one cloud's at a time: a stage's, not a study's
        SHARED_PLANES[key] = planes
        return planes


def carry_planes(before: RegisteredPair, keep1: np.ndarray, keep2: np.ndarray, after: RegisteredPair) -> None:
    """Pass the planes of ``before``'s clouds (in ``SHARED_PLANES``) on to ``after``'s clouds
    that are their survivors ``keep1``, ``keep2`` (``CarriedPlanes``). A cloud kept whole is the
    same array and keeps its planes as they are; a cloud the stage moved keeps none."""
    with SHARED_PLANES_LOCK:
        for (_, normal_k), known in list(SHARED_PLANES.items()):
            for was, keep, now in ((before.xyz1, keep1, after.xyz1), (before.xyz2, keep2, after.xyz2)):
                cut = now is not was and keep.dtype == bool and len(now) == np.count_nonzero(keep)
                if known.other is was and cut and np.array_equal(now, was[keep]):
                    SHARED_PLANES[(id(now), normal_k)] = CarriedPlanes(known, now, keep)


# The planes of the last cloud asked for, by its array object, and those carried to the next
# stage's clouds. They hold those clouds (and the tree) alive until another cloud's planes are
# made: so an id cannot be reused meanwhile. A stage's clouds are not changed in place (a
# correction makes new ones).
SHARED_PLANES: dict[tuple[int, int], Planes | CarriedPlanes] = {}
SHARED_PLANES_LOCK = threading.Lock()


def check_clouds(name: str, params, xyz: np.ndarray, other: np.ndarray) -> None:
    """A HypothesisError when the chosen cloud ``xyz`` or the ``other`` is too small to fit."""
    for cloud, points, need in (
        (params.cloud, xyz, MIN_POINTS),
        (3 - params.cloud, other, max(MIN_POINTS, params.normal_k)),
    ):
        if len(points) < need:
            raise HypothesisError(f"{name}: too few points: cloud {cloud} has {len(points)}, it needs at least {need}")


def check_overlap(name: str, params, pairs: int) -> None:
    """A HypothesisError when fewer than ``MIN_POINTS`` points were paired with a plane."""
    if pairs < MIN_POINTS:
        raise HypothesisError(
            f"{name}: no overlap: {pairs} points of cloud {params.cloud} have a point of cloud "
            f"{3 - params.cloud} on a plane within max_correspondence_m = {params.max_correspondence_m} m, "
            f"it needs at least {MIN_POINTS}"
        )


def evenly_spaced(rows: np.ndarray, most: int) -> np.ndarray:
    """At most ``most`` of ``rows``, evenly spaced (the fit's sample)."""
    if len(rows) <= most:
        return rows
    return rows[np.linspace(0, len(rows) - 1, most).round().astype(np.int64)]


def range_calibration(pair: RegisteredPair, params: Params) -> Outcome:
    """The chosen cloud's ranges corrected by a fitted scale and offset; nothing removed."""
    name = "range_calibration"
    xyz, other = (pair.xyz2, pair.xyz1) if params.cloud == 2 else (pair.xyz1, pair.xyz2)
    origin = pair.point_origins(params.cloud)  # each point's own lidar
    check_clouds(name, params, xyz, other)
    ring = cloud_channels(pair, params.cloud) if params.per_ring else None

    d = xyz - origin
    r = np.linalg.norm(d, axis=1)
    measurable = r > 1e-9
    u = np.zeros_like(d)
    u[measurable] = d[measurable] / r[measurable, None]
    candidates = evenly_spaced(np.flatnonzero(measurable), params.max_points)
    groups, group_of = _groups(ring, candidates)
    pairing = Pairing(planes_of(other, params.normal_k), params.max_correspondence_m)
    rs, us, origins = r[candidates], u[candidates], np.broadcast_to(origin, xyz.shape)[candidates]
    r_max = float(rs.max())
    theta = np.concatenate([[1.0], np.zeros(len(groups))])  # alpha, then beta per group
    # With the pose: cloud 2 turned by R about sensor 2's origin c and moved by t, fitted with
    # theta by Gauss-Newton (each step's rotation a small rotation vector, applied on the left).
    R, t, c = np.eye(3), np.zeros(3), pair.T_1_2[:3, 3]
    rigid = 6 if params.with_pose else 0
    iterations, converged = 0, False
    while iterations < params.max_iterations and not converged:
        iterations += 1
        calibrated = origins + (theta[0] * rs - theta[1:][group_of])[:, None] * us
        use, n, q = pairing(_moved(calibrated, R, c, t) if rigid else calibrated)
        check_overlap(name, params, len(use))
        nu = np.einsum("ij,ij->i", n, us[use] @ R.T if rigid else us[use])
        # the Jacobian's rows: r (n . Ru) for alpha, -(n . Ru) for the point's group's beta;
        # with the pose, (R (x - c)) x n for the rotation and n for the translation
        a, b, g = rs[use] * nu, -nu, group_of[use]
        if rigid:
            pose_columns = np.hstack([np.cross((calibrated[use] - c) @ R.T, n), n])
            y = np.einsum("ij,ij->i", n, q - _moved(origins[use], R, c, t))
        else:
            pose_columns, y = np.empty((len(use), 0)), np.einsum("ij,ij->i", n, q - origins[use])
        residual = a * theta[0] + b * theta[1:][g] - y
        weight = _huber(residual)
        # solved for the calibration itself and the pose's increment (the pose's columns are
        # its derivative at the current pose, whose own residual is in y)
        information, gradient = _normal_equations(a, b, g, y, weight, len(theta), pose_columns)
        try:
            new = np.linalg.solve(information, gradient)
        except np.linalg.LinAlgError:
            raise HypothesisError(
                f"{name}: the ranges do not constrain a scale and offset: "
                f"the {len(use)} pairs' normals and ranges are degenerate"
            ) from None
        step, new = new[len(theta) :], new[: len(theta)]
        # the largest change of a corrected point of the sample
        change = np.abs(new[0] - theta[0]) * r_max + np.abs(new[1:] - theta[1:]).max()
        if rigid:
            change += np.linalg.norm(step[:3]) * r_max + np.linalg.norm(step[3:])
            R, t = rotation_from_vector(step[:3]) @ R, t + step[3:]
        converged = bool(change < TOLERANCE_M)
        theta = new

    residual = a * theta[0] + b * theta[1:][g] + pose_columns @ step - y
    m, p = len(residual), len(theta)
    sigma2 = float(weight @ residual**2) / max(m - p - rigid, 1)
    try:
        full_covariance = sigma2 * np.linalg.inv(information)
    except np.linalg.LinAlgError:
        full_covariance = np.full((p + rigid, p + rigid), np.nan)
    covariance = full_covariance[:p, :p]  # the calibration's, the pose's uncertainty taken into it
    alpha, betas = theta[0], theta[1:]
    scale, offsets = 1.0 / alpha, betas / alpha
    # first order: scale = 1/alpha, offset_g = beta_g / alpha
    A = np.zeros((p, p))
    A[0, 0] = -1.0 / alpha**2
    A[1:, 0] = -betas / alpha**2
    A[1:, 1:] = np.eye(p - 1) / alpha
    se = np.sqrt(np.clip(np.diag(A @ covariance @ A.T), 0, None))
    # A fit far from any sensor's calibration explains the field by moving points out of it (a
    # vehicle's points thrown kilometres away): refused, so that it is never suggested.
    if not (abs(scale - 1.0) <= params.max_scale_change and np.all(np.abs(offsets) <= params.max_offset_m)):
        raise HypothesisError(
            f"{name}: the fit (scale {scale:.6g}, offset {float(np.max(np.abs(offsets))):.4g} m) is beyond a range "
            f"calibration's bounds (max_scale_change {params.max_scale_change:g}, max_offset_m "
            f"{params.max_offset_m:g}): the discrepancy is not a range error"
        )

    def number(value) -> float | None:
        return float(value) if np.isfinite(value) else None

    fitted = {
        "cloud": params.cloud,
        "scale": float(scale),
        "scale_se": number(se[0]),
        "points": int(m),
        "residual_rms_m": float(np.sqrt(np.mean(residual**2))),
        "sigma_m": float(np.sqrt(sigma2)),
        "iterations": iterations,
        "converged": converged,
        "method": "point_to_plane_huber",
        "parameters": p + rigid,
    }
    if rigid:  # turned about sensor 2's origin c and moved by t: T in frame 1
        offset_significance = abs(offsets[0]) / se[1] if ring is None and se[1] > 0 else 0.0
        scale_significance = abs(scale - 1.0) / se[0] if se[0] > 0 else 0.0
        fitted["calibration_seen"] = bool(max(scale_significance, offset_significance) >= MIN_CALIBRATION_SIGNIFICANCE)
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, c + t - R @ c
        # each step turned about the moved sensor's origin, c + t (the Jacobian's columns)
        fitted["pose"] = transform_record(T, full_covariance[p:, p:], about=c + t)
    if ring is None:
        fitted.update(offset_m=float(offsets[0]), offset_se_m=number(se[1]))
        offset_of_point = np.full(len(xyz), offsets[0])
    else:
        fitted["offset_m"] = float(np.mean([offsets[g] for g in _ring_group(groups, np.unique(ring))]))
        fitted["ring_offsets_m"] = {str(k): float(offsets[g]) for k, g in _ring_items(groups, np.unique(ring))}
        fitted["ring_offsets_se_m"] = {str(k): number(se[1 + g]) for k, g in _ring_items(groups, np.unique(ring))}
        offset_of_point = offsets[_group_index(groups, ring)]
    corrected_r = np.where(measurable, (r - offset_of_point) / scale, 0.0)
    new_xyz = np.where(measurable[:, None], origin + corrected_r[:, None] * u, xyz)
    keep1, keep2 = np.ones(len(pair.xyz1), dtype=bool), np.ones(len(pair.xyz2), dtype=bool)
    if rigid:
        return Outcome(keep1, keep2, xyz2=_moved(new_xyz, R, c, t), T_1_2=T @ pair.T_1_2, fitted=fitted)
    if params.cloud == 2:
        return Outcome(keep1, keep2, xyz2=new_xyz, fitted=fitted)
    return Outcome(keep1, keep2, xyz1=new_xyz, fitted=fitted)


def cloud_channels(pair: RegisteredPair, cloud: int, name: str = "range_calibration") -> np.ndarray:
    """Each point's channel (laser) of cloud 1 or 2, whose range offset ``per_ring`` fits: its
    ``ring`` attribute, else the channel of its own lidar's model nearest its elevation about
    that lidar, numbered from the lowest. A return's elevation lies within a few hundredths of a
    degree of its beam's, and beams are at least 0.3 deg apart, so the elevation names the laser
    where the scan does not record it. A rig's lidars are numbered one after another (each
    lidar's rings or channels past the last of the one before): two lidars' ring 0 are two lasers.
    ``name``: the hypothesis that asks (``elevation_calibration`` numbers its lasers the same way),
    for its error messages."""
    attributes = pair.attributes1 if cloud == 1 else pair.attributes2
    ring = attributes.get("ring")
    if ring is not None and not np.isfinite(ring).all():
        raise HypothesisError(f"{name}: per laser: cloud {cloud} has points without a ring")
    views = pair.lidars(cloud)
    if ring is None and any(view.sensor is None for view in views):
        raise HypothesisError(f"{name}: per laser needs a ring attribute or a sensor model; cloud {cloud} has neither")
    xyz = pair.xyz1 if cloud == 1 else pair.xyz2
    channel, first = np.zeros(len(xyz), dtype=np.int64), 0
    for view in views:
        if ring is not None:
            own = np.asarray(ring[view.points]).astype(np.int64)
            count = int(own.max()) + 1 if len(own) else 0
        else:
            channels = sensor_channels(view.sensor)
            own = nearest_channel(directions(in_sensor_frame(xyz[view.points], view.pose))[1], channels)
            count = len(channels)
        channel[view.points] = first + own
        first += count
    return channel


def _normal_equations(
    a: np.ndarray, b: np.ndarray, g: np.ndarray, y: np.ndarray, w: np.ndarray, p: int, dense: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``J^T W J`` and ``J^T W y`` for rows ``[a, 0.., b (column 1 + g), ..0, dense]``, without
    building the calibration's sparse part of ``J`` (``dense``: (m, k) further columns, k >= 0)."""
    groups, k = p - 1, dense.shape[1]
    information = np.zeros((p + k, p + k))
    information[0, 0] = w @ (a * a)
    cross = np.bincount(g, w * a * b, groups)
    information[0, 1:p] = information[1:p, 0] = cross
    information[np.arange(1, p), np.arange(1, p)] = np.bincount(g, w * b * b, groups)
    gradient = np.concatenate([[w @ (a * y)], np.bincount(g, w * b * y, groups), (w * y) @ dense])
    if k:
        weighted = dense * w[:, None]
        information[p:, p:] = weighted.T @ dense
        information[0, p:] = information[p:, 0] = weighted.T @ a
        by_group = np.stack([np.bincount(g, weighted[:, j] * b, groups) for j in range(k)], axis=1)
        information[1:p, p:] = by_group
        information[p:, 1:p] = by_group.T
    return information, gradient


def _moved(xyz: np.ndarray, R: np.ndarray, c: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Points turned by ``R`` about ``c`` and moved by ``t``."""
    return (xyz - c) @ R.T + c + t


def _huber(residual: np.ndarray) -> np.ndarray:
    """Huber weights, k = 1.345 robust standard deviations (MAD) of the residuals."""
    scale = 1.4826 * float(np.median(np.abs(residual - np.median(residual))))
    if not scale > 0:
        return np.ones_like(residual)
    a = np.abs(residual) / (HUBER_K * scale)
    return np.where(a <= 1, 1.0, 1.0 / np.maximum(a, 1e-300))


def _normals(points: np.ndarray, tree, index: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The normals of ``points[index]``: the covariance's smallest eigenvector of the ``k``
    nearest points; a neighbourhood that is no plane (a line, or a blob) gets -inf (unused).
    (The plane through the point itself, not through the neighbours' mean: on the simulated
    intersection the mean, pulled off curved and bent surfaces, doubled the fit's bias.) And
    each row's ``k`` nearest (``Planes.neighbours``): -1 where two of the ``k`` + 1 nearest are
    equally near (which one a search picks may change) or the cloud has no more than ``k``
    points."""
    around = np.full((len(index), k), -1, dtype=np.int32)
    if len(index) == 0:
        return np.empty((0, 3)), around
    reach = min(k + 1, len(points))
    distance, neighbours = tree.query(points[index], k=reach)
    distinct = np.zeros(len(index), dtype=bool)
    if reach > k:
        distinct = np.all(distance[:, 1:] > distance[:, :-1], axis=1)
    neighbours = neighbours[:, :k]
    around[distinct] = neighbours[distinct]
    tied = np.flatnonzero(~distinct)
    if len(tied):  # the k nearest as a search of k picks among the equally near
        neighbours[tied] = tree.query(points[index[tied]], k=k)[1]
    local = points[neighbours]
    local = local - local.mean(axis=1, keepdims=True)
    covariance = np.einsum("nki,nkj->nij", local, local) / k
    values, vectors = np.linalg.eigh(covariance)  # ascending
    normal = vectors[:, :, 0]
    planar = (values[:, 1] > 0.05 * values[:, 2]) & (values[:, 0] < 0.1 * values[:, 1])
    normal[~planar] = -np.inf
    return normal, around


def _groups(ring: np.ndarray | None, candidates: np.ndarray) -> tuple[dict, np.ndarray]:
    """The offset groups (``{ring: group}``; -1 the pooled rings) and each candidate's group."""
    if ring is None:
        return {None: 0}, np.zeros(len(candidates), dtype=np.int64)
    values, counts = np.unique(ring[candidates], return_counts=True)
    own = [int(v) for v, c in zip(values, counts) if c >= MIN_RING_POINTS]
    groups = {v: g for g, v in enumerate(own)}
    if len(own) < len(values) or not own:
        groups[-1] = len(own)
    return groups, _group_index(groups, ring[candidates])


def _group_index(groups: dict, ring: np.ndarray) -> np.ndarray:
    """Each point's offset group: its ring's own, else the pooled one."""
    pooled = groups.get(-1, 0)
    keys = np.array(sorted(k for k in groups if k is not None and k != -1), dtype=np.int64)
    if len(keys) == 0:
        return np.full(len(ring), pooled, dtype=np.int64)
    at = np.clip(np.searchsorted(keys, ring), 0, len(keys) - 1)
    found = keys[at] == ring
    own = np.array([groups[int(k)] for k in keys], dtype=np.int64)
    return np.where(found, own[at], pooled)


def _ring_items(groups: dict, rings: np.ndarray):
    for k in rings:
        yield int(k), groups.get(int(k), groups.get(-1, 0))


def _ring_group(groups: dict, rings: np.ndarray):
    return [g for _, g in _ring_items(groups, rings)]
