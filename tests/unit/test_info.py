"""``lidarfield info FILE``: what a bag, a capture or a scan file holds, in one screen."""

from __future__ import annotations

import numpy as np
import pytest

from lidarfield.cli import main
from lidarfield.io.rosbag.writer import CloudMessage, write_bag
from lidarfield.scan import Scan


def info(path, capsys) -> list[str]:
    assert main(["info", str(path)]) == 0
    return capsys.readouterr().out.splitlines()


def test_bag_topics_counts_span_and_fields(tmp_path, capsys):
    pytest.importorskip("rosbags")
    rng = np.random.default_rng(0)
    scans = [Scan(rng.normal(size=(50, 3)) + 5.0) for _ in range(3)]
    clouds = [CloudMessage(s, 1e9 + 0.1 * k) for k, s in enumerate(scans)]
    clouds += [CloudMessage(Scan(rng.normal(size=(9, 3)) + 5), 1e9 + 0.05 * k, topic=f"/aux{k:02d}") for k in range(20)]
    poses = [(1e9 + 0.02 * k, np.eye(4)) for k in range(16)]
    path = write_bag(tmp_path / "drive", clouds, storage="mcap", layout="ouster", poses=poses)
    lines = info(path, capsys)
    assert len(lines) <= 24
    assert (
        lines[0] == f"{path}: ROS 2 bag folder, 39 messages on 22 topics, 2001-09-09 01:46:40.000 UTC .. 2001-09-09 "
        f"01:46:40.950 UTC (0.950 s)"
    )
    assert any(line.split()[:4] == ["/odom", "nav_msgs/Odometry", "16", "poses"] for line in lines)
    assert "  ... and 7 more topics" in lines and "... and 17 more PointCloud2 topics" in lines
    assert (
        f"scans on /points: 3 ({path}#/points#k, k = 0..2), 1 x 50 points of 48 bytes, fields x y z intensity t "
        f"reflectivity ring ambient range" in lines
    )


def test_velodyne_capture_rotations_and_dropped_partial_one(shared_data, capsys):
    pytest.importorskip("velodyne_decoder")
    lines = info(shared_data / "velodyne-pcap" / "sample_velodyne_vlp16_gps.pcap", capsys)
    assert lines[0].endswith("sample_velodyne_vlp16_gps.pcap: Velodyne capture, VLP16, strongest return(s)")
    assert (
        lines[1]
        == "packets: 293 data, 57 other; 3 whole rotation(s) (#0..#2), 65 data packets after the last one (a partial "
        "rotation) not used"
    )
    assert lines[2].startswith("scan #0: 18,790 points (0 invalid rows dropped)")


def test_a_container_and_a_plain_file(expd, capsys):
    lines = info(expd / "signagePCs.mat", capsys)
    assert lines[0].endswith("signagePCs.mat: mat file, 10 scan(s) (#0..#9)")
    assert lines[1].startswith("scan #0: 12,906 points (16,054 invalid rows dropped)")
    lines = info(expd / "Cloud1_ExpD.txt", capsys)
    assert lines[1].startswith("scan: 12,906 points (16,054 invalid rows dropped)")
