"""config/kitti.yaml, the KITTI example study, is valid once its placeholder path is a KITTI
odometry folder (the test's own simulated one)."""

from __future__ import annotations

from conftest import ROOT
from helpers.datasets import write_kitti_layout
from lidarfield.study.config import validate_config
from lidarfield.yaml_file import read_yaml


def test_the_kitti_example_plans_its_pairs(tmp_path):
    write_kitti_layout(tmp_path / "dataset")
    config = read_yaml(ROOT / "config" / "kitti.yaml", "config")
    dataset = config["sequences"]["kitti-07"]["dataset"]
    assert dataset == {"format": "kitti", "path": "/data/kitti/dataset", "sequence": "07"}
    dataset["path"] = str(tmp_path / "dataset")
    config["sequences"]["kitti-07"]["last"] = 3  # the test's layout holds 4 scans
    study = validate_config(config, base_dir=ROOT)
    assert sorted(study.pairs) == ["kitti-07-000", "kitti-07-001", "kitti-07-002"]
    assert len(study.config["hypotheses"]) == 3 and study.pairs["kitti-07-000"].scan1.spec["sensor"] == "hdl64"
