"""Does a scan fit its sensor model? The share of its points outside the model's elevation and
range limits, measured at ingest.

A wrong model (``os1-128``, +-22.5 deg, for a +-45 deg sensor) would otherwise show only as a
``field_of_view`` stage that removes half of every scan. Real sensors stray a little past
their nominal beam angles (per-unit calibration) and, now and then, past their datasheet
range, so an elevation within ``ELEVATION_TOLERANCE_DEG`` of the limits counts as inside and a
scan is reported only when more than ``MAX_SHARE_OUTSIDE`` of its points are outside.
"""

from __future__ import annotations

import logging

import numpy as np

from .models import SensorModel

log = logging.getLogger(__name__)

ELEVATION_TOLERANCE_DEG = 1.0
MAX_SHARE_OUTSIDE = 0.01


def sensor_fit(xyz: np.ndarray, model: SensorModel | None) -> dict | None:
    """How the points (sensor frame) sit against the model's limits; None without a model.

    ``outside`` is the share of points outside either limit; ``outside_elevation`` and
    ``outside_range`` that of each, with the data's extent beside the model's."""
    if model is None or len(xyz) == 0:
        return None
    xyz = np.asarray(xyz, dtype=np.float64)
    horizontal = np.hypot(xyz[:, 0], xyz[:, 1])
    elevation = np.degrees(np.arctan2(xyz[:, 2], horizontal))
    distance = np.sqrt(horizontal**2 + xyz[:, 2] ** 2)
    lo, hi = model.elevation_limits_deg
    off_elevation = (elevation < lo - ELEVATION_TOLERANCE_DEG) | (elevation > hi + ELEVATION_TOLERANCE_DEG)
    off_range = (distance < model.min_range_m) | (distance > model.max_range_m)
    return {
        "sensor": model.name,
        "points": int(len(xyz)),
        "outside": float(np.mean(off_elevation | off_range)),
        "outside_elevation": float(np.mean(off_elevation)),
        "outside_range": float(np.mean(off_range)),
        "elevation_deg": [float(elevation.min()), float(elevation.max())],
        "model_elevation_deg": [lo, hi],
        "range_m": [float(distance.min()), float(distance.max())],
        "model_range_m": [model.min_range_m, model.max_range_m if np.isfinite(model.max_range_m) else None],
    }


def fit_warning(fit: dict | None, scan: str) -> str:
    """One sentence when more than ``MAX_SHARE_OUTSIDE`` of the scan's points are outside its
    model's limits ('' otherwise), with the data's extent against the model's."""
    if fit is None or fit["outside"] <= MAX_SHARE_OUTSIDE:
        return ""
    parts = []
    if fit["outside_elevation"] > 0:
        (lo, hi), (model_lo, model_hi) = fit["elevation_deg"], fit["model_elevation_deg"]
        parts.append(
            f"{fit['outside_elevation']:.1%} outside its elevation limits "
            f"(data {lo:.1f} to {hi:.1f} deg, model {model_lo:.1f} to {model_hi:.1f} deg)"
        )
    if fit["outside_range"] > 0:
        (near, far), (model_near, model_far) = fit["range_m"], fit["model_range_m"]
        model_far = "inf" if model_far is None else f"{model_far:g}"
        parts.append(
            f"{fit['outside_range']:.1%} outside its range limits "
            f"(data {near:.2f} to {far:.1f} m, model {model_near:g} to {model_far} m)"
        )
    return (
        f"{scan}: {fit['outside']:.1%} of the points do not fit sensor model {fit['sensor']!r}: "
        + " and ".join(parts)
        + ": is it the right sensor?"
    )


def log_fit(xyz: np.ndarray, model: SensorModel | None, name: str) -> None:
    """At ingest: a warning in the log when the scan ``name`` does not fit its sensor model."""
    warning = fit_warning(sensor_fit(xyz, model), name)
    if warning:
        log.warning(warning)
