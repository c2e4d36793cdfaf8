"""The discrepancy field from above (x-y) and in perspective: arrows from mean1 to mean2."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize

from .output import save
from .settings import PlotSettings
from .stage_data import StageData, sensor_origins
from .style import (
    BACKGROUND_COLOUR,
    MAGNITUDE_CMAP,
    POINTS_3D,
    figure,
    format_length,
    legend,
    mark_sensors,
    nice_length,
    set_equal_3d,
    set_top_axes,
    vector_colours,
)

PERSPECTIVE_VIEW = dict(elev=35.0, azim=-60.0)


def magnified_tips(stage: StageData, magnification: float) -> np.ndarray:
    return stage.field.tails + magnification * stage.field.vectors


def draw_field_top(ax, stage: StageData, bg: np.ndarray, norm: Normalize, limits: np.ndarray, settings: PlotSettings):
    """Arrows (magnified) over the faint points, sensors marked, the scale arrow in a corner."""
    f = stage.field
    ax.scatter(
        bg[:, 0], bg[:, 1], s=0.8, c=BACKGROUND_COLOUR, alpha=0.45, lw=0, rasterized=True, label="points (both clouds)"
    )
    order = np.lexsort((f.magnitude, f.significant))  # significant and largest drawn last, on top
    m = settings.magnification
    q = ax.quiver(
        f.tails[order, 0],
        f.tails[order, 1],
        m * f.vectors[order, 0],
        m * f.vectors[order, 1],
        color=vector_colours(f, norm)[order],
        angles="xy",
        scale_units="xy",
        scale=1.0,
        width=0.004,
        headwidth=3.5,
        headlength=4.5,
        minlength=0.5,
        zorder=3,
    )
    if not f.significant.all():
        ax.plot([], [], color="0.8", lw=3, label=f.faded_label())
    mark_sensors(ax, sensor_origins(stage.pair))
    scale = nice_length(norm.vmax / 2)  # from the shared colour scale: one arrow in both halves of before/after
    ax.quiverkey(
        q,
        X=0.84,
        Y=0.04,
        U=m * scale,
        coordinates="axes",
        labelpos="N",
        color="k",
        label=f"scale: {format_length(scale)}" + (f" (drawn ×{m:g})" if m != 1 else ""),
        fontproperties=dict(size=8),
    )
    set_top_axes(ax, limits)
    legend(ax, loc="lower left")
    return q


def draw_field_3d(
    ax, stage: StageData, bg: np.ndarray, norm: Normalize, limits: np.ndarray, settings: PlotSettings
) -> None:
    f = stage.field
    ax.scatter(bg[:, 0], bg[:, 1], bg[:, 2], s=0.3, c=BACKGROUND_COLOUR, alpha=0.25, lw=0, rasterized=True, **POINTS_3D)
    if len(f.magnitude):
        colours = vector_colours(f, norm)
        m = settings.magnification
        # A 3-D quiver draws the shafts, then two head lines per arrow: colours in that order.
        ax.quiver(
            *f.tails.T,
            *(m * f.vectors).T,
            colors=np.concatenate([colours, np.repeat(colours, 2, axis=0)]),
            arrow_length_ratio=0.25,
            linewidths=1.3,
        )
    mark_sensors(ax, sensor_origins(stage.pair), three_d=True)
    if len(f.magnitude) and not f.significant.all():
        ax.text2D(0.02, 0.02, f.faded_label(), transform=ax.transAxes, fontsize=8, color="0.3")
    set_equal_3d(ax, limits)
    ax.view_init(**PERSPECTIVE_VIEW)


def stage_title(stage: StageData, what: str) -> str:
    pair_name = stage.path.parent.parent.name
    f = stage.field
    return (
        f"{pair_name} · {stage.label} · {what}\n"
        f"{len(f.magnitude)} valid voxels ({np.count_nonzero(f.significant)} with |z| ≥ {f.z_min:g})"
        f" · largest vector {f.max_magnitude:.3f} m"
    )


def colour_bar(fig, ax, norm: Normalize) -> None:
    three_d = getattr(ax, "name", "") == "3d"  # its z tick labels stand out to the right of its box
    fig.colorbar(
        ScalarMappable(norm, MAGNITUDE_CMAP),
        ax=ax,
        shrink=0.8,
        pad=0.12 if three_d else 0.05,
        label="vector magnitude |mean2 − mean1| (m)",
    )


def plot_field_top(
    stage: StageData, bg: np.ndarray, norm: Normalize, limits: np.ndarray, out_dir: Path, settings: PlotSettings
) -> list[Path]:
    fig = figure(9.0, 7.5, settings.dpi)
    ax = fig.add_subplot()
    draw_field_top(ax, stage, bg, norm, limits, settings)
    colour_bar(fig, ax, norm)
    ax.set_title(stage_title(stage, "field from above"), fontsize=10)
    return save(fig, out_dir, "field_top", settings)


def plot_field_perspective(
    stage: StageData, bg: np.ndarray, norm: Normalize, limits: np.ndarray, out_dir: Path, settings: PlotSettings
) -> list[Path]:
    fig = figure(9.0, 7.5, settings.dpi)
    ax = fig.add_subplot(projection="3d")
    draw_field_3d(ax, stage, bg, norm, limits, settings)
    colour_bar(fig, ax, norm)
    m = settings.magnification
    ax.set_title(
        stage_title(stage, "field in perspective" + (f" (vectors drawn ×{m:g})" if m != 1 else "")), fontsize=10
    )
    return save(fig, out_dir, "field_perspective", settings)
