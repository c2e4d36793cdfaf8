"""nuScenes (v1.0 tables): ``<path>/<version>/{scene,sample,sample_data,ego_pose,
calibrated_sensor,sensor}.json`` and the lidar files ``<path>/samples/LIDAR_TOP/*.pcd.bin``
(key frames) and ``<path>/sweeps/LIDAR_TOP/*.pcd.bin`` (the sweeps between them).

A scene's scans are the LIDAR_TOP sample_data whose sample belongs to the scene, in time order:
every sweep (``sweeps: true``, the default; nuScenes ties each sweep to its nearest sample, so
the sweeps before a scene's first key frame and after its last are the scene's too) or the key
frames only (``sweeps: false``). The points are in the LIDAR_TOP sensor frame. nuScenes gives
the vehicle's pose (ego_pose: global-from-ego, at the sweep's timestamp) and the lidar's
calibration (calibrated_sensor: ego-from-lidar); each scan's pose is their product,
world-from-lidar. Quaternions are [w, x, y, z]; timestamps integer microseconds, divided
(correctly rounded) into seconds. The lidar is a Velodyne HDL-32E (the ``hdl32`` preset)
spinning at 20 Hz.

Only the tables are read, never the point files (their existence is checked). A full
v1.0-trainval ``sample_data.json`` and ``ego_pose.json`` hold millions of records: they are
decoded once per process, keeping only the LIDAR_TOP records and the ego poses they use, so a
study of several scenes reads them once.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..errors import ConfigError
from ..io.rows import file_key
from ..poses import QUATERNION_TOLERANCE, poses_from_quaternions
from . import DatasetScan, DatasetSequence

SENSOR = "hdl32"
CHANNEL = "LIDAR_TOP"
TABLES = ("scene", "sample", "sample_data", "ego_pose", "calibrated_sensor", "sensor")
_PIECE = 1 << 24  # characters of JSON decoded at a time


def read_index(settings: dict, base_dir: Path) -> DatasetSequence:
    root = Path(settings["path"])
    folder = _version_folder(base_dir / root, settings.get("version"))
    index = lidar_index(folder)
    name = settings.get("scene")
    scene = index.scenes.get(name) if name else None
    if scene is None:
        raise ConfigError(
            f"dataset.scene: no scene {name!r} in {folder / 'scene.json'}; its scenes: {_names(sorted(index.scenes))}"
        )
    sweeps = settings.get("sweeps", True) is not False
    records = [r for r in index.records.get(scene, []) if sweeps or r.key_frame]
    missing = {r.filename for r in records if not (base_dir / root / r.filename).is_file()}
    if missing:
        first = next(r.filename for r in records if r.filename in missing)
        hint = (
            " (no sweep is there: without the sweeps/ folder, use sweeps: false for the key frames only)"
            if not any(r.key_frame for r in records if r.filename in missing)
            else ""
        )
        raise ConfigError(
            f"dataset: {len(missing)} of the {len(records)} lidar files of {name} not found, the first: "
            f"{base_dir / root / first}{hint}"
        )
    scans = [
        DatasetScan(
            str(root / r.filename),
            "nuscenes",
            (_matrix(*index.ego[r.ego_pose], index.ego_table, r.ego_pose) @ index.calibration[r.calibration]).tolist(),
            r.timestamp_us / 1e6,  # correctly rounded; * 1e-6 rounds twice (an ulp, 0.24 us, off)
        )
        for r in records
    ]
    what = f"nuScenes {folder.name} {name}" + (" (key frames)" if not sweeps else "")
    return DatasetSequence(scans, SENSOR, what)


@dataclass(frozen=True)
class LidarRecord:
    """One LIDAR_TOP sample_data."""

    timestamp_us: int
    filename: str
    key_frame: bool
    ego_pose: str  # token
    calibration: str  # calibrated_sensor token


@dataclass(frozen=True)
class LidarIndex:
    """The LIDAR_TOP side of a version folder's tables."""

    scenes: dict[str, str]  # name -> token, in the table's order
    records: dict[str, list[LidarRecord]]  # scene token -> its lidar sample_data, in time order
    ego: dict[str, tuple]  # ego_pose token -> (translation, rotation) of global-from-ego
    ego_table: Path
    calibration: dict[str, np.ndarray]  # calibrated_sensor token -> 4x4 ego-from-lidar


def lidar_index(folder: Path) -> LidarIndex:
    """The LIDAR_TOP records of ``folder``'s tables, read once per process while the files
    are unchanged."""
    paths = {name: folder / f"{name}.json" for name in TABLES}
    for path in paths.values():
        if not path.is_file():
            raise ConfigError("dataset: nuScenes table not found", path)
    return _cached_index(tuple(file_key(paths[name]) for name in TABLES))


@lru_cache(maxsize=2)
def _cached_index(keys: tuple) -> LidarIndex:
    paths = dict(zip(TABLES, (Path(key[0]) for key in keys), strict=True))
    sensor_rows = _fields(paths["sensor"], _load(paths["sensor"]), "token", "channel")
    sensors = {token for token, channel in sensor_rows if channel == CHANNEL}
    if not sensors:
        raise ConfigError(f"dataset: no sensor of channel {CHANNEL}", paths["sensor"])
    calibration = {
        token: _matrix(translation, rotation, paths["calibrated_sensor"], token)
        for token, sensor, translation, rotation in _fields(
            paths["calibrated_sensor"],
            _load(paths["calibrated_sensor"]),
            "token",
            "sensor_token",
            "translation",
            "rotation",
        )
        if sensor in sensors
    }
    scene_rows = _fields(paths["scene"], _load(paths["scene"]), "token", "name")
    scenes = {name: token for token, name in scene_rows}
    sample_scene = dict(_fields(paths["sample"], _load(paths["sample"]), "token", "scene_token"))
    # The big tables: keep the lidar records while decoding, drop the others at once.
    lidar_rows = _load(paths["sample_data"], lambda r: r if r.get("calibrated_sensor_token") in calibration else None)
    columns = ("sample_token", "timestamp", "filename", "is_key_frame", "ego_pose_token", "calibrated_sensor_token")
    records: dict[str, list[LidarRecord]] = {}
    for sample, timestamp, filename, key_frame, ego_pose, calib in _fields(paths["sample_data"], lidar_rows, *columns):
        scene = sample_scene.get(sample)
        if scene is None:
            raise ConfigError(
                f"dataset: lidar file {filename} refers to sample {sample}, not in sample.json", paths["sample_data"]
            )
        if not isinstance(timestamp, int) or not isinstance(filename, str):
            raise ConfigError(
                f"dataset: lidar sample_data {filename!r} at {timestamp!r}: a timestamp (integer, us) and a "
                "filename expected",
                paths["sample_data"],
            )
        records.setdefault(scene, []).append(LidarRecord(timestamp, filename, bool(key_frame), ego_pose, calib))
    needed = {r.ego_pose for rows in records.values() for r in rows}
    ego_rows = _load(paths["ego_pose"], lambda r: r if r.get("token") in needed else None)
    # Matrices for the scene a study reads only: a whole trainval holds 340,000 lidar poses.
    ego = {
        token: (translation, rotation)
        for token, translation, rotation in _fields(paths["ego_pose"], ego_rows, "token", "translation", "rotation")
    }
    absent = needed - set(ego)
    if absent:
        raise ConfigError(
            f"dataset: {len(absent)} ego pose(s) the lidar sample_data refer to are missing, e.g. {min(absent)}",
            paths["ego_pose"],
        )
    for rows in records.values():
        rows.sort(key=lambda r: (r.timestamp_us, r.filename))
    return LidarIndex(scenes, records, ego, paths["ego_pose"], calibration)


def _load(path: Path, keep=None) -> list:
    """A table's records; ``keep(record)`` returning None drops a record while it is decoded.
    A big table filtered so is decoded piece by piece (a gigabyte of JSON would otherwise be
    held twice, as bytes and as text, beside its records)."""
    if keep is not None and path.stat().st_size > _PIECE:
        rows = _load_in_pieces(path, keep)
        if rows is not None:
            return rows
    try:
        with open(path, "rb") as f:
            rows = json.load(f, object_hook=keep)
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ConfigError(f"dataset: not a JSON table: {e}", path) from None
    if not isinstance(rows, list):
        raise ConfigError(f"dataset: a nuScenes table is a JSON list of records, not a {type(rows).__name__}", path)
    return [r for r in rows if r is not None] if keep is not None else rows


def _load_in_pieces(path: Path, keep) -> list | None:
    """The kept records of a JSON list of flat records, decoded in pieces cut after a ``}``;
    None when the file is not such a list (a ``}`` in a string or a nested object cuts a piece
    that does not decode), and the caller decodes it whole, which also says where it is wrong."""
    rows: list = []
    try:
        with open(path, encoding="utf-8") as f:
            rest = f.read(_PIECE).lstrip()
            if not rest.startswith("["):
                return None
            rest = rest[1:]
            while more := f.read(_PIECE):
                rest += more
                cut = rest.rfind("}") + 1
                if cut:
                    rows += _piece(rest[:cut], keep)
                    rest = rest[cut:]
            rest = rest.rstrip()
            if not rest.endswith("]"):
                return None
            rows += _piece(rest[:-1], keep)
    except (json.JSONDecodeError, UnicodeDecodeError):
        return None
    return [r for r in rows if r is not None]


def _piece(text: str, keep) -> list:
    text = text.lstrip()
    text = text[1:] if text.startswith(",") else text
    return json.loads(f"[{text}]", object_hook=keep) if text.strip() else []


def _fields(path: Path, rows: list, *names: str) -> list[tuple]:
    """The ``names`` fields of each record, or a ConfigError naming the table and the field."""
    try:
        return [tuple(r[name] for name in names) for r in rows]
    except KeyError as e:
        raise ConfigError(f"dataset: a record has no field {e.args[0]!r}", path) from None
    except TypeError:
        raise ConfigError("dataset: a record is not a JSON object", path) from None


def _matrix(translation, rotation, path: Path, token: str) -> np.ndarray:
    """4x4 from a translation [x, y, z] and a unit quaternion [w, x, y, z]."""
    try:
        t = np.asarray(translation, dtype=np.float64)
        q = np.asarray(rotation, dtype=np.float64)
    except (TypeError, ValueError):
        t = q = np.zeros(0)
    if t.shape != (3,) or q.shape != (4,) or not (np.isfinite(t).all() and np.isfinite(q).all()):
        raise ConfigError(f"dataset: record {token}: translation [x, y, z] and rotation [w, x, y, z] expected", path)
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUATERNION_TOLERANCE:
        raise ConfigError(f"dataset: record {token}: rotation {q.tolist()} is not a unit quaternion", path)
    return poses_from_quaternions(q, t)[0]


def _version_folder(root: Path, version: str | None) -> Path:
    """``root/version``; without a version, the one version folder there is."""
    if not root.is_dir():
        raise ConfigError("dataset: nuScenes folder not found", root)
    versions = _versions(root)
    if version:
        folder = root / version
        if not folder.is_dir():
            raise ConfigError(
                f"dataset.version: no version folder {version!r}; its versions: {', '.join(versions) or 'none'}", root
            )
        return folder
    if len(versions) != 1:
        raise ConfigError(
            f"dataset.version: which version folder holds the tables? Its versions: {', '.join(versions) or 'none'}",
            root,
        )
    return root / versions[0]


def _versions(root: Path) -> list[str]:
    return sorted(p.name for p in root.iterdir() if (p / "scene.json").is_file())


def _names(names: list[str], shown: int = 12) -> str:
    more = len(names) - shown
    return ", ".join(names[:shown]) + (f", ... ({more} more)" if more > 0 else "") if names else "none"


def describe(path: Path) -> str | None:
    """The version folders of a nuScenes folder and their scenes."""
    if not path.is_dir():
        return None
    versions = _versions(path)
    if not versions:
        return None
    lines = [f"{path}: nuScenes dataset"]
    for version in versions:  # scene.json only: the big tables take seconds
        try:
            scenes = _fields(path / version / "scene.json", _load(path / version / "scene.json"), "name", "nbr_samples")
        except ConfigError as e:
            lines.append(f"  {version}: {e}")
            continue
        samples = sum(int(count) for _, count in scenes)
        lines.append(
            f"  {version}: {len(scenes)} scenes, {samples} key frames: {_names(sorted(name for name, _ in scenes))}"
        )
    return "\n".join(lines)
