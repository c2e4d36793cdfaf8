"""One pair, stage by stage: magnitude statistics, and the rigid part and randomness of the field."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..analysis.tags import TAGS
from .output import png_bytes, save
from .settings import PlotSettings, plot_settings
from .style import Margins, figure, legend_at_right

MAGNITUDE_SERIES = (
    ("max_magnitude", "max", "o-"),
    ("p95_magnitude", "95th percentile", "s-"),
    ("mean_magnitude", "mean", "^-"),
    ("paper_max_metric", "paper metric ‖max |u|,|v|,|w|‖", "D--"),
)


STAGE_AXIS_MARGINS = Margins(bottom=0.8, top=0.45)  # the stage ticks are two lines: level, hypothesis


def column(rows: list[dict], key: str) -> np.ndarray:
    """A numeric column of the rows; NaN where a row lacks it."""
    out = []
    for r in rows:
        v = r.get(key)
        try:
            out.append(float(v))
        except (TypeError, ValueError):
            out.append(np.nan)
    return np.array(out, dtype=np.float64)


def translation_norm(rows: list[dict]) -> np.ndarray:
    norms = []
    for r in rows:
        t = r.get("rigid_translation_m")
        try:
            norms.append(float(np.linalg.norm(np.asarray(t, dtype=np.float64))))
        except (TypeError, ValueError):
            norms.append(np.nan)
    return np.array(norms)


def stage_ticks(ax, rows: list[dict]) -> None:
    levels = column(rows, "level")
    ax.set_xticks(levels, [f"{int(lv):02d}\n{r.get('hypothesis', '')}" for lv, r in zip(levels, rows)], fontsize=8)
    ax.set_xlabel("stage")
    ax.grid(True, lw=0.3, alpha=0.6)


def sorted_rows(rows: list[dict]) -> list[dict]:
    return sorted(rows, key=lambda r: float(r.get("level", 0)))


def stages_figure(rows: list[dict], dpi: int):
    rows = sorted_rows(rows)
    fig = figure(8.0, 5.0, dpi, STAGE_AXIS_MARGINS)
    ax = fig.add_subplot()
    x = column(rows, "level")
    for key, label, style in MAGNITUDE_SERIES:
        ax.plot(x, column(rows, key), style, label=label)
    stage_ticks(ax, rows)
    ax.set_ylabel("vector magnitude (m)")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8)
    ax.set_title(f"{rows[0].get('pair', '') if rows else ''} · field magnitude stage by stage", fontsize=10)
    return fig


def rigid_randomness_figure(rows: list[dict], dpi: int):
    rows = sorted_rows(rows)
    fig = figure(8.0, 6.5, dpi, Margins(right=0.85, bottom=0.8, top=0.45, hspace=0.12))
    ax_share, ax_rigid = fig.subplots(2, 1, sharex=True)
    x = column(rows, "level")
    ax_share.plot(x, column(rows, "rigid_energy_share"), "o-", label="rigid energy share")
    ax_share.plot(x, column(rows, "mean_resultant_length"), "s-", label="mean resultant length")
    ax_share.set_ylim(-0.02, 1.02)
    ax_share.set_ylabel("share (0..1)")
    ax_share.legend(fontsize=8)
    ax_share.grid(True, lw=0.3, alpha=0.6)
    ax_share.set_title(
        f"{rows[0].get('pair', '') if rows else ''} · rigid part and randomness of the field", fontsize=10
    )
    ax_rigid.plot(x, translation_norm(rows), "o-", color="C2", label="rigid translation ‖t‖ (m)")
    ax_rigid.set_ylabel("translation (m)")
    ax_rot = ax_rigid.twinx()
    ax_rot.plot(x, column(rows, "rigid_rotation_deg"), "^--", color="C3", label="rigid rotation (deg)")
    ax_rot.set_ylabel("rotation (deg)")
    lines = ax_rigid.get_lines() + ax_rot.get_lines()
    ax_rigid.legend(lines, [ln.get_label() for ln in lines], fontsize=8)
    stage_ticks(ax_rigid, rows)
    return fig


def tags_figure(rows: list[dict], dpi: int):
    """Per stage, each tag's share of the field energy (bars), with the verdict and the
    significant voxels under the stage ticks."""
    rows = sorted_rows(rows)
    fig = figure(8.0, 5.0, dpi, Margins(bottom=1.1, top=0.45))
    ax = fig.add_subplot()
    x = column(rows, "level")
    width = 0.8 / len(TAGS)
    for i, tag in enumerate(TAGS):
        ax.bar(
            x + (i - (len(TAGS) - 1) / 2) * width,
            column(rows, f"energy_share_{tag}"),
            width,
            label=tag.replace("_", " "),
        )
    ax.set_ylim(0, 1.02)
    ax.set_ylabel("share of the field energy Σ min(n1, n2)·|v|² (0..1)")
    levels = [f"{int(lv):02d} {r.get('hypothesis', '')}" for lv, r in zip(x, rows)]
    verdicts = [
        f"{r.get('verdict') or '?'} · {r.get('voxels_significant', '?')}/{r.get('voxels_valid', '?')}" for r in rows
    ]
    ax.set_xticks(x, [f"{a}\n{b}" for a, b in zip(levels, verdicts)], fontsize=8)
    ax.set_xlabel("stage (verdict, voxels with |z| ≥ z_min / valid)")
    ax.grid(True, axis="y", lw=0.3, alpha=0.6)
    # The last stage's two-line tick label reaches past the axes: a wider gap keeps it off the legend.
    legend_at_right(fig, ax.get_legend_handles_labels()[0], gap_in=0.7, fontsize=8, title="voxel tag", title_fontsize=8)
    ax.set_title(
        f"{rows[0].get('pair', '') if rows else ''} · where the field's energy sits, stage by stage", fontsize=10
    )
    return fig


PAIR_FIGURES = {"stages": stages_figure, "rigid_randomness": rigid_randomness_figure, "tags": tags_figure}


def plot_pair(stats_rows: list[dict], out_dir: str | Path, settings: dict | PlotSettings | None = None) -> list[Path]:
    """``stages.png``, ``rigid_randomness.png`` and ``tags.png`` of one pair from its summary rows."""
    s = settings if isinstance(settings, PlotSettings) else plot_settings(settings)
    written = []
    for stem, make in PAIR_FIGURES.items():
        written += save(make(stats_rows, s.dpi), Path(out_dir), stem, s)
    return written


def pair_figure_png(stem: str, rows: list[dict], dpi: int) -> bytes:
    """One pair figure as PNG bytes (the report renders them when the files are absent)."""
    return png_bytes(PAIR_FIGURES[stem](rows, dpi), dpi)
