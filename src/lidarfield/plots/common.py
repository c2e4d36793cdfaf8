"""What every figure shares: settings, loading a stage folder, subsampling, styling, saving.

A stage folder holds ``points.parquet`` (survivors), ``removed.parquet`` (points this stage
removed, with a ``hypothesis`` column) and ``field.parquet`` (one row per voxel); see the
shared layout. Figures are written atomically: a reader never sees half a PNG.
"""

from __future__ import annotations

import io
from dataclasses import dataclass, fields
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # before pyplot: batch jobs have no display

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.cm import ScalarMappable  # noqa: E402
from matplotlib.colors import Normalize  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from ..config import figure_settings  # noqa: E402
from ..errors import ConfigError, InputError  # noqa: E402
from ..io.atomic import atomic_path  # noqa: E402
from ..io.parquet_table import read_table  # noqa: E402
from ..pair import RegisteredPair, read_pair  # noqa: E402
from ..stages import level_of  # noqa: E402
from .png import compact_image, encode_png, figure_image, figure_png, page_copy_path  # noqa: E402

FIELD_COLUMNS = ("voxel", "n1", "n2", "x1", "y1", "z1", "x2", "y2", "z2", "u", "v", "w", "magnitude", "valid")
CLOUD_COLOURS = {1: "#d62728", 2: "#1f77b4"}  # red = cloud 1, blue = cloud 2 (removed figures)
KEPT_COLOUR = "0.55"
BACKGROUND_COLOUR = "0.6"
MAGNITUDE_CMAP = "viridis"
FADED_ALPHA = 0.2  # vectors within their sampling noise (|z| < grid.z_min) are drawn faint
SENSOR_STYLE = {1: dict(marker="^", color="#d62728", label="sensor 1"), 2: dict(marker="v", color="#1f77b4", label="sensor 2")}
# 3-D point layers: flat colours, and nothing drawn outside the axes box (the view limits leave
# out the farthest returns; mplot3d would draw them over the labels)
POINTS_3D = dict(depthshade=False, axlim_clip=True)
SVG_MAX_BYTES = 2_000_000  # "SVG where it stays small": above this only the PNG is kept
SUBSAMPLE_SEED = 0


# A stage's figures. Stage 0 removes nothing and has no previous stage: it gets neither the
# removed_* figures nor before_after.
STAGE_FIGURES = ("field_top", "field_perspective", "removed_top", "removed_perspective", "top_voxels", "before_after")


@dataclass(frozen=True)
class PlotSettings:
    """The ``plots`` section of the config."""

    magnification: float | str = "auto"  # vectors drawn this many times their length, or "auto"
    top_k: int = 10  # voxels drawn as wireframes in top_voxels.png
    background_points: int = 20000  # max points drawn faint behind the vectors, per figure
    figures: tuple[str, ...] = STAGE_FIGURES  # which of a stage's figures to draw
    formats: tuple[str, ...] = ("png",)  # "svg" adds an SVG where it stays small
    dpi: int = 120
    interactive: bool = True  # write field_3d.html


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


@dataclass
class VectorField:
    """The valid vectors of a stage's field: tails (mean1), vectors (mean2 - mean1), magnitudes."""

    tails: np.ndarray  # (M, 3)
    vectors: np.ndarray  # (M, 3)
    magnitude: np.ndarray  # (M,)
    columns: dict[str, np.ndarray]  # the valid rows of every field column
    meta: dict

    @property
    def max_magnitude(self) -> float:
        return float(self.magnitude.max()) if len(self.magnitude) else 0.0

    @property
    def z_min(self) -> float:
        return float(self.meta.get("z_min") or 3.0)

    @property
    def significant(self) -> np.ndarray:
        """|z| >= z_min per vector (all True for a field written before z existed)."""
        if "z" not in self.columns:
            return np.ones(len(self.magnitude), dtype=bool)
        with np.errstate(invalid="ignore"):
            return np.abs(np.asarray(self.columns["z"], dtype=np.float64)) >= self.z_min

    def colours(self, norm: Normalize) -> np.ndarray:
        """RGBA per vector: its magnitude's colour, faded to ``FADED_ALPHA`` where |z| < z_min."""
        colours = ScalarMappable(norm, MAGNITUDE_CMAP).to_rgba(self.magnitude)
        colours[~self.significant, 3] = FADED_ALPHA
        return colours

    def faded_label(self) -> str:
        return f"faded: |z| < {self.z_min:g}, within sampling noise ({np.count_nonzero(~self.significant)} of {len(self.magnitude)})"


@dataclass
class Stage:
    """One stage folder, loaded."""

    path: Path
    pair: RegisteredPair  # the survivors of this stage
    points_meta: dict
    removed: dict[str, np.ndarray]  # removed.parquet columns (empty arrays for stage 0)
    field: VectorField

    @property
    def stage_id(self) -> str:
        return str(self.points_meta.get("stage") or self.field.meta.get("stage") or self.path.name)

    @property
    def level(self) -> int:
        level = self.points_meta.get("level")
        if level is None:
            level = level_of(self.stage_id) or 0
        return int(level)

    @property
    def hypothesis(self) -> str:
        return str(self.points_meta.get("hypothesis") or ("none" if self.level == 0 else "?"))

    @property
    def label(self) -> str:
        return f"stage {self.level:02d} {self.hypothesis}"


def read_vector_field(path: str | Path) -> VectorField:
    """The valid rows of a field Parquet file (contract columns required)."""
    columns, meta = read_table(path, required=FIELD_COLUMNS)
    valid = np.asarray(columns["valid"], dtype=bool) & np.isfinite(columns["magnitude"])
    columns = {k: np.asarray(v)[valid] for k, v in columns.items()}
    tails = np.column_stack([columns["x1"], columns["y1"], columns["z1"]]).astype(np.float64)
    vectors = np.column_stack([columns["u"], columns["v"], columns["w"]]).astype(np.float64)
    return VectorField(tails, vectors, columns["magnitude"].astype(np.float64), columns, meta)


def load_stage(stage_dir: str | Path) -> Stage:
    """Read a stage folder; a missing or malformed file raises InputError naming it."""
    stage_dir = Path(stage_dir)
    if not stage_dir.is_dir():
        raise InputError("stage folder not found", stage_dir)
    field = read_vector_field(stage_dir / "field.parquet")
    pair, points_meta = read_pair(stage_dir / "points.parquet")
    removed_path = stage_dir / "removed.parquet"
    if removed_path.exists():
        removed, _ = read_table(removed_path, required=("cloud", "x", "y", "z"))
    else:
        removed = {"cloud": np.zeros(0, np.uint8), "x": np.zeros(0), "y": np.zeros(0), "z": np.zeros(0)}
    return Stage(stage_dir, pair, points_meta, removed, field)


def subsample(xyz: np.ndarray, n: int, seed: int = SUBSAMPLE_SEED) -> np.ndarray:
    """At most ``n`` rows of ``xyz``, chosen with a fixed seed (same figure on every run)."""
    if len(xyz) <= n:
        return xyz
    rng = np.random.default_rng(seed)
    return xyz[np.sort(rng.choice(len(xyz), size=n, replace=False))]


def removed_xyz(removed: dict[str, np.ndarray], cloud: int) -> np.ndarray:
    mask = np.asarray(removed["cloud"]) == cloud
    return np.column_stack([removed["x"][mask], removed["y"][mask], removed["z"][mask]]).astype(np.float64)


def background(pair: RegisteredPair, n: int) -> np.ndarray:
    """Both clouds together, subsampled to at most ``n`` points."""
    return subsample(np.vstack([pair.xyz1, pair.xyz2]), n)


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
        left=margins.left / width_in, right=1 - margins.right / width_in,
        bottom=margins.bottom / height_in, top=1 - margins.top / height_in,
        wspace=margins.wspace, hspace=margins.hspace,
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


def sensor_origins(pair: RegisteredPair) -> dict[int, np.ndarray]:
    return {1: pair.origin1, 2: pair.origin2}


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


def save(fig, out_dir: Path, stem: str, settings: PlotSettings) -> list[Path]:
    """Write ``stem.png`` (and ``stem.svg`` when asked and small enough) atomically; close.
    Beside the PNG, its page copy (``plots.png.compact_file``) from the same image."""
    written = []
    try:
        for fmt in settings.formats:
            if fmt == "png":
                image = figure_image(fig, settings.dpi)
                data = encode_png(image, settings.dpi)
            else:
                buf = io.BytesIO()
                fig.savefig(buf, format=fmt, dpi=settings.dpi)
                data = buf.getvalue()
                if len(data) > SVG_MAX_BYTES:
                    continue
            path = out_dir / f"{stem}.{fmt}"
            with atomic_path(path) as tmp:
                tmp.write_bytes(data)
            written.append(path)
            if fmt == "png":  # after the file: a copy older than its file is not used
                with atomic_path(page_copy_path(path)) as tmp:
                    tmp.write_bytes(compact_image(image))
    finally:
        plt.close(fig)
    return written


def png_bytes(fig, dpi: int) -> bytes:
    """The figure as PNG bytes (for embedding in a report); closes the figure."""
    try:
        return figure_png(fig, dpi)
    finally:
        plt.close(fig)
