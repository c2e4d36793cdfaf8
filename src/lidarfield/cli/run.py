"""``lidarfield run``: one pair through a study's whole hypothesis stack, without Snakemake."""

from __future__ import annotations

import argparse
import math

TABLE_COLUMNS = (
    "stage",
    "hypothesis",
    "n1",
    "n2",
    "removed1",
    "removed2",
    "voxels_valid",
    "max_magnitude",
    "paper_max_metric",
)


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "run",
        help="run one pair through the config's hypothesis stack (no Snakemake)",
        description="Read two scans, register them, apply every hypothesis of the config's stack and write, "
        "per stage, the points, the removed points, the field, a summary row and, with rematch:, the pose error "
        "of rematching the stage (rematch.parquet), plus DIR/summary.parquet/.csv.",
    )
    add_pair_arguments(parser)
    parser.add_argument("--config", required=True, help="study YAML: its grid, hypotheses and rematch section are used")
    parser.add_argument(
        "--out", required=True, metavar="DIR", help="output folder (new, empty, or from an earlier run)"
    )
    parser.set_defaults(func=_run)


def add_pair_arguments(parser) -> None:
    """The two scans and how they are read and registered (``lidarfield run`` and ``explain``);
    ``pair_inputs`` reads them back."""
    parser.add_argument("scan1", help="scan 1 (its sensor frame is the frame of the results)")
    parser.add_argument("scan2", help="scan 2")
    how = parser.add_mutually_exclusive_group()
    how.add_argument(
        "--register", metavar="METHOD", help="identity (default), truth, icp, icp_point_to_plane, gicp or ndt"
    )
    how.add_argument("--transform", metavar="FILE", help="file holding the pose of sensor 2 in frame 1")
    parser.add_argument("--sensor", metavar="NAME", help="sensor preset or YAML file of both scans (e.g. vlp16)")
    parser.add_argument(
        "--poses",
        metavar="TOPIC",
        help="ROS bag scans: take their poses from this topic (Odometry, PoseStamped, TF) for --register truth",
    )
    parser.add_argument("--pose-frame", metavar="FRAME", help="with --poses on a TF topic: the sensor's child frame")


def pair_inputs(args: argparse.Namespace) -> dict:
    """The keyword arguments of ``add_pair_arguments``' options: register, transform, sensor, poses."""
    poses = (
        None if args.poses is None else {"topic": args.poses, **({"frame": args.pose_frame} if args.pose_frame else {})}
    )
    return {"register": args.register, "transform": args.transform, "sensor": args.sensor, "poses": poses}


def _run(args: argparse.Namespace) -> int:
    from ..analysis.rematch import METHOD_COLUMNS, method_rows
    from ..commands.scans import run_pair

    rows = run_pair(args.scan1, args.scan2, args.config, args.out, **pair_inputs(args))
    print(format_table(rows))
    for line in findings_lines(rows):
        print(line)
    rematched = method_rows(rows)
    if rematched:
        print(
            "\nrematch: pose error of each method from the stage's survivors (median and 90th percentile over trials)"
        )
        print(format_table(rematched, METHOD_COLUMNS))
    print(format_next_steps(rows, args.out))
    print(f"wrote {args.out}/stages/*/ and {args.out}/summary.parquet, summary.csv")
    return 0


def format_next_steps(rows: list[dict], out_dir) -> str:
    """Per stage its verdict and the best candidate of its suggestions.parquet."""
    from pathlib import Path

    from ..report.suggestions import describe_fitted, read_suggestions

    lines = ["what to try next (best candidate alone on each stage's survivors):"]
    for row in rows:
        best = (read_suggestions(Path(out_dir) / "stages" / row["stage"]) or [None])[0]
        field = (
            f"{row.get('verdict')}, {row.get('voxels_significant')} of {row.get('voxels_valid')} vectors significant"
        )
        if best is None or not best["whitened_reduction"] > 0:
            lines.append(f"  {row['stage']} ({field}): no candidate reduces the energy")
            continue
        if best.get("corrects"):
            fitted = describe_fitted(best.get("fitted"))
            cost = f"(fitted {fitted})" if fitted else f"(moving points {best['displacement_median_m']:.3f} m)"
        else:
            cost = f"removing {100 * best['removed_share']:.1f}% of the points"
        lines.append(
            f"  {row['stage']} ({field}): {best['hypothesis']} reduces the energy by "
            f"{100 * best['whitened_reduction']:.1f}% in units of its noise ({100 * best['energy_reduction']:.1f}% "
            f"raw) {cost}"
        )
    return "\n".join(lines)


def format_table(rows: list[dict], columns: tuple[str, ...] = TABLE_COLUMNS) -> str:
    """The rows as an aligned text table (floats with 3 decimals; the first two columns text)."""
    cells = [[_cell(row.get(column)) for column in columns] for row in rows]
    widths = [max(len(c), *(len(r[i]) for r in cells)) for i, c in enumerate(columns)]
    lines = [
        "  ".join(c.ljust(w) if i < 2 else c.rjust(w) for i, (c, w) in enumerate(zip(line, widths)))
        for line in [list(columns), *cells]
    ]
    return "\n".join(lines)


def findings_lines(rows: list[dict]) -> list[str]:
    """What the table does not say plainly: the registration's, the scans' and the grid's
    warnings, and each stage's findings (lidarfield.analysis.findings)."""
    from ..analysis.findings import grid_findings, sensor_findings, stage_findings

    lines = [f"registration: {rows[0]['registration_warning']}"] if rows and rows[0].get("registration_warning") else []
    lines += [f"sensor model: {text}" for text in (sensor_findings(rows[0]) if rows else [])]
    lines += [f"grid: {text}" for text in (grid_findings(rows[0]) if rows else [])]
    lines += [f"{row['stage']}: {text}" for row in rows for text in stage_findings(row)]
    return lines


def _cell(value) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return f"{value:.3f}" if isinstance(value, float) else str(value)
