"""Checking a study config against the schema, and filling in the schema's defaults.

JSON Schema's numbers admit NaN and infinities, which the stage ids' canonical JSON cannot
hold: they are refused here too. A failing config raises one ConfigError that names the
deepest key that failed.
"""

from __future__ import annotations

import copy

import jsonschema
import numpy as np

from ..defaults import schema
from ..errors import ConfigError


def _fill_defaults(instance, subschema: dict, validator: jsonschema.Draft7Validator) -> None:
    """Fill in the schema's defaults, in place, in a config that has validated.

    Done after validation, not during it (jsonschema's FAQ recipe), because inside a
    ``oneOf`` the branches that fail would leave their defaults behind.
    """
    if "$ref" in subschema:
        subschema = {**_resolve(subschema["$ref"]), **{k: v for k, v in subschema.items() if k != "$ref"}}
    for key in ("oneOf", "anyOf"):
        if key in subschema:
            for branch in subschema[key]:
                if validator.evolve(schema=branch).is_valid(instance):
                    _fill_defaults(instance, branch, validator)
                    break
    if isinstance(instance, dict):
        properties = subschema.get("properties", {})
        for name, prop in properties.items():
            if name not in instance and "default" in prop:
                instance[name] = copy.deepcopy(prop["default"])
            if name in instance:
                _fill_defaults(instance[name], prop, validator)
        extra = subschema.get("additionalProperties")
        if isinstance(extra, dict):
            for name, value in instance.items():
                if name not in properties:
                    _fill_defaults(value, extra, validator)
    elif isinstance(instance, list) and isinstance(subschema.get("items"), dict):
        for item in instance:
            _fill_defaults(item, subschema["items"], validator)


def _resolve(ref: str) -> dict:
    """A local ``#/definitions/...`` reference of the config schema."""
    node = schema()
    for part in ref.removeprefix("#/").split("/"):
        node = node[part]
    return node


def _error_location(error: jsonschema.ValidationError) -> str:
    return ".".join(str(p) for p in error.absolute_path) or "(top level)"


def _non_finite_key(node, key: str = "") -> str | None:
    """The first key holding NaN or an infinity (JSON Schema's numbers admit them; the stage
    ids' canonical JSON cannot hold them)."""
    if isinstance(node, float) and not np.isfinite(node):
        return key or "(top level)"
    children = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for name, child in children:
        found = _non_finite_key(child, f"{key}.{name}" if key else str(name))
        if found:
            return found
    return None


def check_config(config: dict, source: str) -> None:
    """Validate ``config`` in place against the schema and fill in its defaults."""
    validator = jsonschema.Draft7Validator(schema())
    errors = sorted(validator.iter_errors(config), key=lambda e: list(e.absolute_path))
    if not errors:
        key = _non_finite_key(config)
        if key:
            raise ConfigError(f"config key {key}: NaN or infinite; a finite number is needed", source)
        _fill_defaults(config, schema(), validator)
        return
    # oneOf failures bury the useful message: report the deepest one.
    error = errors[0]
    while error.context:
        error = max(error.context, key=lambda e: len(e.absolute_path))
    raise ConfigError(f"config key {_error_location(error)}: {error.message}", source)
