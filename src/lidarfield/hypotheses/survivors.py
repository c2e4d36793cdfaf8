"""Rows of a cloud after a removal: what a carried neighbourhood is numbered by."""

from __future__ import annotations

import numpy as np


def survivor_rows(keep: np.ndarray) -> np.ndarray:
    """Each row of the cloud before a removal, numbered among the rows ``keep`` (a mask) that
    survive it (int32: a neighbour index's type). Meaningful only at surviving rows."""
    return np.cumsum(keep, dtype=np.int32) - 1
