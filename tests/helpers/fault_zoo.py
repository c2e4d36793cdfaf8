"""The fault zoo of the diagnosis benchmark (issue 36; ``bench/diagnosis.py`` runs it all, the
tests a slice): pairs with one known adversity, or none, and what ``explain`` proposes for them.

A case is a *base pair* (two scans with their reference poses: real scans from the shared data,
or a simulated scene seen by a preset) and one *fault* at one *level* (barely visible, visible,
obvious). A real base pair is registered by its reference poses (``real_pose`` "reference", the
issue's definition), or by those refined by the tool's own registration of the fault-free pair
("registered": GICP from the reference, as a user registers a pair; ``registered_base``).
Faults of a scan are injected in its own sensor frame before the pair is registered by those
poses: the points a faulty sensor would have reported (range scale and offset,
one channel's elevation, motion during the sweep, a moving object, the own vehicle's body, a
cut field of view). Faults of the registration are applied to the registered pair: scan 2
placed off (translation, yaw, pitch and roll about its own origin), or by the pose of a moment
``dt`` later or earlier (a time offset between a scan and its pose, along a drive).

Objects are added by casting each returned ray of a scan against the object's box: a ray that
meets the box before its return reports the box instead (the occlusion it causes); rays that
returned nothing (sky) see nothing of it.

``NAMING`` says which hypotheses name which fault (docs/diagnosis.md); ``run_case`` runs
``explain`` as ``lidarfield explain`` does without a config and records the result.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lidarfield.commands.scans import explain_with_study
from lidarfield.io import read_scan
from lidarfield.io.pose_files import read_kitti_poses, read_pose
from lidarfield.pair import RegisteredPair
from lidarfield.poses import apply_pose, in_sensor_frame, invert_pose, pose_from_xyzrpy
from lidarfield.registration import register_pair
from lidarfield.scan import Scan, still_sweep
from lidarfield.sensors.models import PRESETS
from lidarfield.sensors.rig import LIDAR, Lidar
from lidarfield.study.config import validate_config

ROOT = Path(__file__).resolve().parents[2]
SHARED_DATA = Path(os.environ.get("LIDARFIELD_DATA", ROOT.parent / "shared" / "data"))

LEVELS = ("barely", "visible", "obvious")
# Fault: (unit, magnitude per level). Misregistration is scan 2 moved in frame 1 along
# (0.8, 0.6, 0), turned about its own z axis, or about the horizontal axis (1, 1, 0) (pitch and
# roll together); a time offset is scan 2 placed where its sensor was ``dt`` later.
FAULTS = {
    "translation": ("m", (0.03, 0.10, 0.30)),
    "yaw": ("deg", (0.05, 0.2, 0.8)),
    "pitch_roll": ("deg", (0.05, 0.2, 0.8)),
    "range_scale": ("scale - 1", (0.001, 0.003, 0.01)),
    "range_offset": ("m", (0.01, 0.03, 0.10)),
    "channel_elevation": ("deg", (0.1, 0.3, 1.0)),
    "motion_distortion": ("m/s", (1.0, 3.0, 10.0)),
    "moving_object": ("m moved", (0.3, 1.0, 3.0)),
    "ego_body": ("body", ("pole", "car", "truck")),
    "fov_cut": ("deg cut", (30.0, 90.0, 180.0)),
    "time_offset": ("ms", (10.0, 25.0, 50.0)),
}
CONTROL = "none"
# Which hypotheses name which fault. A time offset along a drive moves scan 2 along its path:
# from one pair it is a translation (and a turn, on a bend), so realign names it; only a study of
# many pairs (the offset is the same time at every speed) tells the two apart.
NAMING = {
    "translation": {"realign"},
    "yaw": {"realign"},
    "pitch_roll": {"realign"},
    "range_scale": {"range_calibration"},
    "range_offset": {"range_calibration"},
    "channel_elevation": {"elevation_calibration"},
    "motion_distortion": {"deskew"},
    "moving_object": {"moving_objects"},
    "ego_body": {"ego_vehicle"},
    "fov_cut": {"field_of_view"},
    "time_offset": {"realign"},
}
# Faults named in the tables but left out of the rates: one channel's elevation is below the
# stage-0 field's noise on most pairs (bench/channel_elevation.py: its share of a voxel's points
# times its lift is 0.4-2.7 cm against standard errors of 4-20 cm at 1 deg), so the field reads
# random and nothing is proposed whatever names it (docs/diagnosis.md).
UNRATED = {"channel_elevation"}
# What a control may propose and still count as nothing: what is in any pair by construction
# (the own vehicle, the fields of view, shadows from another viewpoint), and a realign within
# the reference pose's own accuracy.
CONTROL_ALLOWED = {"ego_vehicle", "field_of_view", "shadow"}
# The reference pose's own accuracy, as a pose's accuracy is stated: how far sensor 2 may be
# off (m) and turned (deg). A real reference (scan matching, a registration, NDT) is good to a
# few centimetres and about 0.1 deg (5 cm at 30 m); the simulated truth is exact (a realign
# there fits the range noise: 1 cm, 0.02 deg). A correction within it counts as none (the
# issue), for a control and before a proposal alike. ``displacement``: the earlier measure,
# the most a point moved (5 cm real, 1 cm simulated), reported beside it (``named_displacement``):
# at an OS1-128's 160 m a 0.085 deg error moves a point 24 cm.
REFERENCE_ACCURACY = {"real": (0.05, 0.1), "simulated": (0.01, 0.02)}
REFERENCE_ACCURACY_M = {"real": 0.05, "simulated": 0.01}
ACCURACY_MEASURES = ("pose", "displacement")
# How a real base pair is registered before its faults: by its reference poses, or by the tool's
# registration of the fault-free pair started from them (the `register` rule's GICP, defaults).
REAL_POSES = ("reference", "registered")
REGISTRATION = {"method": "gicp", "guess": "truth"}
SCAN_FAULTS = tuple(f for f in FAULTS if f != "time_offset")
# The own vehicle's body shows only where the two sensors stood apart (from one place it is the
# same in both scans): on the drives, not on the pairs from one place.
STILL_FAULTS = tuple(f for f in SCAN_FAULTS if f != "ego_body")

SIM_PRESETS = ("vlp16", "hdl32", "vlp32c", "hdl64", "os1-128", "paper-sim-80")
SIM_NOISE_M = 0.01
# A moving object (size in metres, distance from the sensor): a car, or a person indoors.
MOVING_OBJECTS = (((4.5, 1.8, 1.5), 8.0), ((4.5, 1.8, 1.5), 6.0), ((0.5, 0.5, 1.7), 3.0), ((0.5, 0.5, 1.7), 2.0))
# The own vehicle's body, a box in the sensor frame (centre, size): a pole of a roof rack beside
# the sensor, a car's body 0.3 m below it (the built-in ego-car scene's), a box truck's cargo
# body behind it (the ego-truck scene's).
EGO_BODIES = {
    "pole": ((-0.5, 0.4, -0.6), (0.2, 0.2, 1.2)),
    "car": ((-0.3, 0.0, -1.05), (4.6, 1.9, 1.5)),
    "truck": ((-2.8, 0.0, -1.2), (5.0, 2.2, 3.2)),
}


@dataclass
class BasePair:
    """Two scans, each in its sensor frame with its reference pose (world from sensor), and the
    velocity of sensor 2 in its own frame (m/s, rad/s) when the pair is along a drive."""

    name: str
    scan1: Scan
    scan2: Scan
    velocity: tuple[np.ndarray, np.ndarray] | None = None


@dataclass(frozen=True)
class BaseSpec:
    """A base pair before it is loaded: what it is, which faults it takes, how to load it."""

    source: str  # "real" or "simulated"
    sensor: str
    kind: str  # "still": one place; "drive": consecutive scans of a drive; "apart": metres apart
    faults: tuple[str, ...]
    load: callable


@dataclass(frozen=True)
class Case:
    base: str
    fault: str  # a FAULTS key, or CONTROL
    level: str  # a LEVELS entry, "" for a control
    real_pose: str = "reference"  # a REAL_POSES entry: how a real base pair is registered

    @property
    def name(self) -> str:
        return f"{self.base}/{self.fault}" + (f"-{self.level}" if self.level else "")

    @property
    def magnitude(self):
        if self.fault == CONTROL:
            return 0.0
        return FAULTS[self.fault][1][LEVELS.index(self.level)]


# --- base pairs -------------------------------------------------------------------------


def _posed(scan: Scan, pose: np.ndarray) -> Scan:
    scan.pose = np.asarray(pose, dtype=np.float64)
    scan.sweep_motion = still_sweep()  # taken still or de-skewed: the faults add the motion
    return scan


def _velocity_between(T_1_2: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Constant velocity (sensor frame) from one scan's pose to the next ``dt_s`` later."""
    from scipy.spatial.transform import Rotation

    return T_1_2[:3, 3] / dt_s, Rotation.from_matrix(T_1_2[:3, :3]).as_rotvec() / dt_s


def real_bases() -> dict[str, BaseSpec]:
    """The real base pairs, by name ({} when the shared data is absent). Every fault of a scan
    on each; a time offset where the pair's scans are consecutive scans of a drive."""
    d, expd_file = SHARED_DATA, ROOT / "config" / "expd-T_1_10.txt"
    if not (d.is_dir() and expd_file.is_file()):
        return {}

    def expd():
        T = read_pose(expd_file)
        s1 = _posed(read_scan(d / "expd-vlp16" / "Cloud1_ExpD.txt", sensor="vlp16"), np.eye(4))
        s2 = _posed(read_scan(d / "expd-vlp16" / "Cloud10_ExpD.txt", sensor="vlp16"), T)
        return BasePair("real-expd-vlp16", s1, s2, _velocity_between(T, 0.9))  # scans 1 and 10 at 10 Hz

    def hdl32_pair():
        folder = d / "hdl32-pair"
        s1 = _posed(read_scan(folder / "251370668.pcd", sensor="hdl32"), np.eye(4))
        s2 = _posed(read_scan(folder / "251371071.pcd", sensor="hdl32"), read_pose(folder / "relative.txt"))
        return BasePair("real-hdl32-pair", s1, s2)

    def os1_frames():
        folder = d / "ouster-os1-128"
        poses = read_kitti_poses(folder / "OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt")
        scans = [read_scan(folder / f"lb_n3_scan{k}_xyz_refl_float32.bin", sensor="os1-128") for k in (0, 1)]
        T = invert_pose(poses[0]) @ poses[1]
        return BasePair("real-os1-128-frames", *(_posed(s, p) for s, p in zip(scans, poses)), _velocity_between(T, 0.1))

    def vlp16_capture():
        # Consecutive rotations of the capture, taken from one place (GICP between them: under
        # 1 cm; the median distance of a point to the other rotation's nearest one: 4.4 mm).
        path = d / "velodyne-pcap" / "sample_velodyne_vlp16_gps.pcap"
        return BasePair("real-vlp16-capture", *(_posed(read_scan(f"{path}#{k}"), np.eye(4)) for k in (0, 1)))

    with_time = (*SCAN_FAULTS, "time_offset")
    return {
        "real-expd-vlp16": BaseSpec("real", "vlp16", "drive", with_time, expd),
        "real-hdl32-pair": BaseSpec("real", "hdl32", "apart", SCAN_FAULTS, hdl32_pair),
        "real-os1-128-frames": BaseSpec("real", "os1-128", "drive", with_time, os1_frames),
        "real-vlp16-capture": BaseSpec("real", "vlp16", "still", STILL_FAULTS, vlp16_capture),
    }


def _sim_scan(scene, model, pose, t, seed) -> Scan:
    from lidarfield.simulation.raycast import simulate_scan

    return _posed(simulate_scan(scene, model, pose, time_s=t, seed=seed, range_noise_m=SIM_NOISE_M), pose)


# A two-lidar rig (Argoverse 2's layout, tests/helpers/av2_layout.py): two VLP-32C stacked
# 0.3 m apart, the lower one upside down; the scan's frame is the upper lidar's.
RIG = "rig"


def _rig_lidars() -> tuple[Lidar, Lidar]:
    from helpers.av2_layout import DOWN_IN_VEHICLE, UP_IN_VEHICLE

    model = PRESETS["vlp32c"]
    return Lidar("up_lidar", np.eye(4), model), Lidar("down_lidar", invert_pose(UP_IN_VEHICLE) @ DOWN_IN_VEHICLE, model)


def _sim_rig_scan(scene, pose, t, seed) -> Scan:
    """The rig's scan with its upper lidar at ``pose``: each lidar cast from its own place, the
    points in the upper lidar's frame with their ``lidar``."""
    lidars = _rig_lidars()
    parts = [_sim_scan(scene, lidar.sensor, pose @ lidar.pose, t, seed + 10 * k) for k, lidar in enumerate(lidars)]
    xyz = np.vstack([apply_pose(lidar.pose, part.xyz) for lidar, part in zip(lidars, parts)])
    names = sorted(set.intersection(*(set(part.attributes) for part in parts)))
    attributes = {name: np.concatenate([part.attributes[name] for part in parts]) for name in names}
    attributes[LIDAR] = np.repeat(np.arange(len(parts), dtype=np.uint8), [len(part) for part in parts])
    return _posed(Scan(xyz, attributes, lidars[0].sensor, lidars=lidars), pose)


def traffic_rig_pair():
    """The rig at the intersection with traffic, registered by the truth: scan 2 1.6 m on and
    0.3 s later, the cars moved."""
    from lidarfield.registration import register_pair
    from lidarfield.simulation.scene import load_scene

    scene = load_scene("paper-intersection-traffic")
    scans = [
        _sim_rig_scan(scene, pose_from_xyzrpy(p), t, k)
        for k, (p, t) in enumerate((([0, 0, 2, 0, 0, 0], 0.0), ([1.5, 0.5, 2, 0, 0, 0.1], 0.3)))
    ]
    return register_pair(*scans, "truth")


def _intersection_drive(frames: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Issue 27's drive (tests/helpers/drive.py), 2 m up: 3 m/s round the crossing's centre,
    10 Hz; per scan its pose and the sensor's velocities in its own frame."""
    from lidarfield.simulation.trajectory import arc_trajectory

    return [
        (f.pose, f.pose[:3, :3].T @ np.asarray(f.linear_velocity_mps), np.asarray(f.angular_velocity_rps))
        for f in arc_trajectory((0, 0), 2.5, 0.0, 3.0, 10.0, frames, 2.0)
    ]


def _canyon_drive(frames: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Along the street canyon at 10 m/s, 10 Hz, 2 m up, 1.5 m right of its centre line."""
    return [
        (pose_from_xyzrpy([-6.0 + k, -1.5, 2.0, 0, 0, 0]), np.array([10.0, 0, 0]), np.zeros(3)) for k in range(frames)
    ]


SIM_SCENES = {"intersection": ("paper-intersection", _intersection_drive), "canyon": ("street-canyon", _canyon_drive)}
# The second scan of each kind: the first again (one place), the next, or the one 3 m on.
SIM_SECOND = {"intersection": {"still": 0, "drive": 1, "apart": 10}, "canyon": {"still": 0, "drive": 1, "apart": 3}}
SIM_FAULTS = {"still": STILL_FAULTS, "drive": ("translation", "time_offset", "ego_body"), "apart": ()}


def sim_bases() -> dict[str, BaseSpec]:
    """The simulated base pairs, by name (``sim-{scene}-{kind}-{preset}``): per preset, the
    paper's intersection and the street canyon from one place (two samplings 0.1 s apart,
    their own range noise), consecutive scans of a drive, and scans 3 m apart along it; and the
    intersection seen by the two-lidar rig (``RIG``)."""

    def loader(scene_key, kind, preset):
        def load():
            from lidarfield.simulation.scene import load_scene

            scene_name, drive = SIM_SCENES[scene_key]
            scene, k2 = load_scene(scene_name), SIM_SECOND[scene_key][kind]
            frames = drive(k2 + 1)
            if preset == RIG:
                s1 = _sim_rig_scan(scene, frames[0][0], 0.0, 1)
                s2 = _sim_rig_scan(scene, frames[k2][0], 0.1 * max(k2, 1), 2)
            else:
                s1 = _sim_scan(scene, PRESETS[preset], frames[0][0], 0.0, 1)
                s2 = _sim_scan(scene, PRESETS[preset], frames[k2][0], 0.1 * max(k2, 1), 2)
            velocity = frames[k2][1:] if kind == "drive" else None
            return BasePair(f"sim-{scene_key}-{kind}-{preset}", s1, s2, velocity)

        return load

    chosen = [(preset, scene) for preset in SIM_PRESETS for scene in SIM_SCENES] + [(RIG, "intersection")]
    return {
        f"sim-{scene}-{kind}-{preset}": BaseSpec(
            "simulated", preset, kind, SIM_FAULTS[kind], loader(scene, kind, preset)
        )
        for preset, scene in chosen
        for kind in SIM_FAULTS
    }


@functools.cache
def bases() -> dict[str, BaseSpec]:
    return {**real_bases(), **sim_bases()}


def registered_base(base: BasePair) -> BasePair:
    """The base pair with scan 2's pose refined by the tool's registration (``REGISTRATION``:
    GICP from the reference poses) of the fault-free pair, at full resolution; scan 1 keeps its
    pose. Raises ValueError when the registration did not converge."""
    pair = register_pair(base.scan1, base.scan2, REGISTRATION)
    if not pair.registration["converged"]:
        raise ValueError(f"{base.name}: GICP from the reference did not converge: {pair.registration.get('warning')}")
    scan2 = dataclasses.replace(base.scan2, pose=base.scan1.pose @ pair.T_1_2)
    return dataclasses.replace(base, scan2=scan2)


@functools.cache
def load_base(name: str, points: int | None, real_pose: str = "reference") -> BasePair:
    """A base pair (a real one registered as ``real_pose`` says, once), each scan subsampled to
    at most ``points`` (fixed seed)."""
    base = bases()[name].load()
    if real_pose == "registered" and bases()[name].source == "real":
        base = registered_base(base)
    if points is None:
        return base
    rng = np.random.default_rng(0)
    s1, s2 = (
        s.subset(np.sort(rng.choice(len(s), size=points, replace=False))) if len(s) > points else s
        for s in (base.scan1, base.scan2)
    )
    return dataclasses.replace(base, scan1=s1, scan2=s2)


def cases_of(name: str, real_pose: str = "reference") -> list[Case]:
    """A base pair's control and its faults at every level."""
    faults = bases()[name].faults
    levels = [(CONTROL, "")] + [(fault, level) for fault in faults for level in LEVELS]
    return [Case(name, fault, level, real_pose) for fault, level in levels]


# --- faults of a scan, in its sensor frame ------------------------------------------------


def spherical(xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Range, azimuth and elevation (radians) of points about the origin."""
    r = np.linalg.norm(xyz, axis=1)
    return r, np.arctan2(xyz[:, 1], xyz[:, 0]), np.arcsin(np.clip(xyz[:, 2] / np.maximum(r, 1e-12), -1, 1))


def from_spherical(r, azimuth, elevation) -> np.ndarray:
    c = np.cos(elevation)
    return np.column_stack([r * c * np.cos(azimuth), r * c * np.sin(azimuth), r * np.sin(elevation)])


def lidar_parts(scan: Scan) -> list[tuple[np.ndarray, np.ndarray, object]]:
    """Each lidar of the scan: the mask of its points, its pose in the scan's frame and its
    model (one lidar at the frame's origin for a scan without a rig)."""
    if not scan.lidars:
        return [(np.ones(len(scan), dtype=bool), np.eye(4), scan.sensor)]
    ids = np.asarray(scan.attributes[LIDAR])
    return [(ids == k, lidar.pose, lidar.sensor or scan.sensor) for k, lidar in enumerate(scan.lidars)]


def in_each_lidar(scan: Scan, move) -> np.ndarray:
    """The scan's points, each lidar's moved by ``move(k, its points in its own frame, their
    mask, its model)`` (points in its frame): a fault of a lidar is about its own origin."""
    out = scan.xyz.copy()
    for k, (mask, pose, model) in enumerate(lidar_parts(scan)):
        out[mask] = apply_pose(pose, move(k, in_sensor_frame(scan.xyz[mask], pose), mask, model))
    return out


def range_fault(xyz: np.ndarray, scale: float, offset_m: float) -> np.ndarray:
    """Every range r reported as ``scale * r + offset_m`` along its ray."""
    r = np.linalg.norm(xyz, axis=1, keepdims=True)
    return xyz * (scale + offset_m / np.maximum(r, 1e-12))


def channels(scan: Scan) -> np.ndarray:
    """Each point's channel: the scan's ``ring``, else the model's nearest elevation."""
    if "ring" in scan.attributes:
        return np.asarray(scan.attributes["ring"]).astype(int)
    elevation = np.degrees(spherical(scan.xyz)[2])
    table = np.asarray(scan.sensor.elevation_deg)
    return np.argmin(np.abs(elevation[:, None] - table[None, :]), axis=1)


def faulty_channel(model) -> int:
    """The channel whose elevation is faulted: the one nearest -5 deg (it sees the ground and
    walls at every sensor's typical mount)."""
    return int(np.argmin(np.abs(np.asarray(model.elevation_deg) + 5.0)))


def faulted_channel_mask(scan: Scan) -> np.ndarray:
    """The points of the channel ``channel_elevation`` faults: the first lidar's
    ``faulty_channel``."""
    mask, _, model = lidar_parts(scan)[0]
    return mask & (channels(scan) == faulty_channel(model))


def elevation_fault(xyz: np.ndarray, chosen: np.ndarray, offset_deg: float) -> np.ndarray:
    """The ``chosen`` points reported ``offset_deg`` higher, at their range and azimuth."""
    out = xyz.copy()
    r, az, el = spherical(xyz[chosen])
    out[chosen] = from_spherical(r, az, el + np.radians(offset_deg))
    return out


def sweep_times(scan: Scan) -> np.ndarray:
    """Each point's firing time from the sweep start: the scan's ``time``, else from its
    azimuth, counter-clockwise from +x (``deskew``'s default) at the model's rotation rate."""
    if "time" in scan.attributes:
        return np.asarray(scan.attributes["time"], dtype=np.float64)
    azimuth = np.degrees(np.arctan2(scan.xyz[:, 1], scan.xyz[:, 0]))
    return np.mod(azimuth, 360.0) / 360.0 / scan.sensor.rotation_hz


def motion_fault(scan: Scan, speed_mps: float) -> Scan:
    """The scan as a driver without de-skewing reports it when its sensor moves forward (+x) at
    ``speed_mps`` during the sweep: a point fired ``t`` after the start is seen from ``v t``
    further, ``p - v t``; the scan records its times and that motion (as the simulator does)."""
    t = sweep_times(scan)
    v = np.array([speed_mps, 0.0, 0.0])
    moved = Scan(
        scan.xyz - t[:, None] * v,
        {**scan.attributes, "time": t},
        scan.sensor,
        scan.pose,
        scan.source,
        lidars=scan.lidars,
    )
    moved.sweep_motion = {"velocity_mps": v.tolist(), "angular_velocity_rps": [0.0, 0.0, 0.0]}
    return moved


def ray_box_distance(xyz: np.ndarray, T_box_sensor: np.ndarray, size) -> np.ndarray:
    """Distance from the sensor (the origin) along each point's ray to the box (its frame
    ``T_box_sensor`` maps sensor coordinates into the box's, centred, axis-aligned; ``size``
    its edges); inf where the ray misses it (slab method)."""
    origin = T_box_sensor[:3, 3]
    r = np.linalg.norm(xyz, axis=1)
    direction = (xyz / np.maximum(r, 1e-12)[:, None]) @ T_box_sensor[:3, :3].T
    half = np.asarray(size, dtype=np.float64) / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (-half - origin) / direction, (half - origin) / direction
    near = np.nanmax(np.minimum(t1, t2), axis=1)
    far = np.nanmin(np.maximum(t1, t2), axis=1)
    hit = (near <= far) & (far > 0)
    return np.where(hit, np.maximum(near, 0.0), np.inf)


def with_box(scan: Scan, T_box_sensor: np.ndarray, size) -> Scan:
    """The scan with a box in front of its returns: a ray (from its own lidar) meeting the box
    before its return reports the box (dropped when nearer than the lidar's minimum range)."""
    keep = np.ones(len(scan), dtype=bool)

    def blocked_by_box(k, own, mask, model):
        distance = ray_box_distance(own, T_box_sensor @ lidar_parts(scan)[k][1], size)
        r = np.linalg.norm(own, axis=1)
        blocked = distance < r
        own = own.copy()
        own[blocked] *= (distance[blocked] / r[blocked])[:, None]
        keep[mask] = ~blocked | (distance >= model.min_range_m)
        return own

    out = _with_xyz(scan, in_each_lidar(scan, blocked_by_box))
    return out if keep.all() else out.subset(keep)


def box_frame(center, yaw_rad: float = 0.0) -> np.ndarray:
    """The box's frame: its pose's inverse (box from world)."""
    return invert_pose(pose_from_xyzrpy([*center, 0.0, 0.0, yaw_rad]))


def object_place(scan: Scan, displacement_m: float) -> tuple[np.ndarray, float, np.ndarray, tuple]:
    """Where a moving object stands in the scan's frame (centre, heading, unit direction of its
    motion, size): the first of ``MOVING_OBJECTS`` (a car 8 m or 6 m away, a person 3 m or 2 m
    away, for scans taken indoors) that has a place on the ground, at an azimuth whose two
    positions (before and after moving ``displacement_m`` along its heading, across the
    sensor's view) hold none of the scan's points; of those, the one hiding the most returns
    (a box inside a building hides none: its rays return from the facade)."""
    range_m = np.linalg.norm(scan.xyz, axis=1)
    for size, distance in MOVING_OBJECTS:
        lift = size[2] / 2 + 0.15  # its floor 0.15 m above the lowest ground point near it
        best, best_hidden = None, 0
        for azimuth in np.radians(np.arange(0, 360, 15)):
            heading = azimuth + np.pi / 2
            along = np.array([np.cos(heading), np.sin(heading), 0.0])
            xy = distance * np.array([np.cos(azimuth), np.sin(azimuth), 0.0])
            near = np.linalg.norm(scan.xyz[:, :2] - xy[:2], axis=1) < max(size[0], 1.0)
            if near.sum() < 20:
                continue
            center = xy + [0, 0, np.percentile(scan.xyz[near, 2], 5) + lift]
            hidden, clear = 0, True
            for shift in (0.0, displacement_m):
                T = box_frame(center + shift * along, heading)
                inside = np.all(np.abs(apply_pose(T, scan.xyz)) < np.asarray(size) / 2 + [0.2, 0.2, 0], axis=1)
                clear &= not inside.any()
                hidden += int(np.count_nonzero(ray_box_distance(scan.xyz, T, size) < range_m))
            if clear and hidden > best_hidden:
                best, best_hidden = (center, heading, along, size), hidden
        if best is not None:
            return best
    raise ValueError("no free place on the ground for a moving object")


def fov_fault(scan: Scan, cut_deg: float) -> Scan:
    """Scan 2 sees ``cut_deg`` of azimuth less, centred behind it (a sensor mounted against a
    part of its vehicle, or configured to a sector): each lidar's points there dropped (about its
    own origin), its model's azimuth limits set."""
    half = 180.0 - cut_deg / 2
    keep = np.ones(len(scan), dtype=bool)
    for mask, pose, _ in lidar_parts(scan):
        own = in_sensor_frame(scan.xyz[mask], pose)
        keep[mask] = np.abs(np.degrees(np.arctan2(own[:, 1], own[:, 0]))) <= half
    out = scan.subset(keep)
    out.sensor = dataclasses.replace(scan.sensor, azimuth_limits_deg=(-half, half))
    out.lidars = tuple(
        dataclasses.replace(lidar, sensor=dataclasses.replace(lidar.sensor, azimuth_limits_deg=(-half, half)))
        for lidar in scan.lidars
    )
    return out


# --- the case: faults injected, registered, explained ----------------------------------------


def _about_origin2(pair: RegisteredPair, T_err_sensor2: np.ndarray) -> RegisteredPair:
    """Scan 2 placed by ``T_1_2 @ T_err`` instead of ``T_1_2``."""
    T = pair.T_1_2 @ T_err_sensor2
    move = T @ invert_pose(pair.T_1_2)
    return dataclasses.replace(pair, xyz2=apply_pose(move, pair.xyz2), T_1_2=T)


def _rotation_about_axis(axis, angle_deg: float) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(np.radians(angle_deg) * np.asarray(axis) / np.linalg.norm(axis)).as_matrix()
    return T


def faulted_pair(base: BasePair, case: Case) -> RegisteredPair:
    """The base pair with the case's fault, registered by the reference poses."""
    s1, s2 = base.scan1, base.scan2
    m = case.magnitude
    if case.fault in ("range_scale", "range_offset"):
        scale, offset = (1.0 + m, 0.0) if case.fault == "range_scale" else (1.0, m)
        s2 = _with_xyz(s2, in_each_lidar(s2, lambda k, own, mask, model: range_fault(own, scale, offset)))
    elif case.fault == "channel_elevation":  # of the first lidar
        chosen = faulted_channel_mask(s2)

        def one_channel(k, own, mask, model):
            return elevation_fault(own, chosen[mask], m) if k == 0 else own

        s2 = _with_xyz(s2, in_each_lidar(s2, one_channel))
    elif case.fault == "motion_distortion":
        s2 = motion_fault(s2, m)
    elif case.fault == "moving_object":
        center, heading, along, size = object_place(s1, m)
        T_1_2 = invert_pose(s1.pose) @ s2.pose
        s1 = with_box(s1, box_frame(center, heading), size)
        s2 = with_box(s2, box_frame(center + m * along, heading) @ T_1_2, size)
    elif case.fault == "ego_body":
        center, size = EGO_BODIES[m]
        s1, s2 = (with_box(s, box_frame(center), size) for s in (s1, s2))
    elif case.fault == "fov_cut":
        s2 = fov_fault(s2, m)
    pair = register_pair(s1, s2, "truth")
    if case.fault == "translation":
        pair = _about_origin2(
            pair, invert_pose(pair.T_1_2) @ pose_from_xyzrpy([0.8 * m, 0.6 * m, 0, 0, 0, 0]) @ pair.T_1_2
        )
    elif case.fault == "yaw":
        pair = _about_origin2(pair, _rotation_about_axis((0, 0, 1), m))
    elif case.fault == "pitch_roll":
        pair = _about_origin2(pair, _rotation_about_axis((1, 1, 0), m))
    elif case.fault == "time_offset":
        from scipy.spatial.transform import Rotation

        v, w = base.velocity
        dt = m / 1000.0
        T_err = np.eye(4)
        T_err[:3, :3], T_err[:3, 3] = Rotation.from_rotvec(w * dt).as_matrix(), v * dt
        pair = _about_origin2(pair, T_err)
    return pair


def _with_xyz(scan: Scan, xyz: np.ndarray) -> Scan:
    """The scan with its points moved, everything else kept."""
    out = Scan(xyz, dict(scan.attributes), scan.sensor, scan.pose, scan.source, lidars=scan.lidars)
    out.sweep_motion, out.stamp_s = scan.sweep_motion, scan.stamp_s
    return out


@functools.cache
def default_study():
    """The settings ``lidarfield explain`` takes without a config."""
    return validate_config({}, require_pairs=False)


def run_case(case: Case, points: int | None) -> dict:
    """One row of the benchmark's table: the case, what explain proposed and whether it named
    the fault (for a control: proposed nothing beyond ``CONTROL_ALLOWED`` and ended random)."""
    spec, base = bases()[case.base], load_base(case.base, points, case.real_pose)
    start, cpu_start = time.perf_counter(), time.process_time()
    try:
        pair = faulted_pair(base, case)
    except ValueError as e:  # the fault has no place in this pair (a car in a small room)
        return {**case_columns(case, spec), "error": str(e)}
    explanation = explain_with_study(pair, default_study(), case.name)
    seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - cpu_start
    stack = [row["hypothesis"] for row in explanation.steps]
    first = explanation.stages[0].statistics
    return {
        **case_columns(case, spec),
        "error": "",
        "points1": len(pair.xyz1),
        "points2": len(pair.xyz2),
        "verdict0": first["verdict"],
        "p_direction0": float(first["p_direction"]),
        "p_coherence0": float(first["p_coherence"]),
        "voxels_valid0": int(first["voxels_valid"]),
        "voxels_significant0": int(first["voxels_significant"]),
        "rigid_translation_m0": float(np.linalg.norm(first["rigid_translation_m"])),
        "rigid_energy_share0": float(first["rigid_energy_share"]),
        "energy_share_radial0": float(first.get("energy_share_radial", np.nan)),
        "first": stack[0] if stack else "",
        "proposal": proposal(case, explanation.steps, source=spec.source),
        "stack": " > ".join(stack),
        "verdicts": " > ".join(s.statistics["verdict"] for s in explanation.stages),
        "first_displacement_max_m": float(explanation.steps[0]["displacement_max_m"]) if stack else np.nan,
        "verdict_after_first": explanation.stages[1].statistics["verdict"] if stack else "",
        "final_verdict": explanation.verdict,
        "stop": explanation.stop,
        "named": named(case, spec.source, explanation.steps, explanation.verdict),
        "named_strict": named(case, spec.source, explanation.steps, explanation.verdict, strict=True),
        "named_displacement": named(case, spec.source, explanation.steps, explanation.verdict, measure="displacement"),
        "seconds": seconds,
        "cpu_seconds": cpu_seconds,
    }


def case_columns(case: Case, spec: BaseSpec) -> dict:
    return {
        "case": case.name,
        "base": case.base,
        "real_pose": case.real_pose if spec.source == "real" else "truth",
        "source": spec.source,
        "sensor": spec.sensor,
        "kind": spec.kind,
        "fault": case.fault,
        "level": case.level,
        "magnitude": str(case.magnitude),
        "unit": FAULTS[case.fault][0] if case.fault in FAULTS else "",
    }


def within_reference(row: dict, source: str, measure: str = "pose") -> bool:
    """Whether a step is a ``realign`` within the reference pose's own accuracy
    (``REFERENCE_ACCURACY`` for ``measure`` "pose": its fitted translation and angle;
    ``REFERENCE_ACCURACY_M`` for "displacement": the most it moved a point)."""
    if row["hypothesis"] != "realign":
        return False
    if measure == "displacement":
        return row["displacement_max_m"] <= REFERENCE_ACCURACY_M[source]
    fitted = json.loads(row["fitted"] or "{}")
    most_m, most_deg = REFERENCE_ACCURACY[source]
    return float(np.linalg.norm(fitted["translation_m"])) <= most_m and fitted["angle_deg"] <= most_deg


def proposal(case: Case, steps: list[dict], strict: bool = False, source: str = "", measure: str = "pose") -> str:
    """The first proposal ("" for none). Proposals of what the pair holds by construction
    (``CONTROL_ALLOWED``: a real van's own body, the fields of view) and a ``realign`` within
    the reference's accuracy (``within_reference``, given the base pair's ``source``) that
    come before it are passed over, unless ``strict`` or they name the case's fault."""
    passed_over = set() if strict else CONTROL_ALLOWED - NAMING.get(case.fault, set())
    naming = NAMING.get(case.fault, set())

    def counts(row: dict) -> bool:
        if row["hypothesis"] in passed_over:
            return False
        return strict or "realign" in naming or not (source and within_reference(row, source, measure))

    proposals = [row["hypothesis"] for row in steps if counts(row)]
    return proposals[0] if proposals else ""


def named(
    case: Case, source: str, steps: list[dict], final_verdict: str, strict: bool = False, measure: str = "pose"
) -> bool:
    """Whether the first proposal (``proposal``) names the fault. For a control: whether
    nothing was proposed beyond ``CONTROL_ALLOWED`` (or a realign within the reference's
    accuracy) and the field ends random."""
    if case.fault != CONTROL:
        return proposal(case, steps, strict, source, measure) in NAMING[case.fault]
    for row in steps:
        if row["hypothesis"] not in CONTROL_ALLOWED and not within_reference(row, source, measure):
            return False
    return final_verdict == "random"


# The small slice (``bench/diagnosis.py --slice small``): every fault at its visible level and
# the controls, on one real pair and one simulated base of each kind.
SMALL_BASES = ("real-expd-vlp16", "sim-intersection-still-vlp16", "sim-canyon-drive-hdl32", "sim-canyon-apart-os1-128")


def zoo(slice_name: str, real_pose: str = "reference") -> list[Case]:
    """The cases of a slice: ``full`` (every base pair) or ``small``, the real base pairs
    registered as ``real_pose`` says."""
    if slice_name == "full":
        return [case for name in bases() for case in cases_of(name, real_pose)]
    chosen = [name for name in SMALL_BASES if name in bases()]
    return [case for name in chosen for case in cases_of(name, real_pose) if case.level in ("", "visible")]
