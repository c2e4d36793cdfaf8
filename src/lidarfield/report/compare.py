"""Two studies side by side (for example two variants of a hypothesis stack), pair by pair and
stage by stage: both stacks' statistics with deltas, both curves, both fields from above.

Stages are matched by level: the stage ids differ between variants (they hash the stack), the
level and the hypothesis name say what each stage did.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.atomic import write_text
from ..plots.output import png_bytes
from ..plots.pair_stats import column, sorted_rows, stage_ticks
from ..plots.style import figure
from ..storage.layout import level_of
from .discover import discover
from .explorer import ASSETS, explorer_div, explorer_scripts, points_script, write_assets
from .page import esc, image, image_file, page, table

COMPARED = (
    ("max_magnitude", "max (m)"),
    ("p95_magnitude", "p95 (m)"),
    ("mean_magnitude", "mean (m)"),
    ("paper_max_metric", "paper metric (m)"),
    ("voxels_valid", "valid voxels"),
)
DPI = 110


def _by_level(rows: list[dict]) -> dict[int, dict]:
    return {int(float(r.get("level", 0))): r for r in rows}


def _number(row: dict | None, key: str) -> float:
    try:
        return float(row[key]) if row is not None else np.nan
    except (KeyError, TypeError, ValueError):
        return np.nan


def comparison_table(rows_a: list[dict], rows_b: list[dict]) -> str:
    a, b = _by_level(rows_a), _by_level(rows_b)
    headers = ["level", "hypothesis A", "hypothesis B"]
    for _, label in COMPARED:
        headers += [f"{label} A", f"{label} B", f"Δ {label}"]
    body, cell_classes = [], []
    for level in sorted(set(a) | set(b)):
        ra, rb = a.get(level), b.get(level)
        row = [f"{level:02d}", ra.get("hypothesis", "") if ra else "—", rb.get("hypothesis", "") if rb else "—"]
        classes = ["", "", ""]
        for key, _ in COMPARED:
            va, vb = _number(ra, key), _number(rb, key)
            delta = vb - va
            row += [va, vb, delta]
            # smaller magnitudes mean a better-explained field; a count has no better direction
            sign = (
                ""
                if key == "voxels_valid" or not np.isfinite(delta) or delta == 0
                else ("better" if delta < 0 else "worse")
            )
            classes += ["", "", sign]
        body.append(row)
        cell_classes.append(classes)
    return table(headers, body, text_columns=3, cell_classes=cell_classes)


def comparison_figure(name: str, rows_a: list[dict], rows_b: list[dict]):
    fig = figure(8.0, 4.5, DPI)
    ax = fig.add_subplot()
    for rows, style, label in ((rows_a, "-", "A"), (rows_b, "--", "B")):
        rows = sorted_rows(rows)
        if not rows:
            continue
        x = column(rows, "level")
        ax.plot(x, column(rows, "max_magnitude"), "o" + style, color="C0", label=f"max ({label})")
        ax.plot(x, column(rows, "p95_magnitude"), "s" + style, color="C1", label=f"p95 ({label})")
        ax.plot(x, column(rows, "mean_magnitude"), "^" + style, color="C2", label=f"mean ({label})")
    stage_ticks(ax, sorted_rows(rows_a if len(rows_a) >= len(rows_b) else rows_b))
    ax.set_ylabel("vector magnitude (m)")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8, ncol=2)
    ax.set_title(f"{name}: study A (solid) and study B (dashed)", fontsize=10)
    return fig


def _stage_dir_by_level(stage_dirs: list[Path]) -> dict[int, Path]:
    return {level_of(d.name): d for d in stage_dirs if level_of(d.name) is not None}


# Two explorers beside each other: each one's views above each other.
SIDE_BY_SIDE_STYLE = "<style>.side-by-side .explorer-views { flex-direction: column; }</style>"


def explorers_side_by_side(name: str, stages_a: list[Path], stages_b: list[Path], out_dir: Path) -> list[str]:
    """The pair in A's explorer beside B's, camera and stage linked, where both have its explorer data."""
    if not (stages_a and stages_b and points_script(stages_a[0].parent.parent).is_file()):
        return []
    if not points_script(stages_b[0].parent.parent).is_file():
        return []
    cells = [
        f"<div><p><b>{label}</b></p>{explorer_div(name, stages, out_dir, '', link=f'pair-{name}')}</div>"
        for label, stages in (("A", stages_a), ("B", stages_b))
    ]
    return [
        f"<h3>{esc(name)}: A and B in the explorer</h3>",
        '<p class="note">Rotating one 3-D view turns the other; the slider moves both to the same level.</p>',
        SIDE_BY_SIDE_STYLE,
        '<div class="figures side-by-side">' + "".join(cells) + "</div>",
    ]


def compare_studies(results_a: str | Path, results_b: str | Path, out_html: str | Path) -> Path:
    """Write a page comparing two results folders; returns its path."""
    results_a, results_b, out_html = Path(results_a), Path(results_b), Path(out_html)
    pairs_a, rows_a = discover(results_a)
    pairs_b, rows_b = discover(results_b)
    names = list(pairs_a) + [n for n in pairs_b if n not in pairs_a]
    body = [
        "<h1>lidarfield: two studies compared</h1>",
        f"<p>A: <code>{esc(results_a)}</code> ({len(pairs_a)} pairs)<br>B: <code>{esc(results_b)}</code> "
        f"({len(pairs_b)} pairs)</p>",
        '<p class="note">Stages are matched by level. Δ = B − A; green: B smaller (more of the discrepancy '
        "explained), red: B larger.</p>",
        "<ul>"
        + "".join(
            f'<li><a href="#pair-{esc(n)}">{esc(n)}</a>'
            + ("" if n in pairs_a and n in pairs_b else f" (only in {'A' if n in pairs_a else 'B'})")
            + "</li>"
            for n in names
        )
        + "</ul>",
    ]
    explored = False
    for name in names:
        pa = [r for r in rows_a if str(r.get("pair")) == name]
        pb = [r for r in rows_b if str(r.get("pair")) == name]
        body += [
            f'<h2 id="pair-{esc(name)}">pair {esc(name)}</h2>',
            comparison_table(pa, pb),
            image(png_bytes(comparison_figure(name, pa, pb), DPI), f"{name}: stage by stage, A and B"),
        ]
        explorers = explorers_side_by_side(name, pairs_a.get(name, []), pairs_b.get(name, []), out_html.parent)
        body += explorers
        explored = explored or bool(explorers)
        dirs_a, dirs_b = _stage_dir_by_level(pairs_a.get(name, [])), _stage_dir_by_level(pairs_b.get(name, []))
        for level in sorted(set(dirs_a) | set(dirs_b)):
            body.append(f"<h3>{esc(name)} · stage {level:02d}</h3>")
            cells = []
            for label, dirs in (("A", dirs_a), ("B", dirs_b)):
                d = dirs.get(level)
                cells.append(
                    image_file(d / "figures" / "field_top.png", f"{label}: {d.name}: field from above")
                    if d
                    else f'<p class="missing">{label}: no stage {level:02d}</p>'
                )
            body.append('<div class="figures side-by-side">' + "".join(cells) + "</div>")  # A beside B
    if explored:
        write_assets(out_html.parent / ASSETS)
        body += explorer_scripts(out_html.parent / ASSETS, out_html.parent)
    write_text(out_html, page("lidarfield: two studies compared", body))
    return out_html
