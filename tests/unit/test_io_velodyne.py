"""Raw Velodyne captures (the real VLP-16 and HDL-32E ones) through velodyne-decoder."""

from __future__ import annotations

import shutil
import struct

import numpy as np
import pytest

from lidarfield.cli import main
from lidarfield.errors import InputError
from lidarfield.io import read_scan, scan_count
from lidarfield.io.formats.velodyne import capture_summary

pytest.importorskip("velodyne_decoder")

VLP16 = "sample_velodyne_vlp16_gps.pcap"
HDL32 = "sample_velodyne_hdl32.pcap"
# VLP-16 lasers in firing order: elevation (deg) of laser i
VLP16_ELEVATION = [-15, 1, -13, 3, -11, 5, -9, 7, -7, 9, -5, 11, -3, 13, -1, 15]


@pytest.fixture(scope="module")
def captures(shared_data):
    return shared_data / "velodyne-pcap"


@pytest.mark.parametrize(
    "name, model, rotations, points, rings",
    [(VLP16, "VLP16", 3, (18_000, 19_500), 16), (HDL32, "HDL32E", 2, (57_000, 59_000), 31)],
)
def test_whole_rotations_of_the_real_captures(captures, name, model, rotations, points, rings):
    path = captures / name
    summary = capture_summary(path)
    assert summary.model == model and summary.return_mode == "strongest"
    assert scan_count(path) == summary.rotations == rotations
    stamps = []
    for k in range(rotations):
        scan = read_scan(f"{path}#{k}")
        assert points[0] <= len(scan) <= points[1]
        assert np.unique(scan.attributes["ring"]).size == rings  # one HDL-32E laser returns nothing here
        # One rotation: returns all round (but for an occluded sector), firing over one 10 Hz turn.
        azimuth = np.degrees(np.arctan2(scan.xyz[:, 1], scan.xyz[:, 0]))
        assert (np.histogram(azimuth, bins=36, range=(-180, 180))[0] > 0).sum() >= 34
        assert 0.095 < scan.attributes["time"].max() < 0.115 and scan.attributes["time"].min() == 0.0
        stamps.append(scan.stamp_s)
    assert np.allclose(np.diff(stamps), 0.1, atol=0.015)  # consecutive rotations
    # The partial rotation after the last whole one is not a scan.
    with pytest.raises(InputError, match=f"scan #{rotations} requested but the file holds {rotations} scan"):
        read_scan(f"{path}#{rotations}")


def vlp16_reference(payload: bytes) -> np.ndarray:
    """The first firing sequence of each block of one VLP-16 packet, decoded by the manual's
    formulas (ROS frame: x forward, y left; distance unit 2 mm), as (ring, x, y, z) rows."""
    rows = []
    for block in range(12):
        base = block * 100
        flag, azimuth = struct.unpack_from("<HH", payload, base)
        assert flag == 0xEEFF
        for laser in range(16):
            distance, _ = struct.unpack_from("<HB", payload, base + 4 + 3 * laser)
            r = distance * 0.002
            if r < 0.1:
                continue
            omega, alpha = (
                np.radians(VLP16_ELEVATION[laser]),
                np.radians(azimuth / 100.0 + laser * 2.304 / 55.296 * 0.2),
            )
            rows.append(
                (laser, r * np.cos(omega) * np.cos(alpha), -r * np.cos(omega) * np.sin(alpha), r * np.sin(omega))
            )
    return np.array(rows)


def test_vlp16_points_match_the_manual_formulas(captures):
    """velodyne-decoder's points of the first packets, against a plain decoder of the packet
    format: each reference point has a decoded point of the same ring within 2 cm."""
    from lidarfield.io.formats.velodyne import PACKET_SIZE, udp_payloads

    path = captures / VLP16
    scan = read_scan(f"{path}#0")
    payloads = [p for _, p in udp_payloads(path) if len(p) == PACKET_SIZE][:8]
    reference = np.vstack([vlp16_reference(p) for p in payloads])
    assert len(reference) > 500
    # Rings are numbered by elevation (0 = lowest) in the decoded scan.
    ring_of_laser = np.argsort(np.argsort(VLP16_ELEVATION))
    for laser, x, y, z in reference:
        candidates = scan.xyz[scan.attributes["ring"] == ring_of_laser[int(laser)]]
        assert np.linalg.norm(candidates - [x, y, z], axis=1).min() < 0.02


def rewrite_payloads(source, target, rewrite) -> None:
    """Copy a capture, passing each 1206-byte payload (a bytearray) through ``rewrite``."""
    data = bytearray(source.read_bytes())
    offset = 24  # pcap: 24-byte file header, then a 16-byte header per record
    while offset < len(data):
        length = struct.unpack_from("<I", data, offset + 8)[0]
        if length == 42 + 1206:  # Ethernet + IP + UDP headers, then the payload
            start = offset + 16 + 42
            data[start : start + 1206] = rewrite(bytearray(data[start : start + 1206]))
        offset += 16 + length
    target.write_bytes(bytes(data))


def test_model_from_the_sensor_when_the_packets_do_not_say(captures, tmp_path):
    """An old capture without factory bytes: the packet rate tells an HDL-32E; a sensor given
    overrides it, and one that does not fit the packets is an error."""

    def without_factory_bytes(payload):
        payload[1204:1206] = b"\0\0"
        return payload

    old = tmp_path / "old.pcap"
    rewrite_payloads(captures / HDL32, old, without_factory_bytes)
    assert capture_summary(old).model == "HDL32E"
    np.testing.assert_array_equal(read_scan(f"{old}#1").xyz, read_scan(f"{captures / HDL32}#1").xyz)
    assert capture_summary(old, read_scan(f"{old}#0", sensor="hdl32").sensor).model == "HDL32E"
    with pytest.raises(
        InputError, match=r"sample_velodyne_hdl32.pcap: the packets do not decode as a VLP16: Expected model ID"
    ):
        read_scan(f"{captures / HDL32}#0", sensor="vlp16")


def test_dual_returns_keep_both_with_their_return_type(captures, tmp_path):
    """The VLP-16 capture made dual: each block pair holds the last return (1 m farther) then
    the strongest, at the same azimuth; both come back, told apart by return_type."""

    def dual(payload):
        payload[1204] = 0x39
        for k in range(6):
            strongest = payload[200 * k : 200 * k + 100]
            last = bytearray(strongest)
            for j in range(32):
                distance = struct.unpack_from("<H", last, 4 + 3 * j)[0]
                struct.pack_into("<H", last, 4 + 3 * j, distance + 500 if distance else 0)  # 2 mm units
            payload[200 * k : 200 * k + 200] = last + strongest
        return payload

    path = tmp_path / "dual.pcap"
    rewrite_payloads(captures / VLP16, path, dual)
    assert capture_summary(path).return_mode == "dual"
    scan = read_scan(f"{path}#0")
    kind = scan.attributes["return_type"]
    assert set(np.unique(kind)) == {1, 2}  # velodyne-decoder's flags: 1 strongest, 2 last
    ranges = {}
    for flag in (1, 2):
        order = np.lexsort((scan.attributes["ring"][kind == flag], scan.attributes["time"][kind == flag]))
        ranges[flag] = np.linalg.norm(scan.xyz[kind == flag], axis=1)[order]
    assert len(ranges[1]) == len(ranges[2]) > 8000
    np.testing.assert_allclose(ranges[2] - ranges[1], 1.0, atol=0.005)


def test_a_pcap_that_is_not_velodyne_is_one_line_exit_2_and_no_output(shared_data, tmp_path, capsys):
    ouster = tmp_path / "lidar.pcap"  # an Ouster capture without its .json beside it
    shutil.copy(shared_data / "ouster-os1-128" / "OS-1-128_v2.3.0_1024x10_lb_n3.pcap", ouster)
    config = tmp_path / "study.yaml"
    config.write_text("hypotheses: []\n")
    out = tmp_path / "out"
    assert main(["run", f"{ouster}#0", f"{ouster}#1", "--config", str(config), "--out", str(out)]) == 2
    error = capsys.readouterr().err.strip()
    assert error == (
        f"lidarfield run: error: {ouster}: not a Velodyne capture (no 1206-byte data packets; UDP payloads: "
        "8448 bytes x 192, 48 bytes x 30) and no Ouster .json metadata beside it"
    )
    assert not out.exists()
    text = tmp_path / "text.pcap"
    text.write_text("not a capture")
    with pytest.raises(InputError, match="text.pcap: not a readable pcap capture"):
        scan_count(text)
