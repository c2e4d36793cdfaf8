"""The k voxels with the largest vectors, drawn as wireframes over both clouds.

A spherical voxel is the solid between two azimuths, two elevations and two ranges about
sensor 1; without range shells its ranges are the nearest and farthest of its points.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.lines import Line2D
from mpl_toolkits.mplot3d.art3d import Line3DCollection

from ..errors import InputError
from ..field.grid import CartesianGrid, Grid, SphericalGrid, grid_from_config
from .field_views import PERSPECTIVE_VIEW
from .output import save
from .settings import PlotSettings
from .stage_data import StageData, sensor_origins, subsample
from .style import CLOUD_COLOURS, POINTS_3D, Margins, figure, legend_at_right, mark_sensors, set_equal_3d, set_top_axes

ARC_SAMPLES = 16


def _spherical_to_xyz(az_deg: np.ndarray, el_deg: np.ndarray, r: np.ndarray) -> np.ndarray:
    az, el = np.radians(az_deg), np.radians(el_deg)
    return np.column_stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)])


def spherical_voxel_wireframe(
    az_deg: tuple[float, float], el_deg: tuple[float, float], r_m: tuple[float, float], n_arc: int = ARC_SAMPLES
) -> list[np.ndarray]:
    """The 12 edges of a spherical voxel as (n, 3) polylines: 4 radial segments, 4 azimuth
    arcs and 4 elevation arcs (arcs sampled with ``n_arc`` points)."""
    (a0, a1), (e0, e1), (r0, r1) = az_deg, el_deg, r_m
    t = np.linspace(0.0, 1.0, n_arc)
    edges = []
    for a in (a0, a1):
        for e in (e0, e1):
            edges.append(_spherical_to_xyz(np.array([a, a]), np.array([e, e]), np.array([r0, r1])))
    for r in (r0, r1):
        for e in (e0, e1):
            edges.append(_spherical_to_xyz(a0 + t * (a1 - a0), np.full(n_arc, e), np.full(n_arc, r)))
        for a in (a0, a1):
            edges.append(_spherical_to_xyz(np.full(n_arc, a), e0 + t * (e1 - e0), np.full(n_arc, r)))
    return edges


def box_wireframe(lo: np.ndarray, hi: np.ndarray) -> list[np.ndarray]:
    """The 12 edges of an axis-aligned box as two-point polylines."""
    corners = np.array([[hi[i] if (c >> i) & 1 else lo[i] for i in range(3)] for c in range(8)])
    return [corners[[a, b]] for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]


def voxel_wireframe(grid: Grid, voxel_id: int, voxel_ids_of_points: np.ndarray, points: np.ndarray) -> list[np.ndarray]:
    """Wireframe of one voxel of ``grid``; ``points``/``voxel_ids_of_points`` give the range
    extent of a spherical voxel when the grid has no range shells."""
    bins = {k: int(v[0]) for k, v in grid.bins(np.array([voxel_id])).items()}
    if isinstance(grid, CartesianGrid):
        lo = np.asarray(grid.origin) + grid.cell_m * np.array([bins["ix"], bins["iy"], bins["iz"]])
        return box_wireframe(lo, lo + grid.cell_m)
    azimuth, elevation = _voxel_angles(grid, bins)
    if grid.range_edges_m is not None:
        r = (grid.range_edges_m[bins["r_bin"]], grid.range_edges_m[bins["r_bin"] + 1])
    else:
        ranges = np.linalg.norm(points[voxel_ids_of_points == voxel_id], axis=1)
        r = (float(ranges.min()), float(ranges.max())) if len(ranges) else (0.0, 0.0)
    return spherical_voxel_wireframe(azimuth, elevation, r)


def _voxel_angles(grid: SphericalGrid, bins: dict) -> tuple[tuple[float, float], tuple[float, float]]:
    """(first, last) azimuth and elevation (deg) of a spherical voxel: its grid's edges, even or
    moved between channels (field.channels)."""
    azimuth, elevation = grid.azimuth_edges(), grid.elevation_edges()
    a, e = bins["az_bin"], bins["el_bin"]
    return (float(azimuth[a]), float(azimuth[a + 1])), (float(elevation[e]), float(elevation[e + 1]))


def voxel_description(grid: Grid, voxel_id: int) -> str:
    bins = {k: int(v[0]) for k, v in grid.bins(np.array([voxel_id])).items()}
    if isinstance(grid, SphericalGrid):
        (a0, a1), (e0, e1) = _voxel_angles(grid, bins)
        text = f"az {a0:.4g} to {a1:.4g}°, el {e0:.4g} to {e1:.4g}°"
        return text + (f", shell {bins['r_bin']}" if bins["r_bin"] >= 0 else "")
    return f"cell ({bins['ix']}, {bins['iy']}, {bins['iz']})"


def clip_to_box(polyline: np.ndarray, limits: np.ndarray) -> np.ndarray:
    """The vertices inside the axis limits (3-D axes do not clip lines themselves); an edge
    leaving the view is cut at its last sampled vertex inside."""
    inside = np.all((polyline >= limits[:, 0]) & (polyline <= limits[:, 1]), axis=1)
    return polyline[inside]


def stage_grid(stage: StageData) -> Grid:
    grid_config = stage.field.meta.get("grid")
    if not isinstance(grid_config, dict):
        raise InputError("field metadata has no 'grid' settings: cannot draw its voxels", stage.path / "field.parquet")
    return grid_from_config(grid_config)


def plot_top_voxels(stage: StageData, limits: np.ndarray, out_dir: Path, settings: PlotSettings) -> list[Path]:
    f = stage.field
    grid = stage_grid(stage)
    k = min(settings.top_k, len(f.magnitude))
    top = np.argsort(f.magnitude)[::-1][:k]
    points = np.vstack([stage.pair.xyz1, stage.pair.xyz2])
    point_ids = (
        grid.assign(points)
        if k and isinstance(grid, SphericalGrid) and grid.range_edges_m is None
        else np.zeros(0, np.int64)
    )
    colours = plt.get_cmap("tab10" if k <= 10 else "turbo")(
        np.linspace(0, 1, max(k, 1)) if k > 10 else np.arange(max(k, 1))
    )
    frames = [voxel_wireframe(grid, int(f.columns["voxel"][i]), point_ids, points) for i in top]

    fig = figure(14.0, 6.2, settings.dpi, Margins(top=0.5, bottom=0.55))
    ax_top = fig.add_subplot(1, 2, 1)
    ax_3d = fig.add_subplot(1, 2, 2, projection="3d")
    n_bg = settings.background_points // 2
    for c, xyz in ((1, stage.pair.xyz1), (2, stage.pair.xyz2)):
        bg = subsample(xyz, n_bg, seed=c)
        ax_top.scatter(bg[:, 0], bg[:, 1], s=0.6, c=CLOUD_COLOURS[c], alpha=0.3, lw=0, rasterized=True)
        ax_3d.scatter(*bg.T, s=0.3, c=CLOUD_COLOURS[c], alpha=0.15, lw=0, rasterized=True, **POINTS_3D)
    handles = [Line2D([], [], ls="", marker=".", color=CLOUD_COLOURS[c], label=f"cloud {c}") for c in (1, 2)]
    # one collection per view for all edges: hundreds of Line2D artists would dominate the time
    edge_colours = [colour for edges, colour in zip(frames, colours) for _ in edges]
    ax_top.add_collection(
        LineCollection([e[:, :2] for edges in frames for e in edges], colors=edge_colours, linewidths=1.2)
    )
    clipped = [clip_to_box(e, limits) for edges in frames for e in edges]
    kept = [(c, col) for c, col in zip(clipped, edge_colours) if len(c) >= 2]
    if kept:  # every edge may lie outside the view; mplot3d cannot add an empty collection
        ax_3d.add_collection3d(Line3DCollection([c for c, _ in kept], colors=[col for _, col in kept], linewidths=1.0))
    for rank, (i, colour) in enumerate(zip(top, colours), start=1):
        tail, tip = f.tails[i], f.tails[i] + settings.magnification * f.vectors[i]
        ax_top.annotate("", xy=tip[:2], xytext=tail[:2], arrowprops=dict(arrowstyle="-|>", color="k", lw=1.2))
        ax_top.text(*tail[:2], f" {rank}", fontsize=8, fontweight="bold", color=colour, va="bottom")
        ax_3d.plot(*np.column_stack([tail, tip]), color="k", lw=1.5)
        ax_3d.text(*tail, f"{rank}", fontsize=8, color=colour, fontweight="bold")
        voxel_id = int(f.columns["voxel"][i])
        handles.append(
            Line2D([], [], color=colour, label=f"#{rank}: {f.magnitude[i]:.3f} m · {voxel_description(grid, voxel_id)}")
        )
    for ax, three_d in ((ax_top, False), (ax_3d, True)):
        mark_sensors(ax, sensor_origins(stage.pair), three_d=three_d)
    set_top_axes(ax_top, limits)
    set_equal_3d(ax_3d, limits)
    ax_3d.view_init(**PERSPECTIVE_VIEW)
    legend_at_right(fig, handles, gap_in=0.9, fontsize=8, title=f"top {k} voxels (arrow ×{settings.magnification:g})")
    pair_name = stage.path.parent.parent.name
    fig.suptitle(f"{pair_name} · {stage.label} · the {k} voxels with the largest vectors", fontsize=11)
    return save(fig, out_dir, "top_voxels", settings)
