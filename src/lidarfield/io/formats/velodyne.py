"""Raw Velodyne captures (``.pcap`` of the sensor's UDP packets) through ``velodyne-decoder``.

One rotation is one scan: ``path#k`` selects the k-th whole rotation. A rotation begins at the
azimuth of the capture's first data packet and ends one turn later, as ``velodyne-decoder``
cuts them; the packets after the last whole rotation (a partial rotation) are dropped, never
returned as a scan. The model comes from the packets' factory bytes (product id), or, in old
captures without them, from the data packets' rate (HDL-32E 553 us apart, VLP-16 1327 us), or
from ``sensor:`` (``vlp16``, ``hdl32``, ``hdl64``, which override what the packets say). Dual
return captures keep both returns, with a ``return_type`` attribute.

Attributes: ``intensity``, ``ring`` (the laser, 0 = lowest), ``time`` (seconds since the
rotation's first firing); the scan's ``stamp_s`` is that first firing's capture time.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Iterator, NamedTuple

import numpy as np

from ...errors import InputError
from ...scan import Scan
from ...sensors.models import PRESETS, SensorModel
from ..rows import file_key, scan_from_rows

PACKET_SIZE = 1206  # UDP payload of a Velodyne data packet
PRODUCTS = {0x21: "HDL32E", 0x22: "VLP16", 0x24: "PuckHiRes", 0x28: "VLP32C", 0xA1: "VLS128"}
PRODUCT_OF_MODEL = {model: product for product, model in PRODUCTS.items()}
RETURN_MODES = {0x37: "strongest", 0x38: "last", 0x39: "dual"}
PACKET_INTERVAL_US = {"HDL32E": 552.96, "VLP16": 1327.1}  # 12 firing blocks per packet
MODEL_OF_PRESET = {"vlp16": "VLP16", "hdl32": "HDL32E", "hdl64": "HDL64E_S3"}
PRESET_OF_MODEL = {model: preset for preset, model in MODEL_OF_PRESET.items()}
_INSTALL = "reading Velodyne captures needs the velodyne-decoder package: pip install velodyne-decoder"


class Capture(NamedTuple):
    """What a capture's packets say: the model, the return mode and the rotations in it."""

    model: str
    return_mode: str
    data_packets: int
    other_packets: int
    rotations: int  # whole rotations
    dropped_packets: int  # after the last whole rotation


def udp_payloads(path: Path) -> Iterator[tuple[float, bytes]]:
    """(capture time, UDP payload) of each packet of a classic pcap file."""
    import dpkt

    try:
        with open(path, "rb") as f:
            for stamp, frame in dpkt.pcap.Reader(f):
                try:
                    data = dpkt.ethernet.Ethernet(frame)
                except dpkt.dpkt.UnpackError:
                    continue
                while hasattr(data, "data") and not isinstance(data, bytes):
                    data = data.data
                yield stamp, bytes(data)
    except (ValueError, dpkt.dpkt.NeedData) as e:
        raise InputError(f"not a readable pcap capture ({e or type(e).__name__})", path) from None


def is_velodyne(path: Path, sniff: int = 200) -> bool:
    """Whether the first packets of the capture include Velodyne data packets."""
    for k, (_, payload) in enumerate(udp_payloads(path)):
        if len(payload) == PACKET_SIZE:
            return True
        if k >= sniff:
            break
    return False


def detect_model(path: Path, sensor: SensorModel | None) -> tuple[str, str]:
    """(velodyne-decoder model name, return mode) from ``sensor`` or the packets."""
    stamps, factory = [], set()
    for stamp, payload in udp_payloads(path):
        if len(payload) == PACKET_SIZE:
            stamps.append(stamp)
            factory.add((payload[1204], payload[1205]))
        if len(stamps) >= 200:
            break
    if not stamps:
        raise InputError("not a Velodyne capture: no 1206-byte data packets", path)
    modes = {RETURN_MODES.get(mode, "strongest") for mode, _ in factory}
    return_mode = "dual" if "dual" in modes else modes.pop()
    if sensor is not None:
        if sensor.name not in MODEL_OF_PRESET:
            raise InputError(
                f"sensor {sensor.name!r} is not a Velodyne model velodyne-decoder knows ({', '.join(MODEL_OF_PRESET)})",
                path,
            )
        return MODEL_OF_PRESET[sensor.name], return_mode
    products = {PRODUCTS[product] for _, product in factory if product in PRODUCTS}
    if len(products) == 1:
        return products.pop(), return_mode
    interval_us = float(np.median(np.diff(stamps))) * 1e6 if len(stamps) > 1 else 0.0
    for model, expected in PACKET_INTERVAL_US.items():
        if abs(interval_us - expected) < 0.05 * expected:
            return model, return_mode
    raise InputError(
        f"cannot tell the Velodyne model from the packets (factory bytes {sorted(factory)}, packets "
        f"{interval_us:.0f} us apart): give the sensor (vlp16, hdl32 or hdl64)",
        path,
    )


def _decoder(model: str):
    try:
        import velodyne_decoder as vd
    except ImportError:
        raise InputError(_INSTALL) from None
    return vd.StreamDecoder(vd.Config(model=getattr(vd.Model, model)))


def data_packets(path: Path, model: str) -> Iterator[tuple[float, bytes]]:
    """The capture's data packets. Captures older than the factory bytes carry a zero product
    id, which velodyne-decoder refuses: the model's id is written in."""
    product = PRODUCT_OF_MODEL.get(model)
    for stamp, payload in udp_payloads(path):
        if len(payload) != PACKET_SIZE:
            continue
        if payload[1205] == 0 and product is not None:
            payload = payload[:1205] + bytes([product])
        yield stamp, payload


def rotations(path: Path, model: str) -> Iterator[tuple[float, np.ndarray]]:
    """(stamp, points) of each whole rotation, in order. The decoder hands a rotation over when
    a packet begins the next one; what it still holds at the end (``finish()``) is partial and
    is never yielded."""
    decoder = _decoder(model)
    for stamp, payload in data_packets(path, model):
        result = _decode(decoder, stamp, payload, path, model)
        if result is not None:
            yield result


def _decode(decoder, stamp: float, payload: bytes, path: Path, model: str):
    try:
        result = decoder.decode(stamp, payload, True)
    except RuntimeError as e:  # velodyne-decoder: a packet of another model, a corrupt packet
        raise InputError(f"the packets do not decode as a {model}: {' '.join(str(e).split())}", path) from None
    return None if result is None else (result[0].host, result[1])


def capture_summary(path: Path, sensor: SensorModel | None = None) -> Capture:
    return _summary(*file_key(path), None if sensor is None else sensor.name)


@lru_cache(maxsize=16)
def _summary(name: str, size: int, mtime_ns: int, preset: str | None) -> Capture:
    """One pass over the capture: its packets counted and its rotations cut (cached by file
    state: a sequence asks once per scan)."""
    path = Path(name)
    model, return_mode = detect_model(path, PRESETS.get(preset) if preset else None)
    decoder = _decoder(model)
    data = whole = pending = 0
    for stamp, payload in data_packets(path, model):
        data += 1
        pending += 1
        if _decode(decoder, stamp, payload, path, model) is not None:
            whole += 1
            pending = 1  # this packet begins the next rotation
    other = sum(1 for _, payload in udp_payloads(path) if len(payload) != PACKET_SIZE)
    return Capture(model, return_mode, data, other, whole, pending)


def count_velodyne(path: Path, sensor: SensorModel | None = None) -> int:
    return capture_summary(path, sensor).rotations


def read_velodyne(path: Path, index: int = 0, sensor: SensorModel | None = None) -> Scan:
    capture = capture_summary(path, sensor)
    found = next((r for k, r in enumerate(rotations(path, capture.model)) if k == index), None)
    if found is None:
        raise InputError(
            f"rotation #{index} requested but the capture holds {capture.rotations} whole rotation(s)", path
        )
    stamp, points = found
    first = float(points["time"].min())
    attributes = {
        "intensity": points["intensity"].astype(np.float32),
        "ring": points["ring"].astype(np.uint16),
        "time": points["time"].astype(np.float64) - first,
    }
    if capture.return_mode == "dual":
        attributes["return_type"] = points["return_type"].astype(np.uint8)
    xyz = np.column_stack([points[a] for a in "xyz"]).astype(np.float64)
    preset = PRESET_OF_MODEL.get(capture.model)
    scan = scan_from_rows(xyz, attributes, path, sensor=sensor or (PRESETS.get(preset) if preset else None))
    scan.source = f"{path}#{index}"
    scan.stamp_s = stamp + first
    return scan
