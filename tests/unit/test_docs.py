"""The documentation site's generated pages (docs/hooks/generated.py), without building the
site: the config reference names every key of the schema, the hypotheses page every built-in
hypothesis and each of its parameters, and the API page every public name."""

from __future__ import annotations

import importlib.util
import re

import pytest
import yaml

import lidarfield
import lidarfield.hypotheses
from conftest import ROOT

SCHEMA = ROOT / "workflow" / "schemas" / "config.schema.yaml"


@pytest.fixture(scope="module")
def hook():
    spec = importlib.util.spec_from_file_location("docs_generated", ROOT / "docs" / "hooks" / "generated.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def schema_keys(node) -> set[str]:
    """Every key of the schema: property names and definition names, found by walking
    properties, definitions, oneOf/anyOf/allOf, items and additionalProperties recursively."""
    keys: set[str] = set()
    if isinstance(node, dict):
        for group in ("properties", "definitions"):
            for key, child in node.get(group, {}).items():
                keys.add(key)
                keys |= schema_keys(child)
        for group in ("oneOf", "anyOf", "allOf"):
            for child in node.get(group, []):
                keys |= schema_keys(child)
        for group in ("items", "additionalProperties"):
            keys |= schema_keys(node.get(group))
    elif isinstance(node, list):
        for child in node:
            keys |= schema_keys(child)
    return keys


def in_code(key: str, markdown: str) -> bool:
    """``key`` is a whole name inside a code span (`grid.z_min`, `seed`, ...)."""
    return re.search(rf"`[^`\n]*(?<![\w-]){re.escape(key)}(?![\w-])[^`\n]*`", markdown) is not None


def test_the_walk_finds_nested_keys():
    keys = schema_keys(yaml.safe_load(SCHEMA.read_text()))
    # nested in a definition, in a oneOf alternative, and deep in an object
    assert {"results", "grid", "rolling_shutter", "transform", "guess", "center_xy", "max_mb"} <= keys


def test_config_reference_names_every_schema_key(hook):
    markdown = hook.config_reference(SCHEMA)
    missing = sorted(key for key in schema_keys(yaml.safe_load(SCHEMA.read_text())) if not in_code(key, markdown))
    assert not missing, f"keys of {SCHEMA.name} missing from the config reference: {missing}"


def test_config_reference_gives_types_and_defaults(hook):
    markdown = hook.config_reference(SCHEMA)
    assert "| `grid.azimuth_bins` | integer (>= 1) | `36` |" in markdown
    assert re.search(r"\| `pairs.<name>.simulate.pose1` \| [^|]+ \| required \|", markdown)


def test_hypotheses_page_names_every_hypothesis_and_parameter(hook):
    markdown = hook.hypotheses_reference()
    names = lidarfield.available_hypotheses()
    assert {"ego_vehicle", "field_of_view", "shadow", "plugin"} <= set(names)
    parameters = lidarfield.hypotheses.describe_hypotheses()
    for name in names:
        section = markdown.split(f"### `{name}`", 1)
        assert len(section) == 2, f"hypothesis {name} missing from the hypotheses page"
        body = section[1].split("\n### ", 1)[0]
        for parameter, _type, _default, doc in parameters[name]:
            assert f"| `{parameter}` |" in body, f"{name}: parameter {parameter} missing"
            assert " ".join(doc.split()) in body


def test_api_page_has_a_block_for_every_public_name(hook):
    markdown = hook.api_reference()
    for name in lidarfield._EXPORTS:
        assert re.search(rf"^::: lidarfield\.[\w.]+\.{name}$", markdown, re.M), name
