"""The study overview (``results/report.html``): what the whole study shows, read from the top.

First the study level (the pairs x stages heat map, what each hypothesis changed, the polar
voxel maps per stage), then the pairs ranked by what remains at their last stage, each linking
to its own page, and the config folded at the end. Its size grows with the number of pairs
only through one table row per pair: the study figures are a fixed handful, every pair's own
figures live on its page. Each section is a small function returning HTML parts, so that new
sections slot in.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import yaml

from .. import __version__
from ..io.atomic import write_text
from ..plots.study import StudyFigure, study_figures
from ..study.tables import StudyTables
from .budget import MB, budget_mb, utf8_len
from .explanation import study_explain_parts
from .explorer import ASSETS
from .page import esc, image, image_file, page, table
from .pair_page import DPI, findings_parts
from .polar_svg import polar_map_parts
from .rematch import study_rematch_parts
from .study_view import STYLE, heatmap_parts, ranking_filter, ranking_table, script_tag
from .suggestions import study_suggestions

log = logging.getLogger(__name__)

TITLE = "lidarfield study report"
SUGGESTED_PAIRS = 20  # the overview's next steps: for the pairs with most left; the others' on their pages


def header_parts(tables: StudyTables) -> list[str]:
    s = tables.summary
    stack = s.sort_values("level").groupby("level")["hypothesis"].first()
    return [
        f"<h1>{TITLE}</h1>",
        f'<p class="note">lidarfield {esc(__version__)} · {s["pair"].nunique()} pairs · {len(stack)} stages: '
        + " → ".join(f"{int(k):02d} {esc(v)}" for k, v in stack.items())
        + ". Vectors run from the mean of cloud 1 to the mean of cloud 2 in each voxel; a hypothesis that explains "
        "part of the discrepancy shrinks the field and breaks its pattern. The study level comes first; every pair "
        "has its own page (ranked list below).</p>",
    ]


def hypotheses_table(hypotheses) -> str:
    """Per hypothesis, over the pairs: how often and how much it shrank the field."""
    headers = [
        "stage",
        "hypothesis",
        "pairs",
        "p95 fell in",
        "median Δ p95 (m)",
        "median Δ max (m)",
        "median Δ rms (m)",
        "median removed (%)",
    ]
    body = []
    for level, rows in hypotheses.groupby("level", sort=True):
        delta = {
            m: (rows[f"{m}_magnitude_after"] - rows[f"{m}_magnitude_before"]).to_numpy(dtype=float)
            for m in ("p95", "max", "rms")
        }
        fell = np.count_nonzero(delta["p95"] < 0)
        body.append(
            [
                f"{int(level):02d}",
                rows["hypothesis"].iloc[0],
                len(rows),
                f"{fell} ({100 * fell / len(rows):.0f}%)",
                float(np.nanmedian(delta["p95"])),
                float(np.nanmedian(delta["max"])),
                float(np.nanmedian(delta["rms"])),
                float(100 * np.nanmedian(rows["removed_share"].to_numpy(dtype=float))),
            ]
        )
    return table(headers, body, text_columns=2)


def figure_html(f: StudyFigure, figures_dir: Path | None) -> str:
    """A study figure embedded: its PNG file when the workflow drew it, else drawn now; its hover
    spots over it (the figure made again for their places, not rendered)."""
    path = figures_dir / f"{f.stem}.png" if figures_dir is not None else None
    if path is not None and path.is_file():
        return image_file(path, f.caption, f.spots())
    return image(f.png(), f.caption, f.spots())


def study_level_parts(tables: StudyTables, figures_dir: Path | None) -> list[str]:
    figures = study_figures(tables.summary, tables.voxels, tables.hypotheses, tables.pairs, tables.grid)
    maps = [f for f in figures if f.stem.startswith("voxels_")]
    # the heat map is the page's grid of links (its PNG stays in study/figures, for papers)
    others = [f for f in figures if f not in maps and f.stem != "heatmap"]
    parts = [
        "<h2>The study level</h2>",
        *heatmap_parts(tables.summary, tables.pairs),
        '<p class="note">Hover a box of what each hypothesis changed for its quartiles, its 5-95 % range and '
        "the pairs at either end; hover a point of the largest vector's lines for its pair and value (beyond a "
        "dozen pairs: the median's, with the largest and smallest pair).</p>",
        '<div class="figures">',
        *(figure_html(f, figures_dir) for f in others),
        "</div>",
    ]
    if len(tables.hypotheses):
        parts += [
            "<h3>What each hypothesis changed</h3>",
            '<p class="note">Δ = after − before (the previous stage), per pair; negative: the field shrank. '
            "Removed: points of both clouds the stage removed, in % of those that entered it.</p>",
            hypotheses_table(tables.hypotheses),
        ]
    parts.append("<h3>Voxels over the pairs, stage by stage</h3>")
    if maps:
        parts += [
            '<p class="note">The grid is in sensor 1\'s frame, so a voxel is the same direction from the vehicle in '
            "every pair. Left: the median magnitude over the pairs where the voxel is valid. Right: the share of those "
            "pairs where its magnitude exceeds that pair-stage's median magnitude; about 0.5 everywhere means no "
            "direction stands out, red where the same direction is large along the drive (a ring, a sector of the "
            "own vehicle, a mounting effect). Table: <code>study/voxels.parquet</code>.</p>",
            '<p class="note">Hover a cell for its voxel, its median magnitude, its share and in how many pairs it '
            "is valid (the same maps as <code>study/figures/voxels_{level}.png</code>).</p>",
            *polar_map_parts(tables.voxels, tables.grid),
        ]
    else:
        parts.append(
            '<p class="note">No polar voxel maps: they need a spherical grid and the stages\' field files.</p>'
        )
    return parts


def ranking_parts(tables: StudyTables, stage_figures: set[str], last_stages: dict[str, Path]) -> list[str]:
    return [
        "<h2>Pairs ranked by what remains at the last stage</h2>",
        '<p class="note">Ranked by the p95 magnitude of the last stage, largest first '
        "(<code>study/pairs.parquet</code>); a click on a column's header sorts by it. "
        "A pair's name opens its page, its last stage opens that page at that stage: its table, its "
        "stage-by-stage figures and, where drawn "
        "(<code>plots.pairs</code>), its explorer and stage figures. What to try next: the best candidate at "
        "the last stage, where computed (<code>suggest_pairs</code>). Removed share: of both clouds' points, by "
        "all the stages. Rows in red: the registration did not converge or warned.</p>",
        ranking_filter(),
        ranking_table(tables, stage_figures, last_stages),
    ]


def next_steps_parts(tables: StudyTables, last_stages: dict[str, Path]) -> list[str]:
    """The best candidates at the last stage of the pairs with the most left, in rank order."""
    pairs = list(tables.pairs["pair"])
    ranked = [p for p in pairs if p in last_stages][:SUGGESTED_PAIRS]
    notes = []
    if len(last_stages) < len(pairs):
        notes.append(
            f"What to try next is computed for {len(last_stages)} of the study's {len(pairs)} pairs, spread over "
            "them (the config's <code>suggest_pairs</code>); any other pair's page says how to make its own."
        )
    if len(last_stages) > SUGGESTED_PAIRS:
        notes.append(
            f"The {SUGGESTED_PAIRS} of them with the most left at their last stage, in rank order; "
            "every pair's page has its own tables."
        )
    note = f'<p class="note">{" ".join(notes)}</p>' if notes else ""
    return ["<h2>What to try next</h2>", note, study_suggestions({p: [last_stages[p]] for p in ranked})]


def config_parts(config: dict | None) -> list[str]:
    return [
        "<h2>Study configuration</h2>",
        "<details><summary>the config this study ran with (YAML, defaults filled in)</summary>",
        f"<pre>{esc(yaml.safe_dump(config or {}, sort_keys=False, default_flow_style=None))}</pre></details>",
    ]


def overview_parts(
    config: dict | None,
    tables: StudyTables,
    figures_dir: Path | None,
    stage_figures: set[str],
    last_stages: dict[str, Path],
    explained: list[dict] = (),
    out_dir: Path = Path("."),
) -> list[str]:
    rows = tables.summary.to_dict("records")
    return [
        *header_parts(tables),
        *findings_parts(rows),
        *study_level_parts(tables, figures_dir),
        *study_rematch_parts(rows, DPI),
        *next_steps_parts(tables, last_stages),
        *study_explain_parts(list(explained), out_dir),
        *ranking_parts(tables, stage_figures, last_stages),
        *config_parts(config),
        STYLE,
        script_tag(out_dir / ASSETS, out_dir),
    ]


def write_overview(
    config: dict | None,
    tables: StudyTables,
    out_html: str | Path,
    figures_dir: str | Path | None = None,
    stage_figures: set[str] = frozenset(),
    last_stages: dict[str, Path] | None = None,
    max_mb: float | None = None,
    explained: list[dict] = (),
) -> Path:
    """Write the study overview; returns its path. ``figures_dir``: the study figures drawn by
    the workflow (drawn here when absent); ``stage_figures``: the pairs whose stage figures are
    drawn; ``last_stages``: each pair's last stage folder (for what to try next); ``explained``:
    the pairs' explain records (``report.explanation.read_explanations``), for what explain found."""
    out_html = Path(out_html)
    figures = None if figures_dir is None else Path(figures_dir)
    parts = overview_parts(config, tables, figures, set(stage_figures), last_stages or {}, explained, out_html.parent)
    html = page(TITLE, parts)
    write_text(out_html, html)
    size, max_mb = utf8_len(html), budget_mb(config, max_mb)
    log.info("%s: %.2f MB (budget %g MB), %d pairs", out_html, size / MB, max_mb, len(tables.pairs))
    if size > max_mb * MB:
        log.warning("%s is over its %g MB budget", out_html, max_mb)
    return out_html
