"""One entry of a hypothesis stack, ``{name: params}``: its name (its canonical JSON, what
stage ids and suggestions hash and compare, is :func:`lidarfield.storage.stage_ids.canonical_json`)."""

from __future__ import annotations


def step_name(step: dict) -> str:
    """The hypothesis name of one stack entry ``{name: params}``."""
    (name,) = step.keys()
    return name
