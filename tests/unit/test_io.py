"""Scan I/O: round trips through every writer/reader pair, and every reader on real files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lidarfield.io import FORMATS, read_scan, scan_count, scan_format, split_reference, write_scan
from lidarfield.io.formats.pcd import lzf_decompress, write_pcd
from lidarfield.scan import Scan
from lidarfield.sensors.models import PRESETS


@pytest.fixture
def scan() -> Scan:
    rng = np.random.default_rng(7)
    n = 500
    return Scan(
        rng.normal(0.0, 40.0, (n, 3)),
        {
            "intensity": rng.integers(0, 256, n).astype(np.float32),
            "ring": rng.integers(0, 16, n).astype(np.uint16),
            "time": rng.random(n) * 0.1,
        },
        source="synthetic",
    )


# (extension, coordinate tolerance in metres, attributes the format keeps)
ROUND_TRIPS = [
    ("pcd", 0.0, ("intensity", "ring", "time")),
    ("ply", 0.0, ("intensity", "ring", "time")),
    ("bin", 1e-5, ("intensity",)),  # float32 coordinates, |xyz| < ~200 m
    ("txt", 0.0, ("intensity",)),
    ("xyz", 0.0, ("intensity",)),
    ("csv", 0.0, ("intensity", "ring", "time")),
    ("npy", 0.0, ("intensity", "ring", "time")),
    ("parquet", 0.0, ("intensity", "ring", "time")),
    ("las", 2.5e-5, ("intensity", "ring", "time")),
    ("laz", 2.5e-5, ("intensity", "ring", "time")),
]


@pytest.mark.parametrize("extension, tolerance, kept", ROUND_TRIPS)
def test_round_trip(tmp_path, scan, extension, tolerance, kept):
    path = tmp_path / f"scan.{extension}"
    write_scan(scan, path)
    back = read_scan(path)
    assert len(back) == len(scan) and back.dropped_invalid == 0
    np.testing.assert_allclose(back.xyz, scan.xyz, rtol=0, atol=tolerance)
    assert set(back.attributes) == set(kept)
    for name in kept:
        np.testing.assert_array_equal(
            back.attributes[name].astype(np.float64), scan.attributes[name].astype(np.float64)
        )


def test_every_writable_format_has_a_round_trip():
    tested = {scan_format(f"scan.{extension}").name for extension, _, _ in ROUND_TRIPS}
    assert tested == {f.name for f in FORMATS.values() if f.writable}


def test_ascii_pcd_round_trip(tmp_path, scan):
    write_pcd(scan, tmp_path / "a.pcd", data="ascii")
    back = read_scan(tmp_path / "a.pcd")
    np.testing.assert_array_equal(back.xyz, scan.xyz)
    np.testing.assert_array_equal(back.attributes["ring"], scan.attributes["ring"])


def test_ascii_ply_with_faces_after_the_vertices(tmp_path):
    header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    header += "property uchar scalar_intensity\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
    (tmp_path / "a.ply").write_text(header + "0 0 0 5\n1 0 0 6\n0 1 0.5 7\n3 0 1 2\n")
    back = read_scan(tmp_path / "a.ply")
    np.testing.assert_array_equal(back.xyz, [[0, 0, 0], [1, 0, 0], [0, 1, 0.5]])
    np.testing.assert_array_equal(back.attributes["intensity"], [5, 6, 7])


def test_big_endian_ply_after_another_element(tmp_path):
    header = "ply\nformat binary_big_endian 1.0\nelement camera 1\nproperty double f\n"
    header += "element vertex 2\nproperty double x\nproperty double y\nproperty double z\nend_header\n"
    body = np.array([9.0], ">f8").tobytes() + np.array([[1.5, -2, 3], [4, 5, 6.25]], ">f8").tobytes()
    (tmp_path / "b.ply").write_bytes(header.encode() + body)
    np.testing.assert_array_equal(read_scan(tmp_path / "b.ply").xyz, [[1.5, -2, 3], [4, 5, 6.25]])


def test_binary_compressed_pcd_written_by_open3d(tmp_path, scan):
    o3d = pytest.importorskip("open3d")
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(scan.xyz))
    path = tmp_path / "c.pcd"
    o3d.io.write_point_cloud(str(path), cloud, write_ascii=False, compressed=True)
    assert b"binary_compressed" in path.read_bytes()[:400]
    np.testing.assert_allclose(read_scan(path).xyz, scan.xyz, atol=1e-5)  # Open3D stores float32


def test_lzf_overlapping_back_reference():
    # literal 'ab' (ctrl 1), then a back reference of length 6 at distance 2: 'abababab'
    assert lzf_decompress(bytes([1]) + b"ab" + bytes([(4 << 5) | 0, 1]), 8) == b"abababab"


def test_laz_is_compressed_and_las_is_not(tmp_path, scan):
    laspy = pytest.importorskip("laspy")
    for extension, compressed in (("las", False), ("laz", True)):
        write_scan(scan, tmp_path / f"s.{extension}")
        with laspy.open(tmp_path / f"s.{extension}") as reader:
            assert reader.header.are_points_compressed is compressed
    assert (tmp_path / "s.laz").stat().st_size < 0.8 * (tmp_path / "s.las").stat().st_size


def test_large_float_intensity_survives_las(tmp_path, scan):
    scan.attributes["intensity"] = scan.attributes["intensity"] / 255.0  # reflectance in 0..1
    write_scan(scan, tmp_path / "f.laz")
    back = read_scan(tmp_path / "f.laz")
    np.testing.assert_array_equal(back.attributes["intensity"], scan.attributes["intensity"])


def test_parquet_keeps_metadata(tmp_path, scan):
    scan.sensor = PRESETS["vlp16"]
    scan.pose = np.array([[0, -1, 0, 1.0], [1, 0, 0, 2.0], [0, 0, 1, 3.0], [0, 0, 0, 1]])
    scan.dropped_invalid = 42
    write_scan(scan, tmp_path / "s.parquet")
    back = read_scan(tmp_path / "s.parquet")
    assert back.sensor == PRESETS["vlp16"]
    np.testing.assert_array_equal(back.pose, scan.pose)
    assert back.source == "synthetic" and back.dropped_invalid == 42


def test_invalid_rows_dropped_and_counted(tmp_path):
    rows = np.array([[1, 2, 3], [np.nan, np.nan, np.nan], [4, np.inf, 6], [7, 8, 9]], dtype=float)
    np.save(tmp_path / "s.npy", rows)
    back = read_scan(tmp_path / "s.npy")
    np.testing.assert_array_equal(back.xyz, [[1, 2, 3], [7, 8, 9]])
    assert back.dropped_invalid == 2


def test_csv_header_names_any_case_and_extra_columns(tmp_path):
    (tmp_path / "s.csv").write_text("X,Y,Z,Intensity,label\n1,2,3,10,7\n4,5,6,20,8\n")
    back = read_scan(tmp_path / "s.csv")
    np.testing.assert_array_equal(back.xyz, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(back.attributes["intensity"], [10, 20])
    np.testing.assert_array_equal(back.attributes["label"], [7, 8])


def test_explicit_format_overrides_extension(tmp_path, scan):
    write_scan(scan, tmp_path / "scan.dat", format="ply")
    np.testing.assert_array_equal(read_scan(tmp_path / "scan.dat", format="ply").xyz, scan.xyz)


def test_split_reference(tmp_path):
    assert split_reference("a/b.mat#3") == (Path("a/b.mat"), 3, None)
    assert split_reference("d.bag#/points#2") == (Path("d.bag"), 2, "/points")
    assert split_reference("d#/ns/points") == (Path("d"), None, "/ns/points")
    assert split_reference("a/b.mat")[1] is None
    odd = tmp_path / "odd#2"
    odd.write_text("")
    assert split_reference(odd) == (odd, None, None)  # an existing name is taken as it is


# --- real files ------------------------------------------------------------------------------
def test_hdl32_pcd_and_ply(shared_data):
    for name in ("251370668.pcd", "251371071.pcd"):
        scan = read_scan(shared_data / "hdl32-pair" / name)
        assert len(scan) > 60_000 and "intensity" in scan.attributes
        assert 1.0 < np.median(np.linalg.norm(scan.xyz, axis=1)) < 100.0  # metres, sensor frame
    source = read_scan(shared_data / "hdl32-pair" / "source.ply")
    assert len(source) == 69792 and "intensity" in source.attributes
    assert np.ptp(source.attributes["intensity"]) > 0


def test_hdl32_ply_matches_its_raw_bytes(shared_data):
    """The first vertex, decoded by hand from the bytes after end_header."""
    raw = (shared_data / "hdl32-pair" / "source.ply").read_bytes()
    start = raw.index(b"end_header\n") + len(b"end_header\n")
    first = np.frombuffer(raw, dtype="<f4", count=4, offset=start)
    scan = read_scan(shared_data / "hdl32-pair" / "source.ply")
    np.testing.assert_array_equal(scan.xyz[0], first[:3].astype(np.float64))
    assert scan.attributes["intensity"][0] == first[3]


@pytest.mark.parametrize("name", ["Cloud1_ExpD.txt", "Cloud10_ExpD.txt", "Cloud10Aligned_ExpD.txt"])
def test_expd_text(expd, name):
    values = np.loadtxt(expd / name)
    valid = np.isfinite(values).all(axis=1)
    scan = read_scan(expd / name, sensor="vlp16")
    assert len(scan) == valid.sum() and scan.dropped_invalid == (~valid).sum()
    np.testing.assert_allclose(scan.xyz, values[valid], rtol=1e-15)
    # ring-major: 16 blocks of N lines, ring = block index
    rings = np.repeat(np.arange(16), len(values) // 16)[valid]
    np.testing.assert_array_equal(scan.attributes["ring"], rings)


@pytest.mark.parametrize("name", ["Cloud1_ExpD.txt", "Cloud10_ExpD.txt"])  # in their own sensor frame
def test_expd_ring_is_the_beam(expd, name):
    """Ring r (row r of the organised image) holds the beam at +15 - 2r degrees."""
    scan = read_scan(expd / name, sensor="vlp16")
    rings = scan.attributes["ring"]
    elevation = np.degrees(np.arctan2(scan.xyz[:, 2], np.hypot(scan.xyz[:, 0], scan.xyz[:, 1])))
    means = [elevation[rings == r].mean() for r in range(16)]
    np.testing.assert_allclose(means, np.arange(15, -16, -2), atol=0.1)


def test_expd_text_without_sensor_has_no_ring(expd):
    assert "ring" not in read_scan(expd / "Cloud1_ExpD.txt").attributes


def test_signage_mat_holds_the_expd_scans(expd):
    mat = expd / "signagePCs.mat"
    assert scan_count(mat) == 10
    for k, text in ((0, "Cloud1_ExpD.txt"), (9, "Cloud10_ExpD.txt")):
        from_mat = read_scan(f"{mat}#{k}")
        from_text = read_scan(expd / text)
        assert len(from_mat) == len(from_text) and from_mat.dropped_invalid == from_text.dropped_invalid
        np.testing.assert_allclose(from_mat.xyz, from_text.xyz, atol=1e-6)  # text has 7 decimals
        assert from_mat.source.endswith(f"#{k}")
    sizes = [len(read_scan(f"{mat}#{k}")) for k in range(10)]
    assert all(12_000 < n < 14_000 for n in sizes) and len(set(sizes)) > 1


@pytest.mark.parametrize("k", [0, 1, 2])
def test_ouster_decoded_bins(shared_data, k):
    path = shared_data / "ouster-os1-128" / f"lb_n3_scan{k}_xyz_refl_float32.bin"
    raw = np.fromfile(path, dtype="<f4").reshape(-1, 4)
    scan = read_scan(path)
    assert len(scan) == len(raw) > 100_000
    np.testing.assert_array_equal(scan.xyz, raw[:, :3].astype(np.float64))
    np.testing.assert_array_equal(scan.attributes["intensity"], raw[:, 3])


def test_scan_count_single_file_formats(shared_data):
    assert scan_count(shared_data / "hdl32-pair" / "source.ply") == 1
    scan = read_scan(f"{shared_data / 'hdl32-pair' / 'source.ply'}#0")
    assert len(scan) == 69792
