"""What a hypothesis returns: keep-masks, and optionally corrected coordinates and what it fitted.

A hypothesis (built-in or plugin) returns either

- ``(keep1, keep2)``: one boolean keep-mask per cloud (a *removing* hypothesis), or
- a mapping (or an :class:`Outcome`) with the keys ``keep1``, ``keep2`` (optional: all kept),
  ``xyz1``, ``xyz2`` (optional: the cloud is not moved), ``T_1_2`` (optional: sensor 2's
  corrected pose in frame 1), ``fitted`` (optional: a JSON-able mapping of what was fitted
  and applied) and ``reason1``, ``reason2`` (optional: one string per point of the cloud, why
  it was removed; read for the removed points only, written in the removed file's ``reason``
  column). A hypothesis that returns a corrected cloud or pose is a *correcting* one.

``xyz1`` / ``xyz2`` are the corrected coordinates of **every** point of the cloud it was given,
``(N, 3)`` in frame 1, row for row (so a plugin can write ``pair.xyz2 + shift``); the stage
keeps the rows of its keep-mask. Points it removes go to the removed file as they were, not
corrected. Any wrong type, shape or a non-finite value is one :class:`HypothesisError`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import HypothesisError

KEYS = ("keep1", "keep2", "xyz1", "xyz2", "T_1_2", "fitted", "reason1", "reason2")


@dataclass(frozen=True)
class Outcome:
    """A hypothesis's result. Unpacks as ``keep1, keep2`` (what a removing hypothesis returns)."""

    keep1: np.ndarray
    keep2: np.ndarray
    xyz1: np.ndarray | None = None  # (N1, 3) corrected cloud 1, every row; None: not moved
    xyz2: np.ndarray | None = None  # (N2, 3) corrected cloud 2, every row; None: not moved
    T_1_2: np.ndarray | None = None  # corrected pose of sensor 2 in frame 1; None: unchanged
    fitted: dict = field(default_factory=dict)  # what was fitted and applied (JSON-able)
    reason1: np.ndarray | None = None  # (N1,) strings: why each removed point of cloud 1 went; None: not said
    reason2: np.ndarray | None = None

    def __iter__(self):
        return iter((self.keep1, self.keep2))

    @property
    def corrects(self) -> bool:
        """Whether it moved a cloud or sensor 2's pose (or says it fitted something)."""
        return self.xyz1 is not None or self.xyz2 is not None or self.T_1_2 is not None or bool(self.fitted)


def checked_outcome(result, lengths: tuple[int, int], what: str, path: str | Path | None = None) -> Outcome:
    """``result`` as a validated :class:`Outcome`, or a HypothesisError naming ``what`` (and ``path``)."""

    def fail(message: str):
        raise HypothesisError(f"{what}: {message}", path)

    if isinstance(result, Outcome):
        result = {k: getattr(result, k) for k in KEYS}
    if isinstance(result, Mapping):
        unknown = sorted(set(result) - set(KEYS))
        if unknown:
            fail(f"returned unknown key(s) {', '.join(map(repr, unknown))} (known: {', '.join(KEYS)})")
        raw = dict(result)
    elif isinstance(result, (tuple, list)) and len(result) == 2:
        raw = {"keep1": result[0], "keep2": result[1]}
    else:
        fail(
            "must return (keep1, keep2) or a mapping with keep1, keep2, xyz1, xyz2, T_1_2, fitted; "
            f"got {type(result).__name__}"
        )
    values = {}
    for cloud, n in zip((1, 2), lengths):
        mask = raw.get(f"keep{cloud}")
        if mask is None and isinstance(result, Mapping):
            mask = np.ones(n, dtype=bool)
        mask = np.asarray(mask)
        if mask.dtype != np.bool_ or mask.shape != (n,):
            fail(
                f"keep{cloud} must be a boolean array of length {n} (cloud {cloud}), "
                f"got dtype {mask.dtype} and shape {mask.shape}"
            )
        values[f"keep{cloud}"] = mask
        xyz = raw.get(f"xyz{cloud}")
        if xyz is not None:
            try:
                xyz = np.array(xyz, dtype=np.float64)
            except (TypeError, ValueError):
                fail(f"xyz{cloud} must be an array of numbers, got {type(raw[f'xyz{cloud}']).__name__}")
            if xyz.shape != (n, 3):
                fail(
                    f"xyz{cloud} must have shape ({n}, 3): the corrected coordinates of every point of cloud "
                    f"{cloud}, row for row; got shape {xyz.shape}"
                )
            bad = ~np.isfinite(xyz).all(axis=1)
            if bad.any():
                fail(f"xyz{cloud} has {np.count_nonzero(bad)} row(s) not finite (first: row {np.flatnonzero(bad)[0]})")
        values[f"xyz{cloud}"] = xyz
        values[f"reason{cloud}"] = _checked_reasons(raw.get(f"reason{cloud}"), n, f"reason{cloud}", fail)
    T = raw.get("T_1_2")
    if T is not None:
        try:
            T = np.array(T, dtype=np.float64)
        except (TypeError, ValueError):
            fail(f"T_1_2 must be a 4x4 array of numbers, got {type(raw['T_1_2']).__name__}")
        if T.shape != (4, 4) or not np.isfinite(T).all():
            fail(f"T_1_2 must be a finite 4x4 matrix, got shape {T.shape}")
    values["T_1_2"] = T
    fitted = raw.get("fitted") or {}
    if not isinstance(fitted, Mapping):
        fail(f"fitted must be a mapping, got {type(fitted).__name__}")
    try:
        fitted = json.loads(json.dumps(dict(fitted), allow_nan=False, default=_json_default))
    except (TypeError, ValueError) as e:
        fail(f"fitted must be JSON-able with finite numbers ({e})")
    values["fitted"] = fitted
    return Outcome(**values)


def _checked_reasons(reasons, n: int, name: str, fail) -> np.ndarray | None:
    """One string per point of a cloud (None: no reasons given), else ``fail`` says what is wrong."""
    if reasons is None:
        return None
    values = np.asarray(reasons)
    strings = values.dtype.kind == "U" or (
        values.dtype.kind == "O" and all(isinstance(v, str) for v in values.ravel().tolist())
    )
    if values.shape != (n,) or not strings:
        fail(f"{name} must be {n} strings, one per point of the cloud; got shape {values.shape}, dtype {values.dtype}")
    return values.astype(str)


def reasons_of_removed(outcome: Outcome) -> np.ndarray | None:
    """Why each removed point went, cloud 1's then cloud 2's ('' where not said); None when the
    outcome says nothing."""
    if outcome.reason1 is None and outcome.reason2 is None:
        return None
    parts = []
    for keep, reasons in ((outcome.keep1, outcome.reason1), (outcome.keep2, outcome.reason2)):
        removed = np.count_nonzero(~keep)
        parts.append(np.full(removed, "") if reasons is None else reasons[~keep])
    return np.concatenate(parts)


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not JSON-able")


def displacement(before: np.ndarray, after: np.ndarray | None) -> tuple[float, float]:
    """(median, maximum) distance each point moved, metres; (0, 0) when not moved or empty."""
    if after is None or len(before) == 0:
        return 0.0, 0.0
    d = np.linalg.norm(after - before, axis=1)
    median, maximum = float(np.median(d)), float(d.max())
    return (median if math.isfinite(median) else 0.0), (maximum if math.isfinite(maximum) else 0.0)
