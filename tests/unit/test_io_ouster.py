"""Ouster recordings through the optional ouster-sdk: skipped, with the reason, without it."""

from __future__ import annotations

import builtins

import numpy as np
import pytest

from lidarfield.errors import InputError
from lidarfield.io import read_scan, scan_count

RECORDING = "OS-1-128_v2.3.0_1024x10_lb_n3"


@pytest.fixture(scope="module")
def ouster_folder(shared_data):
    """The OS1-128 folder: its pcap and osf recordings and their decoded frames (.bin); skipped
    without the ouster-sdk."""
    pytest.importorskip("ouster.sdk", reason="optional extra: pip install lidarfield[ouster]")
    return shared_data / "ouster-os1-128"


@pytest.mark.parametrize("extension", ["pcap", "osf"])
def test_frames_match_the_decoded_bins(ouster_folder, extension):
    path = ouster_folder / f"{RECORDING}.{extension}"
    assert scan_count(path) == 3
    for k in range(3):
        scan = read_scan(f"{path}#{k}")
        decoded = np.fromfile(ouster_folder / f"lb_n3_scan{k}_xyz_refl_float32.bin", dtype="<f4").reshape(-1, 4)
        assert len(scan) == len(decoded)
        assert len(scan) + scan.dropped_invalid == 128 * 1024
        np.testing.assert_allclose(scan.xyz, decoded[:, :3], atol=2e-5)  # float32 rounding of the bins
        np.testing.assert_array_equal(scan.attributes["intensity"], decoded[:, 3])
        assert scan.attributes["ring"].max() == 127
        assert 0.09 < scan.attributes["time"].max() < 0.1  # one 10 Hz revolution
        assert scan.sensor.channels == 128


def test_missing_sdk_names_the_extra(shared_data, monkeypatch):
    real_import = builtins.__import__

    def no_ouster(name, *args, **kwargs):
        if name.startswith("ouster"):
            raise ImportError(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_ouster)
    with pytest.raises(InputError, match=r"pip install lidarfield\[ouster\]"):
        read_scan(shared_data / "ouster-os1-128" / f"{RECORDING}.osf#0")
