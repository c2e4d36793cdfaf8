"""A study's pairs and scans, resolved from its ``pairs`` and ``sequences`` sections.

Every scan of the study becomes a :class:`ScanSpec` (the JSON spec its simulate or ingest job
reads, hashed into the stage ids) and every pair a :class:`PairSpec`; sequences expand into
consecutive pairs. Files, sensors and registration settings are checked here, so a bad one
fails before any job runs.
"""

from __future__ import annotations

import glob
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ConfigError, LidarfieldError
from ..poses import pose_from_xyzrpy, poses_of_attached_frame, velocities_from_neighbours
from ..scan import still_sweep


@dataclass(frozen=True)
class ScanSpec:
    """One scan of the study: simulated from a scene, or read from a file."""

    id: str  # unique in the study; the scan's file is results/scans/{kind}/{id}.parquet
    kind: str  # "simulated" | "recorded"
    spec: dict  # JSON-able settings of the simulate or ingest job


@dataclass(frozen=True)
class PairSpec:
    name: str
    scan1: ScanSpec
    scan2: ScanSpec
    register: str | dict

    def inputs(self) -> dict:
        """What ``hash_0`` of the pair's stage ids covers."""
        return {"scan1": self.scan1.spec, "scan2": self.scan2.spec, "register": self.register}


def study_pairs(config: dict, base_dir: Path) -> dict[str, PairSpec]:
    """The pairs of a validated config: its ``pairs``, then the pairs of its ``sequences``."""
    pairs: dict[str, PairSpec] = {}
    for name, entry in config["pairs"].items():
        pairs[name] = _pair(name, entry, base_dir)
    for name, entry in config["sequences"].items():
        for pair in _sequence_pairs(name, entry, base_dir):
            if pair.name in pairs:
                raise ConfigError(f"sequences.{name}: pair name {pair.name!r} is also a pair of 'pairs'")
            pairs[pair.name] = pair
    return pairs


def _existing_file(path: str, key: str, base_dir: Path) -> str:
    """A scan reference ``file``, ``file#k`` or ``bag#/topic#k`` whose file (or bag folder) exists."""
    from ..io.rosbag.bag import is_bag_folder

    file = base_dir / path.split("#", 1)[0]
    if not (file.is_file() or is_bag_folder(file)):
        raise ConfigError(f"{key}: file not found: {file}")
    return path


def _sensor(setting, key: str, base_dir: Path):
    """A scan's sensor setting (preset, YAML file, model, or none), checked now so that a bad
    one fails before any job: its model, or None."""
    from ..sensors.models import sensor_model

    if isinstance(setting, str) and setting.endswith((".yaml", ".yml")):
        _existing_file(setting, f"{key}.sensor", base_dir)
        setting = str(base_dir / setting)
    try:
        return sensor_model(setting)
    except LidarfieldError as e:
        raise ConfigError(f"{key}.sensor: {e}") from None


def _register(setting, key: str, base_dir: Path):
    """A pair's ``register`` setting, checked now so that a bad one fails before any job."""
    from ..registration.settings import parse_settings

    if isinstance(setting, dict) and "transform" in setting:
        _existing_file(setting["transform"], f"{key}.register.transform", base_dir)
    try:
        parse_settings(setting, base_dir)
    except LidarfieldError as e:
        raise ConfigError(f"{key}.{e}") from None
    return setting


def _rounded(values) -> list:
    # Specs are hashed into stage ids: rounding keeps trigonometric last-bit noise out of them.
    return np.asarray(values, dtype=float).round(12).tolist()


# The simulator's calibration faults and the values that mean "no fault".
_NO_FAULT = {"range_scale": 1.0, "range_offset_m": 0.0, "elevation_offsets_deg": None}
_PER_SCAN = ("scan1", "scan2")


def _simulated_scan(
    scan_id: str, sim: dict, pose, time_s: float, velocity, angular_velocity, scan: int | None = None
) -> ScanSpec:
    """The spec of one simulated scan; ``scan`` (1 or 2, a pair's) applies the options'
    ``scan1``/``scan2`` faults over their own. A fault that is off stays out of the spec, so a
    config without faults keeps the spec (and the stage ids) it had before they existed."""
    options = {k: v for k, v in sim["options"].items() if k not in _PER_SCAN}
    if scan is not None:
        options.update(sim["options"].get(f"scan{scan}", {}))
    for key, off in _NO_FAULT.items():
        value = options.pop(key, off)
        if key == "elevation_offsets_deg" and value is not None and any(value):
            options[key] = [float(v) for v in value]
        elif key != "elevation_offsets_deg" and value != off:
            options[key] = float(value)
    spec = {
        "scene": sim["scene"],
        "sensor": sim["sensor"],
        "pose": _rounded(pose),
        "time_s": float(time_s),
        "velocity_mps": _rounded(velocity),
        "angular_velocity_rps": _rounded(angular_velocity),
        **options,
    }
    return ScanSpec(scan_id, "simulated", spec)


def recorded_scan_spec(
    path: str,
    format: str | None = None,
    sensor=None,
    pose=None,
    poses: dict | None = None,
    options: dict | None = None,
    stamp_s: float | None = None,
    sweep_motion: dict | None = None,
    lidars: list[dict] | None = None,
) -> dict:
    """The spec of a recorded scan, as the ingest job reads it and stage ids hash it: the one
    place it is built, for a study's pairs and for ``lidarfield run`` (equal inputs, equal ids).
    ``poses`` ({topic, frame}) takes the scan's pose from a topic of its bag when it is read;
    ``options`` are the format reader's (a dataset's sweep: its frame and lidars); ``stamp_s``
    the scan's time where its dataset gives it, ``sweep_motion`` the motion its points carry
    where the dataset says (none: de-skewed), ``lidars`` the rig the config names (resolved by
    :func:`_lidars`). Keys that are not given stay out of the spec."""
    spec = {"path": path, "format": format, "sensor": sensor, "pose": pose}
    if isinstance(poses, dict):
        spec["poses"] = poses
    if options:
        spec["options"] = options
    if stamp_s is not None:
        spec["stamp_s"] = float(stamp_s)
    if sweep_motion is not None:
        spec["sweep_motion"] = sweep_motion
    if lidars:
        spec["lidars"] = lidars
    return spec


def _recorded_scan(scan_id: str, entry: dict, path: str, pose=None, lidars: list[dict] | None = None) -> ScanSpec:
    spec = recorded_scan_spec(path, entry.get("format"), entry.get("sensor"), pose, entry.get("poses"), lidars=lidars)
    return ScanSpec(scan_id, "recorded", spec)


def _lidars(entry: dict, key: str, base_dir: Path) -> list[dict] | None:
    """The rig an entry names (``lidars``), checked and resolved now: each lidar's name, its
    model (as a mapping), its pose in the scan's frame (4x4) and its rings where given."""
    if entry.get("lidars") is None:
        return None
    rig = []
    for k, lidar in enumerate(entry["lidars"]):
        where = f"{key}.lidars[{k}]"
        model = _sensor(lidar["sensor"], where, base_dir)
        item = {
            "name": lidar["name"],
            "sensor": model.to_dict(),
            "pose": _extrinsic(lidar["pose"], f"{where}.pose", base_dir).tolist(),
        }
        if "rings" in lidar:
            first, end = lidar["rings"]
            if not first < end:
                raise ConfigError(f"{where}.rings: [first, end) with first < end, got {lidar['rings']}")
            item["rings"] = [first, end]
        rig.append(item)
    names = [item["name"] for item in rig]
    if len(set(names)) < len(names):
        raise ConfigError(f"{key}.lidars: names must differ, got {names}")
    return rig


def _pair(name: str, entry: dict, base_dir: Path) -> PairSpec:
    key = f"pairs.{name}"
    if "simulate" in entry:
        sim = _checked_simulation(entry["simulate"], f"{key}.simulate", base_dir)
        still = [[0.0, 0.0, 0.0]] * 2
        scans = [
            _simulated_scan(
                f"{name}-{i + 1}",
                sim,
                pose_from_xyzrpy(sim[f"pose{i + 1}"]),
                sim["time_s"][i],
                sim.get("velocity_mps", still)[i],
                sim.get("angular_velocity_rps", still)[i],
                i + 1,
            )
            for i in (0, 1)
        ]
    else:
        _sensor(entry.get("sensor"), key, base_dir)
        rig = _lidars(entry, key, base_dir)
        scans = [
            _recorded_scan(
                f"{name}-{i}", entry, _existing_file(entry[f"scan{i}"], f"{key}.scan{i}", base_dir), lidars=rig
            )
            for i in (1, 2)
        ]
    return PairSpec(name, scans[0], scans[1], _register(entry["register"], key, base_dir))


def _checked_simulation(sim: dict, key: str, base_dir: Path, pair: bool = True) -> dict:
    """A ``simulate`` section whose sensor, scene file (a built-in scene is the schema's
    business) and elevation offsets (one per beam of the sensor) are checked; per-scan faults
    (``options.scan1``/``scan2``) only in a ``pair``."""
    from ..simulation.faults import checked_elevation_offsets

    sensor = _sensor(sim["sensor"], key, base_dir)
    if sim["scene"].endswith((".yaml", ".yml")):
        _existing_file(sim["scene"], f"{key}.scene", base_dir)
    options = sim["options"]
    for name in _PER_SCAN:
        if name in options and not pair:
            raise ConfigError(
                f"{key}.options.{name}: per-scan faults are for a pair's two sensors; a sequence's scans "
                "share one sensor: set its faults in options"
            )
    for where, faults in [("options", options)] + [(f"options.{n}", options[n]) for n in _PER_SCAN if n in options]:
        checked_elevation_offsets(faults.get("elevation_offsets_deg"), sensor, f"{key}.{where}.elevation_offsets_deg")
    return sim


def _sequence_pairs(name: str, entry: dict, base_dir: Path) -> list[PairSpec]:
    key = f"sequences.{name}"
    if "simulate" in entry:
        scans = _simulated_sequence(name, entry, base_dir)
    elif "dataset" in entry:
        scans = _dataset_sequence(name, entry, base_dir)
    else:
        scans = _recorded_sequence(name, entry, base_dir)
    register = _register(entry["register"], key, base_dir)
    stride = entry["stride"]
    return [
        PairSpec(f"{name}-{i:03d}", scans[j], scans[j + stride], register)
        for i, j in enumerate(range(0, len(scans) - stride, stride))
    ]


def _simulated_sequence(name: str, entry: dict, base_dir: Path) -> list[ScanSpec]:
    from ..simulation.trajectory import arc_trajectory

    sim = _checked_simulation(entry["simulate"], f"sequences.{name}.simulate", base_dir, pair=False)
    rate_hz = sim["trajectory"]["rate_hz"]
    # The schema's trajectory keys are arc_trajectory's parameters.
    return [
        _simulated_scan(f"{name}-s{k:03d}", sim, pose, k / rate_hz, velocity, angular_velocity)
        for k, (pose, velocity, angular_velocity) in enumerate(arc_trajectory(**sim["trajectory"]))
    ]


def _recorded_sequence(name: str, entry: dict, base_dir: Path) -> list[ScanSpec]:
    from ..io import scan_count
    from ..io.pose_files import read_kitti_poses

    key = f"sequences.{name}.scans"
    _sensor(entry.get("sensor"), f"sequences.{name}", base_dir)
    scans = entry["scans"]
    if isinstance(scans, list):
        files = [_existing_file(s, key, base_dir) for s in scans]
    elif any(ch in scans for ch in "*?["):
        matches = glob.glob(str(base_dir / scans))  # an absolute pattern stays absolute
        files = sorted(p if Path(scans).is_absolute() else str(Path(p).relative_to(base_dir)) for p in matches)
        if not files:
            raise ConfigError(f"{key}: no file matches {scans!r} (relative to {base_dir})")
    else:
        _existing_file(scans, key, base_dir)
        container = scans if entry.get("topic") is None else f"{scans}#{entry['topic']}"
        files = [f"{container}#{k}" for k in range(scan_count(base_dir / container, sensor=entry.get("sensor")))]
    first, last = _first_last(name, entry, len(files))
    poses = None
    if isinstance(entry.get("poses"), str):
        _existing_file(entry["poses"], f"sequences.{name}.poses", base_dir)
        poses = read_kitti_poses(base_dir / entry["poses"], expected=len(files))
        if entry.get("extrinsic") is not None:
            extrinsic = _extrinsic(entry["extrinsic"], f"sequences.{name}.extrinsic", base_dir)
            poses = poses_of_attached_frame(poses, extrinsic)
    rig = _lidars(entry, f"sequences.{name}", base_dir)
    return [
        _recorded_scan(f"{name}-s{k:03d}", entry, files[k], None if poses is None else poses[k].tolist(), rig)
        for k in range(first, last + 1)
    ]


def _dataset_sequence(name: str, entry: dict, base_dir: Path) -> list[ScanSpec]:
    """The scans of a dataset sequence (:mod:`lidarfield.datasets`), read from its index."""
    from ..datasets import read_dataset

    key = f"sequences.{name}"
    try:
        dataset = read_dataset(entry["dataset"], base_dir)
    except LidarfieldError as e:
        raise type(e)(f"{key}.{e}" if not e.path else str(e)) from None
    sensor = entry.get("sensor") if entry.get("sensor") is not None else dataset.sensor
    _sensor(sensor, key, base_dir)
    rig = _lidars(entry, key, base_dir)
    if rig and any("lidar_poses" in scan.options for scan in dataset.scans):
        raise ConfigError(f"{key}.lidars: {dataset.what} names its lidars itself (its calibration); give none")
    first, last = _first_last(name, entry, len(dataset.scans))
    scans = dataset.scans[first : last + 1]
    motions = _sweep_motions(dataset)[first : last + 1]
    if _needs_poses(entry["register"]) and any(scan.pose is None for scan in scans):
        raise ConfigError(
            f"{key}: register {entry['register']!r} needs the scans' poses, and {dataset.what} has none; "
            "register by scan matching instead (e.g. register: {method: gicp})"
        )
    return [
        ScanSpec(
            f"{name}-s{k:03d}",
            "recorded",
            recorded_scan_spec(
                scan.path,
                scan.format,
                sensor,
                scan.pose,
                None,
                scan.options,
                scan.stamp_s,
                motion,
                rig,
            ),
        )
        for (k, scan), motion in zip(enumerate(scans, start=first), motions)
    ]


def _sweep_motions(dataset) -> list[dict | None]:
    """Each scan's ``sweep_motion`` as the dataset tells it: still for de-skewed sweeps, else the
    constant velocity between its neighbours' poses where the sequence has poses and stamps."""
    if dataset.deskewed:
        return [still_sweep() for _ in dataset.scans]
    if any(scan.pose is None or scan.stamp_s is None for scan in dataset.scans):
        return [None] * len(dataset.scans)
    poses = [np.asarray(scan.pose, dtype=np.float64) for scan in dataset.scans]
    velocities = velocities_from_neighbours([scan.stamp_s for scan in dataset.scans], poses)
    return [
        None
        if velocity is None
        else {
            "velocity_mps": velocity[0].tolist(),
            "angular_velocity_rps": velocity[1].tolist(),
            "source": "neighbours",
        }
        for velocity in velocities
    ]


def _needs_poses(register) -> bool:
    """Whether a register setting uses the scans' poses (truth, or a scan matching guessed from them)."""
    return register == "truth" or isinstance(register, dict) and register.get("guess") == "truth"


def _first_last(name: str, entry: dict, count: int) -> tuple[int, int]:
    """A sequence's ``first`` and ``last`` scans (inclusive), checked against its ``count``."""
    last = count - 1 if entry["last"] is None else entry["last"]
    if not entry["first"] <= last < count:
        raise ConfigError(f"sequences.{name}: first/last ({entry['first']}, {last}) outside the {count} scans")
    return entry["first"], last


def _extrinsic(setting, key: str, base_dir: Path) -> np.ndarray:
    """The lidar's pose in the frame of a sequence's poses: a matrix file, a KITTI calib.txt's
    Tr, or x, y, z, roll, pitch, yaw."""
    from ..datasets.kitti import read_calib
    from ..io.pose_files import read_pose

    if not isinstance(setting, str):
        return pose_from_xyzrpy(setting)
    _existing_file(setting, key, base_dir)
    path = base_dir / setting
    if any(line.lstrip().startswith("Tr:") for line in path.read_text(errors="replace").splitlines()):
        return read_calib(path)
    return read_pose(path)
