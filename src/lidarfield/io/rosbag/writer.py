"""Write scans into a ROS bag as drivers publish them, with ``rosbags``' own writers: ROS 1
``.bag``, ROS 2 folders with sqlite3 or MCAP storage. The tests and the benchmark build their
bags from real scans with it; a user can hand scans to ROS tools the same way.

Point layouts (``LAYOUTS``): ``velodyne`` (the Velodyne driver's 22-byte point: x, y, z,
intensity float32, ring uint16, time float32 seconds), ``ouster`` (the Ouster driver's 48-byte
padded point: x, y, z, pad, intensity float32, t uint32 ns, reflectivity, ring, ambient uint16,
range uint32) and ``xyz`` (three float32). A scan whose rows are ``rows x columns`` can be
written organised (``height`` = rows).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...scan import Scan
from .pointcloud2 import DATATYPES

LAYOUTS: dict[str, dict] = {
    "velodyne": {
        "names": ["x", "y", "z", "intensity", "ring", "time"],
        "formats": ["f4", "f4", "f4", "f4", "u2", "f4"],
        "offsets": [0, 4, 8, 12, 16, 18],
        "itemsize": 22,
    },
    "ouster": {
        "names": ["x", "y", "z", "intensity", "t", "reflectivity", "ring", "ambient", "range"],
        "formats": ["f4", "f4", "f4", "f4", "u4", "u2", "u2", "u2", "u4"],
        "offsets": [0, 4, 8, 16, 20, 24, 26, 28, 32],
        "itemsize": 48,
    },
    "xyz": {"names": ["x", "y", "z"], "formats": ["f4", "f4", "f4"], "offsets": [0, 4, 8], "itemsize": 12},
}
STORAGES = ("ros1", "sqlite3", "mcap")
_DATATYPE_OF = {np.dtype(code).str[1:]: number for number, code in DATATYPES.items()}


@dataclass
class CloudMessage:
    """One scan to write: its header stamp (s) and, optionally, its organised shape."""

    scan: Scan
    stamp_s: float
    shape: tuple[int, int] | None = None  # (height, width) of an organised cloud
    topic: str | None = None  # default: write_bag's topic
    layout: str | None = None  # default: write_bag's layout


def layout_dtype(layout: str, big_endian: bool = False) -> np.dtype:
    spec = LAYOUTS[layout]
    order = ">" if big_endian else "<"
    return np.dtype({**spec, "formats": [order + f for f in spec["formats"]]})


def write_bag(
    path: str | Path,
    clouds: list[CloudMessage],
    *,
    storage: str = "ros1",
    topic: str = "/points",
    layout: str = "velodyne",
    big_endian: bool = False,
    poses: list[tuple[float, np.ndarray]] = (),
    twists: list[tuple[list[float], list[float]]] = (),
    pose_topic: str = "/odom",
    pose_type: str = "nav_msgs/msg/Odometry",
    frame_id: str = "lidar",
) -> Path:
    """Write the clouds on ``topic`` and the poses (stamp s, 4x4 world-from-sensor) on
    ``pose_topic`` as Odometry, PoseStamped or PoseWithCovarianceStamped, or as TF
    (``tf2_msgs/msg/TFMessage``, ``world`` -> ``frame_id``). Recording time = header stamp.
    ``twists``: one (linear m/s, angular rad/s) per pose, in ``frame_id`` as Odometry's twist is
    (default zero; pose types without a twist ignore them).
    Returns the bag's path (a folder for ROS 2 storages)."""
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    ros1 = storage == "ros1"
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if "tf2_msgs/msg/TFMessage" not in store.types:  # not in rosbags' ROS 1 store
        from rosbags.typesys import get_types_from_msg

        store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    serialize = store.serialize_ros1 if ros1 else store.serialize_cdr
    dtypes = {name: layout_dtype(name, big_endian) for name in LAYOUTS}
    # Each message is built only when it is written: a bag of gigabytes never sits in memory.
    messages = [
        (
            c.stamp_s,
            c.topic or topic,
            lambda c=c: _cloud_message(store, c, dtypes[c.layout or layout], big_endian, frame_id),
        )
        for c in clouds
    ]
    twists = list(twists) or [((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))] * len(poses)
    if len(twists) != len(poses):
        raise ValueError(f"write_bag: {len(twists)} twists for {len(poses)} poses")
    messages += [
        (
            stamp,
            pose_topic,
            lambda stamp=stamp, pose=pose, twist=twist: _pose_message(store, pose_type, stamp, pose, twist, frame_id),
        )
        for (stamp, pose), twist in zip(poses, twists)
    ]
    types = {name: pose_type if name == pose_topic else "sensor_msgs/msg/PointCloud2" for _, name, _ in messages}
    with _writer(path, storage) as writer:
        connections = {name: writer.add_connection(name, msgtype, typestore=store) for name, msgtype in types.items()}
        for stamp, name, build in sorted(messages, key=lambda m: m[0]):
            writer.write(connections[name], _ns(stamp), serialize(build(), types[name]))
    return path


def _writer(path: Path, storage: str):
    if storage == "ros1":
        from rosbags.rosbag1 import Writer

        return Writer(path)
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}[storage]
    return Writer(path, version=9, storage_plugin=plugin)


def _ns(stamp_s: float) -> int:
    return int(round(stamp_s * 1e9))


def _header(store, stamp_s: float, frame_id: str):
    ns = _ns(stamp_s)
    stamp = store.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
    fields = store.types["std_msgs/msg/Header"].__dataclass_fields__
    extra = {"seq": 0} if "seq" in fields else {}
    return store.types["std_msgs/msg/Header"](**extra, stamp=stamp, frame_id=frame_id)


def _cloud_message(store, cloud: CloudMessage, dtype: np.dtype, big_endian: bool, frame_id: str):
    from .pointcloud2 import encode_cloud

    scan = cloud.scan
    attributes = {name: _attribute(scan, name) for name in dtype.names if name not in ("x", "y", "z")}
    data = encode_cloud(scan.xyz, attributes, dtype)
    height, width = cloud.shape or (1, len(scan))
    Field = store.types["sensor_msgs/msg/PointField"]
    fields = [
        Field(name=name, offset=dtype.fields[name][1], datatype=_DATATYPE_OF[dtype.fields[name][0].str[1:]], count=1)
        for name in dtype.names
    ]
    return store.types["sensor_msgs/msg/PointCloud2"](
        header=_header(store, cloud.stamp_s, frame_id),
        height=height,
        width=width,
        fields=fields,
        is_bigendian=big_endian,
        point_step=dtype.itemsize,
        row_step=dtype.itemsize * width,
        data=np.frombuffer(data, dtype=np.uint8),
        is_dense=False,
    )


def _attribute(scan: Scan, name: str) -> np.ndarray:
    """A layout field from the scan's attributes (``t`` from ``time`` in s); zero when absent."""
    if name == "t" and "time" in scan.attributes:
        return np.round(np.asarray(scan.attributes["time"]) * 1e9)
    return scan.attributes.get(name, np.zeros(len(scan)))


def _pose_message(store, pose_type: str, stamp_s: float, pose: np.ndarray, twist, frame_id: str):
    from scipy.spatial.transform import Rotation

    T = store.types
    x, y, z, w = Rotation.from_matrix(np.asarray(pose)[:3, :3]).as_quat()
    position = T["geometry_msgs/msg/Point"](x=pose[0, 3], y=pose[1, 3], z=pose[2, 3])
    orientation = T["geometry_msgs/msg/Quaternion"](x=x, y=y, z=z, w=w)
    header = _header(store, stamp_s, "world")
    plain = T["geometry_msgs/msg/Pose"](position=position, orientation=orientation)
    covariance = np.zeros(36)
    with_covariance = T["geometry_msgs/msg/PoseWithCovariance"](pose=plain, covariance=covariance)
    if pose_type == "nav_msgs/msg/Odometry":
        linear, angular = (T["geometry_msgs/msg/Vector3"](**dict(zip("xyz", map(float, v)))) for v in twist)
        moving = T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=linear, angular=angular), covariance=covariance
        )
        return T[pose_type](header=header, child_frame_id=frame_id, pose=with_covariance, twist=moving)
    if pose_type == "geometry_msgs/msg/PoseStamped":
        return T[pose_type](header=header, pose=plain)
    if pose_type == "geometry_msgs/msg/PoseWithCovarianceStamped":
        return T[pose_type](header=header, pose=with_covariance)
    translation = T["geometry_msgs/msg/Vector3"](x=pose[0, 3], y=pose[1, 3], z=pose[2, 3])
    transform = T["geometry_msgs/msg/TransformStamped"](
        header=header,
        child_frame_id=frame_id,
        transform=T["geometry_msgs/msg/Transform"](translation=translation, rotation=orientation),
    )
    return T["tf2_msgs/msg/TFMessage"](transforms=[transform])
