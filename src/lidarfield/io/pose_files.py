"""Pose files: a 4x4 or 3x4 matrix, or KITTI pose lines (12 numbers per line, the top three
rows of a world-from-sensor matrix, row-major)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..poses import NUMBER_SEPARATORS, pose_from_numbers, rigid_pose
from .atomic import write_text


def read_pose(path: str | Path, line: int = 0) -> np.ndarray:
    """A 4x4 pose from a text file: a 4x4 matrix (4 rows of 4, or one row of 16), a 3x4 matrix
    (3 rows of 4), or KITTI pose lines of 12 numbers, of which ``line`` (0-based) is taken."""
    path = Path(path)
    rows = _numeric_rows(path)
    widths = {len(r) for r in rows}
    if widths == {12}:
        if not 0 <= line < len(rows):
            raise InputError(f"pose line {line} requested but the file holds {len(rows)} KITTI pose line(s)", path)
        return rigid_pose(pose_from_numbers(rows[line]), path)
    if line != 0:
        raise InputError(f"pose line {line} requested but the file holds one matrix, not KITTI pose lines", path)
    if widths == {4} and len(rows) in (3, 4) or widths == {16} and len(rows) == 1:
        return rigid_pose(pose_from_numbers(np.concatenate(rows)), path)
    shape = " + ".join(str(len(r)) for r in rows) if len(rows) <= 6 else f"{len(rows)} rows of {sorted(widths)}"
    raise InputError(
        f"not a pose: found {len(rows)} row(s) of numbers ({shape}); expected a 4x4 or 3x4 matrix or "
        "KITTI lines of 12 numbers",
        path,
    )


def read_kitti_poses(path: str | Path, expected: int | None = None) -> np.ndarray:
    """All poses of a KITTI pose file, (M, 4, 4); one 12-number line per scan.

    With ``expected`` (the number of scans), a file with fewer lines is an error.
    """
    path = Path(path)
    rows = _numeric_rows(path)
    bad = [k for k, r in enumerate(rows) if len(r) != 12]
    if bad:
        raise InputError(f"KITTI pose line {bad[0] + 1} has {len(rows[bad[0]])} numbers, expected 12", path)
    if expected is not None and len(rows) < expected:
        raise InputError(f"holds {len(rows)} pose line(s) for {expected} scans: every scan needs one", path)
    return np.stack([rigid_pose(pose_from_numbers(r), path) for r in rows])


def write_kitti_poses(path: str | Path, poses: np.ndarray) -> None:
    """One KITTI line (top 3x4, row-major) per pose, written whole."""
    lines = [" ".join(f"{v:.17g}" for v in np.asarray(T)[:3].ravel()) for T in poses]
    write_text(path, "\n".join(lines) + "\n")


def _numeric_rows(path: Path) -> list[np.ndarray]:
    if not path.is_file():
        raise InputError("pose file not found", path)
    rows = []
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise InputError("not a text pose file", path) from None
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        try:
            rows.append(np.array([float(v) for v in NUMBER_SEPARATORS.split(line) if v], dtype=np.float64))
        except ValueError:
            raise InputError(f"line {number} is not numeric: {line[:60]!r}", path) from None
    if not rows:
        raise InputError("empty pose file", path)
    return rows


# --- conversions -------------------------------------------------------------------------------
