"""The study report of a results folder: the overview page (``report.html``, see ``overview``)
and one page per pair beside it (``{pair}/report.html``, see ``pair_page``), so that a study of
hundreds of pairs opens at its study level and each pair is one click away.

The workflow writes the same pages from its own jobs (the study tables as Parquet first, each
pair's page in its own job); ``write_report`` builds everything from a results folder at once,
computing the study tables in memory (``lidarfield report``).

The interactive 3-D views are separate files (a few MB each): the pages link them by relative
path, so they open when the report sits in its results folder.
"""

from __future__ import annotations

import logging
from pathlib import Path

from ..defaults import default
from ..study.tables import compute_study_tables
from .explanation import RECORD_FILE, read_explanations
from .explorer import ASSETS, write_assets, write_explorer_data
from .overview import write_overview
from .pair_page import write_pair_page
from .study_view import PAIR_PAGE

log = logging.getLogger(__name__)


def has_stage_figures(stage_dirs: list[Path]) -> bool:
    return any((d / "figures").is_dir() for d in stage_dirs)


def write_report(
    study: dict,
    pairs: dict[str, list[Path]],
    summary_rows: list[dict],
    out_html: str | Path,
    max_mb: float | None = None,
) -> Path:
    """Write the overview at ``out_html`` and every pair's page at ``{out_html's folder}/{pair}/report.html``;
    returns the overview's path.

    ``study`` is the config (folded at the end of the overview), ``pairs`` maps each pair to its
    stage folders in order, ``summary_rows`` are the summary table's rows (one per pair and
    stage). ``max_mb`` is each page's size budget (default: the study's ``report.max_mb``): on
    a pair page, the figures that do not fit, whole tiers at a time, are linked instead of embedded.
    """
    out_html = Path(out_html)
    pairs = {name: [Path(d) for d in dirs] for name, dirs in pairs.items()}
    plotted = {name for name, dirs in pairs.items() if has_stage_figures(dirs)}
    max_mb = max_mb if max_mb is not None else ((study or {}).get("report") or {}).get("max_mb")
    explorer_points = ((study or {}).get("report") or {}).get("explorer_points", default("report", "explorer_points"))
    write_assets(out_html.parent / ASSETS)
    for name, dirs in pairs.items():
        if name in plotted:
            write_explorer_data(dirs[0].parent.parent, dirs, explorer_points)
        rows = [r for r in summary_rows if str(r.get("pair")) == name]
        write_pair_page(
            name,
            dirs,
            rows,
            out_html.parent / PAIR_PAGE.format(pair=name),
            (study or {}).get("plots"),
            with_figures=name in plotted,
            overview_href=f"../{out_html.name}",
            max_mb=max_mb,
        )
    tables = compute_study_tables(pairs, summary_rows)
    last_stages = {name: dirs[-1] for name, dirs in pairs.items() if dirs}
    records = [dirs[0].parent.parent / "explain" / RECORD_FILE for dirs in pairs.values() if dirs]
    explained = read_explanations([path for path in records if path.is_file()])
    return write_overview(
        study, tables, out_html, stage_figures=plotted, last_stages=last_stages, max_mb=max_mb, explained=explained
    )
