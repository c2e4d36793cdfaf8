"""Registration settings: the config's ``register`` value, normalised, validated and completed
with defaults.

Accepted forms: ``"identity"``, ``"truth"``, ``{"transform": FILE}`` and
``{"method": M, "guess": ..., <parameters>}`` with ``M`` one of :data:`METHODS`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..checks import is_number
from ..errors import ConfigError, InputError
from ..io.pose_files import read_pose
from ..poses import parse_pose_arg

FIXED_METHODS = ("identity", "truth", "transform")
MATCHING_METHODS = ("icp", "icp_point_to_plane", "gicp", "ndt")
METHODS = FIXED_METHODS + MATCHING_METHODS

# Defaults for automotive scans (10^4..10^5 points, scenes tens of metres across, sensors
# moving under a metre or so between scans once the guess is applied); docs/registration.md explains each.
DEFAULTS = {
    "voxel_m": 0.2,  # downsampling of both clouds (NDT: of scan 2 only; it models scan 1 itself) ...
    "voxel_deg": 1.0,  # ... by voxels no wider than this seen from the pair's median range
    "min_range_m": 0.0,  # drop points nearer than this to their sensor (e.g. the ego vehicle)
    "max_correspondence_m": 1.0,  # ICP family: pairs farther apart are ignored
    "max_iterations": 50,  # per stage
    "relative_fitness": 1e-6,  # ICP family: stop when fitness and RMSE change less than this
    "relative_rmse": 1e-6,
    "normal_radius_m": 1.0,  # normals / covariances from neighbours within this radius ...
    "normal_max_nn": 30,  # ... and at most this many of them
    "gicp_epsilon": 1e-3,  # GICP covariance regularisation
    "ndt_resolution_m": [2.0, 1.0],  # NDT cell sizes, coarse to fine (one NDT run per size)
    "ndt_min_points_per_voxel": 6,
    "ndt_outlier_threshold": 9.0,  # squared Mahalanobis distance beyond which a residual is ignored
    "fitness_distance_m": 0.5,  # fitness = share of scan-2 points with a scan-1 point this near
    "min_fitness": 0.5,  # below it the registration is reported as not converged
}
_MATCHING_KEYS = {"method", "guess", *DEFAULTS}


@dataclass
class RegistrationSettings:
    method: str
    guess: np.ndarray | str = field(default_factory=lambda: np.eye(4))  # 4x4, or "truth"
    transform_file: Path | None = None
    params: dict = field(default_factory=lambda: dict(DEFAULTS))
    guess_given: object = None  # the guess as the settings wrote it (numbers, file name, "truth")


def parse_settings(settings, base_dir: str | Path | None = None) -> RegistrationSettings:
    """Normalise a ``register`` value; relative file names are taken from ``base_dir``."""
    base = Path(base_dir) if base_dir is not None else Path()
    if isinstance(settings, str):
        settings = {"method": settings}
    if not isinstance(settings, dict):
        raise ConfigError(f"register: expected a method name or a mapping, got {settings!r}")
    settings = dict(settings)
    if "transform" in settings:
        extra = sorted(set(settings) - {"transform", "method"})
        if extra or settings.get("method", "transform") != "transform":
            raise ConfigError(f"register: 'transform' takes no other settings, got {extra or settings['method']}")
        return RegistrationSettings("transform", transform_file=base / str(settings["transform"]))
    method = settings.get("method")
    if method not in METHODS:
        raise ConfigError(f"register: unknown method {method!r}; methods: {', '.join(METHODS)}")
    if method == "transform":
        raise ConfigError("register: method 'transform' needs {transform: FILE}")
    unknown = sorted(set(settings) - (_MATCHING_KEYS if method in MATCHING_METHODS else {"method"}))
    if unknown:
        known = ", ".join(sorted(_MATCHING_KEYS - {"method"})) if method in MATCHING_METHODS else "none"
        raise ConfigError(f"register: unknown setting(s) {unknown} for method {method!r}; known: {known}")
    params = dict(DEFAULTS)
    params.update({k: v for k, v in settings.items() if k in DEFAULTS})
    _check_params(params)
    given = settings.get("guess")
    return RegistrationSettings(method, _guess(given, base), params=params, guess_given=given)


def _guess(value, base: Path) -> np.ndarray | str:
    """4x4 guess from: None (identity), "truth", a pose file, or 6 / 12 / 16 numbers."""
    if value is None:
        return np.eye(4)
    if isinstance(value, str):
        if value in ("truth", "reference"):
            return "truth"
        return read_pose(base / value)
    try:
        numbers = np.asarray(value, dtype=np.float64).ravel()
        return parse_pose_arg(",".join(repr(float(v)) for v in numbers))
    except (ValueError, TypeError, InputError) as e:
        raise ConfigError(f"register.guess: {e}") from None


def _check_params(params: dict) -> None:
    positive = ("voxel_m", "max_correspondence_m", "normal_radius_m", "fitness_distance_m")
    for key in positive:
        if not is_number(params[key], finite=True) or params[key] < 0 or (params[key] == 0 and key != "voxel_m"):
            raise ConfigError(
                f"register.{key}: expected a positive number (voxel_m may be 0: no downsampling), got {params[key]!r}"
            )
    if not is_number(params["voxel_deg"], finite=True) or params["voxel_deg"] <= 0:
        raise ConfigError(f"register.voxel_deg: expected a positive number, got {params['voxel_deg']!r}")
    for key in ("max_iterations", "normal_max_nn"):
        if not isinstance(params[key], int) or params[key] < 1:
            raise ConfigError(f"register.{key}: expected a positive integer, got {params[key]!r}")
    if not isinstance(params["ndt_min_points_per_voxel"], int) or params["ndt_min_points_per_voxel"] < 4:
        raise ConfigError("register.ndt_min_points_per_voxel: expected an integer >= 4 (Open3D's minimum)")
    resolution = params["ndt_resolution_m"]
    resolution = [resolution] if is_number(resolution, finite=True) else resolution
    if (
        not isinstance(resolution, list)
        or not resolution
        or not all(is_number(r, finite=True) and r > 0 for r in resolution)
    ):
        raise ConfigError(
            f"register.ndt_resolution_m: expected a positive number or a list of them, got {resolution!r}"
        )
    params["ndt_resolution_m"] = [float(r) for r in resolution]
    for key in ("min_range_m", "relative_fitness", "relative_rmse", "gicp_epsilon", "ndt_outlier_threshold"):
        if not is_number(params[key], finite=True) or params[key] < 0:
            raise ConfigError(f"register.{key}: expected a non-negative number, got {params[key]!r}")
    if not is_number(params["min_fitness"], finite=True) or not 0 <= params["min_fitness"] <= 1:
        raise ConfigError(f"register.min_fitness: expected a number in [0, 1], got {params['min_fitness']!r}")
