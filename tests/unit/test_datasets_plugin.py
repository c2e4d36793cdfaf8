"""Reader plugins: the documented example (docs/examples/my_reader.py) as 'file.py:function'
and as 'module:function', and the errors of a plugin that is missing, broken or wrong."""

from __future__ import annotations

import shutil
import sys

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import ROOT
from helpers.datasets import simulated_drive
from lidarfield import ConfigError, write_scan
from lidarfield.study.config import validate_config

EXAMPLE = ROOT / "docs" / "examples" / "my_reader.py"
STAMPS = [100.0, 100.1, 100.2, 100.3]


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """A folder of .pcd scans and a poses CSV (rows out of time order), the layout of the example."""
    base = tmp_path_factory.mktemp("study")
    scans, poses = simulated_drive()
    folder = base / "data" / "drive"
    folder.mkdir(parents=True)
    rows = ["file,stamp_s,x,y,z,qx,qy,qz,qw"]
    for k, (scan, pose) in enumerate(zip(scans, poses)):
        write_scan(scan, folder / f"{k:06d}.pcd")
        q = Rotation.from_matrix(pose[:3, :3]).as_quat()
        rows.append(",".join([f"{k:06d}.pcd", f"{STAMPS[k]}", *(repr(float(v)) for v in (*pose[:3, 3], *q))]))
    (folder / "poses.csv").write_text("\n".join([rows[0], *reversed(rows[1:])]) + "\n")
    (base / "readers").mkdir()
    shutil.copy(EXAMPLE, base / "readers" / "my_reader.py")
    return base, poses


def study(base, format: str, **dataset):
    entry = {"dataset": {"format": format, "path": "data/drive", "options": {"sensor": "vlp16"}, **dataset}}
    return validate_config({"sequences": {"mine": entry}}, base_dir=base)


def check_poses_and_times(planned, poses) -> None:
    assert sorted(planned.pairs) == ["mine-000", "mine-001", "mine-002"]
    specs = [planned.pairs[f"mine-{k:03d}"].scan1.spec for k in range(3)] + [planned.pairs["mine-002"].scan2.spec]
    assert [spec["path"] for spec in specs] == [f"data/drive/{k:06d}.pcd" for k in range(4)]
    assert all(spec["format"] == "pcd" and spec["sensor"] == "vlp16" for spec in specs)
    assert [spec["stamp_s"] for spec in specs] == pytest.approx(STAMPS)
    assert np.abs(np.array([spec["pose"] for spec in specs]) - poses).max() < 1e-12


def test_the_example_as_a_file_relative_to_the_study(drive):
    base, poses = drive
    check_poses_and_times(study(base, "readers/my_reader.py:read"), poses)


def test_the_example_as_a_module_on_the_path(drive, monkeypatch):
    base, poses = drive
    monkeypatch.syspath_prepend(str(EXAMPLE.parent))
    monkeypatch.delitem(sys.modules, "my_reader", raising=False)
    check_poses_and_times(study(base, "my_reader:read"), poses)


def test_the_example_registers_by_truth(drive):
    from lidarfield.commands.jobs import recorded_scan
    from lidarfield.registration import register_pair

    base, poses = drive
    pair = study(base, "readers/my_reader.py:read").pairs["mine-001"]
    scans = [recorded_scan({**s.spec, "path": str(base / s.spec["path"])}) for s in (pair.scan1, pair.scan2)]
    registered = register_pair(*scans, pair.register)
    assert np.abs(registered.T_1_2 - np.linalg.inv(poses[1]) @ poses[2]).max() < 1e-9


def test_the_example_names_a_missing_csv(drive):
    base, _ = drive
    with pytest.raises(ConfigError, match=r"other\.csv: dataset: the poses CSV is not there"):
        study(base, "readers/my_reader.py:read", options={"poses": "other.csv"})


PLUGINS = {
    "raises.py": "def read(settings, base_dir):\n    raise KeyError('lidar_top')\n",
    "wrong_type.py": "def read(settings, base_dir):\n    return {'scans': []}\n",
    "wrong_scan.py": "def read(settings, base_dir):\n    return [{'path': 'a.pcd'}, {'path': 'b.pcd'}]\n",
    "bad_pose.py": (
        "from lidarfield.datasets import DatasetScan, DatasetSequence\n"
        "def read(settings, base_dir):\n"
        "    return DatasetSequence([DatasetScan(f'{k}.pcd', 'pcd', [[1, 0, 0, 0]]) for k in range(2)])\n"
    ),
    "broken.py": "import numpy as np\nnp.this_is_not_there\n",
}


@pytest.mark.parametrize(
    ("format", "message"),
    [
        ("readers/nowhere.py:read", r"reader plugin file not found: .*readers/nowhere\.py"),
        ("readers/raises.py:nope", r"the reader plugin 'readers/raises\.py' has no function 'nope'"),
        ("no_such_module_here:read", r"cannot import the reader plugin's module 'no_such_module_here'"),
        ("readers/broken.py:read", r"reader plugin .*broken\.py failed to load: AttributeError"),
        ("readers/raises.py:read", r"the reader plugin readers/raises\.py:read failed: KeyError: 'lidar_top'"),
        ("readers/wrong_type.py:read", r"readers/wrong_type\.py:read returned dict, not a DatasetSequence"),
        ("readers/wrong_scan.py:read", r"readers/wrong_scan\.py:read returned list, not a DatasetSequence"),
        ("readers/bad_pose.py:read", r"gave 0\.pcd a pose of shape \(1, 4\), not 4x4"),
        ("kitty", r"unknown format 'kitty'; known: kitti, av2, nuscenes"),
    ],
)
def test_a_plugin_that_cannot_be_used_names_the_problem(tmp_path, format, message):
    (tmp_path / "readers").mkdir()
    for name, text in PLUGINS.items():
        (tmp_path / "readers" / name).write_text(text)
    with pytest.raises(ConfigError, match=message) as error:
        validate_config({"sequences": {"mine": {"dataset": {"format": format, "path": "x"}}}}, base_dir=tmp_path)
    assert "sequences.mine.dataset.format: " in str(error.value)
