"""Stage k-1 and stage k side by side: same axes, same colour scale, same magnification."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .field_views import colour_bar, draw_field_top
from .output import save
from .settings import PlotSettings
from .stage_data import StageData, background
from .style import figure, magnitude_norm


def plot_before_after(
    before: StageData, after: StageData, limits: np.ndarray, out_dir: Path, settings: PlotSettings
) -> list[Path]:
    norm = magnitude_norm(before.field, after.field)
    fig = figure(16.0, 7.5, settings.dpi)
    axes = fig.subplots(1, 2, sharex=True, sharey=True)
    for ax, stage in zip(axes, (before, after)):
        draw_field_top(ax, stage, background(stage.pair, settings.background_points), norm, limits, settings)
        f = stage.field
        ax.set_title(f"{stage.label}\n{len(f.magnitude)} valid voxels · largest {f.max_magnitude:.3f} m", fontsize=10)
    colour_bar(fig, axes, norm)
    pair_name = after.path.parent.parent.name
    a, b = before.field.max_magnitude, after.field.max_magnitude
    fig.suptitle(
        f"{pair_name} · before / after {after.hypothesis}: largest vector {a:.3f} → {b:.3f} m ({b - a:+.3f} m)",
        fontsize=11,
    )
    return save(fig, out_dir, "before_after", settings)
