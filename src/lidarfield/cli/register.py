"""``lidarfield register``: scan 2 in scan 1's frame (registered.parquet), or the translation of
an aligned copy of a scan (``--from-aligned``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..registration.settings import DEFAULTS

_PARAMETER_FLAGS = ("voxel_m", "max_correspondence_m", "max_iterations", "min_fitness", "min_range_m")


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "register",
        help="express scan 2 in scan 1's frame (identity, truth, transform file, ICP/GICP/NDT)",
        description="Register SCAN2 to SCAN1 and write the registered pair (both clouds in frame 1, T_1_2 and "
        "the registration's fitness in the metadata). With --from-aligned ORIGINAL ALIGNED, write instead "
        "the pure translation that maps ORIGINAL onto its aligned copy, row for row, as a 4x4 text pose.",
    )
    p.add_argument("scans", nargs="*", metavar="SCAN", help="SCAN1 SCAN2 (a file, or file#k for scan k of a container)")
    p.add_argument("--out", required=True, type=Path, help="registered.parquet, or T.txt with --from-aligned")
    p.add_argument(
        "--from-aligned",
        nargs=2,
        type=Path,
        metavar=("ORIGINAL", "ALIGNED"),
        help="derive the translation ORIGINAL -> ALIGNED (row-aligned x y z text files)",
    )
    p.add_argument(
        "--method",
        default="identity",
        choices=("identity", "truth", "icp", "icp_point_to_plane", "gicp", "ndt"),
        help="registration method (default identity)",
    )
    p.add_argument("--transform", type=Path, help="fixed pose of sensor 2 in frame 1 (4x4 / 3x4 / KITTI file)")
    guess = p.add_mutually_exclusive_group()
    guess.add_argument(
        "--guess",
        help="initial T_1_2: x,y,z,roll,pitch,yaw (m, rad) or 16 numbers; "
        "negative first value: --guess=-1,...; 'truth' = the scans' reference poses",
    )
    guess.add_argument("--guess-file", type=Path, help="initial T_1_2 from a pose file")
    p.add_argument("--pose1", help="world-from-sensor pose of scan 1: a pose file, or FILE#k for KITTI line k")
    p.add_argument("--pose2", help="world-from-sensor pose of scan 2 (same forms)")
    p.add_argument("--format", help="scan file format of both scans (default: from the extension)")
    p.add_argument("--sensor", help="sensor model of both scans (preset name or YAML)")
    p.add_argument("--voxel-m", type=float, help=f"downsampling voxel, m (default {DEFAULTS['voxel_m']:g})")
    p.add_argument(
        "--max-correspondence-m",
        type=float,
        help=f"ICP/GICP pair distance limit, m (default {DEFAULTS['max_correspondence_m']:g})",
    )
    p.add_argument("--max-iterations", type=int, help=f"iterations per stage (default {DEFAULTS['max_iterations']})")
    p.add_argument(
        "--min-fitness",
        type=float,
        help=f"fitness below which it is not converged (default {DEFAULTS['min_fitness']:g})",
    )
    p.add_argument(
        "--min-range-m", type=float, help=f"ignore points nearer their sensor, m (default {DEFAULTS['min_range_m']:g})"
    )
    p.set_defaults(func=run)


def run(args) -> int:
    if args.from_aligned:
        if args.scans:
            raise InputError("--from-aligned takes no SCAN arguments")
        return _from_aligned(*args.from_aligned, args.out)
    if len(args.scans) != 2:
        raise InputError(f"expected SCAN1 SCAN2, got {len(args.scans)} scan argument(s)")
    from ..commands.scans import register_scans

    poses = [_pose_spec(spec) if spec else None for spec in (args.pose1, args.pose2)]
    pair = register_scans(*args.scans, _settings(args), args.out, args.format, args.sensor, poses)
    _print_registration(pair)
    print(f"wrote {args.out}")
    return 0


def _settings(args):
    if args.transform:
        if args.method != "identity" or args.guess or args.guess_file:
            raise InputError("--transform replaces --method and --guess: give one or the other")
        return {"transform": str(args.transform)}
    settings = {"method": args.method}
    if args.guess or args.guess_file:
        if args.method in ("identity", "truth"):
            raise InputError(f"--guess applies to scan matching, not to --method {args.method}")
        settings["guess"] = str(args.guess_file) if args.guess_file else _guess_arg(args.guess)
    for key in _PARAMETER_FLAGS:
        value = getattr(args, key)
        if value is not None:
            settings[key] = value
    return settings


def _guess_arg(text: str):
    from ..poses import parse_pose_arg

    return "truth" if text.strip() in ("truth", "reference") else parse_pose_arg(text).ravel().tolist()


def _pose_spec(spec: str) -> np.ndarray:
    from ..io.pose_files import read_pose

    path, _, line = spec.partition("#")
    if line and not line.isdigit():
        raise InputError(f"pose {spec!r}: expected FILE or FILE#k with k a line number from 0")
    return read_pose(path, int(line) if line else 0)


def _print_registration(pair) -> None:
    from ..poses import xyzrpy_from_pose

    reg = pair.registration
    x, y, z, _, _, yaw = xyzrpy_from_pose(pair.T_1_2)
    rmse = "none" if reg["inlier_rmse"] is None else f"{reg['inlier_rmse']:.4f} m"
    print(
        f"method {reg['method']}: converged {reg['converged']}, fitness {reg['fitness']:.4f} "
        f"(within {reg['fitness_distance_m']} m), inlier RMSE {rmse}"
    )
    print(f"T_1_2: translation ({x:.4f}, {y:.4f}, {z:.4f}) m, yaw {np.degrees(yaw):.4f} deg")
    if "translation_error_m" in reg:
        print(f"against the reference poses: {reg['translation_error_m']:.4f} m, {reg['rotation_error_deg']:.4f} deg")
    if reg.get("warning"):
        print(f"WARNING: {reg['warning']}")


def _from_aligned(original: Path, aligned: Path, out: Path) -> int:
    from ..commands.scans import transform_from_aligned

    T, offsets, spread = transform_from_aligned(original, aligned, out)
    print(f"translation {T[:3, 3].tolist()} m from {len(offsets)} rows; spread {spread:.3g} m")
    print(f"wrote {out}")
    return 0
