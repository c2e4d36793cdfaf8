"""The study config: loaded from YAML, validated once against the JSON schema, defaults filled.

The schema (:mod:`lidarfield.defaults`) is the one source of truth: the Snakemake workflow
and ``lidarfield run`` both go through :func:`validate_config`. Relative paths in a config are
relative to the folder the study is run from (the working directory), as in Snakemake.

Validation also expands ``sequences`` into consecutive pairs and resolves every scan of the
study into a :class:`~lidarfield.study.pairs.ScanSpec` (:mod:`lidarfield.study.pairs`), so that
the workflow knows all its jobs when it is parsed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ConfigError, LidarfieldError
from ..field.grid import FieldSettings, field_settings_from_config
from ..plots.settings import PlotSettings, plot_settings
from ..storage.layout import RESULTS_FOLDERS
from ..storage.stage_ids import stage_ids
from ..yaml_file import read_yaml
from .pairs import PairSpec, ScanSpec, study_pairs
from .schema import check_config


@dataclass
class Study:
    config: dict  # validated, defaults filled in
    base_dir: Path
    pairs: dict[str, PairSpec]
    grid: FieldSettings  # the grid section, typed
    hypotheses: list[dict]  # normalised stack, defaults filled in
    plots: PlotSettings  # the plots section, typed (which pairs get figures: plot_pairs)
    scans: dict[str, ScanSpec] = field(default_factory=dict)
    suggest: list[dict] | None = None  # the config's candidates, normalised; None: the default
    plot_pairs: list[str] = field(default_factory=list)  # the pairs that get per-stage figures
    # the pairs that get what to try next at their last stage (suggest_pairs) and the plotted ones
    suggest_pairs: list[str] = field(default_factory=list)
    rematch: dict | None = None  # the validated rematch section; None: no rematching

    @property
    def grid_section(self) -> dict:
        """The config's ``grid`` section as written (defaults filled in): what the field jobs
        and ``shadow``'s default grid take."""
        return self.config["grid"]

    def stage_ids(self, pair: str) -> list[str]:
        return stage_ids(self.pairs[pair].inputs(), self.hypotheses, self.base_dir)

    def candidates(self, level: int) -> list[dict]:
        """The normalised candidate hypotheses of stage ``level`` (see ``suggest``)."""
        from ..analysis.suggest import candidate_steps

        return candidate_steps(self.suggest, self.hypotheses[:level], self.base_dir, self.grid_section)


def load_config(path: str | Path, base_dir: str | Path | None = None, require_pairs: bool = True) -> Study:
    """Read a study YAML file and validate it (paths relative to ``base_dir``, default: cwd).

    ``require_pairs=False`` accepts a config without pairs (``lidarfield run`` takes its pair
    from the command line and uses only the grid, the hypotheses and the plots)."""
    path = Path(path)
    config = read_yaml(path, "config")
    if not isinstance(config, dict):
        raise ConfigError("a study config is a YAML mapping (pairs, grid, hypotheses, ...)", path)
    return validate_config(config, base_dir, source=str(path), require_pairs=require_pairs)


def validate_config(
    config: dict, base_dir: str | Path | None = None, source: str = "config", require_pairs: bool = True
) -> Study:
    """Validate a config dict in place (defaults filled in) and resolve its pairs and stack."""
    from ..hypotheses import validate_stack

    base_dir = Path.cwd() if base_dir is None else Path(base_dir)
    check_config(config, source)
    try:
        grid = field_settings_from_config(config["grid"])
        plots = plot_settings(config["plots"])
        if "rematch" in config:
            _check_rematch(config["rematch"])
        hypotheses = validate_stack(config["hypotheses"], base_dir, study_grid=config["grid"])
        suggest = None
        if config["suggest"] is not None:
            from ..analysis.suggest import candidate_steps

            suggest = candidate_steps(config["suggest"], hypotheses, base_dir, config["grid"])
        pairs = study_pairs(config, base_dir)
    except LidarfieldError as e:
        raise type(e)(str(e) if e.path else f"{source}: {e}") from None
    taken = sorted(set(pairs) & set(RESULTS_FOLDERS))
    if taken:
        raise ConfigError(f"pair name(s) {taken} are folders of the results folder; rename the pair(s)", source)
    if require_pairs and not pairs:
        raise ConfigError("the study has no pairs: add entries under 'pairs' or 'sequences'", source)
    scans = {}
    for pair in pairs.values():
        scans[pair.scan1.id] = pair.scan1
        scans[pair.scan2.id] = pair.scan2
    names = sorted(pairs)
    plotted = selected_pairs(config["plots"]["pairs"], names, AUTO_PLOT_PAIRS, "plots.pairs", source)
    suggested = selected_pairs(config["suggest_pairs"], names, AUTO_SUGGEST_PAIRS, "suggest_pairs", source)
    suggested = sorted(set(suggested) | set(plotted))
    return Study(
        config, base_dir, pairs, grid, hypotheses, plots, scans, suggest, plotted, suggested, config.get("rematch")
    )


# A study of up to this many pairs gets every pair's stage figures by default; a larger one
# gets this many, evenly spaced (a drive's pairs are named in driving order).
AUTO_PLOT_PAIRS = 12
# The same for what to try next at the last stage. Its candidates fit corrections: 44% of a
# 1,000-pair drive's job time when every pair had them (bench/RESULTS.md), and the
# study's next steps need a spread of pairs, not every one.
AUTO_SUGGEST_PAIRS = 100


def selected_pairs(
    setting: str | list[str], names: list[str], auto: int, key: str, source: str = "config"
) -> list[str]:
    """The pairs a selection setting (``plots.pairs``, ``suggest_pairs``) names, in name order:
    all, none, a list of names, or auto (every pair of a study of up to ``auto`` pairs, else
    ``auto`` pairs evenly spaced in name order, first and last included).

    Decided when the config is read (the workflow knows its jobs when it is parsed), so
    ``auto`` goes by the number of pairs, not by any result."""
    if setting == "all" or (setting == "auto" and len(names) <= auto):
        return list(names)
    if setting == "none":
        return []
    if setting == "auto":
        picks = np.unique(np.round(np.linspace(0, len(names) - 1, auto)).astype(int))
        return [names[i] for i in picks]
    unknown = [name for name in setting if name not in names]
    if unknown and names:
        raise ConfigError(f"config key {key}: unknown pair(s) {unknown}; the study's pairs are {names[:20]}", source)
    return [name for name in names if name in setting]


def _check_rematch(section: dict) -> None:
    """The rematch parameters are those of a register method: checked by the same parser."""
    from ..registration.settings import parse_settings

    if {"method", "guess"} & set(section["parameters"]):
        raise ConfigError("rematch.parameters: method and guess are not parameters (see rematch.methods)")
    try:
        parse_settings({"method": section["methods"][0], **section["parameters"]})
    except LidarfieldError as e:
        message = str(e).replace("register: ", "").replace("register.", "")
        raise ConfigError(f"rematch.parameters: {message}") from None
