"""``lidarfield compare``: two studies side by side."""

from __future__ import annotations

from pathlib import Path


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "compare",
        help="compare two results folders pair by pair and stage by stage (HTML)",
        description="Put two studies (e.g. two variants of a hypothesis stack) side by side: both stacks' "
        "statistics with deltas, both stage-by-stage curves and both fields from above, matched by stage level.",
    )
    p.add_argument("results_a", type=Path, help="results folder of study A")
    p.add_argument("results_b", type=Path, help="results folder of study B")
    p.add_argument("--out", required=True, type=Path, help="the HTML file to write")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..report import compare_studies

    print(compare_studies(args.results_a, args.results_b, args.out))
    return 0
