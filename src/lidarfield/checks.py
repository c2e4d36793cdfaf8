"""The one check of a setting's number: what a config, a hypothesis's parameters or a grid
accept as a number."""

from __future__ import annotations

import math

import numpy as np


def is_number(value, *, finite: bool = False, positive: bool = False) -> bool:
    """A real number: int, float or a NumPy scalar of either, not a bool (YAML's ``yes`` is
    not a number); with ``finite`` not NaN nor infinite; with ``positive`` finite and > 0."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        return False
    if positive:
        return math.isfinite(value) and value > 0
    return math.isfinite(value) if finite else True


def is_integer(value) -> bool:
    """An int or a NumPy integer, not a bool."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)
