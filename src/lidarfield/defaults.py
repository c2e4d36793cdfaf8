"""The study config's schema, the one source of every default.

The schema (``workflow/schemas/config.schema.yaml``, shipped in the package as
``lidarfield/schemas/config.schema.yaml``) declares each setting with its default. The typed
settings objects of the code (``SphericalGrid``, ``FieldSettings``, ``PlotSettings``, ...)
take their defaults from here, so a default is written once; ``tests/unit/test_defaults.py``
checks every one against the schema.
"""

from __future__ import annotations

import copy
from functools import cache
from pathlib import Path

import yaml

SCHEMA_PATH = Path(__file__).parent / "schemas" / "config.schema.yaml"


@cache
def schema() -> dict:
    """The config schema (parsed once per process)."""
    return yaml.load(SCHEMA_PATH.read_text(), Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))


def section(name: str) -> dict:
    """The schema of one section of the config (``grid``, ``plots``, ``report``, ...)."""
    return schema()["definitions"][name]


def default(name: str, key: str):
    """The default of ``key`` in section ``name`` (a fresh copy: callers may change it)."""
    return copy.deepcopy(section(name)["properties"][key]["default"])
