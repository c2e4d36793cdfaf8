"""What a scan file holds, in a few lines: its format, its scans and, for recordings, the
topics or packets, the time span and the point fields (``lidarfield info FILE``)."""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from ..scan import Scan
from . import read_scan, scan_count, scan_format, split_reference

MAX_TOPICS = 15  # one screen
MAX_CLOUD_TOPICS = 4


def describe_file(reference: str | Path) -> str:
    reference = split_reference(reference)
    fmt = scan_format(reference.path)
    if fmt.name == "rosbag":
        return _describe_bag(reference.path)
    if fmt.name == "pcap":
        from .formats.pcap import capture_vendor

        if capture_vendor(reference.path) == "velodyne":
            return _describe_velodyne(reference.path)
    count = scan_count(reference.path)
    lines = [f"{reference.path}: {fmt.name} file, {count} scan(s)" + (f" (#0..#{count - 1})" if count > 1 else "")]
    first = read_scan(f"{reference.path}#0" if fmt.container else reference.path)
    lines.append(_scan_line("scan #0" if fmt.container else "scan", first))
    return "\n".join(lines)


def _scan_line(label: str, scan: Scan) -> str:
    extent = np.linalg.norm(scan.xyz, axis=1).max()
    parts = [
        f"{label}: {len(scan):,} points ({scan.dropped_invalid:,} invalid rows dropped), farthest {extent:.1f} m",
        f"attributes: {', '.join(scan.attributes) or 'none'}",
        f"sensor: {scan.sensor.name if scan.sensor else 'not given'}",
        f"pose: {'given' if scan.pose is not None else 'none'}",
    ]
    if scan.stamp_s is not None:
        parts.append(f"stamp {_time(scan.stamp_s)}")
    return "; ".join(parts)


def _time(seconds: float) -> str:
    return datetime.fromtimestamp(seconds, timezone.utc).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] + " UTC"


def _span(start_s: float, end_s: float) -> str:
    return f"{_time(start_s)} .. {_time(end_s)} ({end_s - start_s:.3f} s)"


def _describe_bag(path: Path) -> str:
    from .rosbag.bag import bag_topics, message_times, nth_message, open_bag, topic_connections
    from .rosbag.poses import POSE_OF, TF
    from .rosbag.reader import POINTCLOUD2

    reader = open_bag(path)
    topics = bag_topics(reader)
    kind = "ROS 1 bag" if not reader.is2 else "ROS 2 bag" + (" folder" if path.is_dir() else "")
    total = sum(t.count for t in topics)
    lines = [
        f"{path}: {kind}, {total:,} messages on {len(topics)} topics, "
        f"{_span(reader.start_time * 1e-9, reader.end_time * 1e-9)}"
    ]
    roles = {**{msgtype: "poses" for msgtype in (*POSE_OF, TF)}, POINTCLOUD2: "scans"}
    order = {"poses": 0, "scans": 1, "": 2}  # the few pose topics stay in view
    topics.sort(key=lambda t: (order[roles.get(t.msgtype, "")], t.name))
    width = max([len(t.name) for t in topics[:MAX_TOPICS]] + [5])
    for topic in topics[:MAX_TOPICS]:
        role = roles.get(topic.msgtype, "")
        lines.append(f"  {topic.name:<{width}}  {topic.msgtype.replace('/msg/', '/'):<42} {topic.count:>9,}  {role}")
    if len(topics) > MAX_TOPICS:
        lines.append(f"  ... and {len(topics) - MAX_TOPICS} more topics")
    clouds = sorted((t for t in topics if t.msgtype == POINTCLOUD2), key=lambda t: -t.count)  # main lidars first
    for topic in clouds[:MAX_CLOUD_TOPICS]:
        connections = topic_connections(reader, topic.name)
        times = message_times(reader, connections)
        if not len(times):
            continue
        connection, _, raw = nth_message(reader, connections, times, 0)
        msg = reader.deserialize(raw, connection.msgtype)
        fields = " ".join(f.name for f in msg.fields)
        select = f"{path}#{topic.name}#k" if len(clouds) > 1 else f"{path}#k"
        lines.append(
            f"scans on {topic.name}: {topic.count:,} ({select}, k = 0..{topic.count - 1}), "
            f"{msg.height} x {msg.width} points of {msg.point_step} bytes, fields {fields}"
        )
    if len(clouds) > MAX_CLOUD_TOPICS:
        lines.append(f"... and {len(clouds) - MAX_CLOUD_TOPICS} more PointCloud2 topics")
    if not clouds:
        lines.append("no sensor_msgs/PointCloud2 topic: no scans")
    return "\n".join(lines)


def _describe_velodyne(path: Path) -> str:
    from .formats.velodyne import capture_summary

    capture = capture_summary(path)
    scan = read_scan(f"{path}#0") if capture.rotations else None
    lines = [
        f"{path}: Velodyne capture, {capture.model}, {capture.return_mode} return(s)",
        f"packets: {capture.data_packets:,} data, {capture.other_packets:,} other; {capture.rotations} whole "
        f"rotation(s)"
        + (f" (#0..#{capture.rotations - 1})" if capture.rotations else "")
        + f", {capture.dropped_packets} data packets after the last one (a partial rotation) not used",
    ]
    if scan is not None:
        lines.append(_scan_line("scan #0", scan))
    return "\n".join(lines)
