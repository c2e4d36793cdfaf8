"""Rematching: does a stage's mitigation make scan matching better?

Stage k's survivors of scan 2 are registered again to those of scan 1, with each method of the
study's ``rematch`` settings, from the reference pose perturbed by seeded random offsets, and
each estimate is compared with the reference pose (the pair's truth when its scans carry poses,
otherwise the study's registration). Every stage of every pair gets the same offsets, so the
errors of two stages differ only by what the stage removed.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from ..checks import is_number
from ..errors import RegistrationError
from ..io.parquet_table import read_table
from ..poses import pose_error

log = logging.getLogger(__name__)

# The per-trial table's columns, in order.
COLUMNS = (
    "method",
    "trial",
    "start_dx_m",
    "start_dy_m",
    "start_dz_m",
    "start_rx_deg",
    "start_ry_deg",
    "start_rz_deg",
    "start_translation_m",
    "start_rotation_deg",
    "translation_error_m",
    "rotation_error_deg",
    "converged",
    "fitness",
    "seconds",
    "failure",
)
# Summary columns per method: rematch_{method}_{error}_{statistic}.
ERRORS = {"translation": ("translation_error_m", "m"), "rotation": ("rotation_error_deg", "deg")}
STATISTICS = {"median": 50, "p90": 90}


def start_offsets(trials: int, max_translation_m: float, max_rotation_deg: float, seed: int) -> np.ndarray:
    """(trials, 6) offsets: a translation (m) uniform in the ball of radius ``max_translation_m``
    and a rotation vector (rad) with a uniform axis and an angle uniform in [0, ``max_rotation_deg``]."""
    rng = np.random.default_rng(seed)
    translation = _unit_vectors(rng, trials) * (max_translation_m * np.cbrt(rng.random(trials)))[:, None]
    rotation = _unit_vectors(rng, trials) * np.radians(max_rotation_deg * rng.random(trials))[:, None]
    return np.hstack([translation, rotation])


def _unit_vectors(rng: np.random.Generator, n: int) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def perturbed(T_ref: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """``T_ref`` moved by ``offset`` (translation in frame 1, then the rotation about sensor 2),
    so that ``pose_error(perturbed(T, o), T)`` is (|o[:3]|, |o[3:]| in degrees)."""
    from scipy.spatial.transform import Rotation

    T = np.array(T_ref, dtype=np.float64)
    T[:3, 3] += offset[:3]
    T[:3, :3] = T[:3, :3] @ Rotation.from_rotvec(offset[3:]).as_matrix()
    return T


def rematch(xyz1: np.ndarray, xyz2_sensor: np.ndarray, reference: np.ndarray, settings: dict) -> dict[str, np.ndarray]:
    """The per-trial table of registering ``xyz2_sensor`` (scan 2 in its own sensor frame) to
    ``xyz1`` (frame 1) with each method of ``settings`` (the config's validated ``rematch``
    section) from ``reference`` perturbed by its seeded offsets.

    A method that cannot run (too few points, Open3D refusing the input) or whose estimate fits
    poorly gives rows with ``converged`` false and the reason in ``failure``, never an error;
    the errors of a trial where no estimate was made are NaN.
    """
    from ..registration import matching, parse_settings
    from ..registration.core import require_points, scan_match

    offsets = start_offsets(
        settings["trials"], settings["max_translation_m"], settings["max_rotation_deg"], settings["seed"]
    )
    rows = []
    for method in settings["methods"]:
        params = parse_settings({"method": method, **settings["parameters"]}).params
        clouds = matching.prepare(method, xyz1, xyz2_sensor, params)
        try:
            require_points(method, clouds)
            unusable = None
        except RegistrationError as e:
            unusable = str(e)
        for trial, offset in enumerate(offsets):
            guess = perturbed(reference, offset)
            started = time.perf_counter()
            if unusable:
                T, record = guess, {"failure": unusable, "converged": False, "fitness": 0.0}
            else:
                T, record = scan_match(method, clouds, guess, params)
            seconds = time.perf_counter() - started
            estimated = not record.get("failure") and np.isfinite(T).all()
            errors = pose_error(T, reference) if estimated else (np.nan, np.nan)
            rows.append(
                {
                    "method": method,
                    "trial": trial,
                    **dict(zip(COLUMNS[2:8], [*offset[:3], *np.degrees(offset[3:])])),
                    **dict(zip(COLUMNS[8:12], [*pose_error(guess, reference), *errors])),
                    "converged": bool(record["converged"]),
                    "fitness": float(record["fitness"]),
                    "seconds": seconds,
                    "failure": "" if record["converged"] else record.get("warning", record.get("failure", "")),
                }
            )
        log.info("rematch %s: %d trials, %s", method, len(offsets), _medians(rows[-len(offsets) :]))
    return {name: np.array([row[name] for row in rows]) for name in COLUMNS}


def _medians(rows: list[dict]) -> str:
    errors = np.array([(r["translation_error_m"], r["rotation_error_deg"]) for r in rows], dtype=float)
    if np.isnan(errors).all():
        return "no estimate"
    return f"median errors {np.nanmedian(errors[:, 0]):.4f} m, {np.nanmedian(errors[:, 1]):.4f} deg"


def summary_columns(table: dict[str, np.ndarray], methods: list[str] | None = None) -> dict[str, float | None]:
    """Per method: median and 90th percentile of both errors over the trials that gave an
    estimate, and the share of converged trials (``rematch_{method}_...`` columns)."""
    methods = methods or list(dict.fromkeys(table["method"].tolist()))
    columns: dict[str, float | None] = {}
    for method in methods:
        mine = table["method"] == method
        for error, (column, unit) in ERRORS.items():
            values = table[column][mine].astype(float)
            values = values[np.isfinite(values)]
            for statistic, q in STATISTICS.items():
                columns[f"rematch_{method}_{error}_{statistic}_{unit}"] = (
                    float(np.percentile(values, q)) if len(values) else None
                )
        columns[f"rematch_{method}_converged_share"] = float(np.mean(table["converged"][mine])) if mine.any() else None
    return columns


# The summary's rematch columns as one row per stage and method (translation errors in cm).
METHOD_COLUMNS = (
    "stage",
    "method",
    "translation_median_cm",
    "translation_p90_cm",
    "rotation_median_deg",
    "rotation_p90_deg",
    "converged",
)


def method_rows(rows: list[dict]) -> list[dict]:
    """One row per stage and method (:data:`METHOD_COLUMNS`) from summary rows that carry
    ``rematch_{method}_...`` columns; none for rows without them."""
    out = []
    for row in rows:
        methods = [
            k.removeprefix("rematch_").removesuffix("_converged_share") for k in row if k.endswith("_converged_share")
        ]
        for method in methods:
            values = {}
            for name in METHOD_COLUMNS[2:-1]:
                value = row.get(f"rematch_{method}_{name.replace('_cm', '_m')}")
                values[name] = value * 100 if name.endswith("_cm") and is_number(value, finite=True) else value
            out.append(
                {
                    "stage": row.get("stage"),
                    "method": method,
                    **values,
                    "converged": row[f"rematch_{method}_converged_share"],
                }
            )
    return out


# --- files ----------------------------------------------------------------------------------


def reference_pose(meta: dict) -> tuple[np.ndarray, str]:
    """The pose rematching is measured against, from a points file's metadata: the truth when
    the scans carried poses, otherwise the study's registration ``T_1_2``."""
    registration = meta.get("registration") or {}
    if registration.get("reference_T_1_2") is not None:
        return np.asarray(registration["reference_T_1_2"], dtype=np.float64), "truth"
    return np.asarray(meta["T_1_2"], dtype=np.float64), "registration"


def read_rematch(path: str | Path) -> tuple[dict[str, np.ndarray], dict]:
    """A ``rematch.parquet``: the per-trial table and its metadata."""
    return read_table(path, required=COLUMNS)


def rematch_row(path: str | Path) -> dict:
    """The summary columns of a stage's ``rematch.parquet`` (see :func:`summary_columns`)."""
    table, meta = read_rematch(path)
    return summary_columns(table, (meta.get("settings") or {}).get("methods"))
