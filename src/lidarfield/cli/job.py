"""``lidarfield job``: the entry points the Snakemake rules call, one per rule.

Rules pass only paths and the canonical JSON of their own settings; everything else is in the
library. Not meant for interactive use (see ``lidarfield run`` for one pair without Snakemake).
"""

from __future__ import annotations

import argparse
import json
import sys


def _json(text: str):
    return json.loads(text)


def _json_or_stdin(text: str):
    """JSON, or ``-``: JSON read from stdin (a study's whole config can outgrow the 128 kB that
    Linux allows one command-line argument)."""
    return json.loads(sys.stdin.read() if text == "-" else text)


def add_stage_points(parser: argparse.ArgumentParser, stages: str = "1..k", stage_id: bool = True) -> None:
    """The options naming a stage's points: the registered pair, the stages' changes and
    (``stage_id``) the stage's id, which stage 0 (no changes file) takes its keys from."""
    parser.add_argument("--registered", required=True, help="the pair's registered.parquet")
    parser.add_argument(
        "--stage-changes", nargs="*", default=[], help=f"the changes.parquet of stages {stages}, in order"
    )
    if stage_id:
        parser.add_argument("--stage", required=True, help="the stage's id (its folder's name)")


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("job", help="one workflow job (called by the Snakemake rules)")
    jobs = parser.add_subparsers(dest="job", required=True, metavar="JOB")

    for kind in ("simulate", "ingest"):
        p = jobs.add_parser(kind)
        p.add_argument("--spec", type=_json, required=True)
        p.add_argument("--out", required=True)
        p.set_defaults(func=_scan, kind="simulated" if kind == "simulate" else "recorded")

    p = jobs.add_parser("register")
    p.add_argument("--scan1", required=True)
    p.add_argument("--scan2", required=True)
    p.add_argument("--settings", type=_json, required=True)
    p.add_argument("--out", required=True)
    p.set_defaults(func=_register)

    p = jobs.add_parser("mitigate")
    add_stage_points(p, "1..k-1")
    p.add_argument("--step", type=_json, required=True)
    p.add_argument("--level", type=int, required=True)
    p.add_argument("--changes-out", required=True)
    p.add_argument("--removed-out", required=True)
    p.set_defaults(func=_mitigate)

    p = jobs.add_parser("field")
    add_stage_points(p)
    p.add_argument("--removed", nargs="?", help="the stage's removed.parquet (none for stage 0)")
    p.add_argument("--previous", nargs="?", help="the stage before's field.parquet (none for stage 0)")
    p.add_argument("--grid", type=_json, required=True)
    p.add_argument("--pair", required=True)
    p.add_argument("--field-out", required=True)
    p.add_argument("--stats-out", required=True)
    p.set_defaults(func=_field)

    p = jobs.add_parser("suggest")
    add_stage_points(p)
    p.add_argument("--candidates", type=_json, required=True, help="normalised hypothesis entries")
    p.add_argument(
        "--default-candidates", action="store_true", help="skip the candidates that cannot apply to the pair"
    )
    p.add_argument("--grid", type=_json, required=True)
    p.add_argument("--out", required=True)
    p.set_defaults(func=_suggest)

    p = jobs.add_parser("rematch")
    add_stage_points(p)
    p.add_argument("--settings", type=_json, required=True, help="the validated rematch section")
    p.add_argument("--out", required=True)
    p.set_defaults(func=_rematch)

    p = jobs.add_parser("plot-stage")
    add_stage_points(p, stage_id=False)
    p.add_argument("--stage-dir", required=True)
    p.add_argument("--previous", default="", help="the previous stage's folder ('' for stage 0)")
    p.add_argument("--plots", type=_json, required=True)
    p.add_argument("--plotly-js", help="a shared plotly.js file for the 3-D view (embedded without it)")
    p.add_argument("--out", required=True)
    p.set_defaults(func=_plot_stage)

    p = jobs.add_parser("plotly-js")
    p.add_argument("--out", required=True)
    p.set_defaults(func=_plotly_js)

    p = jobs.add_parser("explorer-points")
    p.add_argument("--registered", required=True, help="the pair's registered.parquet")
    p.add_argument("--budget", type=int, required=True, help="the most points drawn of each cloud (0: all)")
    p.add_argument("--out", required=True, help="the sampled points' script (points.js)")
    p.add_argument("--rest", required=True, help="the other points' script (rest.js), loaded on the page's 'show all'")
    p.set_defaults(func=_explorer_points)

    p = jobs.add_parser("explorer-stage")
    p.add_argument("--registered", required=True, help="the pair's registered.parquet")
    p.add_argument("--field", required=True, help="the stage's field.parquet")
    p.add_argument("--changes", nargs="?", help="the stage's changes.parquet (none for stage 0)")
    p.add_argument("--budget", type=int, required=True, help="the most points drawn of each cloud (0: all)")
    p.add_argument("--out", required=True)
    p.set_defaults(func=_explorer_stage)

    p = jobs.add_parser("report-js")
    p.add_argument("--out", nargs="+", required=True, help="where to write the report's scripts (named as shipped)")
    p.set_defaults(func=_report_js)

    p = jobs.add_parser("plot-pair")
    p.add_argument("--stats", nargs="+", required=True)
    p.add_argument("--rematch", nargs="*", default=[], help="the stages' rematch.parquet files (rematch studies)")
    p.add_argument("--out", required=True)
    p.set_defaults(func=_plot_pair)

    p = jobs.add_parser("summary")
    p.add_argument("--stats", nargs="+", required=True)
    p.add_argument("--rematch", nargs="*", default=[], help="the stages' rematch.parquet files (rematch studies)")
    p.add_argument("--parquet", required=True)
    p.add_argument("--csv", required=True)
    p.set_defaults(func=_summary)

    p = jobs.add_parser("study-voxels")
    p.add_argument("--fields", nargs="+", required=True, help="every stage's field.parquet of the study")
    p.add_argument("--out", required=True)
    p.set_defaults(func=_study_voxels)

    p = jobs.add_parser("study-tables")
    p.add_argument("--summary", required=True)
    p.add_argument("--hypotheses-out", required=True)
    p.add_argument("--pairs-out", required=True)
    p.set_defaults(func=_study_tables)

    p = jobs.add_parser("study-figures")
    p.add_argument("--summary", required=True)
    p.add_argument("--study-dir", required=True, help="the folder of voxels.parquet, hypotheses.parquet, pairs.parquet")
    p.add_argument("--out", required=True)
    p.set_defaults(func=_study_figures)

    p = jobs.add_parser("pair-report")
    p.add_argument("--pair", required=True)
    p.add_argument("--stats", nargs="+", required=True)
    p.add_argument("--rematch", nargs="*", default=[], help="the stages' rematch.parquet files (rematch studies)")
    p.add_argument(
        "--suggestions", nargs="*", default=[], help="the suggestions.parquet of the stages it shows them for"
    )
    p.add_argument("--stage-dirs", nargs="+", required=True)
    p.add_argument("--plots", type=_json, required=True)
    p.add_argument("--figures", action=argparse.BooleanOptionalAction, required=True, help="the pair and stage figures")
    p.add_argument("--on-demand", help="the target that draws the figures of a pair without them")
    p.add_argument("--max-mb", type=float, required=True)
    p.add_argument("--out", required=True)
    p.set_defaults(func=_pair_report)

    p = jobs.add_parser("report")
    p.add_argument(
        "--config",
        type=_json_or_stdin,
        required=True,
        help="the study's config (JSON, or - for stdin), folded at the end of the page",
    )
    p.add_argument("--summary", required=True)
    p.add_argument("--study-dir", required=True)
    p.add_argument("--figures", required=True, help="the study figures' folder")
    p.add_argument("--plotted", type=_json, required=True, help="the pairs whose stage figures are drawn (JSON list)")
    p.add_argument(
        "--suggestions", nargs="*", default=[], help="the suggestions.parquet of suggest_pairs at their last stage"
    )
    p.add_argument("--explain", nargs="*", default=[], help="the pairs' explain.json (those built)")
    p.add_argument("--out", required=True)
    p.set_defaults(func=_report)

    p = jobs.add_parser("explain")
    p.add_argument("--points", required=True, help="the pair's registered.parquet")
    p.add_argument("--pair", required=True)
    p.add_argument("--grid", type=_json, required=True)
    p.add_argument("--suggest", type=_json, required=True, help="the config's suggest list (JSON; null: the defaults)")
    p.add_argument("--settings", type=_json, required=True, help="the config's explain section (JSON)")
    p.add_argument("--plots", type=_json, required=True)
    p.add_argument("--out-dir", required=True)
    p.set_defaults(func=_explain)


def _scan(args: argparse.Namespace) -> None:
    from ..commands.jobs import scan_job

    scan_job(args.kind, args.spec, args.out)


def _register(args: argparse.Namespace) -> None:
    from ..commands.jobs import register_job

    register_job(args.scan1, args.scan2, args.settings, args.out)


def _mitigate(args: argparse.Namespace) -> None:
    from ..commands.jobs import mitigate_stage

    mitigate_stage(
        args.registered, args.stage_changes, args.step, args.stage, args.level, args.changes_out, args.removed_out
    )


def _field(args: argparse.Namespace) -> None:
    from ..commands.jobs import field_stage

    field_stage(
        args.registered,
        args.stage_changes,
        args.removed,
        args.grid,
        args.pair,
        args.field_out,
        args.stats_out,
        args.stage,
        args.previous,
    )


def _suggest(args: argparse.Namespace) -> None:
    from ..commands.jobs import suggest_stage

    suggest_stage(
        args.registered,
        args.stage_changes,
        args.stage,
        args.candidates,
        args.grid,
        args.out,
        defaults=args.default_candidates,
    )


def _rematch(args: argparse.Namespace) -> None:
    from ..commands.jobs import rematch_stage

    rematch_stage(args.registered, args.stage_changes, args.stage, args.settings, args.out)


def _plot_stage(args: argparse.Namespace) -> None:
    from ..plots import plot_stage

    points = (args.registered, args.stage_changes)
    plot_stage(args.stage_dir, args.previous or None, args.out, args.plots, args.plotly_js, points)


def _plotly_js(args: argparse.Namespace) -> None:
    from ..plots import write_plotly_js

    write_plotly_js(args.out)


def _explorer_points(args: argparse.Namespace) -> None:
    from ..report.explorer_data import write_points_scripts

    write_points_scripts(args.registered, args.budget, args.out, args.rest)


def _explorer_stage(args: argparse.Namespace) -> None:
    from ..report.explorer_data import write_stage_script

    write_stage_script(args.registered, args.field, args.changes or None, args.budget, args.out)


def _report_js(args: argparse.Namespace) -> None:
    from ..report.explorer import write_script

    for path in args.out:
        write_script(path)


def _plot_pair(args: argparse.Namespace) -> None:
    from ..commands.jobs import plot_pair_job

    plot_pair_job(args.stats, args.rematch, args.out)


def _summary(args: argparse.Namespace) -> None:
    from ..study.summary import write_summary

    write_summary(args.stats, args.parquet, args.csv, args.rematch)


def _study_voxels(args: argparse.Namespace) -> None:
    from ..study.tables import write_study_voxels

    write_study_voxels(args.fields, args.out)


def _study_tables(args: argparse.Namespace) -> None:
    from ..study.tables import write_study_tables

    write_study_tables(args.summary, args.hypotheses_out, args.pairs_out)


def _study_figures(args: argparse.Namespace) -> None:
    from ..commands.jobs import study_figures_job

    study_figures_job(args.summary, args.study_dir, args.out)


def _pair_report(args: argparse.Namespace) -> None:
    from ..commands.jobs import pair_report_job

    pair_report_job(
        args.pair,
        args.stage_dirs,
        args.stats,
        args.rematch,
        args.suggestions,
        args.plots,
        args.figures,
        args.on_demand,
        args.max_mb,
        args.out,
    )


def _report(args: argparse.Namespace) -> None:
    from ..commands.jobs import report_job

    report_job(
        args.config, args.summary, args.study_dir, args.figures, args.plotted, args.suggestions, args.explain, args.out
    )


def _explain(args: argparse.Namespace) -> None:
    from ..commands.jobs import explain_job

    explain_job(args.points, args.pair, args.grid, args.suggest, args.settings, args.plots, args.out_dir)
