"""``register_pair``: express scan 2 in scan 1's sensor frame and record how well that went."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import RegistrationError
from ..io.pose_files import read_pose
from ..pair import RegisteredPair
from ..poses import apply_pose, pose_error, relative_pose
from ..scan import Scan
from ..sensors.fit import sensor_fit
from .settings import MATCHING_METHODS, RegistrationSettings, parse_settings

if TYPE_CHECKING:  # Open3D: imported where a pair is matched, not by config checks
    from . import matching

# Fewer points than this after downsampling cannot constrain six degrees of freedom robustly.
_MIN_POINTS = 10


def register_pair(
    scan1: Scan, scan2: Scan, settings: str | dict = "identity", base_dir: str | Path | None = None
) -> RegisteredPair:
    """Scan 2 expressed in scan 1's frame, with ``T_1_2`` (pose of sensor 2 in frame 1).

    ``settings`` is the config's ``register`` value (see :mod:`.settings`). The pair's
    ``registration`` metadata holds the method, fitness, inlier RMSE, ``converged`` and, when
    both scans carry world-from-sensor poses, the error against their relative pose. A scan
    matching that fails or fits poorly is not an exception: ``converged`` is False and
    ``warning`` says why. Relative file names in ``settings`` are taken from ``base_dir``.
    """
    from . import matching  # Open3D: imported by the jobs that register, not by config checks

    s = parse_settings(settings, base_dir)
    reference = _reference(scan1, scan2)
    p = s.params
    clouds = matching.prepare(s.method, scan1.xyz, scan2.xyz, p)
    if s.method in MATCHING_METHODS:
        guess = _require_reference(reference, scan1, scan2, "guess 'truth'") if isinstance(s.guess, str) else s.guess
        require_points(s.method, clouds)
        T, record = scan_match(s.method, clouds, guess, p)
        record.update(guess=s.guess_given, guess_T_1_2=np.asarray(guess).tolist(), parameters=dict(p))
    else:
        T = _fixed_transform(s, scan1, scan2, reference)
        record = {"method": s.method}
        if s.method == "transform":
            record["transform_file"] = str(s.transform_file)
        _judge(record, clouds, T, p, matched=False)
    record["points_used"] = [len(clouds.target.points), len(clouds.source.points)]
    record["voxel_used_m"] = clouds.voxel_m
    if reference is not None:
        translation_error, rotation_error = pose_error(T, reference)
        record.update(translation_error_m=translation_error, rotation_error_deg=rotation_error)
        record["reference_T_1_2"] = reference.tolist()
        record["reference_exact"] = scan1.simulated and scan2.simulated  # the simulation's truth
    return RegisteredPair(
        scan1.xyz,
        apply_pose(T, scan2.xyz),
        T,
        scan1.sensor,
        scan2.sensor,
        dict(scan1.attributes),
        dict(scan2.attributes),
        record,
        {"1": sensor_fit(scan1.xyz, scan1.sensor), "2": sensor_fit(scan2.xyz, scan2.sensor)},
        {str(k): sweep_record(scan) for k, scan in ((1, scan1), (2, scan2)) if sweep_record(scan)},
        scan1.lidars,
        scan2.lidars,
    )


def sweep_record(scan: Scan) -> dict:
    """What a scan recorded of when and how it was taken (``RegisteredPair.sweeps``)."""
    return {
        key: value
        for key, value in (("stamp_s", scan.stamp_s), ("sweep_motion", scan.sweep_motion))
        if value is not None
    }


def _reference(scan1: Scan, scan2: Scan) -> np.ndarray | None:
    if scan1.pose is None or scan2.pose is None:
        return None
    return relative_pose(scan1.pose, scan2.pose)


def _require_reference(reference, scan1: Scan, scan2: Scan, what: str) -> np.ndarray:
    if reference is None:
        missing = [s.source or f"scan {k}" for k, s in ((1, scan1), (2, scan2)) if s.pose is None]
        raise RegistrationError(
            f"{what} needs the world-from-sensor pose of both scans; missing for {', '.join(missing)}"
        )
    return reference


def _fixed_transform(s: RegistrationSettings, scan1: Scan, scan2: Scan, reference) -> np.ndarray:
    if s.method == "identity":
        return np.eye(4)
    if s.method == "truth":
        return _require_reference(reference, scan1, scan2, "registration 'truth'")
    return read_pose(s.transform_file)


def require_points(method: str, clouds: matching.Clouds) -> None:
    """Raise ``RegistrationError`` when a cloud is too small to constrain a pose."""
    for k, cloud in ((1, clouds.target), (2, clouds.source)):
        if len(cloud.points) < _MIN_POINTS:
            raise RegistrationError(
                f"{method}: scan {k} has {len(cloud.points)} point(s) after min_range_m and voxel_m: too few to match"
            )


def scan_match(method: str, clouds: matching.Clouds, guess: np.ndarray, p: dict) -> tuple[np.ndarray, dict]:
    """One scan matching of scan 2 to scan 1 from ``guess``: the estimate of ``T_1_2`` and its
    record (``failure`` when Open3D did not run, ``fitness``, ``inlier_rmse``, ``converged``,
    ``warning``). A failure or a poor fit is recorded, never raised."""
    from . import matching

    result = matching.match(method, clouds, guess, p)
    record: dict = {"method": method}
    if result.failure:
        record["failure"] = f"Open3D refused the input: {result.failure}"
    elif np.array_equal(result.T, guess):
        # Open3D's NDT returns its guess untouched when too few residuals survive (cells
        # too small for the data); a good guess would then pass the fitness check unnoticed.
        record["failure"] = "Open3D returned the guess unchanged: no iteration took place"
    _judge(record, clouds, result.T, p, matched=True)
    return result.T, record


def _judge(record: dict, clouds: matching.Clouds, T: np.ndarray, p: dict, matched: bool) -> None:
    """Measure the fitness of ``T``, and set ``converged`` and ``warning`` from the fitness and
    the estimate.

    Converged means: the estimate is a finite rigid pose and the fitness reaches
    ``min_fitness``, and, for scan matching, Open3D ran and left its guess. Open3D 0.20 does
    not report iteration counts or whether its own stopping criteria were met, so these are
    the checks available.
    """
    from . import matching

    fitness, rmse = matching.evaluate(clouds.scored_source, clouds.scored_target, T, p["fitness_distance_m"])
    record.update(fitness=fitness, inlier_rmse=rmse, fitness_distance_m=p["fitness_distance_m"])
    record["min_fitness"] = p["min_fitness"]
    problems = []
    if record.get("failure"):
        problems.append(f"{record['failure']}; T_1_2 is the guess")
    if not np.isfinite(T).all() or abs(np.linalg.det(T[:3, :3]) - 1) > 1e-6:
        problems.append("the estimate is not a finite rigid pose")
    if not record["fitness"] >= record["min_fitness"]:
        problems.append(
            f"poor fitness {record['fitness']:.3f} < min_fitness {record['min_fitness']} "
            f"(share of scan-2 points within {record['fitness_distance_m']} m of scan 1)"
        )
    # A fixed transform has nothing to iterate, but one that fits poorly (a zero-overlap pair:
    # fitness 0) is no more a converged registration than a scan matching that fits poorly.
    record["converged"] = not problems
    if matched and problems:
        problems.insert(0, f"{record['method']} did not converge")
    if problems:
        record["warning"] = "; ".join(problems)
