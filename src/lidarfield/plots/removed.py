"""The points a stage removed: red (cloud 1) and blue (cloud 2) over the kept points in grey."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .field_views import PERSPECTIVE_VIEW
from .output import save
from .settings import PlotSettings
from .stage_data import StageData, removed_xyz, sensor_origins, subsample
from .style import CLOUD_COLOURS, KEPT_COLOUR, POINTS_3D, figure, legend, mark_sensors, set_equal_3d, set_top_axes


def removed_title(stage: StageData, view: str) -> str:
    pair_name = stage.path.parent.parent.name
    n1 = int(np.count_nonzero(stage.removed["cloud"] == 1))
    n2 = int(np.count_nonzero(stage.removed["cloud"] == 2))
    return (
        f"{pair_name} · {stage.label} · removed points, {view}\n"
        f"removed {n1} of cloud 1, {n2} of cloud 2; kept {len(stage.pair.xyz1)} + {len(stage.pair.xyz2)}"
    )


def _layers(stage: StageData, n: int) -> tuple[np.ndarray, dict[int, np.ndarray]]:
    """Kept points (subsampled) and the removed points of each cloud (all, up to ``n`` each)."""
    kept = subsample(np.vstack([stage.pair.xyz1, stage.pair.xyz2]), n)
    removed = {c: subsample(removed_xyz(stage.removed, c), n) for c in (1, 2)}
    return kept, removed


def _label(cloud: int, full: int, drawn: int) -> str:
    shown = "" if drawn == full else f", {drawn} drawn"
    return f"removed from cloud {cloud} ({full}{shown})"


def plot_removed(stage: StageData, view: str, limits: np.ndarray, out_dir: Path, settings: PlotSettings) -> list[Path]:
    """``removed_top`` (view "top") or ``removed_perspective`` (view "perspective")."""
    kept, removed = _layers(stage, settings.background_points)
    counts = {c: int(np.count_nonzero(stage.removed["cloud"] == c)) for c in (1, 2)}
    fig = figure(9.0, 7.5, settings.dpi)
    three_d = view == "perspective"
    ax = fig.add_subplot(projection="3d") if three_d else fig.add_subplot()
    axes = slice(0, 3) if three_d else slice(0, 2)
    extra = POINTS_3D if three_d else {}
    ax.scatter(
        *kept[:, axes].T, s=0.5, c=KEPT_COLOUR, alpha=0.35, lw=0, rasterized=True, label="kept (both clouds)", **extra
    )
    for c, xyz in removed.items():
        if len(xyz):
            ax.scatter(
                *xyz[:, axes].T,
                s=3,
                c=CLOUD_COLOURS[c],
                alpha=0.8,
                lw=0,
                rasterized=True,
                label=_label(c, counts[c], len(xyz)),
                **extra,
            )
    mark_sensors(ax, sensor_origins(stage.pair), three_d=three_d)
    if three_d:
        set_equal_3d(ax, limits)
        ax.view_init(**PERSPECTIVE_VIEW)
    else:
        set_top_axes(ax, limits)
    legend(ax, loc="upper left")
    ax.set_title(removed_title(stage, "from above" if view == "top" else "in perspective"), fontsize=10)
    return save(fig, out_dir, f"removed_{view}", settings)
