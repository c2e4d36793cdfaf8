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
the other fills (``coverage``) has ``field_of_view`` applied when its model says so, objects
that moved have ``moving_objects`` applied when it explains the points seen through
(:func:`explains_seen_through`): a moved object is evidenced by free space, not by the field
(its voxels hold its own spread, so its vectors are small in units of their noise, and the
voxels its removal empties leave the reduction), and the vehicle's own body has
``ego_vehicle`` applied when most of what it removes is carried (``carried``; also in place of
a correction the ranking chose: a correction would fit the body).
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
    """Whether one suggestion row (``SUGGESTION_COLUMNS``) is worth applying: never a fit with
    the pose that found none of its own correction (``calibration_seen``: it is the pose alone)."""
    if not row["calibration_seen"]:
        return False
    reduction, share = float(row["whitened_reduction"]), float(row["removed_share"])
    if not (math.isfinite(reduction) and reduction > 0 and reduction >= settings.min_energy_reduction):
        return False
    if not math.isfinite(share):  # no points at all: nothing to remove, nothing to explain
        return False
    null = sum(float(row[name]) for name in ("removal_null", "fitted_null") if math.isfinite(row[name]))
    return share <= settings.max_removed_share and reduction >= settings.min_reduction_per_removed * null


def explains_seen_through(row: dict, settings: ExplainSettings) -> bool:
    """Whether a removal (a suggestion row) explains the points one scan saw through where the
    other has returns (``seen_through_removed``): it removes at least ``min_energy_reduction``
    of them and ``min_reduction_per_removed`` times what removing as many points of each voxel
    at random would (``seen_through_null``: the null of a removal, read on the points seen
    through, which random thinning cannot single out), at most ``max_removed_share`` of the
    points, and it leaves the field no worse in units of its noise (a whitened reduction below
    0 says it removed one scan's part of what moved and kept the other's)."""
    share, null = float(row["seen_through_removed"]), float(row["seen_through_null"])
    if not (math.isfinite(share) and share > 0 and math.isfinite(null)):
        return False
    removed, whitened = float(row["removed_share"]), float(row["whitened_reduction"])
    return (
        share >= settings.min_energy_reduction
        and share >= settings.min_reduction_per_removed * null
        and removed <= settings.max_removed_share
        and not whitened < 0  # NaN: no voxel valid before and after to say
    )


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
