"""``lidarfield simulate``: ray-cast one scan of a scene and write it as scan Parquet."""

from __future__ import annotations

from ..defaults import default
from ..errors import ConfigError


def _numbers(text: str, count: int, what: str) -> list[float]:
    """Comma-separated numbers, checked here (not by argparse) so that a mistake is one line."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise ConfigError(f"{what}: not numbers: {text!r}") from None
    if len(values) != count:
        raise ConfigError(f"{what} needs {count} comma-separated values, got {len(values)}: {text!r}")
    return values


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("simulate", help="ray-cast one scan of a scene at a pose")
    p.add_argument("--scene", required=True, help="built-in scene name (e.g. paper-intersection) or a scene YAML")
    p.add_argument(
        "--sensor", required=True, help="sensor preset (paper-sim-80, vlp16, hdl32, hdl64, os1-128) or a YAML model"
    )
    p.add_argument(
        "--pose",
        required=True,
        help="x,y,z,roll,pitch,yaw (m, rad): world-from-sensor at the sweep start (negative first value: "
        "--pose=-1,...)",
    )
    p.add_argument("--out", required=True, help="output scan Parquet")
    p.add_argument("--time", type=float, default=0.0, help="scene time in seconds: places moving objects (default 0)")
    seed, noise, dropout = (default("simulation_options", key) for key in ("seed", "range_noise_m", "dropout"))
    p.add_argument("--seed", type=int, default=seed, help=f"seed of the noise and dropout (default {seed})")
    p.add_argument(
        "--range-noise",
        type=float,
        default=noise,
        metavar="M",
        help=f"Gaussian range noise sigma, m (default {noise:g})",
    )
    p.add_argument(
        "--dropout",
        type=float,
        default=dropout,
        metavar="P",
        help=f"probability of losing each return (default {dropout:g})",
    )
    p.add_argument(
        "--max-range",
        type=float,
        default=None,
        metavar="M",
        help="range limit below the model's (default: the model's)",
    )
    p.add_argument("--rolling-shutter", action="store_true", help="move the sensor during the sweep")
    p.add_argument("--velocity", default="0,0,0", help="vx,vy,vz m/s, world frame (rolling shutter)")
    p.add_argument("--angular-velocity", default="0,0,0", help="wx,wy,wz rad/s, sensor frame (rolling shutter)")
    scale, offset = (default("simulation_options", key) for key in ("range_scale", "range_offset_m"))
    p.add_argument(
        "--range-scale",
        default=str(scale),
        metavar="S",
        help=f"calibration fault: measured range = S * true range + M (default {scale:g})",
    )
    p.add_argument(
        "--range-offset",
        default=str(offset),
        metavar="M",
        help=f"calibration fault: range offset, m (default {offset:g})",
    )
    p.add_argument(
        "--elevation-offsets",
        default=None,
        metavar="A,B,...",
        help="calibration fault: one offset per beam (deg); beam k fires at its elevation + offset k but is "
        "reported at its nominal elevation (default: none; negative first value: --elevation-offsets=-0.1,...)",
    )
    p.set_defaults(func=run)


def run(args) -> int:
    from ..io import write_scan
    from ..poses import pose_from_xyzrpy
    from ..sensors.models import sensor_model
    from ..simulation.raycast import simulate_scan
    from ..simulation.scene import load_scene

    pose = pose_from_xyzrpy(_numbers(args.pose, 6, "--pose"))
    velocity = _numbers(args.velocity, 3, "--velocity")
    angular_velocity = _numbers(args.angular_velocity, 3, "--angular-velocity")
    moving = any(velocity) or any(angular_velocity)
    if moving and not args.rolling_shutter:
        raise ConfigError("--velocity/--angular-velocity need --rolling-shutter")
    range_scale = _numbers(args.range_scale, 1, "--range-scale")[0]
    range_offset = _numbers(args.range_offset, 1, "--range-offset")[0]
    sensor = sensor_model(args.sensor)
    offsets = None
    if args.elevation_offsets is not None:
        offsets = _numbers(args.elevation_offsets, sensor.channels, f"--elevation-offsets (sensor {sensor.name})")
    scan = simulate_scan(
        load_scene(args.scene),
        sensor,
        pose,
        time_s=args.time,
        seed=args.seed,
        range_noise_m=args.range_noise,
        dropout=args.dropout,
        max_range_m=args.max_range,
        rolling_shutter=args.rolling_shutter,
        linear_velocity_mps=velocity,
        angular_velocity_rps=angular_velocity,
        range_scale=range_scale,
        range_offset_m=range_offset,
        elevation_offsets_deg=offsets,
    )
    write_scan(scan, args.out)
    print(f"{len(scan)} points -> {args.out}")
    return 0
