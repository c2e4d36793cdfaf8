"""``lidarfield info`` on a dataset folder: its sequences, scans, time spans and poses; a folder
that is no dataset's says which folders are read."""

from __future__ import annotations

import subprocess
import sys

import pytest

from helpers.datasets import write_kitti_layout
from lidarfield import InputError
from lidarfield.cli import main
from lidarfield.cli.info import describe_path


@pytest.fixture(scope="module")
def kitti_root(tmp_path_factory):
    """A KITTI odometry folder of two sequences: 07 with poses, 11 without (as 11-21 are)."""
    root = tmp_path_factory.mktemp("kitti") / "dataset"
    write_kitti_layout(root, sequence="07")
    write_kitti_layout(root, sequence="11", with_poses=False)
    return root


def test_info_on_a_kitti_folder_lists_its_sequences(kitti_root, capsys):
    assert main(["info", str(kitti_root)]) == 0
    assert capsys.readouterr().out.splitlines() == [
        f"{kitti_root}: KITTI odometry dataset",
        "  sequence 07: 4 scans, 0.3 s, poses",
        "  sequence 11: 4 scans, 0.3 s, no poses",
    ]


def test_info_names_what_a_sequence_lacks(tmp_path):
    root = tmp_path / "dataset"
    write_kitti_layout(root)
    (root / "sequences" / "07" / "calib.txt").unlink()
    (root / "sequences" / "07" / "times.txt").unlink()
    assert describe_path(root).splitlines()[1] == "  sequence 07: 4 scans, poses, no calib.txt"


def test_a_scan_file_inside_the_dataset_is_still_a_scan_file(kitti_root):
    text = describe_path(kitti_root / "sequences" / "07" / "velodyne" / "000000.bin")
    assert text.splitlines()[0].endswith("000000.bin: bin file, 1 scan(s)")


def test_a_folder_that_is_no_dataset_says_which_folders_are_read(tmp_path, capsys):
    folder = tmp_path / "just-a-folder"
    folder.mkdir()
    (folder / "notes.txt").write_text("nothing here\n")
    with pytest.raises(InputError, match=r"just-a-folder: a folder that is no dataset lidarfield reads \(KITTI"):
        describe_path(folder)
    assert main(["info", str(folder)]) == 2
    assert "no ROS 2 bag" in capsys.readouterr().err


def test_describing_a_file_does_not_import_the_datasets():
    """lidarfield.io must not depend on lidarfield.datasets: the dataset readers build on io."""
    code = "import sys, lidarfield.io.describe, lidarfield.cli.info; print('lidarfield.datasets' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout == "False\n"
