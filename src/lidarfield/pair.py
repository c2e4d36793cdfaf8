"""A registered pair: both clouds in scan 1's sensor frame, and the pose of sensor 2 in frame 1.

This is the object every hypothesis receives, and what the registered-pair and stage-points
Parquet files hold (column ``cloud`` = 1 or 2, ``x, y, z`` in frame 1, plus attributes).
"""

from __future__ import annotations

import threading
import weakref
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .errors import InputError
from .io.parquet_table import read_table, write_table
from .sensors.models import SensorModel
from .sensors.rig import Lidar, LidarView, check_lidar_ids, cloud_lidars, lidars_from_meta, lidars_to_meta


@dataclass
class RegisteredPair:
    xyz1: np.ndarray  # (N1, 3) cloud 1, frame 1
    xyz2: np.ndarray  # (N2, 3) cloud 2, frame 1
    T_1_2: np.ndarray = field(default_factory=lambda: np.eye(4))  # pose of sensor 2 in frame 1
    sensor1: SensorModel | None = None
    sensor2: SensorModel | None = None
    attributes1: dict[str, np.ndarray] = field(default_factory=dict)
    attributes2: dict[str, np.ndarray] = field(default_factory=dict)
    # method, fitness, inlier_rmse, converged, errors against reference poses, ...
    registration: dict = field(default_factory=dict)
    # How each scan fitted its sensor model at ingest ({"1": ..., "2": ...}: sensor_fit.sensor_fit).
    sensor_fit: dict = field(default_factory=dict)
    # When each scan was taken and how its sensor moved during the sweep, as the scans recorded
    # them ({"1": {"stamp_s": ..., "sweep_motion": ...}, "2": ...}; see Scan; missing: unknown).
    sweeps: dict = field(default_factory=dict)
    # Each scan's rig when several lidars measured it (``lidars``; the points' ``lidar``
    # attribute names each point's); empty: one lidar at the scan frame's origin, ``sensorK``.
    lidars1: tuple[Lidar, ...] = ()
    lidars2: tuple[Lidar, ...] = ()
    # What hypotheses derived from the clouds and may reuse, e.g. ``outliers``' neighbour
    # distances by (cloud, k). Not written to files, not compared, not carried by subset().
    neighbours: dict = field(default_factory=dict, compare=False, repr=False)
    # What was derived from the clouds and the pose and may be used again while they are the
    # same (``remembered``): each cloud's range images on its lidars' models, its k-d trees in
    # frame 1 and in its own sensor's frame. A stage's field, ``moving_objects``, ``shadow`` and
    # the carried body look at the same clouds. Not passed on by ``replace``; ``subset`` and
    # ``with_cloud2`` pass on what the clouds they keep (the same arrays) alone were made into.
    derived: dict = field(default_factory=dict, init=False, compare=False, repr=False)

    def __post_init__(self):
        self.xyz1, self.xyz2 = _points(self.xyz1), _points(self.xyz2)
        self.T_1_2 = np.asarray(self.T_1_2, dtype=np.float64).reshape(4, 4)
        self.lidars1, self.lidars2 = tuple(self.lidars1), tuple(self.lidars2)
        check_lidar_ids(self.lidars1, self.attributes1)
        check_lidar_ids(self.lidars2, self.attributes2)

    def __getstate__(self) -> dict:
        """Pickled without what was derived from the clouds (``neighbours``, ``derived``): made
        again where asked for, not sent to another process (the figures' process)."""
        return {**self.__dict__, "neighbours": {}, "derived": {}}

    def remembered(self, key, make: Callable[[], object], clouds: tuple[int, ...] = (1, 2)):
        """``make()``, made once for the ``clouds`` it is made of as they are now, with sensor
        2's pose where cloud 2 is one of them (kept in ``derived`` under ``key``; made again once
        they were replaced). What it returns is shared: not to be changed. Two threads asking at
        once may both make it: the same value."""
        made_of = self._made_of(clouds)
        known = self.derived.get(key)
        if known is not None and _made_of_same(known, made_of):
            _holding(self)
            return known[3]
        value = make()
        self.derived[key] = (*made_of, value)
        _holding(self)
        return value

    def _made_of(self, clouds: tuple[int, ...]) -> tuple:
        """What a value derived from ``clouds`` is made of: the arrays (the same objects) and
        sensor 2's pose (an equal one), None for what it does not depend on."""
        with_2 = 2 in clouds
        return (
            self.xyz1 if 1 in clouds else None,
            self.xyz2 if with_2 else None,
            tuple(self.T_1_2.ravel().tolist()) if with_2 else None,
        )

    def with_cloud2(self, xyz2: np.ndarray, T_1_2: np.ndarray) -> RegisteredPair:
        """The pair with cloud 2 at ``xyz2`` and sensor 2 at ``T_1_2``; what was derived from
        cloud 1 alone passed on."""
        return self._passing_derived(replace(self, xyz2=xyz2, T_1_2=T_1_2))

    def _passing_derived(self, other: RegisteredPair) -> RegisteredPair:
        """``other``, made from this pair, given what this pair derived from the clouds (and the
        pose) that ``other`` has as they were: the same arrays, an equal pose."""
        kept = dict(self.derived)  # a copy at once: another thread may let it go meanwhile (_holding)
        for key, known in kept.items():
            clouds = tuple(cloud for cloud, was in ((1, known[0]), (2, known[1])) if was is not None)
            if _made_of_same(known, other._made_of(clouds)):
                other.derived[key] = known
        return other

    @property
    def origin1(self) -> np.ndarray:
        return np.zeros(3)

    @property
    def origin2(self) -> np.ndarray:
        """Sensor 2's origin in frame 1."""
        return self.T_1_2[:3, 3].copy()

    @property
    def pose_exact(self) -> bool:
        """Whether sensor 2's pose is the simulation's truth: both scans simulated, the pair
        registered by their poses (``truth``) and the pose not moved since (by a correction or
        a misregistration put on it)."""
        record = self.registration or {}
        return bool(record.get("reference_exact")) and np.array_equal(record["reference_T_1_2"], self.T_1_2)

    def lidars(self, cloud: int) -> list[LidarView]:
        """The lidars that measured cloud 1 or 2, each placed in frame 1 with its points."""
        if cloud == 1:
            return cloud_lidars(np.eye(4), self.sensor1, self.lidars1, self.attributes1, len(self.xyz1), 1)
        return cloud_lidars(self.T_1_2, self.sensor2, self.lidars2, self.attributes2, len(self.xyz2), 2)

    def point_origins(self, cloud: int) -> np.ndarray:
        """Where the lidar of each point of cloud 1 or 2 was, in frame 1: (3,) when one lidar
        measured the whole cloud, else (N, 3); either broadcasts against the points."""
        views = self.lidars(cloud)
        if len(views) == 1:
            return views[0].origin
        origins = np.zeros((len(self.xyz1 if cloud == 1 else self.xyz2), 3))
        for view in views:
            origins[view.points] = view.origin
        return origins

    def subset(self, keep1: np.ndarray, keep2: np.ndarray) -> "RegisteredPair":
        """The pair of the points ``keep1`` and ``keep2`` (boolean masks or rows). A cloud kept
        whole (a mask of every point) is the same array, its attributes' too, and what was
        derived from it alone is passed on: a correction's stage keeps the other cloud as it was
        (the clouds are never changed in place)."""
        whole1, whole2 = _whole(keep1, len(self.xyz1)), _whole(keep2, len(self.xyz2))
        return self._passing_derived(
            RegisteredPair(
                self.xyz1 if whole1 else self.xyz1[keep1],
                self.xyz2 if whole2 else self.xyz2[keep2],
                self.T_1_2,
                self.sensor1,
                self.sensor2,
                {k: v if whole1 else v[keep1] for k, v in self.attributes1.items()},
                {k: v if whole2 else v[keep2] for k, v in self.attributes2.items()},
                self.registration,
                self.sensor_fit,
                self.sweeps,
                self.lidars1,
                self.lidars2,
            )
        )

    def stamp(self, cloud: int) -> float | None:
        """When scan ``cloud`` (1 or 2) was taken (s), if it recorded it."""
        return self.sweeps.get(str(cloud), {}).get("stamp_s")

    def sweep_motion(self, cloud: int) -> dict | None:
        """Scan ``cloud``'s recorded motion during its sweep (see Scan.sweep_motion), if any."""
        return self.sweeps.get(str(cloud), {}).get("sweep_motion")

    # --- the points table -------------------------------------------------------------
    def to_columns(self) -> dict[str, np.ndarray]:
        n1, n2 = len(self.xyz1), len(self.xyz2)
        xyz = np.vstack([self.xyz1, self.xyz2])
        columns = {
            "cloud": np.concatenate([np.full(n1, 1, np.uint8), np.full(n2, 2, np.uint8)]),
            "x": xyz[:, 0],
            "y": xyz[:, 1],
            "z": xyz[:, 2],
        }
        for name in sorted(set(self.attributes1) | set(self.attributes2)):
            a1 = self.attributes1.get(name)
            a2 = self.attributes2.get(name)
            a1 = np.full(n1, np.nan) if a1 is None else a1
            a2 = np.full(n2, np.nan) if a2 is None else a2
            columns[name] = np.concatenate([a1, a2])
        return columns

    def metadata(self) -> dict:
        return {
            "T_1_2": self.T_1_2.tolist(),
            "sensor1": None if self.sensor1 is None else self.sensor1.to_dict(),
            "sensor2": None if self.sensor2 is None else self.sensor2.to_dict(),
            "registration": self.registration,
            "sensor_fit": self.sensor_fit,
            "sweeps": self.sweeps,
            "lidars1": lidars_to_meta(self.lidars1),
            "lidars2": lidars_to_meta(self.lidars2),
        }

    @classmethod
    def from_columns(cls, columns: dict[str, np.ndarray], meta: dict) -> "RegisteredPair":
        cloud = np.asarray(columns["cloud"])
        n1 = int(np.count_nonzero(cloud == 1))
        if (cloud[:n1] == 1).all() and (cloud[n1:] == 2).all():
            in1, in2 = slice(0, n1), slice(n1, None)  # as written (cloud 1 first): views, no copies
        else:
            in1, in2 = cloud == 1, cloud == 2
        xyz = np.empty((len(cloud), 3))
        for axis, name in enumerate("xyz"):
            xyz[:, axis] = columns[name]
        attrs = {k: v for k, v in columns.items() if k not in ("cloud", "x", "y", "z")}
        return cls(
            xyz[in1],
            xyz[in2],
            np.asarray(meta.get("T_1_2", np.eye(4)), dtype=np.float64),
            SensorModel.from_dict(meta["sensor1"]) if meta.get("sensor1") else None,
            SensorModel.from_dict(meta["sensor2"]) if meta.get("sensor2") else None,
            {k: v[in1] for k, v in attrs.items()},
            {k: v[in2] for k, v in attrs.items()},
            meta.get("registration", {}),
            meta.get("sensor_fit", {}),
            meta.get("sweeps", {}),
            lidars_from_meta(meta.get("lidars1")),
            lidars_from_meta(meta.get("lidars2")),
        )


def write_pair(path: str | Path, pair: RegisteredPair, extra_meta: dict | None = None) -> None:
    """Write a registered pair (or a stage's points) as a points Parquet file, atomically."""
    meta = pair.metadata()
    meta.update(extra_meta or {})
    write_table(path, pair.to_columns(), meta)


# The pairs that keep what they derived (``RegisteredPair.remembered``), the last asked for
# last: only the last ``DERIVED_PAIRS`` keep it, so that a caller holding every stage's pair
# (``lidarfield run``, ``explain``) holds about one stage's worth. A range image's sparse tables
# are the bulk: 75 MB for an 80-channel scan's 1,800 columns, whatever its number of points.
DERIVED_PAIRS = 3
_HOLDERS: list[weakref.ref] = []
_HOLDERS_LOCK = threading.Lock()


def _holding(pair: RegisteredPair) -> None:
    """``pair`` is the last asked for; the pairs before the last ``DERIVED_PAIRS`` let go."""
    with _HOLDERS_LOCK:
        _HOLDERS[:] = [held for held in _HOLDERS if held() is not None and held() is not pair]
        _HOLDERS.append(weakref.ref(pair))
        while len(_HOLDERS) > DERIVED_PAIRS:
            oldest = _HOLDERS.pop(0)()
            if oldest is not None:
                oldest.derived.clear()


def _made_of_same(known: tuple, made_of: tuple) -> bool:
    """Whether a ``derived`` entry was made of what ``made_of`` (``_made_of``) names: the same
    arrays, an equal pose."""
    return all(was is now if isinstance(now, np.ndarray) else was == now for was, now in zip(known, made_of))


def _whole(keep: np.ndarray, count: int) -> bool:
    """Whether ``keep`` is a mask of all ``count`` points."""
    keep = np.asarray(keep)
    return keep.dtype == bool and keep.shape == (count,) and bool(keep.all())


def _points(xyz) -> np.ndarray:
    """(N, 3) contiguous float64 points: the array itself where it is one already (what was
    derived from it stays valid for a pair made with it, ``RegisteredPair.remembered``)."""
    points = np.ascontiguousarray(xyz, dtype=np.float64)
    return points if points.ndim == 2 and points.shape[1] == 3 else points.reshape(-1, 3)


def read_pair(path: str | Path) -> tuple[RegisteredPair, dict]:
    """Read a points Parquet file: the pair and the file's full metadata."""
    columns, meta = read_table(path, required=("cloud", "x", "y", "z"))
    if "T_1_2" not in meta:
        raise InputError("not a registered-pair file (no T_1_2 in its lidarfield metadata)", path)
    return RegisteredPair.from_columns(columns, meta), meta
