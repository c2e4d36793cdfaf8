"""A user's YAML file (study config, sensor model, scene, grid): read and parsed, or one line
naming the file and what is wrong with it (PyYAML's own message spans up to eight lines)."""

from __future__ import annotations

from pathlib import Path

import yaml

from .errors import ConfigError


def read_yaml(path: str | Path, what: str):
    """The parsed content of ``path``; ``what`` names the file's role in the error of a
    missing file ("sensor model file not found")."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{what} file not found", path)
    try:
        return yaml.safe_load(path.read_bytes())
    except yaml.YAMLError as e:
        raise ConfigError(f"not valid YAML: {yaml_problem(e)}", path) from None


def yaml_problem(error: yaml.YAMLError) -> str:
    """PyYAML's error as one line: the problem and where (1-based line and column)."""
    problem = getattr(error, "problem", None) or str(error).splitlines()[0]
    mark = getattr(error, "problem_mark", None)
    where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
    context = getattr(error, "context", None)
    return f"{where}{problem}" + (f" ({context})" if context else "")
