"""``lidarfield simulate``: the scan file it writes, and one clear line for bad input."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from lidarfield.cli import main
from lidarfield.io import read_scan
from lidarfield.poses import pose_from_xyzrpy as pose_from_values
from lidarfield.sensors.models import PRESETS

BASE = ["simulate", "--scene", "paper-intersection", "--sensor", "vlp16"]


def test_simulate_writes_a_scan_with_sensor_and_pose(tmp_path, capsys):
    out = tmp_path / "scan.parquet"
    code = main(
        [
            *BASE,
            "--pose=-1,0.5,3,0,0,0.05",
            "--out",
            str(out),
            "--range-noise",
            "0.01",
            "--seed",
            "2",
            "--rolling-shutter",
            "--velocity",
            "1,0,0",
            "--angular-velocity",
            "0,0,0.1",
        ]
    )
    assert code == 0
    scan = read_scan(out)
    assert f"{len(scan)} points" in capsys.readouterr().out
    assert 5000 < len(scan) < 30000
    assert scan.sensor == PRESETS["vlp16"]
    assert np.allclose(scan.pose, pose_from_values([-1, 0.5, 3, 0, 0, 0.05]))
    assert set(scan.attributes) >= {"ring", "time"} and "rolling_shutter" in scan.source


def _fails(args, tmp_path, capsys, *expected):
    out = tmp_path / "out.parquet"
    assert main([*args, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    for text in expected:
        assert text in err
    assert not out.exists() and not list(tmp_path.glob("*.parquet*"))


def test_unknown_scene_lists_the_builtins(tmp_path, capsys):
    _fails(
        ["simulate", "--scene", "mall", "--sensor", "vlp16", "--pose", "0,0,3,0,0,0"],
        tmp_path,
        capsys,
        "unknown scene 'mall'",
        "paper-intersection",
        "paper-intersection-moving-car",
    )


def test_unknown_sensor_lists_the_presets(tmp_path, capsys):
    _fails(
        ["simulate", "--scene", "paper-intersection", "--sensor", "vlp17", "--pose", "0,0,3,0,0,0"],
        tmp_path,
        capsys,
        "unknown sensor 'vlp17'",
        *PRESETS,
    )


@pytest.mark.parametrize("pose", ["0,0,3,0,0", "0,0,3,0,0,0,1", "0,0,three,0,0,0"])
def test_pose_with_the_wrong_values(tmp_path, capsys, pose):
    _fails([*BASE, "--pose", pose], tmp_path, capsys, "--pose")


def test_mesh_that_does_not_load(tmp_path, capsys):
    (tmp_path / "statue.ply").write_text("ply\nthis is no mesh\n")
    scene = tmp_path / "square.yaml"
    scene.write_text(
        yaml.safe_dump({"objects": [{"kind": "plane", "size": [10, 10]}, {"kind": "mesh", "file": "statue.ply"}]})
    )
    _fails(
        ["simulate", "--scene", str(scene), "--sensor", "vlp16", "--pose", "0,0,3,0,0,0"],
        tmp_path,
        capsys,
        "statue.ply",
        "cannot load mesh",
    )


def test_velocity_without_rolling_shutter_is_refused(tmp_path, capsys):
    _fails([*BASE, "--pose", "0,0,3,0,0,0", "--velocity", "1,0,0"], tmp_path, capsys, "--rolling-shutter")


@pytest.mark.parametrize(
    "content, expected",
    [
        ("name: mine\n", "sensor model: needs at least 'name' and 'elevation_deg'"),
        ("name: mine\nelevation_deg: [-15, 15\n", "not valid YAML: line 3, column 1: expected ',' or ']'"),
        ("- 15\n", "a sensor model is a mapping"),
    ],
)
def test_a_bad_sensor_yaml_is_named(tmp_path, capsys, content, expected):
    sensor = tmp_path / "mine.yaml"
    sensor.write_text(content)
    _fails(
        ["simulate", "--scene", "paper-intersection", "--sensor", str(sensor), "--pose", "0,0,3,0,0,0"],
        tmp_path,
        capsys,
        f"{sensor}: ",
        expected,
    )


def test_simulate_applies_and_records_calibration_faults(tmp_path):
    clean, faulted = tmp_path / "clean.parquet", tmp_path / "faulted.parquet"
    args = [*BASE, "--pose", "0,0,3,0,0,0"]
    assert main([*args, "--out", str(clean)]) == 0
    offsets = ",".join(["0"] * 15 + ["0.5"])  # only the top beam (+15 deg) is off
    faulted_args = ["--range-scale", "1.002", "--range-offset", "-0.05", "--elevation-offsets", offsets]
    assert main([*args, *faulted_args, "--out", str(faulted)]) == 0
    a, b = read_scan(clean), read_scan(faulted)
    assert "range_scale=1.002 range_offset_m=-0.05 elevation_offsets_deg=[0.0," in b.source
    assert "range_scale" not in a.source
    same = b.attributes["ring"] < 15
    assert np.array_equal(a.attributes["ring"][a.attributes["ring"] < 15], b.attributes["ring"][same])
    expected = 1.002 * np.linalg.norm(a.xyz[a.attributes["ring"] < 15], axis=1) - 0.05
    assert np.allclose(np.linalg.norm(b.xyz[same], axis=1), expected, rtol=0, atol=1e-9)


@pytest.mark.parametrize(
    "fault, expected",
    [
        (["--range-scale", "0"], "range scale must be positive"),
        (["--range-scale", "big"], "--range-scale: not numbers: 'big'"),
        (["--range-offset", "1,2"], "--range-offset needs 1 comma-separated values, got 2"),
        (
            ["--elevation-offsets", "0.1,0.2"],
            "--elevation-offsets (sensor vlp16) needs 16 comma-separated values, got 2",
        ),
        (["--elevation-offsets", ",".join(["0"] * 15 + ["nan"])], "elevation offsets: must be finite"),
    ],
)
def test_bad_faults_are_one_line(tmp_path, capsys, fault, expected):
    _fails([*BASE, "--pose", "0,0,3,0,0,0", *fault], tmp_path, capsys, expected)
