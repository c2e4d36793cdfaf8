"""``lidarfield report``: one self-contained HTML page for a results folder."""

from __future__ import annotations

import argparse
from pathlib import Path


def positive_mb(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value > 0:  # also refuses NaN
        raise argparse.ArgumentTypeError(f"a size in MB greater than 0, not {text!r}")
    return value


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "report",
        help="self-contained HTML report of every pair and stage of a results folder",
        description="Find the pairs and stages of RESULTS_DIR (a study's results/ or one pair's --out folder) "
        "and write one HTML page with the summary table, the stage-by-stage plots and the figures embedded "
        "while the page stays within --max-mb (the others are linked to their files).",
    )
    p.add_argument("results_dir", type=Path, help="results folder")
    p.add_argument("--out", required=True, type=Path, help="the HTML file to write")
    p.add_argument("--config", type=Path, help="the study YAML, shown in the report")
    p.add_argument(
        "--max-mb", type=positive_mb, help="size budget of the page in MB (default: report.max_mb of --config, else 20)"
    )
    p.set_defaults(func=run)


def run(args) -> int:
    from ..report import discover, write_report
    from ..study.config import load_config

    study = load_config(args.config, require_pairs=False).config if args.config else {}
    pairs, rows = discover(args.results_dir)
    print(write_report(study, pairs, rows, args.out, max_mb=args.max_mb))
    return 0
