"""The figures of one stage.

``plot_stage`` writes, into ``out_dir``, the figures selected in the settings (default: all):
``field_top``, ``field_perspective``, ``removed_top`` and ``removed_perspective`` (not for
stage 0, which removes nothing), ``top_voxels``, ``before_after`` (when the previous stage is
given), as PNG (+ SVG when asked and small), and ``field_3d.html``.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..storage.stage_points import stage_files
from .before_after import plot_before_after
from .field_views import magnified_tips, plot_field_perspective, plot_field_top
from .interactive import plot_interactive
from .removed import plot_removed
from .settings import PlotSettings, plot_settings
from .stage_data import StageData, background, load_stage, removed_xyz
from .style import magnitude_norm, resolve_magnification, view_limits
from .top_voxels import plot_top_voxels

log = logging.getLogger(__name__)


def stage_figures(settings: PlotSettings, level: int, has_previous: bool) -> list[str]:
    """The figures drawn for a stage: the selected ones that show something at this level."""
    return [
        name
        for name in settings.figures
        if not (name.startswith("removed_") and level == 0) and not (name == "before_after" and not has_previous)
    ]


def plot_stage(
    stage_dir: str | Path,
    prev_stage_dir: str | Path | None,
    out_dir: str | Path,
    settings: dict | None = None,
    plotly_js: str | Path | None = None,
    points: tuple[str | Path, Sequence[str | Path]] | None = None,
) -> list[Path]:
    """Write every figure of one stage; returns the paths written.

    ``points``: the files of the stage's points, the pair's ``registered.parquet`` and the
    ``changes.parquet`` of stages 1..k (the previous stage's: all but the last); found from
    the results' layout when None (:func:`~lidarfield.storage.stage_points.stage_files`).
    ``settings`` is the config's ``plots`` section. Axis limits come from the previous stage
    when given (its points are a superset of this stage's), so that both halves of
    ``before_after`` and the figures of consecutive stages share their axes. ``plotly_js``:
    a shared plotly.js file for the 3-D view (embedded when None). Magnification "auto" fits
    the stage's figures to its own largest vector and ``before_after`` to the larger of both.
    """
    stage, prev = load_stage(stage_dir, points), None
    if prev_stage_dir is not None:
        registered, changes = points or stage_files(stage_dir)
        prev = load_stage(prev_stage_dir, (registered, changes[:-1]))
    return draw_stage(stage, prev, out_dir, settings, plotly_js)


def draw_stage(
    stage: StageData,
    prev: StageData | None,
    out_dir: str | Path,
    settings: dict | None = None,
    plotly_js: str | Path | None = None,
) -> list[Path]:
    """``plot_stage`` of a stage (and the one before it) already in memory."""
    start = time.perf_counter()
    s = plot_settings(settings)
    out_dir = Path(out_dir)
    reference = prev if prev is not None else stage
    scene = np.vstack(
        [background(reference.pair, s.background_points), removed_xyz(stage.removed, 1), removed_xyz(stage.removed, 2)]
    )
    shown = [st for st in (stage, prev) if st is not None]
    anchors = np.vstack([st.field.tails for st in shown] + [stage.pair.origin2[None, :], np.zeros((1, 3))])
    span = float(np.max(np.diff(view_limits(scene, anchors)[:2], axis=1)))
    # the stage's own figures fit its own vectors; before/after shares one factor for both
    own = replace(s, magnification=resolve_magnification(s.magnification, stage.field.max_magnitude, span))
    both = replace(
        s, magnification=resolve_magnification(s.magnification, max(st.field.max_magnitude for st in shown), span)
    )
    tips = [magnified_tips(stage, own.magnification)] + [magnified_tips(st, both.magnification) for st in shown]
    limits = view_limits(scene, np.vstack([anchors, *tips]))

    bg = background(stage.pair, s.background_points)
    norm = magnitude_norm(stage.field)
    draw = {
        "field_top": lambda: plot_field_top(stage, bg, norm, limits, out_dir, own),
        "field_perspective": lambda: plot_field_perspective(stage, bg, norm, limits, out_dir, own),
        "removed_top": lambda: plot_removed(stage, "top", limits, out_dir, own),
        "removed_perspective": lambda: plot_removed(stage, "perspective", limits, out_dir, own),
        "top_voxels": lambda: plot_top_voxels(stage, limits, out_dir, own),
        "before_after": lambda: plot_before_after(prev, stage, limits, out_dir, both),
    }
    written = [path for name in stage_figures(s, stage.level, prev is not None) for path in draw[name]()]
    if s.interactive:
        written += plot_interactive(stage, out_dir, own, None if plotly_js is None else Path(plotly_js))
    log.info("plotted %s: %d files in %.2f s", stage.path, len(written), time.perf_counter() - start)
    return written
