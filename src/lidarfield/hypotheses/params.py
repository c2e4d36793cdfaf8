"""Typed hypothesis parameters: YAML values checked against a frozen dataclass's type hints.

Every hypothesis declares its parameters as a frozen dataclass whose fields carry a type hint,
a default and a ``doc`` in their metadata. :func:`parse_params` turns the mapping of a stack
entry into an instance, naming the offending parameter and its expected type on any mistake;
:func:`params_to_dict` gives the normalised, JSON-able mapping back (defaults filled in).
"""

from __future__ import annotations

import dataclasses
import types
import typing
from typing import Any

from ..checks import is_integer, is_number
from ..errors import HypothesisError


def doc(text: str, written_when_set: bool = False) -> dict:
    """Field metadata holding a parameter's documentation. ``written_when_set``: a parameter
    added to a published hypothesis is left out of the normalised entry at its default, so the
    entries, and the stage ids made of them, that were written before it stay what they were."""
    return {"doc": text, "written_when_set": written_when_set}


def type_label(hint: Any) -> str:
    """A reader's name for a type hint: 'number', 'list of 2 numbers', 'integer or null', ..."""
    args = typing.get_args(hint)
    if _is_optional(hint):
        (inner,) = [a for a in args if a is not type(None)]
        return f"{type_label(inner)} or null"
    if _is_union(hint):
        return " or ".join(type_label(a) for a in args)
    origin = typing.get_origin(hint)
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"list of {_plural(args[0])}"
        if len(set(args)) == 1:
            return f"list of {len(args)} {_plural(args[0])}"
        return "list of " + ", ".join(type_label(a) for a in args)
    return {float: "number", int: "integer", bool: "true/false", str: "string", dict: "mapping"}.get(
        hint, getattr(hint, "__name__", str(hint))
    )


def parse_params(cls: type, raw: dict | None, where: str):
    """An instance of the dataclass ``cls`` from a stack entry's mapping (None = all defaults).

    ``where`` prefixes every message (e.g. "hypothesis 2 (shadow)"). A ``ValueError`` raised by
    the dataclass's own ``__post_init__`` checks becomes a ``HypothesisError`` too.
    """
    raw = {} if raw is None else raw
    if not isinstance(raw, dict):
        raise HypothesisError(f"{where}: parameters must be a mapping, got {raw!r}")
    hints = typing.get_type_hints(cls)
    fields = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(raw) - set(fields))
    if unknown:
        expected = ", ".join(f"{name} ({type_label(hints[name])})" for name in fields) or "none"
        raise HypothesisError(f"{where}: unknown parameter(s) {', '.join(unknown)}; expected: {expected}")
    missing = [f.name for f in dataclasses.fields(cls) if f.name not in raw and _default(f) is dataclasses.MISSING]
    if missing:
        raise HypothesisError(
            f"{where}: missing parameter(s) " + ", ".join(f"{n} ({type_label(hints[n])})" for n in missing)
        )
    values = {name: _coerce(value, hints[name], f"{where}: parameter {name!r}") for name, value in raw.items()}
    try:
        return cls(**values)
    except ValueError as e:
        raise HypothesisError(f"{where}: {e}") from None


def params_to_dict(params) -> dict:
    """The JSON-able mapping of a parameters instance (tuples as lists; a ``written_when_set``
    parameter only away from its default)."""
    return {
        f.name: _plain(getattr(params, f.name))
        for f in dataclasses.fields(params)
        if not (f.metadata.get("written_when_set") and getattr(params, f.name) == _default(f))
    }


def describe(cls: type) -> list[tuple[str, str, Any, str]]:
    """(name, type label, default, doc) of each parameter, for help texts and the documentation."""
    hints = typing.get_type_hints(cls)
    return [
        (f.name, type_label(hints[f.name]), _plain(_default(f)), f.metadata.get("doc", ""))
        for f in dataclasses.fields(cls)
    ]


def _default(f: dataclasses.Field) -> Any:
    """A field's default value (MISSING for a required parameter)."""
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return f.default


def _is_optional(hint: Any) -> bool:
    return typing.get_origin(hint) in (typing.Union, types.UnionType) and type(None) in typing.get_args(hint)


def _is_union(hint: Any) -> bool:
    return typing.get_origin(hint) in (typing.Union, types.UnionType)


def _plural(hint: Any) -> str:
    return {float: "numbers", int: "integers", str: "strings", bool: "true/false values"}.get(hint, type_label(hint))


def _coerce(value: Any, hint: Any, what: str) -> Any:
    """``value`` converted to ``hint`` (int -> float, list -> tuple), or a HypothesisError."""
    if _is_optional(hint):
        if value is None:
            return None
        (inner,) = [a for a in typing.get_args(hint) if a is not type(None)]
        try:
            return _coerce(value, inner, what)
        except HypothesisError:
            raise HypothesisError(f"{what}: expected {type_label(hint)}, got {value!r}") from None
    if _is_union(hint):  # the first member that takes the value
        for member in typing.get_args(hint):
            try:
                return _coerce(value, member, what)
            except HypothesisError:
                pass
        raise HypothesisError(f"{what}: expected {type_label(hint)}, got {value!r}")
    origin = typing.get_origin(hint)
    if origin is tuple and isinstance(value, (list, tuple)):
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(v, args[0], what) for v in value)
        if len(value) == len(args):
            return tuple(_coerce(v, a, what) for v, a in zip(value, args))
    elif hint is float and is_number(value):
        return float(value)
    elif hint is int and is_integer(value):
        return value
    elif hint in (bool, str, dict) and isinstance(value, hint):
        return value
    raise HypothesisError(f"{what}: expected {type_label(hint)}, got {value!r}")


def _plain(value: Any) -> Any:
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value
