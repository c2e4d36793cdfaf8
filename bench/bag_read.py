"""Benchmark: one scan from the middle of a 1 GB ROS bag against reading the whole bag.

For each storage (ROS 1, ROS 2 MCAP, ROS 2 sqlite3) it writes a bag of about 1 GB in a
temporary folder: two lidar topics at 10 Hz (the real OS1-128 scan in the Ouster driver's
48-byte layout, 5.2 MB a message, and the real HDL-32E scan in the Velodyne 22-byte layout,
1.5 MB) and odometry at 100 Hz. Then it times ``read_scan(bag#/topic#k)`` for the middle scan
of the Ouster topic (open, index, one chunk, decode) against one pass over every message of the
bag (``rosbags``' AnyReader, raw data, no decoding), both from a closed bag (as a new process
finds it, page cache aside), and prints the ratio; each bag is deleted
before the next is written. Run: python bench/bag_read.py [--gigabytes 1.0] [--dir /tmp]
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
from pathlib import Path

import numpy as np

from lidarfield.io import read_scan
from lidarfield.io.rosbag.bag import _open_reader, open_bag
from lidarfield.io.rosbag.writer import CloudMessage, write_bag
from timing import best_time, machine  # bench/timing.py

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
OUSTER_TOPIC, VELODYNE_TOPIC = "/os_cloud_node/points", "/velodyne_points"


def build_bag(folder: Path, storage: str, gigabytes: float) -> tuple[Path, int]:
    """A bag of about ``gigabytes``; returns it and its number of Ouster scans."""
    ouster = read_scan(DATA / "ouster-os1-128" / "lb_n3_scan0_xyz_refl_float32.bin")
    velodyne = read_scan(DATA / "hdl32-pair" / "source.ply")
    bytes_per_second = 10 * (48 * len(ouster) + 22 * len(velodyne))
    seconds = gigabytes * 1e9 / bytes_per_second
    frames = int(seconds * 10)
    clouds = [CloudMessage(ouster, 0.1 * k, topic=OUSTER_TOPIC, layout="ouster") for k in range(frames)]
    clouds += [CloudMessage(velodyne, 0.1 * k + 0.05, topic=VELODYNE_TOPIC, layout="velodyne") for k in range(frames)]
    path = folder / ("drive.bag" if storage == "ros1" else "drive")
    odometry = [(0.01 * k, np.eye(4)) for k in range(int(seconds * 100))]
    write_bag(path, clouds, storage=storage, poses=odometry)
    return path, frames


def read_everything(path: Path) -> int:
    reader = open_bag(path)
    return sum(len(raw) for _, _, raw in reader.messages())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gigabytes", type=float, default=1.0, help="size of each generated bag")
    parser.add_argument("--dir", default=tempfile.gettempdir(), help="where the bags are written (then deleted)")
    parser.add_argument("--repeat", type=int, default=3, help="best of this many runs")
    args = parser.parse_args()
    print(machine())
    print(
        f"bags of ~{args.gigabytes:g} GB: {OUSTER_TOPIC} (48-byte points) and {VELODYNE_TOPIC} at 10 Hz, /odom at 100 "
        f"Hz"
    )
    for storage in ("ros1", "mcap", "sqlite3"):
        folder = Path(tempfile.mkdtemp(prefix="lidarfield-bench-", dir=args.dir))
        try:
            path, frames = build_bag(folder, storage, args.gigabytes)
            size = sum(f.stat().st_size for f in ([path] if path.is_file() else path.iterdir()))
            middle = f"{path}#{OUSTER_TOPIC}#{frames // 2}"
            # Both from a closed bag, as a new process finds it (the reader cache emptied first).
            one, scan = best_time(lambda: (_open_reader.cache_clear(), read_scan(middle))[1], args.repeat)
            whole, total = best_time(lambda: (_open_reader.cache_clear(), read_everything(path))[1], args.repeat)
            print(
                f"{storage:8s} {size / 1e9:.2f} GB, {frames} scans a topic: one scan (#{frames // 2}, {len(scan):,} "
                f"points) "
                f"{one:.3f} s; every message ({total / 1e9:.2f} GB) {whole:.2f} s; ratio {one / whole:.3f}"
            )
        finally:
            shutil.rmtree(folder)


if __name__ == "__main__":
    main()
