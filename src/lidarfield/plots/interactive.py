"""A rotatable 3-D view of one stage (plotly; works from file:// offline).

A view embeds plotly.js (3.5 MB) unless it is given a shared copy: the workflow writes one
per study (:func:`write_plotly_js`) and each view loads it by relative path, so that a study
of hundreds of stages does not store hundreds of copies.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import plotly.graph_objects as go

from ..io.atomic import write_text
from .settings import PlotSettings
from .stage_data import StageData, subsample

CLOUD_RGB = {1: "rgba(214,39,40,0.45)", 2: "rgba(31,119,180,0.45)"}


def vector_segments(tails: np.ndarray, tips: np.ndarray) -> np.ndarray:
    """Polyline vertices tail, tip, NaN for every vector: one trace draws them all."""
    seg = np.full((len(tails) * 3, 3), np.nan)
    seg[0::3] = tails
    seg[1::3] = tips
    return seg


def _z_texts(f) -> list[str]:
    """ ", z 4.2" per vector (", z 1.3, within noise" below z_min); '' for a field without z."""
    if "z" not in f.columns:
        return [""] * len(f.magnitude)
    return [f", z {z:.1f}" + ("" if sig else ", within noise") for z, sig in zip(f.columns["z"], f.significant)]


def field_figure(stage: StageData, settings: PlotSettings) -> go.Figure:
    f = stage.field
    m = settings.magnification
    fig = go.Figure()
    for c, xyz in ((1, stage.pair.xyz1), (2, stage.pair.xyz2)):
        # float32: plotly stores arrays as typed binary, so this halves the page (µm precision at 100 m)
        pts = subsample(xyz, settings.background_points // 2, seed=c).astype(np.float32)
        fig.add_trace(
            go.Scatter3d(
                x=pts[:, 0],
                y=pts[:, 1],
                z=pts[:, 2],
                mode="markers",
                name=f"cloud {c} ({len(xyz)} points, {len(pts)} drawn)",
                marker=dict(size=1.5, color=CLOUD_RGB[c]),
                hoverinfo="skip",
            )
        )
    tips = f.tails + m * f.vectors
    seg = vector_segments(f.tails, tips)
    colour = np.repeat(f.magnitude, 3)
    fig.add_trace(
        go.Scatter3d(
            x=seg[:, 0],
            y=seg[:, 1],
            z=seg[:, 2],
            mode="lines",
            name=f"vectors mean1→mean2 (×{m:g})",
            line=dict(
                width=5,
                color=colour,
                colorscale="Viridis",
                cmin=0,
                cmax=max(f.max_magnitude, 1e-9),
                colorbar=dict(title="magnitude (m)"),
            ),
            hoverinfo="skip",
        )
    )
    fig.add_trace(
        go.Scatter3d(
            x=tips[:, 0],
            y=tips[:, 1],
            z=tips[:, 2],
            mode="markers",
            name="vector tips (mean2)",
            marker=dict(size=3, color=f.magnitude, colorscale="Viridis", cmin=0, cmax=max(f.max_magnitude, 1e-9)),
            text=[f"voxel {int(v)}: {mag:.3f} m{z}" for v, mag, z in zip(f.columns["voxel"], f.magnitude, _z_texts(f))],
            hoverinfo="text",
        )
    )
    origins = np.array([stage.pair.origin1, stage.pair.origin2])
    fig.add_trace(
        go.Scatter3d(
            x=origins[:, 0],
            y=origins[:, 1],
            z=origins[:, 2],
            mode="markers+text",
            name="sensor origins",
            text=["sensor 1", "sensor 2"],
            marker=dict(size=6, color=["#d62728", "#1f77b4"], symbol="diamond"),
        )
    )
    pair_name = stage.path.parent.parent.name
    fig.update_layout(
        title=f"{pair_name} · {stage.label} · largest vector {f.max_magnitude:.3f} m",
        scene=dict(aspectmode="data", xaxis_title="x (m)", yaxis_title="y (m)", zaxis_title="z (m)"),
        legend=dict(itemsizing="constant", x=0.01, y=0.98, bgcolor="rgba(255,255,255,0.7)"),
        margin=dict(l=0, r=0, t=40, b=0),
    )
    return fig


def plot_interactive(
    stage: StageData, out_dir: Path, settings: PlotSettings, plotly_js: Path | None = None
) -> list[Path]:
    """Write ``field_3d.html``: plotly.js embedded, or loaded from ``plotly_js`` by relative path."""
    path = out_dir / "field_3d.html"
    script = True if plotly_js is None else Path(os.path.relpath(plotly_js, out_dir)).as_posix()
    write_text(path, field_figure(stage, settings).to_html(include_plotlyjs=script, full_html=True))
    return [path]


def write_plotly_js(path: str | Path) -> Path:
    """The plotly.js bundle the 3-D views of a study share."""
    from plotly.offline import get_plotlyjs

    write_text(path, get_plotlyjs())
    return Path(path)
