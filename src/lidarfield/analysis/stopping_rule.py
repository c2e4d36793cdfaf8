"""The stopping rule of ``lidarfield explain``: which candidate of a suggestion table is worth
applying, and when the loop ends.

A candidate is *worth it* when its reduction of the field's energy in units of its noise
(``suggest``'s ``whitened_reduction``: over the voxels valid before and after) is more than 0
and at least ``min_energy_reduction``, it removes at most ``max_removed_share`` of the points
left, and its reduction is at least ``min_reduction_per_removed`` times ``removal_null``, what
removing as many points of each voxel at random would give (a correction removes nothing:
only ``fitted_null`` applies, what fitting its parameters to noise would give). The last test is
the null: a removal is worth it only for what it explains beyond thinning the field, a
correction beyond what its free parameters fit of the noise. The whitened energy, not the raw one, because the
verdict reads the field in units of its noise: a correction that finds the fault can leave the
raw energy unchanged (a turn moves whole rings between voxels at the band edges) while it
takes the field's pattern away. The loop (``study.explain_loop``) applies the best-ranked
candidate that is worth it, and stops when the field's verdict is no longer ``patterned``
(``random``, or ``undetermined`` with too few valid voxels to judge), when no candidate is
worth it, or after ``max_steps``; before it stops, a scan that returned nothing in a sector
the other fills (``coverage``) has ``field_of_view`` applied when its model says so.
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
    reduction, share = float(row["whitened_reduction"]), float(row["removed_share"])
    if not (math.isfinite(reduction) and reduction > 0 and reduction >= settings.min_energy_reduction):
        return False
    if not math.isfinite(share):  # no points at all: nothing to remove, nothing to explain
        return False
    null = sum(float(row[name]) for name in ("removal_null", "fitted_null") if math.isfinite(row[name]))
    return share <= settings.max_removed_share and reduction >= settings.min_reduction_per_removed * null


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
