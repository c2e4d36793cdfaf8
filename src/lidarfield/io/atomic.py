"""Write files whole or not at all: a failed or interrupted write never leaves a partial file.

A write that fails for want of space (a full file system, a spent quota) raises a
``StorageError`` naming the file and the space left, once its partial file is removed: one
line for the user, not a traceback from the library that was writing.
"""

from __future__ import annotations

import errno
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from ..errors import StorageError

# The errors of a write that found no room: no space left, or over the user's disk quota.
NO_ROOM = (errno.ENOSPC, errno.EDQUOT)


def free_space(folder: Path) -> str:
    """The space left to this user on ``folder``'s file system, for a person to read."""
    status = os.statvfs(folder)
    free = status.f_bavail * status.f_frsize
    text = f"{free / 1e6:.1f} MB free" if free >= 1e6 else f"{free / 1e3:.0f} kB free"
    if status.f_files and not status.f_favail:  # (f_files 0: a file system without an inode count)
        text += ", but no file can be made: no inode left"
    return text


def no_room_error(path: Path, error: OSError) -> StorageError:
    """``error`` (no space, or over quota) while writing ``path``, as one line."""
    folder = next((p for p in (path.parent, *path.parents) if p.is_dir()), Path("."))
    return StorageError(f"could not be written: {os.strerror(error.errno)} ({free_space(folder)})", path)


def storage_error(error: OSError) -> StorageError | None:
    """``error`` as a ``StorageError`` when it is a write (outside ``atomic_path``: a folder
    made, ...) that found no room and names its file; else None."""
    if error.errno in NO_ROOM and error.filename is not None:
        return no_room_error(Path(os.fsdecode(error.filename)), error)
    return None


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it is renamed onto ``path``."""
    path = Path(path)
    tmp_path = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
        os.close(fd)
        tmp_path = Path(tmp)
        # mkstemp makes the file private (0600); outputs get the usual mode the umask allows.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        yield tmp_path
        os.replace(tmp_path, path)
    except OSError as error:
        if error.errno not in NO_ROOM:
            raise
        if tmp_path is not None:
            tmp_path.unlink(missing_ok=True)  # before measuring the space left
        raise no_room_error(path, error) from error
    finally:
        if tmp_path is not None and tmp_path.exists():
            tmp_path.unlink()


def write_text(path: str | Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text)
