"""The hypothesis registry: built-in mitigations and the analyst's plugins.

A hypothesis is a pure function ``(pair, params) -> (keep1, keep2)`` of a
:class:`~lidarfield.pair.RegisteredPair` and a frozen dataclass of typed parameters, returning
one boolean keep-mask per cloud, or an :class:`~.outcome.Outcome` that also corrects: the
corrected coordinates of a cloud, sensor 2's corrected pose, and what it fitted (see
:mod:`.outcome`; ``realign``, ``range_calibration``, ``deskew`` and ``elevation_calibration``
are the built-in ones). A stack entry
is a one-key mapping ``{name: {params}}``;
:func:`validate_stack` checks every entry before anything runs and returns the normalised
entries (defaults filled in, the study's grid filled into ``shadow``), which are what stage ids
are computed from.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import HypothesisError
from ..pair import RegisteredPair
from . import (
    crop,
    deskew,
    ego_vehicle,
    elevation_calibration,
    field_of_view,
    moving_objects,
    outliers,
    plugin,
    range_calibration,
    realign,
    shadow,
)
from .outcome import Outcome, checked_outcome
from .params import describe, params_to_dict, parse_params

Masks = tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True)
class Hypothesis:
    name: str
    function: Callable[[RegisteredPair, Any], Masks | Outcome]
    params: type  # frozen dataclass of the parameters, with defaults and docs
    summary: str


def _builtin(module, name: str) -> Hypothesis:
    return Hypothesis(name, getattr(module, name), module.Params, module.__doc__.strip().splitlines()[0])


BUILTINS: dict[str, Hypothesis] = {
    h.name: h
    for h in (
        _builtin(ego_vehicle, "ego_vehicle"),
        _builtin(field_of_view, "field_of_view"),
        _builtin(shadow, "shadow"),
        _builtin(crop, "crop"),
        _builtin(outliers, "outliers"),
        _builtin(moving_objects, "moving_objects"),
        _builtin(realign, "realign"),
        _builtin(range_calibration, "range_calibration"),
        _builtin(deskew, "deskew"),
        _builtin(elevation_calibration, "elevation_calibration"),
    )
}
# The built-ins that correct (move a cloud) rather than remove; "what to try next" ranks them
# after the removals among its default candidates (analysis.suggest).
CORRECTING = frozenset({"realign", "range_calibration", "deskew", "elevation_calibration"})
PLUGIN = Hypothesis("plugin", plugin.run_plugin, plugin.Params, plugin.__doc__.strip().splitlines()[0])


def available_hypotheses() -> list[str]:
    """The names a stack entry may use."""
    return [*BUILTINS, PLUGIN.name]


def _where(name: str, level: int | None) -> str:
    return f"hypothesis {name}" if level is None else f"hypothesis {level} ({name})"


def parse_step(step: dict, base_dir: str | Path = ".", study_grid: dict | None = None, level: int | None = None):
    """(name, params instance) of one stack entry, validated, with the study's grid filled in.

    ``level`` (the entry's 1-based position, = its stage) only makes error messages precise.
    """
    if not isinstance(step, dict) or len(step) != 1:
        at = "" if level is None else f"hypothesis {level}: "
        raise HypothesisError(f"{at}a stack entry is a one-key mapping {{name: {{parameters}}}}, got {step!r}")
    ((name, raw),) = step.items()
    if name != PLUGIN.name and name not in BUILTINS:
        raise HypothesisError(
            f"{_where(name, level)}: unknown hypothesis; available: {', '.join(available_hypotheses())}"
        )
    entry = PLUGIN if name == PLUGIN.name else BUILTINS[name]
    params = parse_params(entry.params, raw, _where(name, level))
    if entry is PLUGIN:
        plugin.check_plugin_file(params, base_dir, level)
    if hasattr(params, "in_study"):
        params = params.in_study(study_grid)
    return name, params


def validate_step(
    step: dict, base_dir: str | Path = ".", study_grid: dict | None = None, level: int | None = None
) -> dict:
    """The normalised entry ``{name: {params}}`` (defaults filled in), or a HypothesisError.

    Idempotent: validating a normalised entry gives it back unchanged.
    """
    return step_spec(*parse_step(step, base_dir, study_grid, level))


def step_spec(name: str, params) -> dict:
    """The normalised entry ``{name: {params}}`` of a parsed one (:func:`parse_step`'s)."""
    return {name: params_to_dict(params)}


def validate_stack(stack: list[dict] | None, base_dir: str | Path = ".", study_grid: dict | None = None) -> list[dict]:
    """Every entry of the stack validated and normalised, before anything runs.

    Pass the study's ``grid`` section as ``study_grid`` so that ``shadow``'s default grid is
    written into its entry (and so into its stage id).
    """
    return [step_spec(name, params) for name, params in parse_stack(stack, base_dir, study_grid)]


def parse_stack(stack: list[dict] | None, base_dir: str | Path = ".", study_grid: dict | None = None) -> list[tuple]:
    """(name, params) of every entry of the stack (:func:`parse_step`), in order."""
    if stack is None:
        return []
    if not isinstance(stack, list):
        raise HypothesisError(f"the hypothesis stack is a list of {{name: {{parameters}}}} entries, got {stack!r}")
    return [parse_step(step, base_dir, study_grid, level) for level, step in enumerate(stack, start=1)]


def apply_step(
    pair: RegisteredPair,
    step: dict,
    base_dir: str | Path = ".",
    study_grid: dict | None = None,
    level: int | None = None,
) -> Outcome:
    """Validate one stack entry and apply it: its checked :class:`Outcome` (which unpacks as the
    keep-masks of both clouds, ``keep1, keep2 = apply_step(...)``)."""
    return run_step(pair, *parse_step(step, base_dir, study_grid, level), base_dir, level)


def run_step(pair: RegisteredPair, name: str, params, base_dir: str | Path = ".", level: int | None = None) -> Outcome:
    """Apply a parsed stack entry (:func:`parse_step`'s name and parameters): its checked
    :class:`Outcome`."""
    if name == PLUGIN.name:
        return plugin.run_plugin(pair, params, base_dir, level)
    result = BUILTINS[name].function(pair, params)
    return checked_outcome(result, (len(pair.xyz1), len(pair.xyz2)), _where(name, level))


def describe_hypotheses() -> dict[str, list[tuple[str, str, Any, str]]]:
    """(name, type, default, doc) of every parameter of every hypothesis, for help and docs."""
    return {h.name: describe(h.params) for h in (*BUILTINS.values(), PLUGIN)}
