"""MkDocs hook: the pages that are generated from the code when the site is built.

A page holds a marker line where its generated part goes; nothing generated is committed:

- ``<!-- generated: config-reference -->``: every key of the config schema
  (``workflow/schemas/config.schema.yaml``), nested ones too, with its type, default and
  description;
- ``<!-- generated: hypotheses -->``: every hypothesis of ``lidarfield.available_hypotheses()``
  with its parameters (``lidarfield.hypotheses.describe_hypotheses()``);
- ``<!-- generated: api -->``: one mkdocstrings block per name of ``lidarfield._EXPORTS``, at
  the module that defines it when the site is built (the flat names are imported lazily, so
  Griffe, which reads the source, cannot resolve ``lidarfield.<name>`` by itself).

``tests/unit/test_docs.py`` calls the generating functions directly.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]
SCHEMA_PATH = ROOT / "workflow" / "schemas" / "config.schema.yaml"

# The site documents this worktree's package, whatever else is installed.
if str(ROOT / "src") not in sys.path:
    sys.path.insert(0, str(ROOT / "src"))


# --- the config reference --------------------------------------------------------------------


def _ref_name(node: dict) -> str | None:
    ref = node.get("$ref", "")
    return ref.rsplit("/", 1)[-1] if ref.startswith("#/definitions/") else None


def _references(node, counts: dict[str, int]) -> None:
    """How often each definition is referenced anywhere in ``node``."""
    if isinstance(node, dict):
        name = _ref_name(node)
        if name:
            counts[name] = counts.get(name, 0) + 1
        for value in node.values():
            _references(value, counts)
    elif isinstance(node, list):
        for value in node:
            _references(value, counts)


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def _plural(label: str) -> str:
    return {
        "number": "numbers",
        "integer": "integers",
        "string": "strings",
        "object": "objects",
        "boolean": "booleans",
    }.get(label, label)


def _anchor(name: str) -> str:
    return "def-" + name.replace("_", "-")


class _Schema:
    def __init__(self, schema: dict):
        self.schema = schema
        self.definitions: dict = schema.get("definitions", {})
        counts: dict[str, int] = {}
        _references(schema.get("properties", {}), counts)
        _references(self.definitions, counts)
        # A definition used in exactly one place is shown where it is used; the others (and the
        # unused ones) are shared types with a section of their own.
        self.shared = [name for name in self.definitions if counts.get(name, 0) != 1]

    def resolve(self, node: dict) -> dict:
        name = _ref_name(node)
        if name is None:
            return node
        return {**self.definitions[name], **{k: v for k, v in node.items() if k != "$ref"}}

    def type_label(self, node: dict) -> str:
        name = _ref_name(node)
        if name in self.shared:
            return f"[{name}](#{_anchor(name)})"
        node = self.resolve(node)
        if "const" in node:
            return f"`{json.dumps(node['const'])}`"
        if "enum" in node:
            return "one of " + ", ".join(f"`{v}`" for v in node["enum"])
        for key in ("oneOf", "anyOf"):
            if key in node:
                return " or ".join(dict.fromkeys(self.type_label(alt) for alt in node[key]))
        kinds = node.get("type")
        if kinds is None:
            return "object" if "properties" in node else "any"
        kinds = kinds if isinstance(kinds, list) else [kinds]
        labels = []
        for kind in kinds:
            if kind == "array" and isinstance(node.get("items"), dict):
                items = self.type_label(node["items"])
                size = ""
                if node.get("minItems") is not None and node.get("minItems") == node.get("maxItems"):
                    size = f"{node['minItems']} "
                labels.append(f"list of {size}{_plural(items)}")
            elif kind == "null":
                labels.append("null")
            else:
                labels.append(kind)
        return " or ".join(dict.fromkeys(labels))

    def limits(self, node: dict) -> str:
        """The value limits of a key: '>= 1', '> 0, <= 1', 'matches ...'."""
        resolved = self.resolve(node)
        limits = []
        for key, sign in (("minimum", ">="), ("exclusiveMinimum", ">"), ("maximum", "<="), ("exclusiveMaximum", "<")):
            if key in resolved:
                limits.append(f"{sign} {resolved[key]}")
        if "pattern" in resolved:
            limits.append(f"matching `{resolved['pattern']}`")
        return ", ".join(limits)

    def type_cell(self, node: dict) -> str:
        limits = self.limits(node)
        return self.type_label(node) + (f" ({limits})" if limits else "")

    def description(self, node: dict) -> str:
        text = node.get("description")
        if text is None and _ref_name(node) not in self.shared:
            text = self.resolve(node).get("description")
        parts = [text] if text else []
        resolved = self.resolve(node)
        for key in ("oneOf", "anyOf"):
            for alt in resolved.get(key, []):
                if "description" in alt and alt["description"] != text:
                    parts.append(f"({self.type_label(alt)}: {alt['description']})")
        return " ".join(parts)

    def rows(self, node: dict, prefix: str, required: bool = False):
        """(key path, type, default, description) of ``node`` and everything nested in it."""
        yield prefix, self.type_cell(node), self.default(node, required), self.description(node)
        if _ref_name(node) in self.shared:
            return
        yield from self.children(self.resolve(node), prefix)

    def children(self, node: dict, prefix: str):
        required = set(node.get("required", []))
        for key, child in node.get("properties", {}).items():
            yield from self.rows(child, f"{prefix}.{key}" if prefix else key, key in required)
        for key in ("oneOf", "anyOf"):
            for alt in node.get(key, []):
                if _ref_name(alt) not in self.shared:
                    yield from self.children(self.resolve(alt), prefix)
        items = node.get("items")
        if isinstance(items, dict) and _ref_name(items) not in self.shared:
            yield from self.children(self.resolve(items), prefix + "[]")
        extra = node.get("additionalProperties")
        if isinstance(extra, dict) and "propertyNames" in node:
            # named entries (pairs, sequences): each is one of the alternatives, shown apart
            yield from self.children(self.resolve(extra), prefix + ".<name>")

    @staticmethod
    def default(node: dict, required: bool) -> str:
        if "default" in node:
            return f"`{json.dumps(node['default'])}`"
        return "required" if required else ""


def _table(rows) -> list[str]:
    lines = ["| key | type | default | description |", "|---|---|---|---|"]
    lines += [f"| `{key}` | {_cell(kind)} | {_cell(default)} | {_cell(text)} |" for key, kind, default, text in rows]
    return lines


def config_reference(schema_path: str | Path = SCHEMA_PATH) -> str:
    """The config reference (Markdown) from the schema's descriptions, types and defaults."""
    schema = yaml.safe_load(Path(schema_path).read_text())
    s = _Schema(schema)
    top = schema.get("properties", {})
    out = [
        "## Top-level keys",
        "",
        _cell(schema.get("description", "")),
        "",
        *_table((key, s.type_cell(node), s.default(node, False), s.description(node)) for key, node in top.items()),
    ]
    for key, node in top.items():
        resolved = s.resolve(node)
        extra = resolved.get("additionalProperties")
        if isinstance(extra, dict) and ("oneOf" in extra or "anyOf" in extra):
            # a mapping of named entries, each one of several kinds
            for alt in extra.get("oneOf", extra.get("anyOf")):
                name = _ref_name(alt) or "entry"
                title = name.replace("_", " ")
                out += ["", f"## `{key}`: {title}", "", f"Each entry `{key}.<name>` may be a {title} (`{name}`):", ""]
                out += _table(s.children(s.resolve(alt), f"{key}.<name>"))
            continue
        rows = list(s.children(resolved, key))
        if rows:
            out += ["", f"## `{key}`", ""]
            if s.description(node):
                out += [_cell(s.description(node)), ""]
            out += _table(rows)
    out += [
        "",
        "## Shared types",
        "",
        "Definitions that several keys refer to (`#/definitions/<name>` in the schema).",
    ]
    for name in s.shared:
        node = s.definitions[name]
        out += ["", f"### `{name}` {{#{_anchor(name)}}}", ""]
        described = s.description(node)
        label = s.type_cell(node)
        out.append(_cell(f"Type: {label}." + (f" Default: {s.default(node, False)}." if "default" in node else "")))
        if described:
            out += ["", _cell(described)]
        rows = list(s.children(node, ""))
        if rows:
            out += ["", *_table((key.lstrip("."), kind, default, text) for key, kind, default, text in rows)]
    return "\n".join(out) + "\n"


# --- the hypotheses --------------------------------------------------------------------------


def _rst_to_md(text: str) -> str:
    return text.replace("``", "`")


def hypotheses_reference() -> str:
    """Every hypothesis a stack entry may name, with its parameters (Markdown)."""
    import lidarfield
    import lidarfield.hypotheses as hypotheses

    params = hypotheses.describe_hypotheses()
    summaries = {name: h.summary for name, h in getattr(hypotheses, "BUILTINS", {}).items()}
    plugin = getattr(hypotheses, "PLUGIN", None)
    if plugin is not None:
        summaries[plugin.name] = plugin.summary
    out = []
    for name in lidarfield.available_hypotheses():
        out += [f"### `{name}`", ""]
        if name in summaries:
            out += [_rst_to_md(summaries[name]), ""]
        rows = params.get(name, [])
        if not rows:
            out += ["No parameters.", ""]
            continue
        out += ["| parameter | type | default | meaning |", "|---|---|---|---|"]
        for param, kind, default, text in rows:
            shown = "required" if type(default).__name__ == "_MISSING_TYPE" else f"`{json.dumps(default)}`"
            out.append(f"| `{param}` | {_cell(kind)} | {shown} | {_cell(text)} |")
        out.append("")
    return "\n".join(out)


# --- the Python API --------------------------------------------------------------------------


def api_path(name: str) -> str:
    """``lidarfield.<module>.<name>`` of a public name, at the module that defines it now.

    The name is imported through the flat API (``lidarfield.<name>``), so the path follows the
    package's layout when the site is built, whatever ``_EXPORTS`` says; subpackages import
    some names lazily too, which Griffe, reading the source, would not follow.
    """
    import lidarfield

    obj = getattr(lidarfield, name)
    module, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    if module and module.startswith("lidarfield") and qualname == name:
        return f"{module}.{name}"
    return f"lidarfield.{lidarfield._EXPORTS[name]}.{name}"


def api_reference() -> str:
    """One mkdocstrings block per public name (``lidarfield._EXPORTS``), grouped by module."""
    import lidarfield

    groups: dict[str, list[str]] = {}
    for name, module in lidarfield._EXPORTS.items():
        groups.setdefault(module.split(".")[0], []).append(name)
    out = []
    for section, names in groups.items():
        out += [f"## `lidarfield.{section}`", ""]
        for name in names:
            out += [
                f"::: {api_path(name)}",
                "    options:",
                "      show_root_heading: true",
                "      heading_level: 3",
                "",
            ]
    return "\n".join(out)


GENERATORS = {
    "<!-- generated: config-reference -->": config_reference,
    "<!-- generated: hypotheses -->": hypotheses_reference,
    "<!-- generated: api -->": api_reference,
}


def on_page_markdown(markdown: str, page, config, files) -> str:
    for marker, generate in GENERATORS.items():
        if marker in markdown:
            markdown = markdown.replace(marker, generate())
    return markdown
