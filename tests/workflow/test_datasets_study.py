"""A dataset sequence through the whole workflow: the same study as its scans given as files
with lidar-frame poses; a broken layout stops the run before any job."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from helpers.datasets import write_kitti_layout
from helpers.workflow import snakemake, write_study
from lidarfield.datasets import read_dataset
from lidarfield.io.pose_files import write_kitti_poses

pytestmark = pytest.mark.slow

KITTI = {"format": "kitti", "path": "kitti", "sequence": "07"}


def study(sequences: dict) -> dict:
    return {
        "sequences": sequences,
        "grid": {"azimuth_bins": 18, "elevation_deg": [-25, 12.5], "elevation_bins": 5, "min_points": 5},
        "hypotheses": [{"ego_vehicle": {"radius_m": 8.0}}],
        "plots": {"pairs": "none"},
        "suggest": [{"ego_vehicle": {}}],
    }


def test_a_kitti_sequence_gives_the_summary_of_its_files_with_lidar_poses(tmp_path):
    write_kitti_layout(tmp_path / "kitti")
    dataset = read_dataset(KITTI, tmp_path)
    write_kitti_poses(tmp_path / "lidar_poses.txt", np.array([scan.pose for scan in dataset.scans]))
    files = {"scans": "kitti/sequences/07/velodyne/*.bin", "poses": "lidar_poses.txt", "sensor": "hdl64"}
    write_study(tmp_path, study({"kitti": {"dataset": KITTI}, "files": files}))
    snakemake(tmp_path, "--cores", "2")
    summary = pd.read_parquet(tmp_path / "results" / "summary.parquet")
    assert len(summary) == 12  # 2 sequences x 3 pairs x 2 stages
    kitti = summary[summary.pair.str.startswith("kitti")].reset_index(drop=True)
    from_files = summary[summary.pair.str.startswith("files")].reset_index(drop=True)
    assert (kitti.rms_magnitude > 0).all() and kitti.registration_method.eq("truth").all()
    columns = [c for c in summary.columns if c not in ("pair", "stage")]
    pd.testing.assert_frame_equal(kitti[columns], from_files[columns])


def test_a_broken_dataset_stops_the_run_with_one_line_and_writes_nothing(tmp_path):
    write_kitti_layout(tmp_path / "kitti")
    (tmp_path / "kitti" / "sequences" / "07" / "calib.txt").unlink()
    write_study(tmp_path, study({"kitti": {"dataset": KITTI}}))
    proc = snakemake(tmp_path, "--cores", "2", check=False)
    assert proc.returncode == 2
    errors = [line for line in proc.stderr.splitlines() if "calib.txt" in line]
    assert errors and "calib.txt not found" in errors[0] and "Traceback" not in proc.stderr
    assert not (tmp_path / "results").exists()
