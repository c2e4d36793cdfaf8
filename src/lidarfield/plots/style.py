"""What every figure shares in its look: colours, the figure and its fixed margins, legends,
sensor marks, axes, scale lengths and the magnification of the vectors."""

from __future__ import annotations

from dataclasses import dataclass

import matplotlib

matplotlib.use("Agg")  # before pyplot: batch jobs have no display

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.cm import ScalarMappable  # noqa: E402
from matplotlib.colors import Normalize  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from .stage_data import VectorField  # noqa: E402

CLOUD_COLOURS = {1: "#d62728", 2: "#1f77b4"}  # red = cloud 1, blue = cloud 2 (removed figures)

KEPT_COLOUR = "0.55"

BACKGROUND_COLOUR = "0.6"

MAGNITUDE_CMAP = "viridis"

FADED_ALPHA = 0.2  # vectors within their sampling noise (|z| < grid.z_min) are drawn faint

SENSOR_STYLE = {
    1: dict(marker="^", color="#d62728", label="sensor 1"),
    2: dict(marker="v", color="#1f77b4", label="sensor 2"),
}

# 3-D point layers: flat colours, and nothing drawn outside the axes box (the view limits leave
# out the farthest returns; mplot3d would draw them over the labels)
POINTS_3D = dict(depthshade=False, axlim_clip=True)


def vector_colours(field: VectorField, norm: Normalize) -> np.ndarray:
    """RGBA per vector: its magnitude's colour, faded to ``FADED_ALPHA`` where |z| < z_min."""
    colours = ScalarMappable(norm, MAGNITUDE_CMAP).to_rgba(field.magnitude)
    colours[~field.significant, 3] = FADED_ALPHA
    return colours


def view_limits(points: np.ndarray, extra: np.ndarray, pad: float = 0.05) -> np.ndarray:
    """(3, 2) axis limits: the 0.5..99.5 percentile box of ``points`` (a few far returns do not
    shrink the scene) grown to hold every row of ``extra`` (the drawn vectors), then padded."""
    boxes = []
    if len(points):
        boxes.append(np.percentile(points, [0.5, 99.5], axis=0).T)
    if len(extra):
        boxes.append(np.column_stack([extra.min(axis=0), extra.max(axis=0)]))
    if not boxes:
        return np.array([[-1.0, 1.0]] * 3)
    lo = np.min([b[:, 0] for b in boxes], axis=0)
    hi = np.max([b[:, 1] for b in boxes], axis=0)
    span = np.maximum(hi - lo, 1e-6)
    return np.column_stack([lo - pad * span, hi + pad * span])


def magnitude_norm(*fields_: VectorField) -> Normalize:
    """One colour scale (0 .. largest magnitude) shared by every field given."""
    vmax = max((f.max_magnitude for f in fields_), default=0.0)
    return Normalize(vmin=0.0, vmax=vmax if vmax > 0 else 1.0)


AUTO_ARROW_SHARE = 1 / 16  # "auto": the largest vector is drawn about this share of the view's width


def resolve_magnification(setting: float | str, max_magnitude: float, view_span_m: float) -> float:
    """The factor the vectors are drawn with. "auto" draws the largest vector at about 1/16 of
    the view (a centimetre field on a 50 m scene is otherwise invisible), rounded down to 1, 2
    or 5 times a power of ten so the scale reads easily, and never shrinks vectors (>= 1)."""
    if setting != "auto":
        return float(setting)
    if not max_magnitude > 0:
        return 1.0
    return max(1.0, nice_length(AUTO_ARROW_SHARE * view_span_m / max_magnitude))


def nice_length(x: float) -> float:
    """A round number (1, 2 or 5 times a power of ten) not above ``x``: the scale arrow's length."""
    if not x > 0:
        return 1.0
    power = 10.0 ** np.floor(np.log10(x))
    for step in (5.0, 2.0, 1.0):
        if step * power <= x:
            return float(step * power)
    return float(power)


def format_length(metres: float) -> str:
    if metres >= 1:
        return f"{metres:g} m"
    if metres >= 0.01:
        return f"{metres * 100:g} cm"
    return f"{metres * 1000:g} mm"


@dataclass(frozen=True)
class Margins:
    """The space around a figure's subplots, in inches; ``wspace``/``hspace`` between subplots
    as a fraction of their width/height (matplotlib's convention)."""

    left: float = 0.85
    right: float = 0.3
    bottom: float = 0.65
    top: float = 0.7
    wspace: float = 0.2
    hspace: float = 0.2


def figure(width_in: float, height_in: float, dpi: int, margins: Margins = Margins()):
    """A figure whose subplots sit within fixed margins. A fixed layout because a layout engine
    (constrained, tight) draws the whole figure once more at save time to measure it: that
    was a third of the time of a stage's figures."""
    fig = plt.figure(figsize=(width_in, height_in), dpi=dpi)
    fig.subplots_adjust(
        left=margins.left / width_in,
        right=1 - margins.right / width_in,
        bottom=margins.bottom / height_in,
        top=1 - margins.top / height_in,
        wspace=margins.wspace,
        hspace=margins.hspace,
    )
    return fig


def legend_at_right(fig, handles: list, gap_in: float = 0.25, **kwargs):
    """A figure legend along the right edge, with the subplots moved out of its way: its width
    is measured from its text (no draw), so no layout engine is needed."""
    box = fig.legend(handles=handles, loc="center right", **kwargs)
    width_in = box.get_window_extent(fig.canvas.get_renderer()).width / fig.dpi
    fig.subplots_adjust(right=1 - (width_in + gap_in) / fig.get_figwidth())
    return box


def mark_sensors(ax, origins: dict[int, np.ndarray], three_d: bool = False) -> None:
    for k, o in origins.items():
        style = SENSOR_STYLE[k]
        if three_d:
            ax.scatter([o[0]], [o[1]], [o[2]], s=50, edgecolors="k", zorder=5, depthshade=False, **style)
        else:
            ax.scatter([o[0]], [o[1]], s=80, edgecolors="k", zorder=5, **style)


def legend(ax, **kwargs):
    """A legend whose markers stay readable even when the points themselves are drawn tiny."""
    handle_box = ax.legend(fontsize=8, framealpha=0.85, **kwargs)
    for handle in handle_box.legend_handles:
        if hasattr(handle, "set_sizes"):
            handle.set_sizes([30])
        handle.set_alpha(1.0)
    return handle_box


def set_equal_3d(ax, limits: np.ndarray, min_z_share: float = 0.3) -> None:
    """True-scale 3-D axes; a flat scene's z range is widened (never squashed) to stay readable."""
    limits = limits.copy()
    horizontal = float(np.max(limits[:2, 1] - limits[:2, 0]))
    if limits[2, 1] - limits[2, 0] < min_z_share * horizontal:
        mid = limits[2].mean()
        limits[2] = [mid - min_z_share * horizontal / 2, mid + min_z_share * horizontal / 2]
    ax.set_xlim(*limits[0])
    ax.set_ylim(*limits[1])
    ax.set_zlim(*limits[2])
    ax.set_box_aspect(tuple(np.maximum(limits[:, 1] - limits[:, 0], 1e-6)))
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    # Matplotlib's automatic ticks crowd a foreshortened 3-D axis (z had 9 labels in 4 cm),
    # and every tick is an object drawn at save time: fewer ticks read better and cost less.
    ax.xaxis.set_major_locator(MaxNLocator(nbins=6, steps=[1, 2, 2.5, 5, 10]))
    ax.yaxis.set_major_locator(MaxNLocator(nbins=6, steps=[1, 2, 2.5, 5, 10]))
    ax.zaxis.set_major_locator(MaxNLocator(nbins=4, steps=[1, 2, 2.5, 5, 10]))
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.pane.set_visible(False)  # white figures: no grey panes (hidden, not drawn transparent)


def set_top_axes(ax, limits: np.ndarray) -> None:
    ax.set_xlim(*limits[0])
    ax.set_ylim(*limits[1])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, lw=0.3, alpha=0.5)
