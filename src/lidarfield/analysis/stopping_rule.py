"""The stopping rule of ``lidarfield explain``: which candidate of a suggestion table is worth
applying, and when the loop ends.

A candidate is *worth it* when its energy reduction (``suggest``: over the voxels valid before
and after) is more than 0 and at least ``min_energy_reduction``, it removes at most
``max_removed_share`` of the points left, and its reduction is at least
``min_reduction_per_removed`` times that share (a correction removes nothing: only the first
test applies). The loop (``study.explain_loop``) applies the best-ranked candidate that is worth it,
and stops when the field's verdict is no longer ``patterned`` (``random``, or ``undetermined``
with too few valid voxels to judge), when no candidate is worth it, or after ``max_steps``.
The defaults are the config's ``explain`` section (the schema).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from ..defaults import default
from ..errors import ConfigError

# Why the loop ended (the ``stop`` of an explanation).
STOP_VERDICT = "verdict {verdict}"
STOP_NOTHING_HELPS = "no candidate is worth it"
STOP_NO_CANDIDATES = "no candidate left to try"
STOP_MAX_STEPS = "max_steps reached"


@dataclass(frozen=True)
class ExplainSettings:
    """The config's ``explain`` section."""

    min_energy_reduction: float = default("explain", "min_energy_reduction")
    max_removed_share: float = default("explain", "max_removed_share")
    min_reduction_per_removed: float = default("explain", "min_reduction_per_removed")
    max_steps: int = default("explain", "max_steps")


def explain_settings(section: dict | None) -> ExplainSettings:
    """ExplainSettings from a config ``explain`` mapping (missing keys take their defaults)."""
    section = dict(section or {})
    known = {f.name for f in fields(ExplainSettings)}
    unknown = set(section) - known
    if unknown:
        raise ConfigError(f"explain: unknown key(s) {sorted(unknown)}; known: {sorted(known)}")
    return ExplainSettings(**section)


def worth_it(row: dict, settings: ExplainSettings) -> bool:
    """Whether one suggestion row (``SUGGESTION_COLUMNS``) is worth applying."""
    reduction, share = float(row["energy_reduction"]), float(row["removed_share"])
    if not (math.isfinite(reduction) and reduction > 0 and reduction >= settings.min_energy_reduction):
        return False
    if not math.isfinite(share):  # no points at all: nothing to remove, nothing to explain
        return False
    return share <= settings.max_removed_share and reduction >= settings.min_reduction_per_removed * share


def best_worth_it(table: dict[str, np.ndarray], settings: ExplainSettings) -> int | None:
    """The row of the best-ranked candidate worth applying (the table is sorted by rank), or None."""
    for i in range(len(table["rank"])):
        if worth_it({name: column[i] for name, column in table.items()}, settings):
            return i
    return None


def repeats(step: dict, applied: list[dict]) -> bool:
    """Whether ``step`` (a normalised stack entry) applies a hypothesis the stack already has: a
    built-in of the same name, or a plugin with the same file and function."""
    ((name, params),) = step.items()
    for done in applied:
        ((done_name, done_params),) = done.items()
        if done_name != name:
            continue
        if name != "plugin" or (params["file"], params["function"]) == (done_params["file"], done_params["function"]):
            return True
    return False
