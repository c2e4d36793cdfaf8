"""Figures of the study level, drawn from its tables (``lidarfield.analysis.study``).

- ``voxels_{level:02d}.png``: per stage level, polar maps (azimuth x elevation, forward up,
  seen from above) of the median magnitude and of the share of pairs above their median, so
  that a ring, an ego-vehicle sector or a mounting effect that repeats along a drive stands out;
- ``hypotheses.png``: per hypothesis, the distribution over pairs of its effect;
- ``heatmap.png``: p95 magnitude per pair (rows, worst remaining first) and stage (columns);
- ``all_pairs.png``: the largest vector stage by stage, one line per pair.

Each figure is a function of the tables returning a matplotlib figure; ``study_figures`` lists
them with their file stem and caption, and ``plot_study`` writes them.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import Normalize

from .output import png_bytes, save
from .settings import PlotSettings
from .style import MAGNITUDE_CMAP, Margins, figure

log = logging.getLogger(__name__)

DPI = 110
MAX_LEGEND_PAIRS = 12
MAX_PAIR_LABELS = 40  # a heat map labels every pair up to this many, else evenly spaced ones
SHARE_CMAP = "RdBu_r"  # share of pairs above their median: 0.5 is white (no pattern)
NO_DATA = "0.85"


@dataclass(frozen=True)
class HoverSpot:
    """A region of a figure and the numbers it shows: the page lays it over the PNG, where the
    pointer shows ``text``. ``box``: left, top, right, bottom, as fractions of the figure from
    its top-left corner (they scale with the image)."""

    box: tuple[float, float, float, float]
    text: str


@dataclass(frozen=True)
class StudyFigure:
    stem: str
    caption: str
    draw: Callable[[], object]  # returns a matplotlib figure
    hover: Callable[[object], list[HoverSpot]] | None = None  # the drawn figure's spots

    def png(self, dpi: int = DPI) -> bytes:
        return png_bytes(self.draw(), dpi)

    def spots(self) -> list[HoverSpot]:
        """The hover spots of the figure as drawn (none without ``hover``); nothing rendered."""
        if self.hover is None:
            return []
        fig = self.draw()
        try:
            return self.hover(fig)
        finally:
            plt.close(fig)


MIN_SPOT_PX = 12  # a spot's least width and height in the figure's pixels (a marker's, at least)


def spot(ax, x: tuple[float, float], y: tuple[float, float], text: str) -> HoverSpot:
    """The spot of the data rectangle ``x`` by ``y`` on ``ax``, at least MIN_SPOT_PX each way."""
    ax.viewLim  # noqa: B018 (applies a pending autoscale, so the transform is the drawn one's)
    corners = ax.transData.transform([(x[0], y[0]), (x[1], y[1])])
    width, height = ax.figure.bbox.width, ax.figure.bbox.height
    box = []
    for k, size in ((0, width), (1, height)):
        lo, hi = sorted(corners[:, k])
        grow = max(0.0, MIN_SPOT_PX - (hi - lo)) / 2
        box.append(((lo - grow) / size, (hi + grow) / size))
    (left, right), (bottom, top) = box
    return HoverSpot((left, 1 - top, right, 1 - bottom), text)


def level_label(level: int, hypothesis: str) -> str:
    return f"{int(level):02d} {hypothesis}"


# --- polar voxel maps ---------------------------------------------------------------------------


def _polar_cells(rows, grid: dict, column: str) -> np.ndarray:
    """(elevation bins, azimuth bins) array of ``column``; NaN where no row or no valid pair."""
    cells = np.full((grid["elevation_bins"], grid["azimuth_bins"]), np.nan)
    values = np.where(rows["pairs_valid"].to_numpy() > 0, rows[column].to_numpy(dtype=float), np.nan)
    cells[rows["el_bin"].to_numpy(), rows["az_bin"].to_numpy()] = values
    return cells


def _polar_axes(fig, position, grid: dict, title: str):
    ax = fig.add_subplot(*position, projection="polar")
    ax.set_theta_zero_location("N")  # forward (+x) up; azimuth = atan2(y, x) counter-clockwise
    lo, hi = grid["elevation_deg"]
    span = hi - lo
    ax.set_rorigin(-0.35 * span)  # a hole in the middle: the lowest band is not squashed to a point
    ax.set_ylim(0, span)
    ticks = np.linspace(0, span, grid["elevation_bins"] + 1)
    # only the innermost and outermost edges labelled: the bands are too narrow for every label
    ax.set_yticks(ticks, [f"{lo + t:g}°" if i in (0, len(ticks) - 1) else "" for i, t in enumerate(ticks)], fontsize=7)
    ax.set_rlabel_position(135)
    ax.set_xticks(np.radians([0, 90, 180, 270]), ["forward +x", "left +y", "back −x", "right −y"], fontsize=8)
    ax.set_facecolor(NO_DATA)
    ax.set_title(title, fontsize=9, pad=14)
    return ax


def _polar_mesh(ax, grid: dict, cells: np.ndarray, cmap: str, norm: Normalize):
    from ..field.grid import grid_from_config

    spherical = grid_from_config(grid)  # its edges: even, or moved between channels (field.channels)
    theta = np.radians(spherical.azimuth_edges())
    elevation = spherical.elevation_edges()
    r = elevation - elevation[0]
    return ax.pcolormesh(theta, r, np.ma.masked_invalid(cells), cmap=cmap, norm=norm, edgecolors="0.5", linewidth=0.2)


def voxel_map_figure(voxels, grid: dict, level: int):
    """Polar maps of one stage level: median magnitude, and share of pairs above their median
    (one row of panels per range shell)."""
    rows = voxels[voxels["level"] == level]
    hypothesis = rows["hypothesis"].iloc[0] if len(rows) else "?"
    pairs = int(rows["pairs"].max()) if len(rows) else 0
    shells = sorted(rows["r_bin"].unique()) if len(rows) else [-1]
    edges = grid.get("range_edges_m")
    fig = figure(
        10.0, 4.2 * len(shells) + 0.6, DPI, Margins(left=0.4, right=0.4, bottom=0.3, top=0.9, wspace=0.55, hspace=0.35)
    )
    magnitude_max = np.nanmax(rows["magnitude_median"].to_numpy(dtype=float), initial=0.0) if len(rows) else 0.0
    magnitude_norm = Normalize(0.0, magnitude_max if magnitude_max > 0 else 1.0)
    share_norm = Normalize(0.0, 1.0)
    for i, shell in enumerate(shells):
        shell_rows = rows[rows["r_bin"] == shell]
        where = "" if shell < 0 or not edges else f", range {edges[shell]:g}-{edges[shell + 1]:g} m"
        ax = _polar_axes(fig, (len(shells), 2, 2 * i + 1), grid, f"median magnitude over pairs{where}")
        mesh = _polar_mesh(ax, grid, _polar_cells(shell_rows, grid, "magnitude_median"), MAGNITUDE_CMAP, magnitude_norm)
        fig.colorbar(mesh, ax=ax, pad=0.16, shrink=0.8).set_label("median magnitude (m)", fontsize=8)
        ax = _polar_axes(fig, (len(shells), 2, 2 * i + 2), grid, f"share of pairs above their own median{where}")
        mesh = _polar_mesh(ax, grid, _polar_cells(shell_rows, grid, "share_above_pair_median"), SHARE_CMAP, share_norm)
        fig.colorbar(mesh, ax=ax, pad=0.16, shrink=0.8).set_label("share of valid pairs (0.5: no pattern)", fontsize=8)
    fig.suptitle(
        f"stage {level_label(level, hypothesis)}: {pairs} pairs, grid in sensor 1's frame seen from above; "
        "radius: elevation (inner ring lowest); grey: no pair valid",
        fontsize=10,
    )
    return fig


# --- hypotheses ---------------------------------------------------------------------------------


def _by_level(hypotheses) -> list[tuple[str, object]]:
    return [
        (level_label(level, rows["hypothesis"].iloc[0]), rows) for level, rows in hypotheses.groupby("level", sort=True)
    ]


def _distribution(ax, groups: list[tuple[str, np.ndarray]], ylabel: str, zero_line: bool) -> None:
    """Box plots (whiskers 5-95 %) with every pair as a faint dot."""
    rng = np.random.default_rng(0)
    data = [values[np.isfinite(values)] for _, values in groups]
    positions = np.arange(1, len(groups) + 1)
    ax.boxplot(
        data, positions=positions, whis=(5, 95), showfliers=False, widths=0.5, medianprops=dict(color="k", lw=1.5)
    )
    for x, values in zip(positions, data):
        ax.scatter(
            x + rng.uniform(-0.18, 0.18, len(values)),
            values,
            s=8,
            alpha=float(np.clip(30 / max(len(values), 1), 0.15, 0.8)),
            color="C0",
            lw=0,
        )
    if zero_line:
        ax.axhline(0.0, color="C3", lw=0.8, ls="--")
    ax.set_xticks(positions, [label.replace(" ", "\n", 1) for label, _ in groups], fontsize=8)
    ax.set_ylabel(ylabel, fontsize=9)
    ax.grid(True, axis="y", lw=0.3, alpha=0.6)


# The hypotheses figure's panels: the value per pair, its axis label, a line at zero.
HYPOTHESIS_PANELS = (
    (lambda r: r["p95_magnitude_after"] - r["p95_magnitude_before"], "change of p95 magnitude (m)", True),
    (lambda r: r["max_magnitude_after"] - r["max_magnitude_before"], "change of max magnitude (m)", True),
    (lambda r: 100.0 * r["removed_share"], "points removed (% of the stage's input)", False),
)


def hypotheses_figure(hypotheses):
    """Per hypothesis, over pairs: the change of p95 and max magnitude, and the points removed."""
    groups = _by_level(hypotheses)
    n_pairs = hypotheses["pair"].nunique()
    fig = figure(
        max(9.0, 1.6 * len(groups) * 3), 4.6, DPI, Margins(left=0.8, right=0.3, bottom=0.85, top=0.75, wspace=0.45)
    )
    for i, (value, ylabel, zero) in enumerate(HYPOTHESIS_PANELS):
        ax = fig.add_subplot(1, 3, i + 1)
        _distribution(ax, [(label, value(rows).to_numpy(dtype=float)) for label, rows in groups], ylabel, zero)
    fig.suptitle(
        f"what each hypothesis changed, over {n_pairs} pairs (box: quartiles, whiskers: 5-95 %, dots: pairs; below "
        f"the red line: smaller)",
        fontsize=10,
    )
    return fig


def hypotheses_hover(fig, hypotheses) -> list[HoverSpot]:
    """Per panel and hypothesis of ``hypotheses_figure``: its box and whiskers, giving the
    quartiles, the 5-95 % range and the pairs at either end."""
    spots = []
    for ax, (value, ylabel, _) in zip(fig.axes, HYPOTHESIS_PANELS):
        for x, (label, rows) in enumerate(_by_level(hypotheses), start=1):
            values = value(rows).to_numpy(dtype=float)
            ok = np.isfinite(values)
            if not ok.any():
                continue
            pairs, values = rows["pair"].to_numpy()[ok], values[ok]
            p5, q1, median, q3, p95 = np.percentile(values, [5, 25, 50, 75, 95])
            low, high = int(np.argmin(values)), int(np.argmax(values))
            text = (
                f"{label}: {ylabel}, {len(values)} pairs: median {median:.4g}, quartiles {q1:.4g} to {q3:.4g}, "
                f"5-95 % {p5:.4g} to {p95:.4g}; least {pairs[low]} {values[low]:.4g}, most {pairs[high]} "
                f"{values[high]:.4g}"
            )
            spots.append(spot(ax, (x - 0.25, x + 0.25), (p5, p95), text))
    return spots


# --- pairs x stages -----------------------------------------------------------------------------


def heatmap_figure(summary, ranking, key: str = "p95_magnitude", unit_label: str = "p95 magnitude (m)"):
    """``key`` per pair (rows, in rank order: most left at the last stage first) and stage level."""
    levels = sorted(summary["level"].astype(int).unique())
    order = list(ranking["pair"])
    table = summary.pivot_table(index="pair", columns="level", values=key, aggfunc="first").reindex(
        index=order, columns=levels
    )
    names = summary.sort_values("level").groupby("level")["hypothesis"].first()
    n = len(order)
    height = min(14.0, max(3.5, 0.16 * n + 1.6))
    fig = figure(7.5, height, DPI, Margins(left=1.6, right=0.3, bottom=0.9, top=0.6))
    ax = fig.add_subplot()
    image = ax.imshow(
        table.to_numpy(dtype=float),
        aspect="auto",
        interpolation="nearest",
        cmap=MAGNITUDE_CMAP,
        norm=Normalize(0.0, max(float(np.nanmax(table.to_numpy(dtype=float), initial=0.0)), 1e-9)),
    )
    ax.set_xticks(
        range(len(levels)), [level_label(lv, names.get(lv, "")).replace(" ", "\n", 1) for lv in levels], fontsize=8
    )
    shown = (
        np.arange(n) if n <= MAX_PAIR_LABELS else np.unique(np.linspace(0, n - 1, MAX_PAIR_LABELS).round().astype(int))
    )
    ax.set_yticks(shown, [f"{i + 1}. {order[i]}" for i in shown], fontsize=7 if n <= MAX_PAIR_LABELS else 6)
    ax.set_xlabel("stage")
    ax.set_ylabel(
        f"pair, ranked by {unit_label.split(' (')[0]} at the last stage"
        + ("" if n <= MAX_PAIR_LABELS else f" (every {n // MAX_PAIR_LABELS}th labelled)"),
        fontsize=8,
    )
    fig.colorbar(image, ax=ax, pad=0.02).set_label(unit_label, fontsize=9)
    ax.set_title(f"{unit_label.split(' (')[0]} of every pair at every stage ({n} pairs)", fontsize=10)
    return fig


def all_pairs_figure(summary, key: str = "max_magnitude", title: str = "largest vector, stage by stage, all pairs"):
    """One line per pair of ``key`` against the stage level (and the median beyond a dozen pairs)."""
    fig = figure(9.0, 5.0, DPI)
    ax = fig.add_subplot()
    by_pair = list(summary.sort_values("level").groupby("pair", sort=True))
    many = len(by_pair) > MAX_LEGEND_PAIRS
    for name, rows in by_pair:
        ax.plot(
            rows["level"],
            rows[key],
            "-" if many else "o-",
            lw=0.6 if many else 1.5,
            alpha=max(0.05, min(0.4, 20.0 / len(by_pair))) if many else 1.0,
            color="C0" if many else None,
            label=None if many else name,
        )
    if many:
        medians = summary.groupby("level")[key].median()
        ax.plot(
            medians.index, medians.to_numpy(), "ko-", lw=2.5, label=f"median of {len(by_pair)} pairs (blue: each pair)"
        )
    levels = sorted(summary["level"].astype(int).unique())
    ax.set_xticks(levels)
    ax.set_xlabel("stage level")
    ax.set_ylabel(f"{key.replace('_', ' ')} (m)")
    ax.set_ylim(bottom=0)
    ax.grid(True, lw=0.3, alpha=0.6)
    ax.legend(fontsize=8, ncol=2)
    ax.set_title(title, fontsize=10)
    return fig


def all_pairs_hover(fig, summary, key: str = "max_magnitude") -> list[HoverSpot]:
    """The points of ``all_pairs_figure``: each pair's at each stage; beyond a dozen pairs, the
    medians', giving the largest and smallest pair too."""
    ax = fig.axes[0]
    names = summary.sort_values("level").groupby("level")["hypothesis"].first()
    what = key.replace("_", " ")
    by_pair = list(summary.sort_values("level").groupby("pair", sort=True))
    spots = []
    if len(by_pair) <= MAX_LEGEND_PAIRS:
        for name, rows in by_pair:
            for level, v in zip(rows["level"].astype(int), rows[key].astype(float)):
                text = f"{name} · stage {level_label(level, names[level])}: {what} {v:.4g} m"
                spots.append(spot(ax, (level, level), (v, v), text))
        return spots
    for level, rows in summary.groupby("level", sort=True):
        values, pairs = rows[key].to_numpy(dtype=float), rows["pair"].to_numpy()
        ok = np.isfinite(values)
        if not ok.any():
            continue
        values, pairs = values[ok], pairs[ok]
        median, low, high = float(np.median(values)), int(np.argmin(values)), int(np.argmax(values))
        text = (
            f"stage {level_label(int(level), names[level])}: {what}, median of {len(values)} pairs {median:.4g} m; "
            f"largest {pairs[high]} {values[high]:.4g} m, smallest {pairs[low]} {values[low]:.4g} m"
        )
        spots.append(spot(ax, (level, level), (median, median), text))
    return spots


# --- all of them ----------------------------------------------------------------------------------


def study_figures(summary, voxels, hypotheses, ranking, grid: dict) -> list[StudyFigure]:
    """The study's figures, in the order the overview shows them."""
    figures = [
        StudyFigure(
            "heatmap",
            "p95 magnitude of every pair at every stage, pairs ranked by what remains",
            lambda: heatmap_figure(summary, ranking),
        ),
    ]
    if len(hypotheses):
        figures.append(
            StudyFigure(
                "hypotheses",
                "what each hypothesis changed, over the pairs",
                lambda: hypotheses_figure(hypotheses),
                lambda fig: hypotheses_hover(fig, hypotheses),
            )
        )
    figures.append(
        StudyFigure(
            "all_pairs",
            "largest vector, stage by stage, all pairs",
            lambda: all_pairs_figure(summary),
            lambda fig: all_pairs_hover(fig, summary),
        )
    )
    if grid.get("kind", "spherical") == "spherical" and voxels is not None and len(voxels):
        for level in sorted(voxels["level"].unique()):
            name = voxels.loc[voxels["level"] == level, "hypothesis"].iloc[0]
            figures.append(
                StudyFigure(
                    f"voxels_{int(level):02d}",
                    f"stage {level_label(level, name)}: voxels over the pairs (polar map)",
                    lambda level=level: voxel_map_figure(voxels, grid, level),
                )
            )
    return figures


def plot_study(summary, voxels, hypotheses, ranking, grid: dict, out_dir: str | Path) -> list[Path]:
    """Write every study figure as PNG into ``out_dir``; returns the paths."""
    out_dir = Path(out_dir)
    settings = PlotSettings(dpi=DPI)
    written = []
    for f in study_figures(summary, voxels, hypotheses, ranking, grid):
        written += save(f.draw(), out_dir, f.stem, settings)
    log.info("study figures: %d written to %s", len(written), out_dir)
    return written
