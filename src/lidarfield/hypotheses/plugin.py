"""``plugin``: the analyst's own hypothesis, a function in a Python file.

Stack entry: ``plugin: {file: hypotheses/moving_cars.py, function: remove, params: {...}}``.
``file`` is relative to the study's base folder. The function is called as
``function(pair, params)`` with the :class:`~lidarfield.pair.RegisteredPair` (read-only arrays)
and the ``params`` mapping, and returns ``(keep1, keep2)``: boolean arrays of the lengths of
the two clouds, or, to correct as well as remove, a mapping with ``keep1``, ``keep2``, ``xyz1``,
``xyz2`` (corrected coordinates of every point, row for row), ``T_1_2`` and ``fitted`` (see
:mod:`.outcome`). Anything that goes wrong (no file, an import or call that raises, masks or
coordinates of the wrong type, shape, or not finite) is one :class:`HypothesisError` naming the
file and the hypothesis.
"""

from __future__ import annotations

import hashlib
import importlib.util
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import HypothesisError
from ..pair import RegisteredPair
from .outcome import Outcome, checked_outcome
from .params import doc


@dataclass(frozen=True)
class Params:
    file: str = field(metadata=doc("the Python file, relative to the study's base folder"))
    function: str = field(
        default="remove",
        metadata=doc(
            "the function in it: (pair, params) -> (keep1, keep2) or {keep1, keep2, xyz1, xyz2, T_1_2, fitted}"
        ),
    )
    params: dict = field(default_factory=dict, metadata=doc("passed to the function as its second argument"))


def plugin_path(params: Params, base_dir: str | Path) -> Path:
    return Path(base_dir) / params.file


def describe_plugin(params: Params, level: int | None = None) -> str:
    """'plugin hypothesis 'remove' (stack entry 3)': how errors name the hypothesis."""
    entry = "" if level is None else f" (stack entry {level})"
    return f"plugin hypothesis {params.function!r}{entry}"


def check_plugin_file(params: Params, base_dir: str | Path, level: int | None = None) -> None:
    path = plugin_path(params, base_dir)
    if not path.is_file():
        raise HypothesisError(f"{describe_plugin(params, level)}: plugin file not found", path)


def run_plugin(pair: RegisteredPair, params: Params, base_dir: str | Path = ".", level: int | None = None) -> Outcome:
    """Load the plugin's file, call its function on ``pair`` and check what it returns."""
    path = plugin_path(params, base_dir)
    what = describe_plugin(params, level)
    check_plugin_file(params, base_dir, level)
    function = _load_function(path, params.function, what)
    try:
        result = function(_read_only(pair), dict(params.params))
    except Exception as e:  # the analyst's code: any failure is reported as theirs
        raise HypothesisError(f"{what}: raised {type(e).__name__}: {e}", path) from e
    return checked_outcome(result, (len(pair.xyz1), len(pair.xyz2)), what, path)


def _load_function(path: Path, name: str, what: str):
    # A module name unique to the file's content, so an edited plugin is never served stale.
    digest = hashlib.sha256(path.read_bytes()).hexdigest()[:12]
    spec = importlib.util.spec_from_file_location(f"lidarfield_plugin_{path.stem}_{digest}", path)
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except Exception as e:
        raise HypothesisError(f"{what}: importing the file raised {type(e).__name__}: {e}", path) from e
    function = getattr(module, name, None)
    if not callable(function):
        found = sorted(
            k
            for k, v in vars(module).items()
            if callable(v) and not k.startswith("_") and getattr(v, "__module__", None) == module.__name__
        )
        raise HypothesisError(
            f"{what}: the file has no function {name!r} (functions: {', '.join(found) or 'none'})", path
        )
    return function


def _read_only(pair: RegisteredPair) -> RegisteredPair:
    """A view of the pair whose arrays the plugin cannot modify in place."""

    def frozen(a: np.ndarray) -> np.ndarray:
        view = a.view()
        view.flags.writeable = False
        return view

    return RegisteredPair(
        frozen(pair.xyz1),
        frozen(pair.xyz2),
        frozen(pair.T_1_2),
        pair.sensor1,
        pair.sensor2,
        {k: frozen(v) for k, v in pair.attributes1.items()},
        {k: frozen(v) for k, v in pair.attributes2.items()},
        dict(pair.registration),
        dict(pair.sensor_fit),
        dict(pair.sweeps),
        pair.lidars1,
        pair.lidars2,
    )
