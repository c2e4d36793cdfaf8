"""A dataset reader plugin: your own layout as a lidarfield sequence, in a few lines.

The layout: a folder of scans (any format lidarfield reads, here ``.pcd``) and a CSV file
beside them with one row per scan, its time and its pose, world-from-lidar, in the scans' own
frame::

    drive/
      poses.csv           file,stamp_s,x,y,z,qx,qy,qz,qw
      000000.pcd          000000.pcd,1700000000.00,0.0,0.0,3.0,0,0,0,1
      000001.pcd          000001.pcd,1700000000.10,1.0,0.1,3.0,0,0,0.0099998,0.99995
      ...

A study names it with the file and the function (the file relative to the study's folder, the
folder Snakemake runs in) or, once it is importable, with its module::

    sequences:
      mine:
        dataset: {format: "docs/examples/my_reader.py:read", path: data/drive, options: {poses: poses.csv}}
        register: truth

lidarfield calls ``read(settings, base_dir)`` once, when the study is planned: ``settings`` is
the sequence's ``dataset`` section (``format``, ``path``, ``options``), ``base_dir`` the
study's folder. It returns the scans in time order; it reads the index only (the CSV), never
the points: the ingest jobs read those, with the format each scan names. A pose must be the
lidar's, in the frame the scan's points are written in: convert poses of another frame (a
camera, the vehicle) here, ``inv(extrinsic) @ pose @ extrinsic``, or ``register: truth``
registers every pair wrongly.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from lidarfield import ConfigError
from lidarfield.datasets import DatasetScan, DatasetSequence

COLUMNS = ["file", "stamp_s", "x", "y", "z", "qx", "qy", "qz", "qw"]


def read(settings: dict, base_dir: Path) -> DatasetSequence:
    options = settings.get("options", {})
    folder = Path(settings["path"])  # kept relative when it is: the scans' paths then are too
    table = base_dir / folder / options.get("poses", "poses.csv")
    if not table.is_file():
        raise ConfigError("dataset: the poses CSV is not there", table)
    with table.open(newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows or set(COLUMNS) - set(rows[0]):
        raise ConfigError(f"dataset: the poses CSV needs the columns {', '.join(COLUMNS)}", table)
    scans = []
    for row in sorted(rows, key=lambda row: float(row["stamp_s"])):
        if not (base_dir / folder / row["file"]).is_file():
            raise ConfigError(f"dataset: {row['file']} is in the poses CSV and not in the folder", table)
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_quat([float(row[k]) for k in ("qx", "qy", "qz", "qw")]).as_matrix()
        pose[:3, 3] = [float(row[k]) for k in ("x", "y", "z")]
        scans.append(DatasetScan(str(folder / row["file"]), "pcd", pose.tolist(), float(row["stamp_s"])))
    return DatasetSequence(scans, options.get("sensor"), f"the scans of {folder} with {table.name}")
