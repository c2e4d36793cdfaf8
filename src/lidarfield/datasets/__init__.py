"""Public driving datasets as scan sequences: a dataset folder and a sequence in, its scans out,
in time order, each with its file, the format that reads it, its pose in the lidar's frame and
its time.

A study names one in a sequence (``dataset: {format: kitti, path: ..., sequence: "07"}``).
Reading a dataset here reads its index only (file listings, pose and calibration tables), never
the points: planning a study of a thousand scans costs what listing a thousand files costs, and
the ingest jobs read the points. Each format module provides ``read_index(settings, base_dir)
-> DatasetSequence`` and ``describe(path) -> str | None`` (what ``lidarfield info`` prints of a
folder of its layout; None for a folder that is not one). Your own layout is a reader plugin:
``format: "mypkg.module:reader"`` or ``format: "readers/mine.py:reader"`` (a file relative to
the study's folder), a function with the signature of ``read_index``.

Poses: every pose a dataset gives is converted here to the scan's own frame (the frame its
points are written in), world-from-lidar, so that ``register: truth`` is right; datasets keep
them in other frames (KITTI odometry: the left camera's; nuScenes: the vehicle's; Argoverse 2:
the vehicle's), which, used as they are, register every pair wrongly without a word.
"""

from __future__ import annotations

import importlib
import importlib.util
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ConfigError, LidarfieldError

# format name -> module of this package
FORMATS = {"kitti": "kitti", "av2": "av2", "nuscenes": "nuscenes"}


@dataclass(frozen=True)
class DatasetScan:
    """One scan of a dataset sequence, as its ingest job reads it."""

    path: str  # the scan's file, relative to the study's folder when the dataset path is
    format: str  # the lidarfield scan format that reads it (see lidarfield.io.FORMATS)
    pose: list | None = None  # 4x4 world-from-lidar in the scan's own frame, None when unknown
    stamp_s: float | None = None  # when it was taken, seconds
    options: dict = field(default_factory=dict)  # the format reader's options (av2: frame, lidars)


@dataclass(frozen=True)
class DatasetSequence:
    """The scans of one sequence, in time order, and the sensor they were taken with."""

    scans: list[DatasetScan]
    sensor: str | dict | None = None  # the default sensor model (a preset name or a model dict)
    what: str = ""  # one line for messages: "KITTI odometry sequence 07"
    # The dataset's sweeps are already motion-compensated (KITTI odometry, Argoverse 2): their
    # scans record no motion (``Scan.sweep_motion`` zero), so ``deskew`` leaves them alone.
    deskewed: bool = False


def read_dataset(settings: dict, base_dir: str | Path = ".") -> DatasetSequence:
    """The scans of the dataset sequence ``settings`` (a sequence's ``dataset`` section) names;
    a ConfigError naming the file and the problem when the layout is not as it should be."""
    base_dir = Path(base_dir)
    reader = _reader(settings["format"], base_dir)
    sequence = reader(settings, base_dir)
    if not sequence.scans:
        raise ConfigError(f"dataset: {sequence.what or settings['format']} holds no scans")
    return sequence


def describe_dataset(path: str | Path) -> str | None:
    """What a dataset folder holds (``lidarfield info``); None when ``path`` is no dataset's."""
    for module in FORMATS.values():
        text = importlib.import_module(f".{module}", __name__).describe(Path(path))
        if text is not None:
            return text
    return None


def _reader(name: str, base_dir: Path):
    if name in FORMATS:
        return importlib.import_module(f".{FORMATS[name]}", __name__).read_index
    if ":" not in name:
        raise ConfigError(
            f"dataset.format: unknown format {name!r}; known: {', '.join(FORMATS)}, or a reader plugin "
            "'package.module:function' / 'file.py:function'"
        )
    where, function = name.rsplit(":", 1)
    if where.endswith(".py"):
        path = base_dir / where
        if not path.is_file():
            raise ConfigError(f"dataset.format: reader plugin file not found: {path}")
        spec = importlib.util.spec_from_file_location(f"lidarfield_dataset_reader_{path.stem}", path)
        module = importlib.util.module_from_spec(spec)
        try:
            spec.loader.exec_module(module)
        except Exception as e:  # the plugin's own code: any error, reported with its file
            raise ConfigError(f"dataset.format: reader plugin {path} failed to load: {type(e).__name__}: {e}") from None
    else:
        try:
            module = importlib.import_module(where)
        except ImportError as e:
            raise ConfigError(f"dataset.format: cannot import the reader plugin's module {where!r}: {e}") from None
    reader = getattr(module, function, None)
    if not callable(reader):
        raise ConfigError(f"dataset.format: the reader plugin {where!r} has no function {function!r}")
    return _checked_plugin(reader, name)


def _checked_plugin(reader, name: str):
    def read_index(settings: dict, base_dir: Path) -> DatasetSequence:
        try:
            sequence = reader(settings, base_dir)
        except LidarfieldError:
            raise  # the plugin's own message, naming its file
        except Exception as e:  # the plugin's own code: any error, reported with its name
            raise ConfigError(f"dataset.format: the reader plugin {name} failed: {type(e).__name__}: {e}") from None
        if not isinstance(sequence, DatasetSequence):
            scans = list(sequence) if isinstance(sequence, (list, tuple)) else None
            if scans is None or not all(isinstance(s, DatasetScan) for s in scans):
                raise ConfigError(
                    f"dataset.format: the reader plugin {name} returned {type(sequence).__name__}, "
                    "not a DatasetSequence (or a list of DatasetScan)"
                )
            sequence = DatasetSequence(scans, None, name)
        wrong = next((s for s in sequence.scans if not isinstance(s, DatasetScan)), None)
        if wrong is not None:
            raise ConfigError(
                f"dataset.format: the reader plugin {name} returned a scan of type {type(wrong).__name__}, "
                "not a DatasetScan"
            )
        for scan in sequence.scans:
            if scan.pose is not None and np.shape(scan.pose) != (4, 4):
                raise ConfigError(
                    f"dataset.format: the reader plugin {name} gave {scan.path} a pose of shape "
                    f"{np.shape(scan.pose)}, not 4x4 (world-from-lidar)"
                )
        return sequence

    return read_index
