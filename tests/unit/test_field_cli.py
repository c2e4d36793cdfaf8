"""``lidarfield field`` on the real ExpD pair, and its bad-input behaviour."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from lidarfield.cli import main
from lidarfield.field.file import read_field
from lidarfield.io import read_scan, write_scan


def test_field_of_the_expd_pair(expd, tmp_path, capsys):
    grid_yaml = tmp_path / "grid.yaml"
    grid_yaml.write_text(
        "grid:\n  kind: spherical\n  azimuth_bins: 36\n  elevation_deg: [-20, 20]\n  elevation_bins: 5\n"
    )
    out = tmp_path / "out"
    code = main(
        [
            "field",
            str(expd / "Cloud1_ExpD.txt"),
            str(expd / "Cloud10Aligned_ExpD.txt"),
            "--out",
            str(out),
            "--grid",
            str(grid_yaml),
        ]
    )
    assert code == 0
    printed = capsys.readouterr().out
    assert "paper max metric" in printed and "mean resultant length" in printed
    # Text scans carry no model nor rings: the edges as given; the VLP-16's channels (odd
    # degrees) lie between them, so its points do not cluster on one and nothing is warned.
    grid = next(line for line in printed.splitlines() if line.startswith("grid "))
    assert grid.split(None, 1)[1] == "no sensor model nor rings: elevation [-20, 20] deg, edges as given"
    assert "grid warning" not in printed
    columns, meta = read_field(out / "field.parquet")
    assert meta["grid"]["azimuth_bins"] == 36 and meta["grid"]["elevation_bins"] == 5
    assert columns["valid"].sum() > 50
    assert columns["az_bin"].max() <= 35 and columns["el_bin"].max() <= 4 and (columns["r_bin"] == -1).all()
    summary = json.loads((out / "summary.json").read_text())
    stats = summary["statistics"]
    assert stats["voxels_valid"] == int(columns["valid"].sum())
    for key in (
        "max_magnitude",
        "mean_magnitude",
        "rms_magnitude",
        "p95_magnitude",
        "paper_max_metric",
        "rigid_rotation_deg",
        "rigid_energy_share",
        "mean_resultant_length",
    ):
        assert math.isfinite(stats[key]), key
    # VLP-16 beams span -15..+15 deg: scan 1 is all inside the +-20 deg grid.
    assert summary["out_of_grid1"] == 0 and summary["n1"] == int(columns["n1"].sum())
    assert summary["n2"] == int(columns["n2"].sum()) + summary["out_of_grid2"]


def test_flags_override_the_grid_and_pose2_moves_scan2(expd, tmp_path):
    scan = str(expd / "Cloud1_ExpD.txt")
    out = tmp_path / "out"
    assert (
        main(
            [
                "field",
                scan,
                scan,
                "--out",
                str(out),
                "--azimuth-bins",
                "12",
                "--elevation-deg",
                "-16",
                "16",
                "--elevation-bins",
                "2",
                "--min-points",
                "5",
                "--pose2",
                "0.01,0,0,0,0,0",
            ]
        )
        == 0
    )
    columns, meta = read_field(out / "field.parquet")
    assert meta["grid"]["elevation_deg"] == [-16.0, 16.0] and meta["min_points"] == 5
    assert columns["az_bin"].max() == 11 and columns["el_bin"].max() == 1
    # A 1 cm shift of a ~1000-point voxel moves few points across bins: the median vector is it.
    assert abs(np.median(columns["u"][columns["valid"]]) - 0.01) < 0.005


@pytest.mark.parametrize("problem", ["missing scan", "bad pose file", "bad grid key", "two-column text"])
def test_bad_input_is_one_line_and_writes_nothing(problem, expd, tmp_path, capsys):
    scan1, scan2 = str(expd / "Cloud1_ExpD.txt"), str(expd / "Cloud10Aligned_ExpD.txt")
    extra: list[str] = []
    culprit = ""
    if problem == "missing scan":
        scan2 = culprit = str(tmp_path / "nope.txt")
    elif problem == "bad pose file":
        culprit = str(tmp_path / "pose.txt")
        (tmp_path / "pose.txt").write_text("1 0 0\n0 1 0\n0 0 1\n")
        extra = ["--transform", culprit]
    elif problem == "bad grid key":
        culprit = str(tmp_path / "grid.yaml")
        (tmp_path / "grid.yaml").write_text("azimuth_bin: 36\n")
        extra = ["--grid", culprit]
        culprit = "grid.azimuth_bin"
    else:
        scan2 = culprit = str(tmp_path / "two.txt")
        (tmp_path / "two.txt").write_text("1 2\n3 4\n5 6\n")
    out = tmp_path / "out"
    assert main(["field", scan1, scan2, "--out", str(out), *extra]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and culprit in err
    assert not out.exists()


BAD_TEXT = {"grid.yaml": "grid:\n  azimuth_bins: [36\n", "pose.txt": "1 0 0 nan\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"}


def _bad_file(tmp_path, expd, name: str) -> str:
    path = tmp_path / name
    if name.endswith(".laz"):  # a real scan, cut in the middle of its compressed points
        write_scan(read_scan(expd / "Cloud10_ExpD.txt"), path)
        path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    else:
        path.write_text(BAD_TEXT[name])
    return str(path)


@pytest.mark.parametrize(
    "option, name, expected",
    [
        ("scan2", "cut.laz", "not a readable LAS/LAZ file"),
        ("--grid", "grid.yaml", "not valid YAML: line 3, column 1: expected ',' or ']', but got '<stream end>'"),
        ("--transform", "pose.txt", "not a rigid pose: NaN or infinite value(s) in the translation"),
    ],
    ids=["truncated LAZ", "YAML syntax error", "NaN translation"],
)
def test_bad_input_is_one_line_from_the_command(option, name, expected, expd, tmp_path):
    """In a process of its own, as a user runs it: no library's logging or multi-line message
    gets past the one line (pytest's log capture would hide them in-process)."""
    culprit = _bad_file(tmp_path, expd, name)
    scans = [str(expd / "Cloud1_ExpD.txt"), culprit if option == "scan2" else str(expd / "Cloud10Aligned_ExpD.txt")]
    extra = [] if option == "scan2" else [option, culprit]
    out = tmp_path / "out"
    done = subprocess.run(
        [sys.executable, "-m", "lidarfield", "field", *scans, "--out", str(out), *extra], capture_output=True, text=True
    )
    assert done.returncode == 2
    assert done.stderr.startswith(f"lidarfield field: error: {culprit}: "), done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and expected in done.stderr, done.stderr
    assert not out.exists()
