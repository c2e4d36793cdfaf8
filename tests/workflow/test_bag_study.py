"""A bag holding two real scans and their odometry gives the same fields as the same scans read
from files with their poses in a KITTI file: through ``lidarfield run`` and through a sequence
study with ``register: truth`` (its ingest jobs here; the whole workflow in the slow test)."""

from __future__ import annotations

import copy
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from helpers.workflow import workflow_command
from lidarfield.cli import main
from lidarfield.commands.jobs import scan_job
from lidarfield.io import read_scan
from lidarfield.io.pose_files import read_kitti_poses
from lidarfield.io.rosbag.writer import CloudMessage, write_bag
from lidarfield.study.config import load_config, validate_config

pytest.importorskip("rosbags")

OUSTER = "ouster-os1-128"
STAMPS = (1700000000.05, 1700000000.15)
STUDY = {
    "grid": {"azimuth_bins": 36, "elevation_deg": [-22.5, 22.5], "elevation_bins": 6, "min_points": 30},
    "hypotheses": [{"ego_vehicle": {"radius_m": 3.0}}],
}


@pytest.fixture(scope="module")
def recording(shared_data, tmp_path_factory):
    """(bag, the two .bin scan files, their KITTI poses file): the same scans and poses."""
    folder = shared_data / OUSTER
    files = [folder / f"lb_n3_scan{k}_xyz_refl_float32.bin" for k in range(2)]
    kitti = folder / "OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt"
    poses = read_kitti_poses(kitti)
    # Odometry at 20 Hz around the scans: samples at the scan stamps hold the KITTI poses.
    odometry = [
        (STAMPS[0] - 0.05, poses[0]),
        (STAMPS[0], poses[0]),
        (STAMPS[1], poses[1]),
        (STAMPS[1] + 0.05, poses[1]),
    ]
    clouds = [CloudMessage(read_scan(f), stamp) for f, stamp in zip(files, STAMPS)]
    bag = write_bag(tmp_path_factory.mktemp("bag") / "drive.bag", clouds, poses=odometry)
    return bag, files, kitti


def fields(folder: Path, stages: list[str] | None = None) -> list[pd.DataFrame]:
    stages = list(pd.read_parquet(folder / "summary.parquet")["stage"]) if stages is None else stages
    return [pd.read_parquet(folder / "stages" / stage / "field.parquet") for stage in stages]


def assert_same_fields(a: list[pd.DataFrame], b: list[pd.DataFrame]) -> None:
    assert len(a) == len(b) == 2
    for fa, fb in zip(a, b):
        assert fa["valid"].sum() > 20  # a real field, not an empty one
        pd.testing.assert_frame_equal(fa, fb)


def study_config(tmp_path: Path, recording) -> Path:
    bag, files, kitti = recording
    config = {
        **STUDY,
        "sequences": {
            "bag": {"scans": str(bag), "poses": {"topic": "/odom"}, "sensor": "os1-128", "register": "truth"},
            "files": {"scans": [str(f) for f in files], "poses": str(kitti), "sensor": "os1-128", "register": "truth"},
        },
    }
    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump(config))
    return path


def run(tmp_path: Path, config: Path, name: str, scans, *options) -> Path:
    out = tmp_path / name
    argv = [
        "run",
        *map(str, scans),
        "--config",
        str(config),
        "--out",
        str(out),
        "--register",
        "truth",
        "--sensor",
        "os1-128",
    ]
    assert main([*argv, *options]) == 0
    return out


@pytest.fixture(scope="module")
def bag_run(recording, tmp_path_factory) -> Path:
    """``lidarfield run`` on the bag's two scans with its odometry: both tests compare it (with
    the run on the files, with the workflow's sequence from the bag)."""
    folder = tmp_path_factory.mktemp("bag-run")
    bag = recording[0]
    return run(folder, study_config(folder, recording), "bag-run", [f"{bag}#0", f"{bag}#1"], "--poses", "/odom")


def test_run_on_a_bag_equals_the_sequence_study_of_files_and_kitti_poses(tmp_path, recording, bag_run):
    config = study_config(tmp_path, recording)
    study = load_config(config)
    # The study's ingest jobs: each sequence's scans with their poses, as the workflow writes them.
    ingested = {}
    for name in ("bag", "files"):
        pair = study.pairs[f"{name}-000"]
        for k, spec in enumerate((pair.scan1, pair.scan2)):
            scan_job("recorded", spec.spec, tmp_path / name / f"scan{k}.parquet")
        ingested[name] = [read_scan(tmp_path / name / f"scan{k}.parquet") for k in range(2)]
    for from_bag, from_files in zip(ingested["bag"], ingested["files"]):
        np.testing.assert_array_equal(from_bag.xyz, from_files.xyz)
        np.testing.assert_allclose(from_bag.pose, from_files.pose, atol=1e-12)
    assert ingested["bag"][1].stamp_s == pytest.approx(STAMPS[1])

    from_files = run(tmp_path, config, "files-run", [tmp_path / "files" / f"scan{k}.parquet" for k in range(2)])
    assert_same_fields(fields(bag_run), fields(from_files))
    # And the poses did matter: without them the pair is registered by identity.
    translation = np.linalg.norm(ingested["files"][1].pose[:3, 3] - ingested["files"][0].pose[:3, 3])
    assert translation > 0.1


@pytest.mark.slow
def test_workflow_sequence_from_a_bag_equals_files_with_kitti_poses(tmp_path, recording, bag_run):
    import subprocess

    config = study_config(tmp_path, recording)
    study, results = load_config(config, base_dir=tmp_path), tmp_path / "results"
    targets = [
        f"results/{pair}/stages/{stage}/field.parquet" for pair in study.pairs for stage in study.stage_ids(pair)
    ]
    proc = subprocess.run(
        [*workflow_command(tmp_path, config), "--cores", "2", *targets],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    from_bag = fields(results / "bag-000", study.stage_ids("bag-000"))
    assert_same_fields(from_bag, fields(results / "files-000", study.stage_ids("files-000")))
    assert_same_fields(fields(bag_run), from_bag)


@pytest.mark.parametrize(
    "reference, options, message",
    [
        (
            "{bag}#/velodyne_points#0",
            [],
            r"drive.bag: topic /velodyne_points is not in the bag; its topics: /odom \(nav_msgs/Odometry, 4\), /points",
        ),
        ("{bag}#0", ["--poses", "/gps"], r"drive.bag: pose topic /gps is not in the bag; its topics: /odom, /points"),
        ("{bag}#5", [], r"drive.bag: scan #5 requested but the file holds 2 scan\(s\)"),
    ],
)
def test_bad_bag_input_is_one_line_exit_2_and_no_output(tmp_path, recording, capsys, reference, options, message):
    bag = recording[0]
    config = study_config(tmp_path, recording)
    out = tmp_path / "out"
    argv = [
        "run",
        reference.format(bag=bag),
        f"{bag}#1",
        "--config",
        str(config),
        "--out",
        str(out),
        "--register",
        "truth",
    ]
    assert main([*argv, *options]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1
    assert re.search(message, error), error
    assert not out.exists()


def test_sequences_from_a_bag_topic_and_a_capture(tmp_path, expd, shared_data):
    from lidarfield.errors import InputError
    from lidarfield.io.rosbag.writer import CloudMessage
    from lidarfield.scan import Scan

    scan = Scan(read_scan(expd / "Cloud1_ExpD.txt").xyz[:500])
    clouds = [CloudMessage(scan, 1.0 + 0.1 * k, topic="/rear") for k in range(5)] + [
        CloudMessage(scan, 1.0, topic="/front")
    ]
    bag = write_bag(tmp_path / "two_lidars", clouds, storage="mcap")
    capture = shared_data / "velodyne-pcap" / "sample_velodyne_vlp16_gps.pcap"
    config = {
        "sequences": {
            "rear": {"scans": str(bag), "topic": "/rear", "first": 1, "stride": 2, "register": "identity"},
            "spin": {"scans": str(capture), "register": "identity"},
        }
    }
    study = validate_config(copy.deepcopy(config), tmp_path)
    assert [(p.scan1.spec["path"], p.scan2.spec["path"]) for n, p in study.pairs.items() if n.startswith("rear")] == [
        (f"{bag}#/rear#1", f"{bag}#/rear#3"),
    ]
    assert [p.scan2.spec["path"] for n, p in study.pairs.items() if n.startswith("spin")] == [
        f"{capture}#1",
        f"{capture}#2",
    ]
    del config["sequences"]["rear"]["topic"]
    with pytest.raises(
        InputError,
        match=r"two_lidars: the bag holds 2 PointCloud2 topics: .*or topic: in a sequence\); topics: /front .*, /rear",
    ):
        validate_config(config, tmp_path)
