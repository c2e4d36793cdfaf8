"""``lidarfield explain``: the hypothesis stack that explains a pair's field, found step by step."""

from __future__ import annotations

import argparse
from pathlib import Path

from .run import add_pair_arguments, format_table, pair_inputs


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "explain",
        help="find the hypothesis stack that explains a pair's field, one suggestion at a time",
        description="Read two scans and register them (as lidarfield run does), then apply the best candidate of "
        "'what to try next' that is worth it, recompute the field and repeat, until the field's verdict is random "
        "or no candidate is worth it (the config's explain settings). Writes DIR/stack.yaml (the stack found, a "
        "ready config), steps.csv (one row per step), explain.json, explain.html and figures/.",
    )
    add_pair_arguments(parser)
    parser.add_argument(
        "--config",
        help="study YAML: its grid, suggest, explain and plots sections are used, not its hypotheses "
        "(default: the schema's defaults)",
    )
    parser.add_argument(
        "--out",
        metavar="DIR",
        help="output folder: new, empty, or from an earlier explain (default: explain-SCAN1-SCAN2)",
    )
    parser.set_defaults(func=_explain)


def _explain(args: argparse.Namespace) -> int:
    from ..commands.scans import explain_scans
    from ..study.explain_loop import PRINTED_COLUMNS

    out = args.out or f"explain-{Path(args.scan1).stem}-{Path(args.scan2).stem}"
    explanation = explain_scans(args.scan1, args.scan2, args.config, out, **pair_inputs(args))
    if explanation.steps:
        print(format_table(explanation.steps, PRINTED_COLUMNS))
    print(f"{len(explanation.steps)} step(s); stopped: {explanation.stop}; the field is {explanation.verdict}")
    for finding in explanation.findings:
        print(f"finding: {finding}")
    print(f"wrote {out}/stack.yaml, steps.csv, explain.json, explain.html and figures/")
    return 0
