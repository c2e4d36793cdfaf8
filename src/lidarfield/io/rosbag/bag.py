"""Access to a ROS bag through ``rosbags`` (no ROS install): opening it, its topics, and its
messages by index.

Reading is lazy: the bag's index gives each message's recording time without reading any
message data (the ROS 1 index, the sqlite3 ``timestamp`` column, the MCAP message indexes),
and only the chunk holding the wanted message is then read.
"""

from __future__ import annotations

import struct
from functools import lru_cache
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ...errors import InputError
from ..rows import file_key

_INSTALL = "reading ROS bags needs the rosbags package: pip install rosbags"


class TopicInfo(NamedTuple):
    name: str
    msgtype: str
    count: int


def is_bag_folder(path: Path) -> bool:
    """A ROS 2 bag folder: a directory holding ``metadata.yaml``."""
    return path.is_dir() and (path / "metadata.yaml").is_file()


def open_bag(path: Path):
    """An open ``rosbags`` AnyReader of the bag; any failure to open is an ``InputError`` naming
    it. Kept open for the next call on the same unchanged file (opening parses every message
    definition: a tenth of a second or more, whatever the bag's size)."""
    path = Path(path)
    files = sorted(path.iterdir()) if path.is_dir() else [path]
    return _open_reader(tuple(file_key(f) for f in files if f.is_file()), str(path))


@lru_cache(maxsize=2)
def _open_reader(_state: tuple, path: str):
    """The reader of ``path``, cached while its files' state (path, size, time) is unchanged."""
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise InputError(_INSTALL) from None
    try:
        reader = AnyReader([Path(path)], default_typestore=get_typestore(Stores.LATEST))
        reader.open()
    except Exception as e:  # rosbags raises its own error types, struct and decompression errors
        raise InputError(f"not a readable ROS bag: {_detail(e)}", path) from None
    return reader


def bag_topics(reader) -> list[TopicInfo]:
    """The bag's topics with their message type and count, by name."""
    counts: dict[str, list] = {}
    for c in reader.connections:
        entry = counts.setdefault(c.topic, [c.msgtype, 0])
        entry[1] += c.msgcount
    return [TopicInfo(name, msgtype, count) for name, (msgtype, count) in sorted(counts.items())]


def topic_connections(reader, topic: str) -> list:
    return [c for c in reader.connections if c.topic == topic]


def message_times(reader, connections: list) -> np.ndarray:
    """Recording times (ns, sorted) of the connections' messages, from the bag's indexes."""
    from rosbags.rosbag1 import Reader as Reader1

    times: list[int] = []
    topics = {c.topic for c in connections}
    for owner in {id(c.owner): c.owner for c in connections}.values():
        if isinstance(owner, Reader1):
            times += [entry.time for c in connections if c.owner is owner for entry in owner.indexes[c.id]]
            continue
        storage = getattr(owner, "storage", owner)  # a folder's reader holds one storage per file
        for part in getattr(storage, "storages", [storage]):
            ids = [c.id for c in part.connections if c.topic in topics]
            times += _storage_times(part, ids)
    return np.sort(np.asarray(times, dtype=np.int64))


def _storage_times(storage, ids: list[int]) -> list[int]:
    """Recording times of a ROS 2 storage file's messages on the given connection ids."""
    if not ids:
        return []
    if hasattr(storage, "dbconn"):  # sqlite3: the timestamp column, no message data
        marks = ",".join("?" * len(ids))
        query = f"SELECT timestamp FROM messages WHERE topic_id IN ({marks})"
        return [row[0] for row in storage.dbconn.execute(query, ids)]
    if getattr(storage, "chunks", None):  # MCAP: the message index record of each chunk
        times = []
        for chunk in storage.chunks:
            for cid in ids:
                if cid in chunk.message_index_offsets:
                    times += _mcap_index_times(storage.bio, chunk.message_index_offsets[cid])
        return times
    connections = [c for c in storage.connections if c.id in ids]  # unindexed: read it through
    return [t for _, t, _ in storage.messages(connections)]


def _mcap_index_times(bio, offset: int) -> list[int]:
    """The log times of one MCAP Message Index record (op 0x07: channel, then (time, offset) pairs)."""
    bio.seek(offset)
    op, _length, _channel, size = struct.unpack("<BQHI", bio.read(15))
    if op != 0x07:
        raise ValueError(f"no MCAP message index at offset {offset}")
    return np.frombuffer(bio.read(size), dtype="<u8")[0::2].astype(np.int64).tolist()


def nth_message(reader, connections: list, times: np.ndarray, index: int):
    """(connection, recording time, raw data) of message ``index`` of the connections, reading
    only the chunk that holds it."""
    time = int(times[index])
    rank = index - int(np.searchsorted(times, time, side="left"))  # messages sharing its time
    for k, message in enumerate(reader.messages(connections=connections, start=time, stop=time + 1)):
        if k == rank:
            return message
    raise InputError(f"message #{index} listed in the index is missing from the data")


def stamp_seconds(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def read_messages(reader, connections: list, start: int | None = None, stop: int | None = None):
    """Deserialised messages of the connections with their recording time (ns), in time order."""
    for connection, time, raw in reader.messages(connections=connections, start=start, stop=stop):
        yield time, reader.deserialize(raw, connection.msgtype)


def _detail(e: Exception) -> str:
    text = " ".join(str(e).split()) or type(e).__name__
    return text if len(text) < 200 else text[:197] + "..."
