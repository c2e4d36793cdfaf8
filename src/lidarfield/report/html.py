"""The study report: one self-contained HTML page (figures embedded as data URIs) comparing
every stage of every pair, so that a team can read it offline or receive it by mail.

A large study's figures would make the page too large to mail: it has a size budget
(``report.max_mb``), and the figures that do not fit, whole tiers at a time (``TIERS``), are
links to their PNG files instead (see ``budget``).

The interactive 3-D views are separate files (a few MB each): the page links them by relative
path, so they open when the report sits in its results folder.
"""

from __future__ import annotations

import logging
import os
from functools import partial
from pathlib import Path

import numpy as np
import yaml

from .. import __version__
from ..io.atomic import write_text
from ..plots import stage_figures
from ..plots.common import PlotSettings, figure, plot_settings, png_bytes
from ..plots.pair_stats import column, pair_figure_png, sorted_rows
from ..stages import level_of
from .budget import MB, Figure, Note, budget_mb, budget_note, embed_tiers, render, utf8_len
from .page import esc, image, missing_image, page, table
from .suggestions import stage_suggestions, study_suggestions

log = logging.getLogger(__name__)

SUMMARY_COLUMNS = (
    "pair", "stage", "level", "hypothesis", "n1", "n2", "removed1", "removed2", "voxels_valid",
    "max_magnitude", "p95_magnitude", "mean_magnitude", "rms_magnitude", "paper_max_metric",
    "rigid_translation_m", "rigid_rotation_deg", "rigid_energy_share", "mean_resultant_length",
    "voxels_significant", "p_direction", "p_coherence", "verdict",
    "registration_method", "registration_fitness",
)
STAGE_FIGURES = (
    ("field_top", "field from above"),
    ("before_after", "before / after (same axes, same colour scale)"),
    ("removed_top", "removed points from above"),
    ("top_voxels", "voxels with the largest vectors"),
    ("field_perspective", "field in perspective"),
    ("removed_perspective", "removed points in perspective"),
)
PAIR_FIGURES = (
    ("stages", "magnitude stage by stage"),
    ("rigid_randomness", "rigid part and randomness stage by stage"),
    ("tags", "share of the field energy per voxel tag, stage by stage"),
)
PAIR_TIER = "pair figures"
# The order in which figures are embedded while the page fits its budget: a pair's summary
# first, then the stage figures that say most about a stage.
TIERS = (PAIR_TIER, *(caption for _, caption in STAGE_FIGURES))
TITLE = "lidarfield study report"
WIDE = {"before_after": 1130, "top_voxels": 1130}  # two-panel figures take a whole row
MAX_LEGEND_PAIRS = 12
OPEN_PAIRS = 3  # the first pairs' sections start expanded; the others are one click away
DPI = 110


def registration_problem(row: dict) -> str:
    """Why a summary row's registration is suspect ('' when it is not)."""
    converged = row.get("registration_converged")
    warning = row.get("registration_warning")
    problems = []
    if converged is False or (isinstance(converged, str) and converged.lower() == "false"):
        problems.append("registration did not converge")
    if isinstance(warning, str) and warning:
        problems.append(f"warning: {warning}")
    return "; ".join(problems)


def overview_table(rows: list[dict]) -> str:
    headers = [c for c in SUMMARY_COLUMNS if any(c in r for r in rows)]
    body, classes = [], []
    for r in rows:
        problem = registration_problem(r)
        body.append([r.get(c, "") for c in headers] + [problem])
        classes.append("flag" if problem else "")
    return table(headers + ["registration problem"], body, classes, text_columns=2)


def all_pairs_figure(rows: list[dict], key: str = "max_magnitude", title: str = "largest vector, stage by stage, all pairs"):
    """One line per pair of ``key`` against the stage level (median in black beyond a dozen pairs)."""
    by_pair: dict[str, list[dict]] = {}
    for r in rows:
        by_pair.setdefault(str(r.get("pair")), []).append(r)
    fig = figure(9.0, 5.0, DPI)
    ax = fig.add_subplot()
    many = len(by_pair) > MAX_LEGEND_PAIRS
    for name, pair_rows in by_pair.items():
        pair_rows = sorted_rows(pair_rows)
        ax.plot(column(pair_rows, "level"), column(pair_rows, key), "-" if many else "o-", lw=0.8 if many else 1.5,
                alpha=0.4 if many else 1.0, label=None if many else name)
    if many:
        levels = np.unique(column(rows, "level"))
        medians = [np.nanmedian(column([r for r in rows if float(r.get("level", -1)) == lv], key)) for lv in levels]
        ax.plot(levels, medians, "ko-", lw=2.5, label=f"median of {len(by_pair)} pairs")
    ax.set_xlabel("stage level")
    ax.set_ylabel(f"{key.replace('_', ' ')} (m)")
    ax.set_ylim(bottom=0)
    ax.grid(True, lw=0.3, alpha=0.6)
    ax.legend(fontsize=8, ncol=2)
    ax.set_title(title, fontsize=10)
    levels = sorted({int(float(r.get("level", 0))) for r in rows})
    ax.set_xticks(levels)
    return fig


def relative_href(path: Path, out_dir: Path) -> str:
    """A link to ``path`` from a page in ``out_dir``: it works wherever the results folder is moved."""
    return Path(os.path.relpath(path, out_dir)).as_posix()


def file_figure(tier: str, path: Path, caption: str, width_px: int, out_dir: Path) -> Figure | str:
    """A figure drawn to a PNG file, or the note that it was not drawn."""
    if not path.is_file():
        return missing_image(caption, path)
    return Figure(tier, caption, width_px, relative_href(path, out_dir), path.read_bytes)


def pair_figures(name: str, pair_dir: Path | None, rows: list[dict], out_dir: Path) -> list[Figure | str]:
    """The pair's stage-by-stage figures: its files, or drawn from its rows when there are none."""
    figures = []
    for stem, caption in PAIR_FIGURES:
        path = pair_dir / "figures" / f"{stem}.png" if pair_dir else None
        if path is not None and path.is_file():
            figures.append(file_figure(PAIR_TIER, path, f"{name}: {caption}", 640, out_dir))
        elif rows:
            figures.append(Figure(PAIR_TIER, f"{name}: {caption}", 640, None, partial(pair_figure_png, stem, rows, DPI)))
    return figures


def stage_parts(name: str, stage_dir: Path, out_dir: Path, settings: PlotSettings) -> list[Figure | str]:
    """A stage's heading, the link to its 3-D view and the figures the settings draw for it."""
    fig_dir = stage_dir / "figures"
    parts = [f"<h3>{esc(name)} · stage {esc(stage_dir.name)}</h3>", stage_suggestions(stage_dir)]
    view = fig_dir / "field_3d.html"
    if view.is_file():
        parts.append(f'<p><a href="{esc(relative_href(view, out_dir))}">interactive 3-D view of this stage</a></p>')
    level = level_of(stage_dir.name) or 0
    drawn = stage_figures(settings, level, has_previous=level > 0)
    stems = [(s, c) for s, c in STAGE_FIGURES if s in drawn]
    figures = [file_figure(c, fig_dir / f"{s}.png", f"{stage_dir.name}: {c}", WIDE.get(s, 560), out_dir) for s, c in stems]
    return parts + ['<div class="figures">', *figures, "</div>"]


def pair_section(name: str, stage_dirs: list[Path], rows: list[dict], out_dir: Path, open_: bool, settings: PlotSettings) -> list[Figure | str]:
    """The pair's collapsible section, as page parts (its figures still to be embedded or linked)."""
    parts = [f'<details id="pair-{esc(name)}"{" open" if open_ else ""}><summary>pair {esc(name)}</summary>']
    pair_dir = stage_dirs[0].parent.parent if stage_dirs else None
    parts += ['<div class="figures">', *pair_figures(name, pair_dir, rows, out_dir), "</div>"]
    for stage_dir in stage_dirs:
        parts += stage_parts(name, stage_dir, out_dir, settings)
    return parts + ["</details>"]


def report_parts(study: dict, pairs: dict[str, list[Path]], summary_rows: list[dict], out_dir: Path) -> list:
    """The page as parts: HTML text, the figures whose tier decides how they appear, and the
    place of the note on what the size budget left out."""
    n_stages = sum(len(d) for d in pairs.values())
    settings = plot_settings((study or {}).get("plots"))
    parts = [
        "<h1>lidarfield study report</h1>",
        f'<p class="note">lidarfield {esc(__version__)} · {len(pairs)} pair(s) · {n_stages} stage(s). '
        "Vectors run from the mean of cloud 1 to the mean of cloud 2 in each voxel; a hypothesis that "
        "explains part of the discrepancy shrinks the field and breaks its pattern.</p>",
        Note(),
        "<h2>Study configuration</h2>",
        f"<pre>{esc(yaml.safe_dump(study or {}, sort_keys=False, default_flow_style=None))}</pre>",
        "<h2>Overview</h2>",
        '<p class="note">One row per pair and stage; rows in red: the registration did not converge or warned.</p>',
        overview_table(summary_rows),
    ]
    parts += ["<h2>What to try next</h2>", study_suggestions(pairs)]
    if summary_rows:
        parts += ["<h2>Stage by stage, all pairs</h2>", image(png_bytes(all_pairs_figure(summary_rows), DPI), "largest vector per stage, one line per pair")]
    parts += ["<h2>Pairs</h2>", "<ul>" + "".join(f'<li><a href="#pair-{esc(n)}">{esc(n)}</a>: ' + ", ".join(esc(d.name) for d in dirs) + "</li>" for n, dirs in pairs.items()) + "</ul>"]
    for i, (name, dirs) in enumerate(pairs.items()):
        rows = [r for r in summary_rows if str(r.get("pair")) == name]
        parts += pair_section(name, dirs, rows, out_dir, i < OPEN_PAIRS, settings)
    return parts


def write_report(study: dict, pairs: dict[str, list[Path]], summary_rows: list[dict], out_html: str | Path, max_mb: float | None = None) -> Path:
    """Write the study report; returns its path.

    ``study`` is the config (shown as YAML), ``pairs`` maps each pair to its stage folders in
    order, ``summary_rows`` are the summary table's rows (one per pair and stage). ``max_mb``
    is the page's size budget (default: the study's ``report.max_mb``): the figures that do not
    fit, whole tiers at a time, are linked instead of embedded.
    """
    out_html = Path(out_html)
    pairs = {name: [Path(d) for d in dirs] for name, dirs in pairs.items()}
    max_mb = budget_mb(study, max_mb)
    parts = report_parts(study, pairs, summary_rows, out_html.parent)
    figures = [p for p in parts if isinstance(p, Figure)]
    tiers = [[f for f in figures if f.tier == tier] for tier in TIERS]
    note = partial(budget_note, figures, max_mb=max_mb)
    budget_bytes = int(max_mb * MB)
    embedded = embed_tiers(tiers, utf8_len(page(TITLE, render(parts, {}, ""))), budget_bytes, note)
    html = page(TITLE, render(parts, embedded, note(embedded)))
    write_text(out_html, html)
    size = utf8_len(html)
    log.info("%s: %.2f MB (budget %g MB), %d figures embedded, %d linked", out_html, size / MB, max_mb, len(embedded), len(figures) - len(embedded))
    if size > budget_bytes:
        log.warning("%s is over its %g MB budget even with every pair and stage figure linked", out_html, max_mb)
    return out_html
