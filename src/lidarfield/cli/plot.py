"""``lidarfield plot``: the figures of one stage folder."""

from __future__ import annotations

from pathlib import Path


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "plot",
        help="figures of one stage: field, removed points, top voxels, before/after, 3-D view",
        description="Draw the figures of a stage folder of a study's results into --out (its field.parquet and "
        "removed.parquet, and its points: the pair's registered.parquet with the stages' changes.parquet).",
    )
    p.add_argument("stage_dir", type=Path, help="stage folder, e.g. results/PAIR/stages/01-ego_vehicle-1a2b3c4d")
    p.add_argument(
        "--before-after", action="store_true", help="with the previous stage: adds before_after and shares its axes"
    )
    p.add_argument("--out", required=True, type=Path, help="output folder for the figures")
    p.add_argument(
        "--config",
        type=Path,
        help="study YAML (validated; paths relative to the working directory): its plots section sets magnification, "
        "top_k, ...",
    )
    p.set_defaults(func=run)


def run(args) -> int:
    from ..plots import plot_stage
    from ..storage.stage_points import stage_files
    from ..study.config import load_config

    settings = load_config(args.config, require_pairs=False).plots if args.config else {}
    changes = stage_files(args.stage_dir)[1] if args.before_after else []
    previous = changes[-2].parent if len(changes) > 1 else None
    for path in plot_stage(args.stage_dir, previous, args.out, settings):
        print(path)
    return 0
