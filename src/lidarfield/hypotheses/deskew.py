"""``deskew``: move each point of a cloud to its scan's reference time, with the scan's own motion.

A correcting hypothesis: it removes nothing, and moves the points of the chosen cloud(s)
(``cloud``: 1, 2 or ``both``). A spinning lidar fires over a sweep (0.1 s at 10 Hz) while its
vehicle moves; a driver that does not de-skew reports each point in the sensor frame of its own
firing. With the scan's motion over the sweep taken as constant (linear velocity ``v`` and
angular velocity ``w``, both in the scan's sensor frame at its reference time), a point ``p``
fired ``s`` seconds after the reference time is, in the reference frame, ``Rot(w s) p + v s``
(``Rot`` the rotation vector's rotation): exact for the simulator's rolling shutter.

``reference`` is the time the scan's pose (and so the pair's frame) refers to: ``start`` for the
simulator and for a Velodyne/Ouster driver's scan stamped at its first packet, ``mid`` or ``end``
for data stamped otherwise. Cloud 2 is de-skewed in sensor 2's frame (through ``T_1_2``) and
put back in frame 1; sensor 2's pose is not changed. A scan of several lidars
(:mod:`lidarfield.sensors.rig`) moves as one body (its velocities are its frame's); what is each
lidar's own is the time of a point without a time attribute: from its azimuth about its own
lidar, at that lidar's rotation rate.

Each point's time: the ``time_attribute`` (seconds or nanoseconds, ``time_unit``; counted from
the sweep start, to the sweep end (negative), or absolute, ``time_zero``); without one, from the
point's azimuth about its own sensor: the sweep starts at ``start_azimuth_deg`` and turns
``counter-clockwise`` (the simulator's sense, seen from above) or ``clockwise`` (a Velodyne's),
once per ``1 / rotation_hz`` of the sensor model.

Each cloud's motion comes from what is known of its scan, in this order (the first that is
known; ``motion_source`` in the record says which, and the parameter of that name can ask for
one of them only):

1. ``record``: the scan's own record of its motion during its sweep (``Scan.sweep_motion``,
   carried by the pair: the simulator writes it; zero for a scan taken still or without rolling
   shutter, whose points then stay where they are; a bag's scan posed by Odometry records its
   twist, ``source: odometry``, see :mod:`lidarfield.io.rosbag.poses`); else ``neighbours``: the
   constant velocity between the poses of the scan's neighbours in its sequence, which a study
   puts in that record's place for a dataset sequence with poses and stamps (``source: neighbours``);
2. ``settings``: ``velocity_mps`` and ``angular_velocity_rps`` as given (the same for every
   chosen cloud without a record);
3. ``pair``: the constant velocity between the pair's two scans, ``T_1_2`` over the difference
   of their stamps (both scans must record ``stamp_s``, as a bag's scans and simulated ones do),
   as a constant twist (``poses.constant_twist``): the same velocities in each scan's frame.
   Right for consecutive scans of one drive; wrong when one of them was taken still (a record
   or the settings say so).

Data already de-skewed (KITTI odometry, Argoverse 2 as datasets) records a still sweep on its
scans, so ``deskew`` moves nothing there unless asked (``motion_source: settings``). A stage
after ``deskew`` still carries the scans' records: do not de-skew the same cloud twice.

What it records (the stage's ``correction``): ``reference``, and per cloud (``cloud1``,
``cloud2``) the ``velocity_mps`` and ``angular_velocity_rps`` used, ``motion_source``,
``time_source``, the span of the points' times about the reference (``time_min_s``,
``time_max_s``) and ``max_displacement_m``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import HypothesisError
from ..pair import RegisteredPair
from ..poses import constant_twist, in_sensor_frame
from ..sensors.models import SensorModel
from .outcome import Outcome
from .params import doc

NAME = "deskew"


@dataclass(frozen=True)
class Params:
    cloud: int | str = field(default="both", metadata=doc("the cloud(s) to de-skew: 1, 2 or both"))
    reference: str = field(
        default="start",
        metadata=doc(
            "the time the scan's pose refers to, to which its points are moved: start (the simulator's, "
            "a driver stamping a scan at its first packet), mid or end of the sweep"
        ),
    )
    velocity_mps: tuple[float, float, float] | None = field(
        default=None,
        metadata=doc("the scan's linear velocity over its sweep, [vx, vy, vz] m/s in its own sensor frame"),
    )
    angular_velocity_rps: tuple[float, float, float] | None = field(
        default=None,
        metadata=doc("the scan's angular velocity over its sweep, rad/s about its own sensor axes (none: 0)"),
    )
    motion_source: str = field(
        default="auto",
        metadata=doc(
            "where each scan's motion comes from: auto (its record, else the settings, else the pair's stamps), "
            "record, settings or pair"
        ),
    )
    time_attribute: str = field(
        default="time", metadata=doc("the per-point time attribute; without it, times come from azimuth")
    )
    time_unit: str = field(default="s", metadata=doc("the time attribute's unit: s or ns"))
    time_zero: str = field(
        default="start",
        metadata=doc(
            "what the time attribute counts from: start (of the sweep), end (negative to the sweep's end) or "
            "absolute (the sweep's start and end taken as the cloud's earliest and latest point)"
        ),
    )
    start_azimuth_deg: float = field(
        default=0.0, metadata=doc("without a time attribute: the azimuth the sweep starts at (deg, from +x)")
    )
    rotation: str = field(
        default="counter-clockwise",
        metadata=doc("without a time attribute: the sense of rotation seen from above, counter-clockwise or clockwise"),
    )
    with_pose: bool = field(
        default=False,
        metadata=doc(
            "refit sensor 2's pose (realign, its defaults) on the de-skewed clouds, where the de-skew moved points"
        ),
    )

    def __post_init__(self):
        if self.cloud not in (1, 2, "both"):
            raise ValueError(f"need cloud 1, 2 or both, got {self.cloud!r}")
        for name, value, allowed in (
            ("reference", self.reference, ("start", "mid", "end")),
            ("time_unit", self.time_unit, ("s", "ns")),
            ("time_zero", self.time_zero, ("start", "end", "absolute")),
            ("rotation", self.rotation, ("counter-clockwise", "clockwise")),
            ("motion_source", self.motion_source, ("auto", "record", "settings", "pair")),
        ):
            if value not in allowed:
                raise ValueError(f"need {name} {' or '.join(allowed)}, got {value!r}")
        for name in ("velocity_mps", "angular_velocity_rps"):
            value = getattr(self, name)
            if value is not None and not all(math.isfinite(v) for v in value):
                raise ValueError(f"need a finite {name}, got {list(value)}")


def deskew(pair: RegisteredPair, params: Params) -> Outcome:
    """The chosen clouds moved to their scans' reference time; nothing removed."""
    clouds = (1, 2) if params.cloud == "both" else (params.cloud,)
    out = {"keep1": np.ones(len(pair.xyz1), dtype=bool), "keep2": np.ones(len(pair.xyz2), dtype=bool)}
    fitted: dict = {"reference": params.reference, "method": "constant_velocity"}
    for cloud in clouds:
        v, w, motion_source = sweep_motion(pair, cloud, params)
        xyz = pair.xyz1 if cloud == 1 else pair.xyz2
        pose = np.eye(4) if cloud == 1 else pair.T_1_2
        local = (xyz - pose[:3, 3]) @ pose[:3, :3]  # the points in their own sensor frame
        s, time_source = _point_times(local, pair, cloud, params)
        moved = _moved(local, s, v, w)
        displacement = np.linalg.norm(moved - local, axis=1)
        if np.any(v) or np.any(w):  # a still scan stays exactly where it is (no round trip of frames)
            out[f"xyz{cloud}"] = moved @ pose[:3, :3].T + pose[:3, 3]
        fitted[f"cloud{cloud}"] = {
            "velocity_mps": v.tolist(),
            "angular_velocity_rps": w.tolist(),
            "motion_source": motion_source,
            "time_source": time_source,
            "time_min_s": float(s.min()) if len(s) else 0.0,
            "time_max_s": float(s.max()) if len(s) else 0.0,
            "max_displacement_m": float(displacement.max()) if len(s) else 0.0,
        }
    if params.with_pose and ("xyz1" in out or "xyz2" in out):
        return _with_pose(pair, out, fitted)
    return Outcome(**out, fitted=fitted)


def _with_pose(pair: RegisteredPair, out: dict, fitted: dict) -> Outcome:
    """The de-skewed clouds with sensor 2's pose refitted on them (``realign``, its defaults).
    A skew's mean over the sweep is a shift, which a pose fitted on the skewed scan took (the
    reference's, or a ``realign`` before): de-skewed alone, the scan lands that shift off."""
    from .realign import Params as RealignParams
    from .realign import realign

    deskewed = replace(pair, xyz1=out.get("xyz1", pair.xyz1), xyz2=out.get("xyz2", pair.xyz2))
    aligned = realign(deskewed, RealignParams())
    pose = {
        k: aligned.fitted[k]
        for k in ("translation_m", "rotation_deg", "angle_deg", "translation_se_m", "rotation_se_deg")
    }
    fitted = {**fitted, "pose": pose, "parameters": aligned.fitted["parameters"]}
    return Outcome(
        out["keep1"], out["keep2"], xyz1=out.get("xyz1"), xyz2=aligned.xyz2, T_1_2=aligned.T_1_2, fitted=fitted
    )


def sweep_motion(pair: RegisteredPair, cloud: int, params: Params) -> tuple[np.ndarray, np.ndarray, str]:
    """Scan ``cloud``'s linear (m/s) and angular (rad/s) velocity in its own sensor frame, and
    where they came from: its record, the settings, or the pair's two stamps (module docstring)."""
    wanted = params.motion_source
    record = pair.sweep_motion(cloud)
    if wanted in ("auto", "record") and record is not None:
        return (
            np.asarray(record["velocity_mps"], dtype=np.float64),
            np.asarray(record["angular_velocity_rps"], dtype=np.float64),
            record.get("source", "record"),
        )
    given = params.velocity_mps is not None or params.angular_velocity_rps is not None
    if wanted in ("auto", "settings") and given:
        return (
            np.asarray(params.velocity_mps or (0.0, 0.0, 0.0), dtype=np.float64),
            np.asarray(params.angular_velocity_rps or (0.0, 0.0, 0.0), dtype=np.float64),
            "settings",
        )
    stamp1, stamp2 = pair.stamp(1), pair.stamp(2)
    if wanted not in ("auto", "pair") or stamp1 is None or stamp2 is None or stamp1 == stamp2:
        missing = {
            "record": "its scan recorded none",
            "settings": "no velocity_mps nor angular_velocity_rps is given",
            "pair": "the pair's scans "
            + ("have one stamp" if stamp1 is not None and stamp1 == stamp2 else "do not both record a stamp")
            + " to derive it from T_1_2",
        }
        reasons = list(missing.values()) if wanted == "auto" else [missing[wanted]]
        raise HypothesisError(
            f"{NAME}: no motion for cloud {cloud} (motion_source {wanted}): "
            + ", ".join(reasons[:-1])
            + (", and " if len(reasons) > 1 else "")
            + reasons[-1]
        )
    # A constant twist: the same velocities in each scan's own frame.
    v, w = constant_twist(pair.T_1_2, stamp2 - stamp1)
    return v, w, "pair"


def _moved(local: np.ndarray, s: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``Rot(w s) p + v s`` for each point ``p`` fired ``s`` seconds after the reference."""
    moved = local + s[:, None] * v
    if np.any(w != 0):
        from scipy.spatial.transform import Rotation

        moved = Rotation.from_rotvec(s[:, None] * w).apply(local) + s[:, None] * v
    return moved


def _point_times(local: np.ndarray, pair: RegisteredPair, cloud: int, params: Params) -> tuple[np.ndarray, str]:
    """Each point of cloud ``cloud`` (``local``: in its scan's frame) timed from the reference
    (:func:`_times_from_reference`): by the time attribute, with the sweep's length of its first
    lidar's model; without one, by its azimuth about its own lidar, at that lidar's rotation rate."""
    xyz, attributes = (pair.xyz1, pair.attributes1) if cloud == 1 else (pair.xyz2, pair.attributes2)
    lidars = pair.lidars(cloud)
    scan_pose = np.eye(4) if cloud == 1 else pair.T_1_2
    if params.time_attribute in attributes or len(lidars) == 1 and np.array_equal(lidars[0].pose, scan_pose):
        return _times_from_reference(local, attributes, lidars[0].sensor, params, cloud)
    s, sources = np.zeros(len(local)), []
    for lidar in lidars:
        own = in_sensor_frame(xyz[lidar.points], lidar.pose)
        s[lidar.points], source = _times_from_reference(own, {}, lidar.sensor, params, cloud)
        sources.append(f"{lidar.name}: {source}")
    return s, "; ".join(sources)


def _times_from_reference(
    local: np.ndarray, attributes: dict, sensor: SensorModel | None, params: Params, cloud: int
) -> tuple[np.ndarray, str]:
    """Each point's time in seconds after the reference time (negative before), and its source."""
    period = None if sensor is None or not sensor.rotation_hz > 0 else 1.0 / sensor.rotation_hz
    if params.time_attribute in attributes:
        t = np.asarray(attributes[params.time_attribute], dtype=np.float64)
        if len(t) and not np.isfinite(t).all():
            raise HypothesisError(
                f"{NAME}: cloud {cloud}'s {params.time_attribute!r} attribute has points without a time"
            )
        if params.time_unit == "ns":
            t = t * 1e-9
        if params.time_zero == "absolute":
            start = float(t.min()) if len(t) else 0.0
            t = t - start
            length = period if period is not None else (float(t.max()) if len(t) else 0.0)
        else:
            if period is None:
                if params.time_zero == "end" or params.reference != "start":
                    raise HypothesisError(
                        f"{NAME}: cloud {cloud}: the sweep's length is unknown (no sensor model's rotation_hz), "
                        f"needed for time_zero {params.time_zero} and reference {params.reference}"
                    )
                period = 0.0
            length = period
            if params.time_zero == "end":
                t = t + period
        source = f"attribute {params.time_attribute} ({params.time_unit}, from {params.time_zero})"
    else:
        if sensor is None or not sensor.rotation_hz > 0:
            raise HypothesisError(
                f"{NAME}: cloud {cloud} has no {params.time_attribute!r} attribute and no sensor model's "
                "rotation_hz to time its points by azimuth"
            )
        sense = 1.0 if params.rotation == "counter-clockwise" else -1.0
        azimuth = np.degrees(np.arctan2(local[:, 1], local[:, 0]))
        turned = np.mod(sense * (azimuth - params.start_azimuth_deg), 360.0)
        length = period
        t = turned / 360.0 * period
        source = f"azimuth ({params.rotation} from {params.start_azimuth_deg:g} deg, {sensor.rotation_hz:g} Hz)"
    reference = {"start": 0.0, "mid": 0.5 * length, "end": length}[params.reference]
    return t - reference, source
