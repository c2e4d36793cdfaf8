"""``elevation_calibration``: fit the elevation offset of the lasers of one cloud that are off, and apply it.

A correcting hypothesis: it removes nothing, and turns the points of the chosen lasers of the
chosen cloud (``cloud``, 1 or 2) about their own lidar, at their range and azimuth. The model is
a per-laser elevation calibration error: laser ``c`` of a spinning lidar reports its returns at
elevation ``e_true + delta_c`` (each laser's elevation angle is calibrated at the factory; a
laser knocked or mis-tabled reports every return of its ring higher or lower). A point at range
``r``, azimuth ``a``, elevation ``e`` about its lidar (its own lidar's frame, in a multi-lidar
scan) is corrected to elevation ``e - delta_c`` at the same ``r`` and ``a``. The lasers are
``range_calibration.cloud_channels``'s: the cloud's ``ring`` attribute, else the channel of its
lidar's model nearest the point's elevation; a rig's lidars numbered one after another.

The fit pairs a sample of at most ``max_points`` points of the cloud (evenly spaced rows) with
the nearest point ``q`` of the other cloud and its normal ``n`` (``range_calibration``'s pairing
and normals), as ``range_calibration`` does. The point-to-plane residual
``n . (p(delta_c) - q)`` of a point of laser ``c`` changes with ``delta_c`` by ``-n . t`` per
radian, ``t = r de`` the point's elevation tangent (``r`` times the unit vector of rising
elevation): every laser's offset has its own residuals, so the normal equations are diagonal,
one weighted mean per laser.

*The screen* (what makes it cheap, and what keeps it off a fault-free pair): one Gauss-Newton
step from 0 for every laser with at least ``MIN_LASER_POINTS`` pairs gives its offset
``delta_c`` and standard error ``se_c``. A laser is fitted only when it is off the other cloud's
surfaces by both measures: ``|delta_c| >= screen_z * se_c`` (its own points are off, beyond
their noise) and ``|delta_c - median| >= screen_z * 1.4826 MAD`` of the lasers' offsets (it is
off where its neighbours are not: a misregistration, a range error or a warped surface moves
every laser's residuals alike, and one laser's elevation error moves its own). The screened
lasers' offsets are then iterated, pairing the corrected sample anew with Huber weights
(k = 1.345 MAD), until no corrected point of the sample moves by more than 0.1 mm (or
``max_iterations``); the other lasers are not changed. A cloud none of whose lasers passes
moves nothing (``parameters`` 0): "what to try next" sees no reduction, and ``explain`` does
not propose it.

What it records (the stage's ``correction``): ``cloud``, ``lasers`` (how many were screened),
``laser_offsets_deg`` and ``laser_offsets_se_deg`` (by laser, as text, the fitted ones only),
``points`` (pairs of the fitted lasers in the last solve), ``residual_rms_m`` and ``sigma_m``
(their point-to-plane residuals' RMS and the weighted standard deviation), ``iterations``,
``converged`` (false where ``max_iterations`` stopped it first) and ``parameters`` (the number
of lasers fitted). The standard errors are ``sigma^2 / sum w (n . t)^2``
of the last solve per laser; like ``range_calibration``'s they treat neighbouring residuals as
independent: read them as lower bounds.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import HypothesisError
from ..pair import RegisteredPair
from ..poses import apply_pose, in_sensor_frame
from .outcome import Outcome
from .params import doc
from .range_calibration import (
    TOLERANCE_M,
    PlaneFit,
    _huber,
    check_clouds,
    check_overlap,
    cloud_channels,
    evenly_spaced,
    planes_of,
)

NAME = "elevation_calibration"
MIN_LASER_POINTS = 30  # a laser's own offset needs this many pairs
MAD_SCALE = 1.4826  # the MAD of a normal distribution times this is its standard deviation


@dataclass(frozen=True)
class Params(PlaneFit):
    screen_z: float = field(
        default=5.0,
        metadata=doc(
            "a laser is fitted when its one-step offset is this many standard errors from 0 and this many "
            "robust spreads of the lasers' offsets from their median"
        ),
    )
    max_offset_deg: float = field(
        default=3.0, metadata=doc("a fitted offset larger than this is no elevation calibration (an error, deg)")
    )

    def __post_init__(self):
        super().__post_init__()
        if not self.screen_z > 0 or not self.max_offset_deg > 0:
            raise ValueError(f"need screen_z > 0 and max_offset_deg > 0, got {self.screen_z} and {self.max_offset_deg}")


def elevation_calibration(pair: RegisteredPair, params: Params) -> Outcome:
    """The chosen cloud's off lasers turned back by their fitted elevation offsets; nothing removed."""
    xyz, other = (pair.xyz2, pair.xyz1) if params.cloud == 2 else (pair.xyz1, pair.xyz2)
    check_clouds(NAME, params, xyz, other)
    laser = cloud_channels(pair, params.cloud, NAME)
    views = pair.lidars(params.cloud)
    lidar = lidar_index(views, len(xyz))
    candidates = evenly_spaced(np.arange(len(xyz)), params.max_points)
    sample, sample_laser, sample_lidar = xyz[candidates], laser[candidates], lidar[candidates]
    planes = planes_of(other, params.normal_k)

    def pairs(points: np.ndarray, rows: np.ndarray):
        """The ``rows`` of ``points`` paired with a plane of the other cloud: those rows,
        ``a = -n . t`` (the residual's change per radian of offset) and the residual ``y``."""
        use, n, q = planes.pair(points[rows], params.max_correspondence_m)
        rows = rows[use]
        t = elevation_tangents(points[rows], sample_lidar[rows], views)
        return rows, -np.einsum("ij,ij->i", n, t), np.einsum("ij,ij->i", n, points[rows] - q)

    rows, a, y = pairs(sample, np.arange(len(sample)))
    check_overlap(NAME, params, len(rows))
    lasers, step, se, _ = laser_steps(sample_laser[rows], a, y, _huber(y))
    chosen = lasers[screened(step, se, params.screen_z)]
    fitted = {"cloud": params.cloud, "lasers": len(lasers), "method": "point_to_plane_huber"}
    keep1, keep2 = np.ones(len(pair.xyz1), dtype=bool), np.ones(len(pair.xyz2), dtype=bool)
    if len(chosen) == 0:  # no laser off: nothing to correct
        return Outcome(keep1, keep2, fitted={**fitted, "laser_offsets_deg": {}, "parameters": 0})

    in_fit = np.flatnonzero(np.isin(sample_laser, chosen))
    origins = np.broadcast_to(pair.point_origins(params.cloud), xyz.shape)[candidates]
    r_max = float(np.linalg.norm(sample[in_fit] - origins[in_fit], axis=1).max())
    delta, se_of = np.zeros(len(chosen)), np.full(len(chosen), np.nan)
    iterations, converged = 0, False
    while iterations < params.max_iterations and not converged:
        iterations += 1
        corrected = sample.copy()
        at = np.searchsorted(chosen, sample_laser[in_fit])
        corrected[in_fit] = turned(sample[in_fit], sample_lidar[in_fit], views, delta[at])
        rows, a, y = pairs(corrected, in_fit)
        weight = _huber(y)
        found, change, se_found, sigma = laser_steps(sample_laser[rows], a, y, weight)
        increment = np.zeros(len(chosen))
        increment[np.searchsorted(chosen, found)] = change
        se_of[:] = np.nan
        se_of[np.searchsorted(chosen, found)] = se_found
        delta += increment
        converged = bool(np.abs(increment).max() * r_max < TOLERANCE_M)
    if np.degrees(np.abs(delta)).max() > params.max_offset_deg:
        raise HypothesisError(
            f"{NAME}: the fit (offset {np.degrees(np.abs(delta)).max():.3g} deg) is beyond an elevation "
            f"calibration's bound (max_offset_deg {params.max_offset_deg:g}): the discrepancy is not a laser's "
            "elevation"
        )
    residual = y + a * increment[np.searchsorted(chosen, sample_laser[rows])]
    fitted |= {
        "laser_offsets_deg": {str(int(c)): float(np.degrees(d)) for c, d in zip(chosen, delta)},
        "laser_offsets_se_deg": {str(int(c)): _number(np.degrees(e)) for c, e in zip(chosen, se_of)},
        "points": len(residual),
        "residual_rms_m": float(np.sqrt(np.mean(residual**2))),
        "sigma_m": sigma,
        "iterations": iterations,
        "converged": converged,
        "parameters": len(chosen),
    }
    moved = np.flatnonzero(np.isin(laser, chosen))
    new_xyz = xyz.copy()
    new_xyz[moved] = turned(xyz[moved], lidar[moved], views, delta[np.searchsorted(chosen, laser[moved])])
    if params.cloud == 2:
        return Outcome(keep1, keep2, xyz2=new_xyz, fitted=fitted)
    return Outcome(keep1, keep2, xyz1=new_xyz, fitted=fitted)


def laser_steps(laser: np.ndarray, a: np.ndarray, y: np.ndarray, weight: np.ndarray):
    """One weighted Gauss-Newton step of every laser's offset from where its residuals ``y``
    are (their change per radian ``a``): the lasers with at least ``MIN_LASER_POINTS`` pairs,
    their steps ``-sum w a y / sum w a^2`` (radians), standard errors
    ``sigma / sqrt(sum w a^2)`` and ``sigma`` (m), the weighted residuals' standard deviation
    after the steps."""
    lasers, index, counts = np.unique(laser, return_inverse=True, return_counts=True)
    information = np.bincount(index, weight * a * a, len(lasers))
    gradient = np.bincount(index, weight * a * y, len(lasers))
    own = (counts >= MIN_LASER_POINTS) & (information > 0)
    step = -gradient[own] / information[own]
    use = own[index]
    after = y[use] + a[use] * step[np.searchsorted(lasers[own], laser[use])]
    sigma = float(np.sqrt(weight[use] @ after**2 / max(int(use.sum()) - int(own.sum()), 1)))
    return lasers[own], step, sigma / np.sqrt(information[own]), sigma


def screened(step: np.ndarray, se: np.ndarray, z: float) -> np.ndarray:
    """Which lasers are off: a step at least ``z`` standard errors from 0 and ``z`` robust
    spreads (1.4826 MAD) of all the lasers' steps from their median."""
    if len(step) == 0:
        return np.zeros(0, dtype=bool)
    centre = np.median(step)
    spread = MAD_SCALE * float(np.median(np.abs(step - centre)))
    return (np.abs(step) >= z * se) & (np.abs(step - centre) >= z * spread)


def lidar_index(views: list, n: int) -> np.ndarray:
    """Each point's lidar: its index in ``views``."""
    index = np.zeros(n, dtype=np.int64)
    for k, view in enumerate(views):
        index[view.points] = k
    return index


def elevation_tangents(points: np.ndarray, lidar: np.ndarray, views: list) -> np.ndarray:
    """``r`` times the unit vector of rising elevation at each point about its lidar (frame 1):
    how the point moves per radian of elevation at its range and azimuth."""
    out = np.zeros_like(points)
    for k, view in enumerate(views):
        mine = lidar == k
        own = in_sensor_frame(points[mine], view.pose)
        horizontal = np.hypot(own[:, 0], own[:, 1])
        scale = np.where(horizontal > 1e-12, own[:, 2] / np.maximum(horizontal, 1e-12), 0.0)
        tangent = np.column_stack([-own[:, 0] * scale, -own[:, 1] * scale, horizontal])
        out[mine] = tangent @ view.pose[:3, :3].T
    return out


def turned(points: np.ndarray, lidar: np.ndarray, views: list, delta: np.ndarray) -> np.ndarray:
    """The points with their elevation about their lidar lowered by ``delta`` (radians, one
    per point), at their range and azimuth."""
    out = points.copy()
    for k, view in enumerate(views):
        mine = lidar == k
        own = in_sensor_frame(points[mine], view.pose)
        r = np.linalg.norm(own, axis=1)
        azimuth = np.arctan2(own[:, 1], own[:, 0])
        elevation = np.arcsin(np.clip(own[:, 2] / np.maximum(r, 1e-12), -1.0, 1.0)) - delta[mine]
        c = np.cos(elevation)
        out[mine] = apply_pose(
            view.pose, np.column_stack([r * c * np.cos(azimuth), r * c * np.sin(azimuth), r * np.sin(elevation)])
        )
    return out


def _number(value) -> float | None:
    return float(value) if np.isfinite(value) else None
