"""A scan's pose from the pose messages of its bag, interpolated at the scan's header stamp.

Sources (``{"topic": ..., "frame": ...}``): ``nav_msgs/Odometry``, ``geometry_msgs/PoseStamped``
and ``PoseWithCovarianceStamped`` (the pose as published, taken as world-from-sensor), or a
``tf2_msgs/TFMessage`` topic (``/tf``) with the sensor's ``frame``: the frame's transforms are
composed up to the root of its tree, with the static ones of ``/tf_static`` when the bag has it.
Between two messages the translation is linear and the rotation a slerp; a stamp outside the
messages' time span is an error. Only the messages recorded within ``WINDOW_NS`` of the scan
are read (all of them if those do not bracket its stamp).

An Odometry topic also gives the scan's ``sweep_motion``: the twist of the message nearest its
stamp. ROS publishes it in the message's ``child_frame_id`` frame, the frame whose pose the
message gives; that frame is taken as the sensor's, as for the pose (no extrinsic is known here),
so the twist as published is the sensor's velocities in its own frame. A twist of exact zeros or
with a NaN is taken as not filled in (many odometry publishers leave it so) and gives no record;
pose messages and TF carry no twist.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from ...errors import InputError
from ...poses import interpolate_pose, poses_from_quaternions
from .bag import bag_topics, read_messages, stamp_seconds, topic_connections

POSE_OF = {
    "nav_msgs/msg/Odometry": lambda m: m.pose.pose,
    "geometry_msgs/msg/PoseStamped": lambda m: m.pose,
    "geometry_msgs/msg/PoseWithCovarianceStamped": lambda m: m.pose.pose,
}
TWIST_OF = {"nav_msgs/msg/Odometry": lambda m: m.twist.twist}
TWIST = "twist"  # the key of a pose topic's twists among its tracks (TF's child frames have none)
TF = "tf2_msgs/msg/TFMessage"
STATIC_TF = "/tf_static"
WINDOW_NS = 5 * 10**9


def pose_and_motion_from_bag(
    reader, path, source: dict, stamp_s: float, near_ns: int
) -> tuple[np.ndarray, dict | None]:
    """World-from-sensor pose at ``stamp_s`` from ``source`` (``topic``, and ``frame`` for TF), and
    the sensor's motion then as a ``sweep_motion`` when the source records it (an Odometry twist)."""
    topic, frame = source["topic"], source.get("frame")
    types = {t.name: t.msgtype for t in bag_topics(reader)}
    kinds = ", ".join(sorted(k.replace("/msg/", "/") for k in (*POSE_OF, TF)))
    if topic not in types:
        raise InputError(f"pose topic {topic} is not in the bag; its topics: {', '.join(sorted(types))}", path)
    if types[topic] not in POSE_OF and types[topic] != TF:
        raise InputError(f"pose topic {topic} holds {types[topic]}, not one of {kinds}", path)
    if types[topic] == TF and not frame:
        raise InputError(f"pose topic {topic} is TF: give the sensor's child frame (frame: ...)", path)
    for start, stop in ((near_ns - WINDOW_NS, near_ns + WINDOW_NS), (None, None)):
        tracks = _tracks(reader, topic, types, start, stop)
        if types[topic] == TF:
            pose = _compose(tracks, frame, stamp_s)
        else:
            pose = interpolate_pose(*tracks[None][1:], stamp_s) if None in tracks else None
        if pose is not None:
            return pose, _sweep_motion(tracks.get(TWIST), stamp_s)
    if types[topic] == TF and frame not in tracks:
        children = sorted(k for k in tracks if k is not None)
        raise InputError(
            f"no transform on {topic} has child frame {frame!r}; child frames: {', '.join(children) or 'none'}", path
        )
    stamps = np.concatenate([t[1] for t in tracks.values() if len(t[1])] or [np.zeros(0)])
    span = f"{stamps.min():.6f} .. {stamps.max():.6f} s" if len(stamps) else "no messages"
    raise InputError(
        f"scan stamp {stamp_s:.6f} s lies outside the time span of the pose messages on {topic} ({span})", path
    )


def _tracks(reader, topic: str, types: dict, start, stop) -> dict:
    """{child frame (None for a pose topic): (parent, stamps (s), poses (M, 4, 4))}, by stamp; an
    Odometry topic's twists under ``TWIST``: (None, stamps, (M, 2, 3) linear and angular)."""
    samples: dict = defaultdict(list)
    parents: dict = {}
    sources = [(topic, start, stop)] + ([(STATIC_TF, None, None)] if types[topic] == TF and STATIC_TF in types else [])
    for name, first, last in sources:
        for _, msg in read_messages(reader, topic_connections(reader, name), first, last):
            if name == topic and types[topic] in POSE_OF:
                pose = POSE_OF[types[topic]](msg)
                samples[None].append((stamp_seconds(msg.header), _matrix(pose.position, pose.orientation)))
                if types[topic] in TWIST_OF:
                    twist = TWIST_OF[types[topic]](msg)
                    samples[TWIST].append((stamp_seconds(msg.header), _vectors(twist.linear, twist.angular)))
                continue
            for t in msg.transforms:
                parents[t.child_frame_id] = t.header.frame_id
                stamp = -np.inf if name == STATIC_TF else stamp_seconds(t.header)
                samples[t.child_frame_id].append((stamp, _matrix(t.transform.translation, t.transform.rotation)))
    tracks = {}
    for child, timed in samples.items():
        timed.sort(key=lambda s: s[0])
        stamps = np.array([s[0] for s in timed])
        tracks[child] = (parents.get(child), stamps, np.stack([s[1] for s in timed]))
    return tracks


def _compose(tracks: dict, frame: str, stamp_s: float) -> np.ndarray | None:
    """Root-from-frame at ``stamp_s`` along the frame's parents; None if a transform is missing
    then (or the frame has none)."""
    if frame not in tracks:
        return None
    pose, seen = np.eye(4), set()
    while frame in tracks and frame not in seen:
        seen.add(frame)
        parent, stamps, poses = tracks[frame]
        step = poses[-1] if np.isneginf(stamps[-1]) else interpolate_pose(stamps, poses, stamp_s)  # static
        if step is None:
            return None
        pose = step @ pose
        frame = parent
    return pose


def _sweep_motion(twists, stamp_s: float) -> dict | None:
    """The twist nearest ``stamp_s`` as a ``sweep_motion``; None without one, or one not filled in."""
    if twists is None:
        return None
    _, stamps, values = twists
    nearest = values[int(np.argmin(np.abs(stamps - stamp_s)))]
    if not (np.isfinite(nearest).all() and np.any(nearest)):
        return None
    linear, angular = nearest
    return {"velocity_mps": linear.tolist(), "angular_velocity_rps": angular.tolist(), "source": "odometry"}


def _vectors(*vectors) -> np.ndarray:
    return np.array([[v.x, v.y, v.z] for v in vectors], dtype=np.float64)


def _matrix(translation, quaternion) -> np.ndarray:
    q = [quaternion.w, quaternion.x, quaternion.y, quaternion.z]
    return poses_from_quaternions(q, [translation.x, translation.y, translation.z])[0]
