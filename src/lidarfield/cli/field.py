"""``lidarfield field``: the discrepancy-vector field of one pair of scans, with its summary."""

from __future__ import annotations

from pathlib import Path

from ..defaults import default
from ..errors import ConfigError
from ..yaml_file import read_yaml

# CLI flag -> grid config key (the same keys as the study config's ``grid`` section).
_GRID_FLAGS = {
    "kind": "kind",
    "azimuth_bins": "azimuth_bins",
    "azimuth_offset_deg": "azimuth_offset_deg",
    "elevation_deg": "elevation_deg",
    "elevation_bins": "elevation_bins",
    "range_edges_m": "range_edges_m",
    "cell_m": "cell_m",
    "min_points": "min_points",
    "max_component_m": "max_component_m",
    "z_min": "z_min",
}


def _default(key: str) -> str:
    """The schema's default of a grid key, as the help shows it."""
    value = default("grid", key)
    return (
        " ".join(f"{v:g}" for v in value)
        if isinstance(value, list)
        else f"{value:g}"
        if isinstance(value, float)
        else str(value)
    )


def add_parser(subparsers) -> None:
    from ..field.grid import SENSORLESS_ELEVATION_DEG

    p = subparsers.add_parser(
        "field",
        help="discrepancy-vector field of two scans: field.parquet + summary.json",
        description="Bin both scans on one grid about sensor 1 and write, per voxel, the counts, means and "
        "mean2 - mean1, plus summary statistics. Grid settings: --grid YAML, then the flags below.",
    )
    p.add_argument("scan1", help="scan 1 (its sensor frame is the field's frame)")
    p.add_argument("scan2", help="scan 2")
    p.add_argument("--out", required=True, type=Path, help="output folder: field.parquet and summary.json")
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--transform", type=Path, help="pose of sensor 2 in frame 1: 4x4 / 3x4 matrix or KITTI line file"
    )
    where.add_argument(
        "--pose2",
        help="pose of sensor 2 in frame 1: x,y,z,roll,pitch,yaw (m, rad); negative first value: --pose2=-1,...",
    )
    p.add_argument("--format", help="scan file format of both scans (default: from the extension)")
    p.add_argument("--grid", type=Path, help="YAML with the grid keys (top level or under 'grid:')")
    p.add_argument("--kind", choices=("spherical", "cartesian"), help=f"grid kind (default {_default('kind')})")
    p.add_argument("--azimuth-bins", type=int, help=f"azimuth bins over 360 deg (default {_default('azimuth_bins')})")
    p.add_argument(
        "--azimuth-offset-deg", type=float, help=f"start of azimuth bin 0 (default {_default('azimuth_offset_deg')})"
    )
    p.add_argument(
        "--elevation-deg",
        type=float,
        nargs=2,
        metavar=("LO", "HI"),
        help=f"elevation range (default: the scans' sensor span, else {list(SENSORLESS_ELEVATION_DEG)}); "
        "band edges move between known channels",
    )
    p.add_argument("--elevation-bins", type=int, help=f"elevation bins (default {_default('elevation_bins')})")
    p.add_argument(
        "--range-edges-m", type=float, nargs="+", metavar="EDGE", help="range shell edges (default: none, one shell)"
    )
    p.add_argument("--cell-m", type=float, help=f"Cartesian cell size, m (default {_default('cell_m')})")
    p.add_argument(
        "--min-points", type=int, help=f"points per cloud for a valid vector (default {_default('min_points')})"
    )
    p.add_argument(
        "--max-component-m", type=float, help="invalidate vectors with a larger |u|, |v| or |w| (default off)"
    )
    p.add_argument(
        "--z-min", type=float, help=f"a vector is significant when |z| >= this (default {_default('z_min')})"
    )
    p.set_defaults(func=run)


def run(args) -> int:
    from ..commands.scans import field_of_scans

    summary = field_of_scans(
        args.scan1, args.scan2, _grid_config(args), args.out, args.format, args.transform, args.pose2
    )
    print(_table(summary))
    print(f"-> {args.out / 'field.parquet'}, {args.out / 'summary.json'}")
    return 0


def _grid_config(args) -> dict:
    """The grid section: the --grid YAML (top level or under 'grid:'), overridden by flags."""
    config: dict = {}
    if args.grid is not None:
        loaded = read_yaml(args.grid, "grid")
        if isinstance(loaded, dict) and isinstance(loaded.get("grid"), dict):
            loaded = loaded["grid"]
        if not isinstance(loaded, dict):
            raise ConfigError("expected a mapping of grid keys (kind, azimuth_bins, ...)", args.grid)
        config.update(loaded)
    for flag, key in _GRID_FLAGS.items():
        value = getattr(args, flag)
        if value is not None:
            config[key] = list(value) if isinstance(value, list) else value
    return config


def _p(value) -> str:
    return "n/a" if value is None else f"{value:.3f}"


def _table(summary: dict) -> str:
    s = summary["statistics"]
    t = s["rigid_translation_m"]
    rows = [
        ("points", f"{summary['n1']:,} / {summary['n2']:,}"),
        ("out of grid", f"{summary['out_of_grid1']:,} / {summary['out_of_grid2']:,}"),
        ("voxels (valid)", f"{s['voxels']} ({s['voxels_valid']})"),
        (
            "magnitude max / mean / p95",
            f"{s['max_magnitude']:.4f} / {s['mean_magnitude']:.4f} / {s['p95_magnitude']:.4f} m",
        ),
        ("paper max metric", f"{s['paper_max_metric']:.4f} m"),
        (
            "rigid part",
            f"t = ({t[0]:+.4f}, {t[1]:+.4f}, {t[2]:+.4f}) m, {s['rigid_rotation_deg']:.4f} deg, "
            f"energy share {s['rigid_energy_share']:.3f}",
        ),
        ("mean resultant length", f"{s['mean_resultant_length']:.3f}"),
        ("significant voxels", f"{s['voxels_significant']} (|z| >= {summary['z_min']:g})"),
        ("randomness", f"{s['verdict']} (p_direction {_p(s['p_direction'])}, p_coherence {_p(s['p_coherence'])})"),
    ]
    if s.get("binning"):  # a spherical grid: its edges, as moved between channels, and why
        rows.append(("grid", s["binning"]))
    if s.get("binning_warning"):
        rows.append(("grid warning", s["binning_warning"]))
    width = max(len(name) for name, _ in rows)
    return "\n".join(f"{name:<{width}}  {value}" for name, value in rows)
