"""``lidarfield report``: one self-contained HTML page for a results folder."""

from __future__ import annotations

from pathlib import Path


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "report",
        help="self-contained HTML report of every pair and stage of a results folder",
        description="Find the pairs and stages of RESULTS_DIR (a study's results/ or one pair's --out folder) "
        "and write one HTML page with the summary table, the stage-by-stage plots and every figure embedded.",
    )
    p.add_argument("results_dir", type=Path, help="results folder")
    p.add_argument("--out", required=True, type=Path, help="the HTML file to write")
    p.add_argument("--config", type=Path, help="the study YAML, shown in the report")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..config import load_config
    from ..report import discover, write_report

    study = load_config(args.config, require_pairs=False).config if args.config else {}
    pairs, rows = discover(args.results_dir)
    print(write_report(study, pairs, rows, args.out))
    return 0
