"""``moving_objects``: remove the objects that moved between the two scans, seen from free space.

With both sensor origins known (``T_1_2``), a point of one cloud is *evidence* of motion when it
lies where the other sensor's rays passed through, with a ball of free space around it: in the
other sensor's frame, it is nearer than every return of that sensor around its direction by
more than the margin m = ``margin_m + range x tan(beam_width_deg)``, "around" being the cells
of that sensor's range image (one row per channel, one column per azimuth step of its model)
within m across the ray, and at least the beams on either side. So an edge that one beam
passes and the next one hits is not free space, nor is a surface that the registration's error
moved by less than m. Directions the other sensor did not see give no evidence either way: no
return in the point's cell, a point outside its elevation limits or nearer than its minimum
range, a point behind what it measured (occluded), and a point in a wide gap between channels
that no ray passed near. A scan of several lidars (:mod:`lidarfield.sensors.rig`) has a range image
per lidar, in its own frame: a point is evidence in the free space of any of them.

What stays put in the sensor's frame is no moving object but the vehicle that carries the
sensors (a truck's cargo body, a roof rack: between two poses of a drive it moves with them, so
in frame 1 it is where the other sensor's rays passed): a point of one cloud that has a point of
the other cloud within ``margin_m`` when both are taken in their own sensor's frame is no
evidence (:func:`~.geometry.near_in_own_frames`; ``ego_vehicle`` is the hypothesis for it). From one place
(sensor 2 within ``margin_m`` of sensor 1) the frames are one and that test says nothing new: a
point with the other cloud's return beside it is not in its free space anyway.

A moving object gives such evidence only on its leading and trailing parts, so evidence grows
to objects: each cloud's points higher than ``ground_height_m`` above a plane fitted to its
ground (and the lower ones in the same ``voxel_m`` column as such a point less than twice that
high: an object's foot) are split into objects, the connected components of their occupied
voxels (``voxel_m``, 26 neighbours). An object is removed whole when at least
``min_evidence_points`` and ``min_evidence_share`` of its points are evidence, and with it
every object of the other cloud that shares at least ``min_overlap_share`` of its voxels (the
same object before or after it moved). Ground points are never removed. The removed file's
``reason`` column says why each point went: ``evidence``, or ``grown`` (the rest of a removed
object).

The free-space test is :mod:`lidarfield.field.free_space`; the ground and the objects are :mod:`.voxel_objects`.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass, field

import numpy as np

from ..errors import NotApplicableError
from ..field.free_space import (
    BEAM_WIDTH_DEG,
    MARGIN_M,
    RangeImage,
    any_lidar,
    free_space_evidence,
    lidar_images,
    range_image,
    sensor_image,
    uniform_channels,
)
from ..pair import RegisteredPair
from ..sensors.models import SensorModel
from ..sensors.rig import LidarView
from .geometry import near_in_own_frames
from .outcome import Outcome
from .params import doc
from .voxel_objects import connected_voxels, off_ground, overlapping_objects, packed, voxel_grid

EVIDENCE, GROWN = "evidence", "grown"  # the removed file's reasons


@dataclass(frozen=True)
class Params:
    angular_resolution_deg: tuple[float, float] | None = field(
        default=None,
        metadata=doc(
            "[azimuth, elevation] size of the cells of each sensor's range image, rows this far apart over its "
            "model's elevation limits (or its cloud's) (null: its model's azimuth step and one row per channel)"
        ),
    )
    margin_m: float = field(
        default=MARGIN_M,
        metadata=doc(
            "a point is evidence when nearer by more than this margin (plus the beam term) than every return of the "
            "other sensor within the margin across the ray from its direction: a ball of free space around it"
        ),
    )
    beam_width_deg: float = field(
        default=BEAM_WIDTH_DEG, metadata=doc("the beam's width: the margin grows by range x tan(beam_width_deg)")
    )
    ground_height_m: float | None = field(
        default=0.3,
        metadata=doc(
            "points lower than this above a plane fitted to the ground are ground: never removed (null: no ground, "
            "every point belongs to an object)"
        ),
    )
    voxel_m: float = field(
        default=0.3, metadata=doc("objects are the connected components of the occupied voxels of this size")
    )
    min_evidence_points: int = field(
        default=10, metadata=doc("an object is removed when at least this many of its points are evidence ...")
    )
    min_evidence_share: float = field(default=0.02, metadata=doc("... and at least this share of its points"))
    min_overlap_share: float | None = field(
        default=0.5,
        metadata=doc(
            "an object of one cloud is also removed when at least this share of its voxels are voxels of an object "
            "removed from the other cloud: the same object before or after it moved (null: never)"
        ),
    )

    def __post_init__(self):
        if self.angular_resolution_deg is not None and not all(0 < v <= 90 for v in self.angular_resolution_deg):
            raise ValueError(f"angular_resolution_deg must be in (0, 90], got {list(self.angular_resolution_deg)}")
        if not (self.margin_m >= 0 and 0 <= self.beam_width_deg < 90):
            raise ValueError(
                f"margin_m must be >= 0 and beam_width_deg in [0, 90); got {self.margin_m}, {self.beam_width_deg}"
            )
        if self.ground_height_m is not None and not self.ground_height_m > 0:
            raise ValueError(f"ground_height_m must be > 0 (or null), got {self.ground_height_m}")
        if not self.voxel_m > 0:
            raise ValueError(f"voxel_m must be > 0, got {self.voxel_m}")
        if self.min_overlap_share is not None and not 0 < self.min_overlap_share <= 1:
            raise ValueError(f"min_overlap_share must be in (0, 1] (or null), got {self.min_overlap_share}")
        if self.min_evidence_points < 1 or not 0 <= self.min_evidence_share <= 1:
            raise ValueError(
                "min_evidence_points must be >= 1 and min_evidence_share in [0, 1]; got "
                f"{self.min_evidence_points}, {self.min_evidence_share}"
            )


def evidenced_objects(evidence: np.ndarray, objects: np.ndarray, params: Params) -> np.ndarray:
    """Mask of the points of the objects (labels ``objects``; < 0: ground, never removed) with
    at least ``min_evidence_points`` evidence points making ``min_evidence_share`` of them."""
    on_object = objects >= 0
    label = objects[on_object]
    size = np.bincount(label)
    evidenced = np.bincount(label, weights=evidence[on_object], minlength=len(size))
    removed_object = (evidenced >= params.min_evidence_points) & (evidenced >= params.min_evidence_share * size)
    removed = np.zeros(len(objects), dtype=bool)
    removed[on_object] = removed_object[label]
    return removed


def sensor_range_image(
    xyz: np.ndarray, model: SensorModel | None, params: Params, lidar: str, ring: np.ndarray | None = None
) -> RangeImage:
    """The range image of a lidar's points (in its frame; ``lidar`` names it: "sensor 1", a
    rig's lidar): one row per channel of its model (its returns' ``ring`` where given), or
    uniform rows of ``angular_resolution_deg``."""
    if params.angular_resolution_deg is None:
        if model is None:
            raise NotApplicableError(
                f"moving_objects: {lidar} has no sensor model, so its channels are unknown: give the sensor "
                "(--sensor, or 'sensor' in the pair's config) or moving_objects' angular_resolution_deg"
            )
        return sensor_image(xyz, model, ring)
    azimuth_step, elevation_step = (math.radians(v) for v in params.angular_resolution_deg)
    if model is not None:
        lo, hi = (math.radians(v) for v in model.elevation_limits_deg)
    else:
        elevation = np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1]))
        lo, hi = (float(elevation.min()), float(elevation.max())) if len(xyz) else (0.0, 0.0)
    channels = uniform_channels(lo, hi, elevation_step)
    return range_image(xyz, azimuth_step, channels, 0.0 if model is None else model.min_range_m)


def check_origins(pair: RegisteredPair) -> None:
    """NotApplicableError when the pair does not say where sensor 2 was (registered by identity)."""
    if (pair.registration or {}).get("method") == "identity":
        raise NotApplicableError(
            "moving_objects needs where both sensors were, and this pair was registered by 'identity', which does "
            "not say where sensor 2 was: register it with 'truth', a transform file or scan matching (scans taken "
            "from one place: an identity transform file says so)"
        )


def pair_evidence(pair: RegisteredPair, params: Params) -> tuple[np.ndarray, np.ndarray]:
    """Free-space evidence of every point of cloud 1 against the returns of scan 2's lidars
    (in any one's free space), and of cloud 2 against scan 1's."""

    def image_of(own: np.ndarray, view: LidarView, ring: np.ndarray | None) -> RangeImage:
        return sensor_range_image(own, view.sensor, params, view.name, ring)

    def evidence(own: np.ndarray, view: LidarView, image: RangeImage) -> np.ndarray:
        return free_space_evidence(own, image, params.margin_m, params.beam_width_deg)

    def images_of(cloud: int) -> list[tuple[LidarView, RangeImage]]:
        if params.angular_resolution_deg is None and all(view.sensor is not None for view in pair.lidars(cloud)):
            return lidar_images(pair, cloud)  # on the models: the pair's own, which its field's co-visibility uses too
        return lidar_images(pair, cloud, image_of)  # (without a model, image_of says why it cannot)

    images = images_of(1), images_of(2)
    return any_lidar(pair.xyz1, images[1], evidence), any_lidar(pair.xyz2, images[0], evidence)


def seen_through(pair: RegisteredPair, params: Params) -> tuple[np.ndarray, np.ndarray]:
    """Per cloud, its points that lie where the other scan's rays passed through
    (:func:`pair_evidence`) and that the vehicle does not carry (:func:`~.geometry.near_in_own_frames`): the
    evidence that something moved, which no static scene gives. Read-only masks, remembered
    for the last pair object (``LAST_SEEN``)."""
    last = LAST_SEEN.get("pair")
    if last is not None and last[0]() is pair and last[1] == params:
        return last[2]
    check_origins(pair)
    evidence = pair_evidence(pair, params)
    carried = near_in_own_frames(pair, evidence, params.margin_m)
    seen = evidence[0] & ~carried[0], evidence[1] & ~carried[1]
    for mask in seen:
        mask.setflags(write=False)
    LAST_SEEN["pair"] = (weakref.ref(pair), params, seen)
    return seen


# The last seen_through: a stage's suggestions ask it twice with the defaults, for the
# moving_objects candidate and for every removal's seen-through columns (analysis.suggest).
# Kept for the same pair object (a stage's pair is not changed in place: a correction makes a
# new one) and parameters only; a weak reference, so it holds no pair alive.
LAST_SEEN: dict[str, tuple] = {}


def moving_objects(pair: RegisteredPair, params: Params) -> Outcome:
    """Keep-masks without the evidenced objects of each cloud (and the objects of the other
    cloud that overlap them), and why each removed point went."""
    clouds = (pair.xyz1, pair.xyz2)
    evidence = seen_through(pair, params)
    voxels = voxel_grid(list(clouds), params.voxel_m)
    size = (
        np.max([v.max(axis=0) for v in voxels if len(v)], axis=0) + 2 if any(map(len, voxels)) else np.ones(3, np.int64)
    )
    keys = [packed(v, size) for v in voxels]
    objects, evidenced = [], []
    for xyz, v, cloud_evidence in zip(clouds, voxels, evidence):
        labels = np.full(len(xyz), -1, dtype=np.int64)
        standing = np.ones(len(xyz), dtype=bool)
        if params.ground_height_m is not None:
            standing = off_ground(xyz, v, params.ground_height_m)
        labels[standing] = connected_voxels(v[standing])
        objects.append(labels)
        evidenced.append(evidenced_objects(cloud_evidence, labels, params))
    keeps, reasons = [], []
    for k in (0, 1):
        removed = evidenced[k].copy()
        if params.min_overlap_share is not None:
            other = 1 - k
            removed_keys = np.unique(keys[other][evidenced[other]])
            removed |= overlapping_objects(objects[k], keys[k], removed_keys, params.min_overlap_share)
        keeps.append(~removed)
        reasons.append(np.where(removed, np.where(evidence[k], EVIDENCE, GROWN), ""))
    return Outcome(keeps[0], keeps[1], reason1=reasons[0], reason2=reasons[1])
