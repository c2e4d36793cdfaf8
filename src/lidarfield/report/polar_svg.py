"""The overview's polar voxel maps as SVG: the same maps as ``study/figures/voxels_{level}.png``
(seen from above, forward up, elevation as the radius with the lowest band inside, a hole in
the middle), each cell a path whose title gives its numbers on hover. No script: the browser
shows a cell's title. The PNGs stay in ``study/figures`` for papers.
"""

from __future__ import annotations

import math

import numpy as np
from matplotlib import colormaps
from matplotlib.colors import Normalize, to_hex

from ..plots.study import NO_DATA, SHARE_CMAP, level_label
from ..plots.style import MAGNITUDE_CMAP
from .page import esc

SIZE = 300  # px, each map's width and height
HOLE = 0.35  # the hole's radius, as a share of the elevation span (the PNG's rorigin)
STYLE = (
    "<style>.polar-maps { display: flex; flex-wrap: wrap; gap: 12px; }"
    " .polar-maps path:hover { stroke: #e00; stroke-width: 2; }</style>"
)


def cell_path(grid: dict, az_bin: int, el_bin: int) -> str:
    """The SVG path of one cell: azimuth from forward (up) counter-clockwise, elevation outwards."""
    lo, hi = grid["elevation_deg"]
    span, bins = hi - lo, grid["elevation_bins"]
    outer = SIZE / 2 - 4
    radius = [outer * (HOLE * span + e * span / bins) / ((1 + HOLE) * span) for e in (el_bin, el_bin + 1)]
    width = 360.0 / grid["azimuth_bins"]
    angles = [math.radians(grid.get("azimuth_offset_deg", 0.0) + (az_bin + k) * width) for k in (0, 1)]

    def at(r: float, a: float) -> str:
        # forward (+x) up, +y (azimuth 90 deg) to the left
        return f"{SIZE / 2 - r * math.sin(a):.1f},{SIZE / 2 - r * math.cos(a):.1f}"

    (r0, r1), (a0, a1) = radius, angles
    sweep = 0  # counter-clockwise on the screen from a0 to a1
    return (
        f"M{at(r0, a0)}L{at(r1, a0)}A{r1:.1f},{r1:.1f} 0 0 {sweep} {at(r1, a1)}"
        f"L{at(r0, a1)}A{r0:.1f},{r0:.1f} 0 0 {1 - sweep} {at(r0, a0)}Z"
    )


def polar_svg(rows, grid: dict, column: str, cmap: str, norm: Normalize, title: str) -> str:
    """One map of ``column`` over the cells of ``rows`` (one shell of one stage level of the
    voxels table); grey where no pair is valid."""
    colours = colormaps[cmap]
    # grey under the cells, as the PNG's: a cell without a row holds no point in any pair
    outer, hole = SIZE / 2 - 4, (SIZE / 2 - 4) * HOLE / (1 + HOLE)
    paths = [
        f'<circle cx="{SIZE / 2}" cy="{SIZE / 2}" r="{outer:.1f}" fill="{to_hex(NO_DATA)}"/>'
        f'<circle cx="{SIZE / 2}" cy="{SIZE / 2}" r="{hole:.1f}" fill="#fff"/>'
    ]
    for r in rows.to_dict("records"):
        valid = r["pairs_valid"] > 0 and np.isfinite(r[column])
        fill = to_hex(colours(norm(r[column]))) if valid else to_hex(NO_DATA)
        tip = (
            f"voxel {int(r['voxel'])} (az {int(r['az_bin'])}, el {int(r['el_bin'])}): "
            f"median magnitude {r['magnitude_median']:.4g} m, share above the pair's median "
            f"{r['share_above_pair_median']:.3g}, valid in {int(r['pairs_valid'])} of {int(r['pairs'])} pairs"
        )
        paths.append(
            f'<path d="{cell_path(grid, int(r["az_bin"]), int(r["el_bin"]))}" fill="{fill}" stroke="#888" '
            f'stroke-width="0.3" data-level="{int(r["level"])}" data-voxel="{int(r["voxel"])}">'
            f"<title>{esc(tip)}</title></path>"
        )
    return (
        f'<figure style="width:{SIZE}px"><svg xmlns="http://www.w3.org/2000/svg" width="{SIZE}" height="{SIZE}" '
        f'viewBox="0 0 {SIZE} {SIZE}" role="img" aria-label="{esc(title)}">{"".join(paths)}'
        f'<text x="{SIZE / 2}" y="11" text-anchor="middle" font-size="10">forward +x</text></svg>'
        f"<figcaption>{esc(title)}</figcaption></figure>"
    )


def polar_map_parts(voxels, grid: dict) -> list[str]:
    """Per stage level (and range shell), the median-magnitude and share maps, hover giving the numbers."""
    if grid.get("kind", "spherical") != "spherical" or voxels is None or not len(voxels):
        return []
    share = Normalize(0.0, 1.0)
    parts = [STYLE]
    for level in sorted(voxels["level"].unique()):
        rows = voxels[voxels["level"] == level]
        # each level on its own scale, as its PNG
        top = float(np.nanmax(rows["magnitude_median"].to_numpy(dtype=float), initial=0.0))
        magnitude = Normalize(0.0, top if top > 0 else 1.0)
        label = level_label(int(level), rows["hypothesis"].iloc[0])
        for shell in sorted(rows["r_bin"].unique()):
            mine = rows[rows["r_bin"] == shell]
            where = "" if shell < 0 else f", range shell {int(shell)}"
            parts += [
                '<div class="polar-maps">',
                polar_svg(
                    mine,
                    grid,
                    "magnitude_median",
                    MAGNITUDE_CMAP,
                    magnitude,
                    f"stage {label}{where}: median magnitude over the pairs (0 to {top:.3g} m, viridis)",
                ),
                polar_svg(
                    mine,
                    grid,
                    "share_above_pair_median",
                    SHARE_CMAP,
                    share,
                    f"stage {label}{where}: share of pairs above their own median (0 blue, 0.5 white, 1 red)",
                ),
                "</div>",
            ]
    return parts
