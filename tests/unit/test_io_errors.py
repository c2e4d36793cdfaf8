"""Scan I/O bad input: one InputError naming the file and the problem, and no output file."""

from __future__ import annotations

import numpy as np
import pytest

from lidarfield.errors import InputError
from lidarfield.io import read_scan, scan_count, write_scan
from lidarfield.scan import Scan


def _raises(reference, *words, **options) -> str:
    with pytest.raises(InputError) as caught:
        read_scan(reference, **options)
    message = str(caught.value)
    assert str(reference).split("#")[0] in message
    for word in words:
        assert word in message, message
    assert "\n" not in message
    return message


def _scan(n=10) -> Scan:
    return Scan(np.random.default_rng(1).normal(size=(n, 3)), {"intensity": np.arange(n, dtype=np.float32)})


def test_missing_file(tmp_path):
    _raises(tmp_path / "nope.pcd", "file not found")


def test_truncated_binary_pcd(tmp_path):
    path = tmp_path / "t.pcd"
    write_scan(_scan(100), path)
    path.write_bytes(path.read_bytes()[:-50])
    _raises(path, "truncated binary PCD", "POINTS 100")


@pytest.mark.parametrize(
    "name, content, words",
    [
        ("two.txt", "1 2\n3 4\n", ("at least 3 columns", "found 2")),
        ("words.xyz", "1 2 3\n4 five 6\n", ("non-numeric",)),
        ("s.csv", "a,b,c\n1,2,3\n", ("x, y, z", "['a', 'b', 'c']")),
        ("empty.txt", "", ("empty scan",)),
        ("comment.txt", "# only a comment\n", ("empty scan",)),
        ("nan.txt", "NaN NaN NaN\nnan nan nan\n", ("empty scan", "all 2 rows")),
    ],
)
def test_bad_text_scans(tmp_path, name, content, words):
    path = tmp_path / name
    path.write_text(content)
    _raises(path, *words)


def test_empty_binary_scan(tmp_path):
    path = tmp_path / "empty.bin"
    path.write_bytes(b"")
    _raises(path, "empty scan")


def test_bin_with_partial_row(tmp_path):
    path = tmp_path / "odd.bin"
    path.write_bytes(b"\0" * 20)
    _raises(path, "not a whole number of 16-byte rows")


def test_unknown_extension(tmp_path):
    path = tmp_path / "scan.e57"
    path.write_bytes(b"x")
    message = _raises(path, "unknown scan file extension '.e57'")
    for known in ("pcd", "ply", ".bin", ".xyz", ".csv", ".npy", ".parquet", ".laz", ".mat", ".pcap"):
        assert known in message


def test_unknown_format(tmp_path):
    path = tmp_path / "scan.pcd"
    write_scan(_scan(), path)
    _raises(path, "unknown scan format 'e57'", "known formats", format="e57")


def test_corrupt_las(tmp_path):
    path = tmp_path / "bad.las"
    write_scan(_scan(100), path)
    raw = bytearray(path.read_bytes())
    path.write_bytes(bytes(raw[:200]))  # header cut short, no points
    _raises(path, "not a readable LAS/LAZ file")
    path.write_bytes(b"this is not a las file" * 20)
    _raises(path, "not a readable LAS/LAZ file")


def test_corrupt_laz_payload(tmp_path):
    path = tmp_path / "bad.laz"
    write_scan(_scan(1000), path)
    raw = path.read_bytes()
    path.write_bytes(raw[: len(raw) // 2])
    _raises(path, "not a readable LAS/LAZ file")


def test_index_out_of_range(tmp_path, expd):
    _raises(f"{expd / 'signagePCs.mat'}#10", "scan #10", "holds 10 scan(s)")
    path = tmp_path / "one.npy"
    write_scan(_scan(), path)
    _raises(f"{path}#1", "scan #1", "holds 1 scan(s)")


def test_container_without_index(expd):
    _raises(expd / "signagePCs.mat", "holds 10 scans", "#k")


def test_mat_without_organised_scans(tmp_path):
    import scipy.io

    path = tmp_path / "flat.mat"
    scipy.io.savemat(path, {"pc": np.zeros((5, 3))})
    with pytest.raises(InputError, match="not a rings x columns x 3"):
        scan_count(path)


def test_read_only_format_cannot_be_written(tmp_path):
    with pytest.raises(InputError, match="read-only"):
        write_scan(_scan(), tmp_path / "out.mat")
    assert not list(tmp_path.iterdir())


def test_failed_write_leaves_no_file(tmp_path):
    scan = _scan()
    scan.attributes["label"] = np.array(["a"] * len(scan))  # strings cannot go into PLY
    with pytest.raises(InputError, match="label"):
        write_scan(scan, tmp_path / "out.ply")
    assert not list(tmp_path.iterdir())
