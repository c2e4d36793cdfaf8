"""One pair's page (``results/{pair}/report.html``): its table of stages, its stage-by-stage
figures, each stage's figures and the links to their 3-D views, and a link back to the study
overview.

The page is built from small functions, each returning a list of parts (HTML text, or a
``Figure`` that the size budget embeds or links): a new section is one more such function in
``pair_page_parts``. Stage figures come in tiers (``TIERS``): the page keeps the budget logic of
``budget``, a whole tier embedded at a time while it fits ``report.max_mb``.
"""

from __future__ import annotations

import json
import math
from functools import partial
from pathlib import Path

from .. import __version__
from ..analysis.findings import findings_items, stage_findings
from ..plots import stage_figures
from ..plots.pair_stats import pair_figure_png
from ..plots.png import compact_png
from ..plots.settings import PlotSettings, plot_settings
from ..storage.layout import level_of
from ..study.summary import LABEL_SCORES
from .budget import Figure, Note, budget_mb, file_figure, write_within_budget
from .explorer import ASSETS, explorer_parts
from .page import esc, relative_href, table
from .rematch import pair_rematch_table
from .suggestions import stage_suggestions

# The summary columns the page's table shows, in its order (study.summary.SUMMARY_COLUMNS is
# the summary file's).
PAGE_TABLE_COLUMNS = (
    "pair",
    "stage",
    "level",
    "hypothesis",
    "n1",
    "n2",
    "removed1",
    "removed2",
    "voxels_valid",
    "max_magnitude",
    "p95_magnitude",
    "mean_magnitude",
    "rms_magnitude",
    "paper_max_metric",
    "rigid_translation_m",
    "rigid_rotation_deg",
    "rigid_energy_share",
    "mean_resultant_length",
    "voxels_significant",
    "p_direction",
    "p_coherence",
    "verdict",
    "registration_method",
    "registration_fitness",
)
# Each stage figure's file stem (plots.settings.STAGE_FIGURES) and caption, in the order the
# page embeds them.
STAGE_FIGURE_CAPTIONS = (
    ("field_top", "field from above"),
    ("before_after", "before / after (same axes, same colour scale)"),
    ("removed_top", "removed points from above"),
    ("top_voxels", "voxels with the largest vectors"),
    ("field_perspective", "field in perspective"),
    ("removed_perspective", "removed points in perspective"),
)
REMATCH_FIGURE = ("pose_error", "pose error of rematching, stage by stage")  # only in studies with rematch
PAIR_FIGURES = (
    ("stages", "magnitude stage by stage"),
    ("rigid_randomness", "rigid part and randomness stage by stage"),
    ("tags", "share of the field energy per voxel tag, stage by stage"),
)
PAIR_TIER = "pair figures"
# The order in which figures are embedded while the page fits its budget: the pair's summary
# first, then the stage figures that say most about a stage.
TIERS = (PAIR_TIER, *(caption for _, caption in STAGE_FIGURE_CAPTIONS))
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


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


# A correcting stage's columns, shown when a stage of the pair corrects (the correction last, wrapped).
CORRECTION_COLUMNS = (
    "displacement1_median_m",
    "displacement1_max_m",
    "displacement2_median_m",
    "displacement2_max_m",
    "correction",
)


def correction_text(value) -> str:
    """A summary row's ``correction`` (canonical JSON) for reading: ``key: value`` pairs, numbers
    to 4 significant digits ('' for a removing stage)."""
    if not isinstance(value, str) or not value:
        return ""
    try:
        fitted = json.loads(value)
    except ValueError:
        return value
    if not isinstance(fitted, dict):
        return value

    def number(v) -> str:
        if isinstance(v, float):
            return f"{v:.4g}"
        if isinstance(v, list):
            return "[" + ", ".join(number(x) for x in v) + "]"
        return str(v)

    return "; ".join(f"{key}: {number(v)}" for key, v in fitted.items())


def stages_table(rows: list[dict]) -> str:
    """One row per stage (rows in red: the registration did not converge or warned); with a
    correcting stage, also each stage's displacements and what it fitted."""
    headers = [c for c in PAGE_TABLE_COLUMNS if any(c in r for r in rows)]
    headers += [c for c in LABEL_SCORES if any(_is_number(r.get(c)) for r in rows)]  # where labelled
    corrects = any(isinstance(r.get("correction"), str) and r["correction"] for r in rows)
    extra = list(CORRECTION_COLUMNS) if corrects else []
    body, classes = [], []
    for r in rows:
        problem, found = registration_problem(r), "; ".join(stage_findings(r))
        corrected = [r.get(c, "") for c in extra[:-1]] + [correction_text(r.get("correction"))] if extra else []
        body.append([r.get(c, "") for c in headers] + corrected + [problem, found])
        classes.append("flag" if problem or found else "")
    columns = headers + extra
    prose = tuple(range(len(columns) - 1, len(columns))) if extra else ()
    prose += (len(columns), len(columns) + 1)  # the two sentences last, wrapped
    return table(columns + ["registration problem", "findings"], body, classes, text_columns=2, prose_columns=prose)


def findings_parts(rows: list[dict]) -> list[str]:
    """What a reader should not miss (lidarfield.analysis.findings: a scan that does not fit its sensor
    model, a stage removing most of a cloud, a field without a valid voxel); nothing when none."""
    items = findings_items(rows)
    if not items:
        return []
    return ["<h2>Findings</h2>", '<ul class="findings">' + "".join(f"<li>{esc(i)}</li>" for i in items) + "</ul>"]


def drawn_pair_figure(stem: str, rows: list[dict]) -> bytes:
    """The page copy of a pair figure drawn for the page (the pair has no figure files)."""
    return compact_png(pair_figure_png(stem, rows, DPI))


def pair_figures(name: str, pair_dir: Path | None, rows: list[dict], out_dir: Path) -> list[Figure | str]:
    """The pair's stage-by-stage figures: its files, or drawn from its rows when there are none."""
    figures = []
    for stem, caption in PAIR_FIGURES:
        path = pair_dir / "figures" / f"{stem}.png" if pair_dir else None
        if path is not None and path.is_file():
            figures.append(file_figure(PAIR_TIER, path, f"{name}: {caption}", out_dir))
        elif rows:
            figures.append(Figure(PAIR_TIER, f"{name}: {caption}", None, partial(drawn_pair_figure, stem, rows)))
    stem, caption = REMATCH_FIGURE
    if pair_dir is not None and (pair_dir / "figures" / f"{stem}.png").is_file():
        figures.append(file_figure(PAIR_TIER, pair_dir / "figures" / f"{stem}.png", f"{name}: {caption}", out_dir))
    return figures


def stage_parts(
    name: str,
    stage_dir: Path,
    out_dir: Path,
    settings: PlotSettings,
    with_figures: bool = True,
    with_suggestions: bool = True,
) -> list[Figure | str]:
    """A stage's heading, (``with_suggestions``) what to try next, and (``with_figures``) the
    link to its 3-D view and the figures the settings draw for it."""
    fig_dir = stage_dir / "figures"
    parts = [f"<h3>{esc(name)} · stage {esc(stage_dir.name)}</h3>"]
    if with_suggestions:
        parts.append(stage_suggestions(stage_dir))
    if not with_figures:
        return parts
    view = fig_dir / "field_3d.html"
    if view.is_file():
        parts.append(f'<p><a href="{esc(relative_href(view, out_dir))}">interactive 3-D view of this stage</a></p>')
    level = level_of(stage_dir.name) or 0
    drawn = stage_figures(settings, level, has_previous=level > 0)
    stems = [(s, c) for s, c in STAGE_FIGURE_CAPTIONS if s in drawn]
    figures = [file_figure(c, fig_dir / f"{s}.png", f"{stage_dir.name}: {c}", out_dir) for s, c in stems]
    return parts + ['<div class="figures">', *figures, "</div>"]


def not_drawn_note(on_demand: str | None, last_suggested: bool) -> str:
    how = (
        f"<code>snakemake --cores 2 {esc(on_demand)}</code> makes them and writes that page, this one with them"
        if on_demand
        else "<code>lidarfield plot STAGE_DIR --out STAGE_DIR/figures</code> draws a stage's figures"
    )
    what = (
        "what to try next at its stages before the last"
        if last_suggested
        else "what to try next at its stages (the config's <code>suggest_pairs</code> leaves it out too)"
    )
    return (
        f'<p class="note">The figures of this pair, and {what}, are not made '
        f"(the config's <code>plots.pairs</code> leaves it out): {how}.</p>"
    )


def grid_parts(rows: list[dict]) -> list[str]:
    """The band and column edges the pair's fields used and why (field.channels), from its
    first stage's row; nothing for rows without them (a Cartesian grid, older results)."""
    first = min(rows, key=lambda r: float(r.get("level") or 0), default={})
    elevation, azimuth = first.get("elevation_edges_deg"), first.get("azimuth_edges_deg")
    if elevation is None or azimuth is None or not len(elevation):
        return []
    edges = ", ".join(f"{e:.4g}" for e in elevation)
    return [
        "<h2>Grid</h2>",
        f'<p class="note">Elevation band edges {esc(edges)} deg; {len(azimuth) - 1} azimuth columns from '
        f"{azimuth[0]:.4g} deg. {esc(str(first.get('binning') or ''))}.</p>",
    ]


def header_parts(name: str, stage_dirs: list[Path], overview_href: str | None) -> list:
    parts = [f'<nav><a href="{esc(overview_href)}">← study overview</a></nav>'] if overview_href else []
    return parts + [
        f"<h1>pair {esc(name)}</h1>",
        f'<p class="note">lidarfield {esc(__version__)} · {len(stage_dirs)} stage(s). Vectors run from the mean of '
        f"cloud 1 "
        "to the mean of cloud 2 in each voxel; a hypothesis that explains part of the discrepancy shrinks the field "
        "and "
        "breaks its pattern.</p>",
        Note(),
    ]


def pair_page_parts(
    name: str,
    stage_dirs: list[Path],
    rows: list[dict],
    out_dir: Path,
    settings: PlotSettings,
    with_figures: bool = True,
    overview_href: str | None = None,
    on_demand: str | None = None,
    suggested: set[str] | None = None,
) -> list:
    """The pair's page as parts (its figures still to be embedded or linked); ``suggested``:
    the names of the stages whose suggestions it shows (None: every stage's)."""
    suggested = {d.name for d in stage_dirs} if suggested is None else suggested
    pair_dir = stage_dirs[0].parent.parent if stage_dirs else None
    parts = header_parts(name, stage_dirs, overview_href) + findings_parts(rows) + grid_parts(rows)
    if with_figures and stage_dirs:
        # the page sits in {results}/{pair}/, the study's shared scripts in {results}/assets/
        how = f"<code>snakemake --cores 2 {esc(on_demand)}</code> writes them." if on_demand else ""
        parts += explorer_parts(name, stage_dirs, out_dir, out_dir.parent / ASSETS, how)
    parts += ["<h2>Stages</h2>", stages_table(rows), pair_rematch_table(rows)]
    if with_figures:
        parts += [
            "<h2>Stage by stage</h2>",
            '<div class="figures">',
            *pair_figures(name, pair_dir, rows, out_dir),
            "</div>",
        ]
    parts += ["<h2>Each stage: what to try next" + (", and its figures</h2>" if with_figures else "</h2>")]
    if not with_figures:
        parts.append(not_drawn_note(on_demand, bool(stage_dirs) and stage_dirs[-1].name in suggested))
    for stage_dir in stage_dirs:
        parts += stage_parts(name, stage_dir, out_dir, settings, with_figures, stage_dir.name in suggested)
    return parts


def write_pair_page(
    name: str,
    stage_dirs: list[str | Path],
    rows: list[dict],
    out_html: str | Path,
    plots: dict | None = None,
    with_figures: bool = True,
    overview_href: str | None = None,
    on_demand: str | None = None,
    max_mb: float | None = None,
    suggested: set[str] | None = None,
) -> Path:
    """Write one pair's page; returns its path.

    ``rows`` are the pair's summary rows; ``plots`` the config's ``plots`` section (which
    figures a stage has: a drawn one that is missing is flagged); ``with_figures`` False for a
    pair that ``plots.pairs`` leaves out: no pair or stage figures (``on_demand``: the target
    that draws them);
    ``max_mb``: the page's size budget (default: the schema's ``report.max_mb``);
    ``suggested``: the names of the stages whose what to try next it shows (None: every stage's;
    a workflow page shows those its job was given, never a file left from another run)."""
    out_html = Path(out_html)
    rows = sorted(rows, key=lambda r: float(r.get("level", 0)))
    parts = pair_page_parts(
        name,
        [Path(d) for d in stage_dirs],
        rows,
        out_html.parent,
        plot_settings(plots),
        with_figures,
        overview_href,
        on_demand,
        suggested,
    )
    return write_within_budget(parts, TIERS, f"lidarfield: pair {name}", out_html, budget_mb(None, max_mb))
