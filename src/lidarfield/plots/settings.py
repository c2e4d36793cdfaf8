"""The ``plots`` section of a study config as a typed object, its defaults from the schema."""

from __future__ import annotations

from dataclasses import dataclass, fields

from ..defaults import default, section
from ..errors import ConfigError

# A stage's figures. Stage 0 removes nothing and has no previous stage: it gets neither the
# removed_* figures nor before_after.
STAGE_FIGURES = tuple(section("plots")["properties"]["figures"]["items"]["enum"])


@dataclass(frozen=True)
class PlotSettings:
    """The ``plots`` section of the config (without ``pairs``, see :func:`figure_settings`)."""

    magnification: float | str = default(
        "plots", "magnification"
    )  # vectors drawn this many times their length, or "auto"
    top_k: int = default("plots", "top_k")  # voxels drawn as wireframes in top_voxels.png
    background_points: int = default(
        "plots", "background_points"
    )  # max points drawn faint behind the vectors, per figure
    figures: tuple[str, ...] = tuple(default("plots", "figures"))  # which of a stage's figures to draw
    formats: tuple[str, ...] = tuple(default("plots", "formats"))  # "svg" adds an SVG where it stays small
    dpi: int = default("plots", "dpi")
    interactive: bool = default("plots", "interactive")  # write field_3d.html


def figure_settings(plots: dict | None) -> dict:
    """The ``plots`` section without ``pairs``: which pairs get figures is the workflow's
    choice, not a figure's setting, so changing it redraws no figure."""
    return {k: v for k, v in (plots or {}).items() if k != "pairs"}


def plot_settings(settings: dict | None) -> PlotSettings:
    """PlotSettings from a config ``plots`` mapping (missing keys take their defaults)."""
    settings = figure_settings(settings)
    known = {f.name for f in fields(PlotSettings)}
    unknown = set(settings) - known
    if unknown:
        raise ConfigError(f"plots: unknown key(s) {sorted(unknown)}; known: {sorted(known)}")
    if "figures" in settings:
        figures = tuple(settings["figures"])
        unknown_figures = [f for f in figures if f not in STAGE_FIGURES]
        if unknown_figures:
            raise ConfigError(f"plots.figures: unknown figure(s) {unknown_figures}; known: {list(STAGE_FIGURES)}")
        settings["figures"] = figures
    if "formats" in settings:
        formats = tuple(settings["formats"])
        bad = [f for f in formats if f not in ("png", "svg")]
        if bad or "png" not in formats:
            raise ConfigError(f"plots.formats: must list 'png' and optionally 'svg', got {list(formats)!r}")
        settings["formats"] = formats
    s = PlotSettings(**settings)
    if s.magnification != "auto" and not (isinstance(s.magnification, (int, float)) and s.magnification > 0):
        raise ConfigError(f"plots.magnification: must be a number > 0 or 'auto', got {s.magnification!r}")
    if s.top_k < 0 or s.background_points < 0 or s.dpi < 50:
        raise ConfigError("plots: top_k and background_points must be >= 0 and dpi >= 50")
    return s
