"""ROS bags as scan containers, through ``rosbags`` (no ROS install): ROS 1 ``.bag`` files, ROS 2
bag folders (``metadata.yaml`` with sqlite3 or MCAP storage) and plain ``.mcap`` / ``.db3`` files.

Every message of a ``sensor_msgs/PointCloud2`` topic is one scan: ``bag#k`` selects the k-th
(0-based, in recording order), ``bag#/topic#k`` names the topic when the bag has several. The
header stamp becomes the scan's ``stamp_s``.

The bag itself is opened and indexed by :mod:`.bag`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...errors import InputError
from ...scan import Scan
from ...sensors.models import SensorModel
from ..rows import scan_from_rows
from .bag import _detail, bag_topics, message_times, nth_message, open_bag, stamp_seconds, topic_connections
from .pointcloud2 import CloudLayoutError, PointField, decode_cloud

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"


def cloud_topic(reader, path: Path, topic: str | None) -> str:
    """The PointCloud2 topic the scans come from: ``topic``, or the bag's only one."""
    topics = bag_topics(reader)
    clouds = [t.name for t in topics if t.msgtype == POINTCLOUD2]
    listing = ", ".join(f"{t.name} ({t.msgtype.replace('/msg/', '/')}, {t.count})" for t in topics) or "none"
    if topic is None:
        if len(clouds) == 1:
            return clouds[0]
        if not clouds:
            raise InputError(f"the bag holds no sensor_msgs/PointCloud2 topic; its topics: {listing}", path)
        raise InputError(
            f"the bag holds {len(clouds)} PointCloud2 topics: name one ({path}#/TOPIC#k, or topic: in a sequence); "
            f"topics: {listing}",
            path,
        )
    if topic not in clouds:
        problem = "is not a PointCloud2 topic" if topic in {t.name for t in topics} else "is not in the bag"
        raise InputError(f"topic {topic} {problem}; its topics: {listing}", path)
    return topic


def cloud_of(msg, path: Path, where: str) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Decode a deserialised PointCloud2 message."""
    fields = [PointField(f.name, f.offset, f.datatype, f.count) for f in msg.fields]
    try:
        return decode_cloud(fields, msg.height, msg.width, msg.point_step, msg.row_step, msg.is_bigendian, msg.data)
    except CloudLayoutError as e:
        raise InputError(f"{where}: unreadable PointCloud2: {e}", path) from None


def count_rosbag(path: Path, topic: str | None = None) -> int:
    reader = open_bag(path)
    return sum(c.msgcount for c in topic_connections(reader, cloud_topic(reader, path, topic)))


def read_rosbag(
    path: Path, index: int = 0, sensor: SensorModel | None = None, topic: str | None = None, poses: dict | None = None
) -> Scan:
    """Scan ``index`` of the bag's PointCloud2 ``topic``; with ``poses`` ({topic, frame}) its
    pose interpolated at its header stamp, and from an Odometry topic its ``sweep_motion`` (see
    :mod:`lidarfield.io.rosbag.poses`)."""
    from .poses import pose_and_motion_from_bag  # SciPy: only for scans posed from the bag

    reader = open_bag(path)
    topic = cloud_topic(reader, path, topic)
    connections = topic_connections(reader, topic)
    times = message_times(reader, connections)
    where = f"{topic} message #{index}"
    try:
        connection, _, raw = nth_message(reader, connections, times, index)
        msg = reader.deserialize(raw, connection.msgtype)
        xyz, attributes = cloud_of(msg, path, where)
        stamp_s = stamp_seconds(msg.header)
        pose, motion = (
            (None, None) if poses is None else pose_and_motion_from_bag(reader, path, poses, stamp_s, int(times[index]))
        )
    except InputError as e:
        if e.path is None:
            raise InputError(f"{where}: {e}", path) from None
        raise
    except Exception as e:  # truncated or corrupt data: rosbags, lz4, zstd and struct errors
        raise InputError(f"{where} cannot be read: {_detail(e)}", path) from None
    scan = scan_from_rows(xyz, attributes, path, sensor=sensor, pose=pose)
    scan.source = f"{path}#{topic}#{index}"
    scan.stamp_s = stamp_s
    scan.sweep_motion = motion
    return scan
