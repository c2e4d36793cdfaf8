"""One entry of a hypothesis stack, ``{name: params}``: its name, and its canonical JSON (what
stage ids and suggestions hash and compare)."""

from __future__ import annotations

import json


def canonical_json(obj) -> str:
    """Key-sorted, whitespace-free JSON: equal settings give equal strings."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)


def step_name(step: dict) -> str:
    """The hypothesis name of one stack entry ``{name: params}``."""
    (name,) = step.keys()
    return name
