"""The results folder's layout: what every stage reads and writes relies on these names.

``results/{pair}/stages/{stage id}/`` holds a stage's files; a stage id is
``{k:02d}-{hypothesis}-{hash8}`` (:mod:`lidarfield.storage.stage_ids`), so its folder name
starts with its level. Beside the pairs' folders, the results folder has its own subfolders.
"""

from __future__ import annotations

# The results folder's own subfolders, beside one folder per pair: no pair may take their names.
RESULTS_FOLDERS = ("scans", "logs", "benchmarks", "assets", "study")


def level_of(stage_id: str) -> int | None:
    """The level k of a stage id ``{k:02d}-...`` (its folder name); None for another name."""
    prefix = stage_id.split("-", 1)[0]
    return int(prefix) if prefix.isdigit() else None
