"""The rigid translation between a scan and an aligned copy of it, row for row.

The authors of the ExpD pair published their NDT result only as ``Cloud10Aligned_ExpD.txt``,
``Cloud10_ExpD.txt`` with every point shifted by one translation. Both files keep the same line
order with NaN rows for missing returns, so the translation is the per-row difference, and its
spread over rows says whether the copy really is a pure translation.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError, RegistrationError
from ..io.atomic import write_text

# Text files print about 15 significant digits: a pure translation spreads by far less than this.
PURE_TRANSLATION_TOLERANCE_M = 1e-6


def read_xyz_rows(path: str | Path) -> np.ndarray:
    """Every row of a whitespace text file of ``x y z`` (N, 3), NaN rows kept in place."""
    path = Path(path)
    if not path.is_file():
        raise InputError("file not found", path)
    try:
        rows = np.loadtxt(path, usecols=(0, 1, 2), ndmin=2, comments="#")
    except (ValueError, IndexError) as e:
        raise InputError(f"not a text file of x y z rows: {e}", path) from None
    if len(rows) == 0:
        raise InputError("empty file: no x y z rows", path)
    return rows


def translation_offsets(original_xyz: np.ndarray, aligned_xyz: np.ndarray) -> np.ndarray:
    """``aligned - original`` for every row where both are finite (M, 3).

    Raises ``RegistrationError`` when the row counts differ or the rows without a return differ
    (then the files do not correspond row for row).
    """
    original = np.asarray(original_xyz, dtype=np.float64).reshape(-1, 3)
    aligned = np.asarray(aligned_xyz, dtype=np.float64).reshape(-1, 3)
    if original.shape != aligned.shape:
        raise RegistrationError(f"the scans do not correspond row for row: {len(original)} rows vs {len(aligned)}")
    valid_original = np.isfinite(original).all(axis=1)
    valid_aligned = np.isfinite(aligned).all(axis=1)
    mismatched = np.flatnonzero(valid_original != valid_aligned)
    if len(mismatched):
        raise RegistrationError(
            f"the scans do not correspond row for row: {len(mismatched)} row(s) are a return in one and "
            f"NaN in the other (first: row {mismatched[0] + 1})"
        )
    if not valid_original.any():
        raise RegistrationError("no row holds a return in both scans")
    return aligned[valid_original] - original[valid_original]


def translation_from_aligned_copy(
    original_xyz: np.ndarray, aligned_xyz: np.ndarray, tolerance_m: float = PURE_TRANSLATION_TOLERANCE_M
) -> np.ndarray:
    """The 4x4 pure translation T with ``aligned = T(original)`` row for row: the pose of the
    original scan's sensor in the aligned frame. Raises ``RegistrationError`` when the per-row
    offsets spread by more than ``tolerance_m`` (the copy is not a pure translation)."""
    offsets = translation_offsets(original_xyz, aligned_xyz)
    translation = offsets.mean(axis=0)
    spread = float(np.abs(offsets - translation).max())
    if spread > tolerance_m:
        raise RegistrationError(
            f"the aligned copy is not a pure translation: per-row offsets spread by {spread:.3g} m "
            f"(tolerance {tolerance_m:g} m)"
        )
    T = np.eye(4)
    T[:3, 3] = translation
    return T


def write_transform(path: str | Path, T: np.ndarray, comment: str | None = None) -> None:
    """A 4x4 pose as four text rows at full float64 precision (``read_pose`` reads it back)."""
    header = "".join(f"# {line}\n" for line in (comment or "").splitlines())
    body = "\n".join(" ".join(f"{v:.17g}" for v in row) for row in np.asarray(T, dtype=np.float64))
    write_text(path, header + body + "\n")
