"""Multi-lidar rigs: a scan whose points several lidars measured, each from its own origin.

A scan (and each cloud of a registered pair) may carry ``lidars``, one :class:`Lidar` per
lidar of the rig: its name, its pose in the scan's frame (the extrinsic) and its sensor model.
The points' ``lidar`` attribute (a small integer) is the index of the lidar that measured each
one. Everything that reasons about rays (what a lidar could see, where its rays passed) takes
each point's own lidar through :func:`cloud_lidars`: one :class:`LidarView` per lidar, placed
in frame 1, with the mask of its points. A scan without ``lidars`` is one lidar at its frame's
origin with the scan's sensor model, as before.

The frame of the scan (and the spherical grid about sensor 1) stays one: the vehicle's, or the
lidar the dataset's ``frame`` names.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .models import SensorModel

LIDAR = "lidar"  # the points' attribute: the index of the lidar that measured each point


@dataclass(frozen=True)
class Lidar:
    """One lidar of a rig: its name, its pose (4x4) in the scan's frame, its sensor model."""

    name: str
    pose: np.ndarray
    sensor: SensorModel | None = None

    def __post_init__(self):
        object.__setattr__(self, "pose", np.asarray(self.pose, dtype=np.float64).reshape(4, 4))

    def __eq__(self, other) -> bool:
        return (
            isinstance(other, Lidar)
            and (self.name, self.sensor) == (other.name, other.sensor)
            and np.array_equal(self.pose, other.pose)
        )

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "pose": self.pose.tolist(),
            "sensor": None if self.sensor is None else self.sensor.to_dict(),
        }

    @classmethod
    def from_dict(cls, d: dict) -> "Lidar":
        sensor = d.get("sensor")
        return cls(str(d["name"]), d["pose"], None if sensor is None else SensorModel.from_dict(sensor))


def lidars_to_meta(lidars: tuple[Lidar, ...]) -> list[dict] | None:
    """The metadata of a rig (None: one lidar at the frame's origin)."""
    return [lidar.to_dict() for lidar in lidars] or None


def lidars_from_meta(items: list[dict] | None) -> tuple[Lidar, ...]:
    return tuple(Lidar.from_dict(item) for item in items or ())


def check_lidar_ids(lidars: tuple[Lidar, ...], attributes: dict[str, np.ndarray]) -> None:
    """ValueError unless a rig's points each name one of its lidars (``lidar`` attribute)."""
    if not lidars:
        return
    ids = attributes.get(LIDAR)
    if ids is None:
        raise ValueError(f"a scan of {len(lidars)} lidars needs the points' {LIDAR!r} attribute")
    ids = np.asarray(ids)
    if len(ids) and not (np.isfinite(ids) & (ids >= 0) & (ids < len(lidars))).all():
        raise ValueError(f"the points' {LIDAR!r} attribute names lidars outside 0..{len(lidars) - 1}")


@dataclass(frozen=True)
class LidarView:
    """One lidar of a cloud as the hypotheses see it: its pose in frame 1, its model, and the
    mask of the cloud's points it measured."""

    name: str
    pose: np.ndarray  # 4x4: the lidar in frame 1
    sensor: SensorModel | None
    points: np.ndarray  # bool mask over the cloud's points

    @property
    def origin(self) -> np.ndarray:
        return self.pose[:3, 3].copy()


def cloud_lidars(
    scan_pose: np.ndarray,
    sensor: SensorModel | None,
    lidars: tuple[Lidar, ...],
    attributes: dict[str, np.ndarray],
    n: int,
    cloud: int,
) -> list[LidarView]:
    """The lidars of a cloud of ``n`` points whose scan frame is at ``scan_pose`` in frame 1:
    its rig's, or one lidar at the frame's origin with the scan's ``sensor``."""
    if not lidars:
        return [LidarView(f"sensor {cloud}", np.asarray(scan_pose, dtype=np.float64), sensor, np.ones(n, dtype=bool))]
    ids = np.asarray(attributes[LIDAR])
    return [LidarView(lidar.name, scan_pose @ lidar.pose, lidar.sensor, ids == k) for k, lidar in enumerate(lidars)]


def rig_of_spec(
    items: list[dict], attributes: dict[str, np.ndarray], n: int, path
) -> tuple[tuple[Lidar, ...], np.ndarray]:
    """The rig a study's config names for a scan of ``n`` points (``lidars`` of its spec: name,
    sensor mapping, 4x4 pose, optional rings [first, end)) and each point's lidar: the scan's own
    ``lidar`` attribute where it has one, else the lidar whose rings hold its ``ring``; one
    lidar without rings takes every point. An InputError naming the scan's file otherwise."""
    lidars = tuple(Lidar(item["name"], item["pose"], SensorModel.from_dict(item["sensor"])) for item in items)
    if LIDAR in attributes:
        ids = np.asarray(attributes[LIDAR])
    elif any("rings" in item for item in items):
        if "ring" not in attributes:
            raise InputError("the config gives the lidars' rings, and the scan has no 'ring' attribute", path)
        ring = np.asarray(attributes["ring"], dtype=np.float64)
        ids = np.full(n, -1, dtype=np.int64)
        for k, item in enumerate(items):
            if "rings" in item:
                ids[(ring >= item["rings"][0]) & (ring < item["rings"][1])] = k
        if (ids < 0).any():
            raise InputError(f"{int((ids < 0).sum())} point(s) have a ring in no lidar's rings", path)
        ids = ids.astype(np.uint8)
    elif len(lidars) == 1:
        ids = np.zeros(n, dtype=np.uint8)
    else:
        raise InputError(
            f"the config names {len(lidars)} lidars: the scan needs a 'lidar' attribute, or each lidar its rings", path
        )
    try:
        check_lidar_ids(lidars, {LIDAR: ids})
    except ValueError as e:
        raise InputError(str(e), path) from None
    return lidars, ids
