"""KITTI odometry folders as sequences: camera-0 poses converted to lidar poses with Tr."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.datasets import KITTI_TR, write_kitti_layout
from lidarfield import ConfigError
from lidarfield.datasets import describe_dataset, read_dataset
from lidarfield.poses import invert_pose, pose_error
from lidarfield.study.config import validate_config


@pytest.fixture(scope="module")
def kitti_folder(tmp_path_factory):
    root = tmp_path_factory.mktemp("kitti") / "dataset"
    _, lidar = write_kitti_layout(root)
    return root, lidar


def test_the_lidar_poses_are_the_simulated_ones(kitti_folder):
    root, lidar = kitti_folder
    sequence = read_dataset({"format": "kitti", "path": str(root), "sequence": "07"})
    assert [scan.format for scan in sequence.scans] == ["bin"] * 4 and sequence.sensor == "hdl64"
    poses = np.array([scan.pose for scan in sequence.scans])
    assert np.abs(poses - lidar).max() < 1e-9
    assert [scan.stamp_s for scan in sequence.scans] == pytest.approx([0.0, 0.1, 0.2, 0.3])


def test_camera_poses_taken_as_lidar_poses_would_move_the_lidar_up(kitti_folder):
    """The trap: KITTI's camera poses used as the lidar's own put the forward motion on z."""
    root, lidar = kitti_folder
    camera = KITTI_TR @ lidar @ np.linalg.inv(KITTI_TR)
    assert abs(camera[3][2, 3]) > 2.5 and abs(lidar[3][2, 3]) < 1e-9  # 3 m forward: camera z, lidar x
    translation_error, _ = pose_error(invert_pose(camera[0]) @ camera[3], invert_pose(lidar[0]) @ lidar[3])
    assert translation_error > 1.0


def test_a_study_registers_the_dataset_by_truth_within_1e_9(kitti_folder, tmp_path):
    root, lidar = kitti_folder
    study = validate_config({"sequences": {"k": {"dataset": {"format": "kitti", "path": str(root), "sequence": "07"}}}})
    assert sorted(study.pairs) == ["k-000", "k-001", "k-002"]
    from lidarfield.commands.jobs import recorded_scan
    from lidarfield.registration import register_pair

    pair = study.pairs["k-001"]
    registered = register_pair(recorded_scan(pair.scan1.spec), recorded_scan(pair.scan2.spec), pair.register)
    expected = invert_pose(lidar[1]) @ lidar[2]
    assert np.abs(registered.T_1_2 - expected).max() < 1e-9
    assert pair.scan1.spec["sensor"] == "hdl64" and pair.scan1.spec["stamp_s"] == pytest.approx(0.1)
    # KITTI's sweeps are de-skewed: deskew leaves them alone (their record, not the stamps' motion)
    from lidarfield.hypotheses import apply_step

    left = apply_step(registered, {"deskew": {}})
    assert left.xyz1 is None and left.xyz2 is None and left.fitted["cloud1"]["motion_source"] == "record"


def test_the_same_scans_as_files_with_lidar_poses_plan_the_same_jobs(kitti_folder, tmp_path):
    """A dataset sequence is the files-and-poses sequence it stands for (same specs, same ids)."""
    from lidarfield.io.pose_files import write_kitti_poses

    root, lidar = kitti_folder
    dataset = read_dataset({"format": "kitti", "path": str(root), "sequence": "07"})
    poses_file = tmp_path / "lidar_poses.txt"
    write_kitti_poses(poses_file, np.array([scan.pose for scan in dataset.scans]))
    scans = str(root / "sequences" / "07" / "velodyne" / "*.bin")
    as_dataset = validate_config(
        {"sequences": {"s": {"dataset": {"format": "kitti", "path": str(root), "sequence": "07"}}}}
    )
    as_files = validate_config({"sequences": {"s": {"scans": scans, "poses": str(poses_file), "sensor": "hdl64"}}})
    for name in as_files.pairs:
        for k in ("scan1", "scan2"):
            a, b = getattr(as_dataset.pairs[name], k).spec, getattr(as_files.pairs[name], k).spec
            # what the dataset knows beyond the files: the stamps, and that its sweeps are de-skewed
            assert a["sweep_motion"] == {"velocity_mps": [0.0] * 3, "angular_velocity_rps": [0.0] * 3}
            assert {**a, "stamp_s": None, "format": None, "sweep_motion": None} == {
                **b,
                "stamp_s": None,
                "sweep_motion": None,
            }
            assert np.abs(np.array(a["pose"]) - np.array(b["pose"])).max() < 1e-12


def test_camera_poses_with_the_extrinsic_give_the_lidar_poses(kitti_folder):
    root, lidar = kitti_folder
    folder = root / "sequences" / "07"
    entry = {"scans": str(folder / "velodyne" / "*.bin"), "poses": str(root / "poses" / "07.txt")}
    plain = validate_config({"sequences": {"s": entry}})
    converted = validate_config({"sequences": {"s": {**entry, "extrinsic": str(folder / "calib.txt")}}})
    pose = np.array(converted.pairs["s-001"].scan2.spec["pose"])
    assert np.abs(pose - lidar[2]).max() < 1e-9
    assert np.abs(np.array(plain.pairs["s-001"].scan2.spec["pose"]) - lidar[2]).max() > 0.5


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda root: (root / "sequences" / "07" / "calib.txt").unlink(), "calib.txt not found"),
        (lambda root: (root / "sequences" / "07" / "calib.txt").write_text("P0: 1 2 3\n"), "no Tr line"),
        (lambda root: (root / "sequences" / "07" / "calib.txt").write_text("Tr: 1 2 3\n"), "Tr holds 3 numbers"),
        (lambda root: (root / "poses" / "07.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n"), "holds 1 poses for 4 scans"),
        (lambda root: (root / "sequences" / "07" / "times.txt").write_text("0\n0.1\n"), "2 times for 4 scans"),
    ],
)
def test_a_broken_layout_names_the_file_and_the_problem(tmp_path, change, message):
    root = tmp_path / "dataset"
    write_kitti_layout(root)
    change(root)
    with pytest.raises(ConfigError, match=message):
        validate_config({"sequences": {"k": {"dataset": {"format": "kitti", "path": str(root), "sequence": "07"}}}})


def test_an_unknown_sequence_lists_the_sequences_there(kitti_folder):
    root, _ = kitti_folder
    with pytest.raises(ConfigError, match=r"no sequence '7'.*its sequences: 07"):
        validate_config({"sequences": {"k": {"dataset": {"format": "kitti", "path": str(root), "sequence": "7"}}}})


def test_a_sequence_without_poses_reads_and_truth_says_it_needs_them(tmp_path):
    root = tmp_path / "dataset"
    write_kitti_layout(root, sequence="11", with_poses=False)
    dataset = {"format": "kitti", "path": str(root), "sequence": "11"}
    assert all(scan.pose is None for scan in read_dataset(dataset).scans)
    with pytest.raises(ConfigError, match="register 'truth' needs the scans' poses"):
        validate_config({"sequences": {"k": {"dataset": dataset}}})
    study = validate_config({"sequences": {"k": {"dataset": dataset, "register": {"method": "gicp"}}}})
    assert len(study.pairs) == 3


def test_info_describes_the_folder(kitti_folder):
    root, _ = kitti_folder
    assert describe_dataset(root) == f"{root}: KITTI odometry dataset\n  sequence 07: 4 scans, 0.3 s, poses"
