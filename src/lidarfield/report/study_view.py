"""The study overview's interactive parts: the heat map of every pair at every stage as a grid of
links (a cell opens that pair's page at that stage, its title gives the numbers), and the
ranked pairs table, sortable by any column and filtered by what its rows say
(``assets/overview.js``). Plain HTML that works without the script: a study of 1,000 pairs
stays a page of links and text, with no plotting library to load.
"""

from __future__ import annotations

import math
from pathlib import Path
from urllib.parse import quote

import numpy as np
from matplotlib import colormaps
from matplotlib.colors import to_hex

from ..plots.style import MAGNITUDE_CMAP
from .page import esc, link, relative_href, table
from .pair_page import registration_problem
from .suggestions import read_suggestions

PAIR_PAGE = "{pair}/report.html"  # a pair's page, relative to the overview
SCRIPT = "overview.js"
STYLE = """<style>
table.heatmap td { padding: 0; border: 1px solid #fff; }
table.heatmap td a { display: block; padding: 1px 6px; color: inherit; text-decoration: none; font-size: 0.85em; }
table.heatmap td a:hover { outline: 2px solid #e00; }
table.heatmap td.dark { color: #fff; }
.table-filter { margin: 0.4em 0; } .table-filter input { width: 24em; }
table.sortable th { cursor: pointer; } table.sortable th.asc::after { content: " ▲"; }
table.sortable th.desc::after { content: " ▼"; }
</style>"""


def pair_href(pair: str, level: int | None = None) -> str:
    href = PAIR_PAGE.format(pair=quote(str(pair)))
    return href if level is None else f"{href}#stage={level}"


def _number(value) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def heatmap_grid(summary, ranking, key: str = "p95_magnitude") -> str:
    """``key`` per pair (rows, in rank order) and stage (columns), each cell a link to that pair
    at that stage, coloured on the static heat map's scale; its title holds the numbers."""
    levels = sorted(int(v) for v in summary["level"].unique())
    names = summary.sort_values("level").groupby("level")["hypothesis"].first()
    rows = {(str(r["pair"]), int(r["level"])): r for r in summary.to_dict("records")}
    values = np.array([_number(r.get(key)) for r in rows.values()])
    top = max(float(np.nanmax(values, initial=0.0)), 1e-9)
    cmap = colormaps[MAGNITUDE_CMAP]
    head = "".join(f"<th>{lv:02d} {esc(names.get(lv, ''))}</th>" for lv in levels)
    body = []
    for rank, pair in enumerate(ranking["pair"], start=1):
        cells = []
        for lv in levels:
            r = rows.get((str(pair), lv))
            value = _number(r.get(key)) if r else math.nan
            if not math.isfinite(value):
                cells.append("<td></td>")
                continue
            share = value / top
            title = (
                f"{pair} · stage {lv:02d} {names.get(lv, '')}: {key} {value:.4g} m, "
                f"max {_number(r.get('max_magnitude')):.4g} m, rms {_number(r.get('rms_magnitude')):.4g} m, "
                f"valid voxels {r.get('voxels_valid', '')}, removed {r.get('removed1', 0)} + {r.get('removed2', 0)}"
            )
            dark = ' class="dark"' if share < 0.55 else ""  # viridis is dark below about half its range
            cells.append(
                f'<td{dark} style="background:{to_hex(cmap(share))}" data-value="{value:.6g}">'
                f'<a href="{esc(pair_href(pair, lv))}" title="{esc(title)}">{value:.3g}</a></td>'
            )
        body.append(f'<tr><td class="text">{rank}. {esc(pair)}</td>{"".join(cells)}</tr>')
    return (
        f'<div class="table-box"><table class="heatmap"><thead><tr><th class="text">pair (ranked)</th>{head}</tr>'
        f"</thead><tbody>{''.join(body)}</tbody></table></div>"
    )


def heatmap_parts(summary, ranking) -> list[str]:
    return [
        "<h3>p95 magnitude of every pair at every stage</h3>",
        '<p class="note">One row a pair, in rank order (the most left at the last stage first); the colour is the '
        "static heat map's (<code>study/figures/heatmap.png</code>). A cell opens that pair's page at that stage "
        "in its explorer (where the pair's figures are drawn); hover a cell for its numbers.</p>",
        heatmap_grid(summary, ranking),
    ]


def removed_shares(summary) -> dict[str, float]:
    """Per pair, the share of both clouds' points its stages removed in all (last stage against stage 0)."""
    s = summary.sort_values(["pair", "level"])
    first, last = s.groupby("pair").head(1).set_index("pair"), s.groupby("pair").tail(1).set_index("pair")
    entered = first["n1"].astype(float) + first["n2"].astype(float)
    left = last["n1"].astype(float) + last["n2"].astype(float)
    return (1.0 - left / entered).to_dict()


def next_step(stage_dir: Path | None) -> tuple[str, float]:
    """The best candidate at a stage and its energy reduction ('' and NaN when not computed)."""
    rows = read_suggestions(stage_dir) if stage_dir is not None else None
    if not rows:
        return "", math.nan
    return str(rows[0]["hypothesis"]), _number(rows[0]["energy_reduction"])


RANKING_HEADERS = (
    "rank",
    "pair",
    "last stage",
    "p95 (m)",
    "max (m)",
    "rms (m)",
    "valid voxels",
    "significant (|z| ≥ z_min)",
    "verdict",
    "rigid energy share",
    "what to try next",
    "its energy reduction",
    "removed share",
    "registration fitness",
    "p95 at stage 00 (m)",
    "stage figures",
    "registration problem",
)


def ranking_table(tables, stage_figures: set[str], last_stages: dict[str, Path]) -> str:
    """One row per pair, ranked; the pair's name links to its page; sortable and filtered by
    ``overview.js``."""
    last = tables.summary.sort_values("level").groupby("pair").tail(1).set_index("pair")
    removed = removed_shares(tables.summary)
    body, classes = [], []
    for r in tables.pairs.to_dict("records"):
        pair = r["pair"]
        extra = last.loc[pair].to_dict() if pair in last.index else {}
        problem = registration_problem(r)
        step, reduction = next_step(last_stages.get(pair))
        body.append(
            [
                int(r["rank"]),
                link(pair_href(pair), str(pair)),
                link(pair_href(pair, int(r["level"])), f"{int(r['level']):02d} {r['hypothesis']}"),
                r["p95_magnitude"],
                r["max_magnitude"],
                r["rms_magnitude"],
                r["voxels_valid"],
                r.get("voxels_significant", ""),
                r.get("verdict", ""),
                _number(extra.get("rigid_energy_share")),
                step,
                reduction,
                removed.get(pair, math.nan),
                _number(extra.get("registration_fitness")),
                r["p95_magnitude_stage0"],
                "drawn" if pair in stage_figures else "",
                problem,
            ]
        )
        classes.append("flag" if problem else "")
    return table(list(RANKING_HEADERS), body, classes, text_columns=3).replace("<table>", '<table class="sortable">', 1)


def ranking_filter() -> str:
    return (
        '<p class="table-filter"><label>filter the pairs: <input type="search" class="filter" '
        'placeholder="words every shown row contains, e.g. significant ego_vehicle"></label> '
        '<span class="filter-count note"></span></p>'
    )


def script_tag(assets: Path, out_dir: Path) -> str:
    return f'<script src="{esc(relative_href(assets / SCRIPT, out_dir))}"></script>'
