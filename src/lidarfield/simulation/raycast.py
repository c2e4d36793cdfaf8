"""Simulated lidar scans: one ray per channel per azimuth step, cast into a scene.

Open3D's ``RaycastingScene`` finds the first triangle each ray hits (in float32); the range is
then recomputed in float64 from that triangle's plane, so every point lies on the scene's
surface to rounding. ``first_hits_reference`` is the plain numpy version of the same kernel.

Timing: azimuth step j of a revolution of n steps fires at ``j / (n * rotation_hz)`` seconds
after the sweep start, all channels at once, azimuth counter-clockwise from the sensor's +x.

Calibration faults (``range_scale``, ``range_offset_m``, ``elevation_offsets_deg``): the scene
and the ray are the truth, the reported point is the measurement. Beam k is cast at its actual
elevation ``elevation_deg[k] + elevation_offsets_deg[k]`` and hits at the true range r; the
sensor believes the beam is at its nominal elevation ``elevation_deg[k]`` and measures
``range_scale * r + range_offset_m`` (then noise), so the point is reported at that measured
range along the nominal direction.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d
import trimesh

from ..errors import ConfigError
from ..scan import SIMULATED, Scan
from ..sensors.models import SensorModel
from .faults import checked_elevation_offsets, checked_range_fault
from .scene import Scene
from .trajectory import motion_record, moved_pose

_REFERENCE_CHUNK = 4096  # rays per block of the numpy kernel: bounds its memory


def azimuth_steps(sensor: SensorModel) -> tuple[np.ndarray, int]:
    """Indices j of the azimuth steps the sensor fires (within its azimuth limits) and the
    number n of steps in a revolution; step j points at azimuth ``360 j / n`` degrees."""
    n = sensor.firings_per_revolution
    steps = np.arange(n)
    if sensor.azimuth_limits_deg is not None:
        start, end = sensor.azimuth_limits_deg
        offset = np.mod(steps * 360.0 / n - start, 360.0)
        steps = steps[offset <= np.mod(end - start, 360.0)]
    return steps, n


def beam_directions(azimuth_rad: np.ndarray, elevation_rad: np.ndarray) -> np.ndarray:
    """Unit beam directions in the sensor frame, shape (n_azimuth, n_channels, 3)."""
    az, el = np.meshgrid(azimuth_rad, elevation_rad, indexing="ij")
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)


def first_hits(mesh: trimesh.Trimesh, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance along each ray to the first triangle it hits (inf for a miss) and that
    triangle's index (-1 for a miss). ``directions`` must be unit vectors."""
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)),
    )
    rays = np.hstack([origins, directions]).astype(np.float32)
    result = scene.cast_rays(o3d.core.Tensor(rays))
    hit = np.isfinite(result["t_hit"].numpy())
    triangle = np.where(hit, result["primitive_ids"].numpy().astype(np.int64), -1)
    distance = np.full(len(origins), np.inf)
    distance[hit] = _plane_distance(mesh.triangles[triangle[hit]], origins[hit], directions[hit])
    return distance, triangle


def _plane_distance(triangles: np.ndarray, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Float64 distance along each ray to the plane of its triangle."""
    normal = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    return np.einsum("ij,ij->i", normal, triangles[:, 0] - origins) / np.einsum("ij,ij->i", normal, directions)


def first_hits_reference(
    mesh: trimesh.Trimesh, origins: np.ndarray, directions: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The plain numpy version of ``first_hits``: Moller-Trumbore against every triangle."""
    triangles = np.asarray(mesh.triangles, dtype=np.float64)
    v0, e1, e2 = triangles[:, 0], triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]
    distance = np.full(len(origins), np.inf)
    triangle = np.full(len(origins), -1, dtype=np.int64)
    for lo in range(0, len(origins), _REFERENCE_CHUNK):
        o, d = origins[lo : lo + _REFERENCE_CHUNK, None, :], directions[lo : lo + _REFERENCE_CHUNK, None, :]
        p = np.cross(d, e2)
        det = np.einsum("rtk,tk->rt", p, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = o - v0
            u = np.einsum("rtk,rtk->rt", s, p) * inv
            q = np.cross(s, e1)
            v = np.einsum("rtk,rtk->rt", d, q) * inv
            t = np.einsum("tk,rtk->rt", e2, q) * inv
            valid = (np.abs(det) > 1e-12) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        t = np.where(valid, t, np.inf)
        best = np.argmin(t, axis=1)
        best_t = t[np.arange(len(best)), best]
        hit = np.isfinite(best_t)
        distance[lo : lo + len(best)] = best_t
        triangle[lo : lo + len(best)] = np.where(hit, best, -1)
    return distance, triangle


def simulate_scan(
    scene: Scene,
    sensor: SensorModel,
    pose: np.ndarray,
    *,
    time_s: float = 0.0,
    seed: int = 0,
    range_noise_m: float = 0.0,
    dropout: float = 0.0,
    max_range_m: float | None = None,
    rolling_shutter: bool = False,
    linear_velocity_mps=(0.0, 0.0, 0.0),
    angular_velocity_rps=(0.0, 0.0, 0.0),
    range_scale: float = 1.0,
    range_offset_m: float = 0.0,
    elevation_offsets_deg=None,
) -> Scan:
    """One sweep of ``sensor`` at ``pose`` (4x4 world-from-sensor at the sweep start) in ``scene``.

    Points are in the sensor frame, ordered by firing (azimuth step, then channel), with
    attributes ``ring`` (index into ``sensor.elevation_deg``), ``time`` (seconds from the
    sweep start; the nominal firing time, also without rolling shutter) and ``object`` (the
    label of the object hit, ``Scene.labelled_objects``: its 1-based place in ``scene.objects``
    for an object that moves in the world, minus that for one the sensor carries, 0 for the
    static scene). Misses, and hits
    nearer than the model's minimum or farther than its (or ``max_range_m``'s, if smaller)
    maximum range give no point. Objects with a velocity are where they are at ``time_s``.

    Options, all off by default, all reproducible from ``seed``:
    ``range_noise_m`` (Gaussian sigma added to each range), ``dropout`` (probability of losing
    each return), and ``rolling_shutter``: each firing at time t is made from the pose moved
    for t by ``linear_velocity_mps`` (world frame) and ``angular_velocity_rps`` (rad/s, sensor
    frame), and moving objects are where they are at ``time_s + t``; each point keeps the
    coordinates measured in the sensor frame of its own firing, as a driver without de-skewing
    outputs them (so with zero velocity the scan equals the instantaneous one exactly).

    Calibration faults, off by default (see the module's docstring for truth and measurement):
    beam k fires at ``elevation_deg[k] + elevation_offsets_deg[k]`` (one offset per channel, or
    None) but its point is reported along the nominal elevation, at the measured range
    ``range_scale * true_range + range_offset_m`` plus noise. Range limits and dropout act on
    the true range, so a range fault changes where the points are, not which rays return one.
    The faults applied are written in the scan's ``source``.

    The scan records when and how it was taken: ``stamp_s`` = ``time_s`` and ``sweep_motion``,
    the motion its points carry in the sensor frame at the sweep start (``motion_record``: the
    velocities with ``rolling_shutter``, zero without, as the points are then instantaneous).
    """
    pose = np.asarray(pose, dtype=np.float64).reshape(4, 4)
    limit = _checked_max_range(sensor, max_range_m)
    if not 0.0 <= dropout <= 1.0 or range_noise_m < 0 or not np.isfinite(range_noise_m):
        raise ConfigError(f"simulate: dropout must be in [0, 1] and range noise >= 0; got {dropout}, {range_noise_m}")
    range_scale, range_offset_m = checked_range_fault(range_scale, range_offset_m)
    elevation_offsets_deg = checked_elevation_offsets(elevation_offsets_deg, sensor)

    steps, steps_per_revolution = azimuth_steps(sensor)
    firing_time = steps / (steps_per_revolution * sensor.rotation_hz)
    azimuth = steps * (2 * np.pi / steps_per_revolution)
    nominal = beam_directions(azimuth, np.radians(sensor.elevation_deg))
    local = nominal  # the directions the beams actually fire in
    if elevation_offsets_deg is not None:
        local = beam_directions(azimuth, np.radians(np.asarray(sensor.elevation_deg) + elevation_offsets_deg))
    motion_time = firing_time if rolling_shutter else np.zeros_like(firing_time)
    poses = moved_pose(pose, motion_time, linear_velocity_mps, angular_velocity_rps)
    world_dirs = np.einsum("aij,acj->aci", poses[:, :3, :3], local).reshape(-1, 3)
    origins = np.repeat(poses[:, :3, 3], sensor.channels, axis=0)
    ray_time = np.repeat(motion_time, sensor.channels)

    distance, label = _scene_hits(scene, time_s, origins, world_dirs, ray_time)
    carried_distance, carried_label = _carried_hits(scene, local.reshape(-1, 3))
    nearer = carried_distance < distance
    distance[nearer], label[nearer] = carried_distance[nearer], carried_label[nearer]
    keep = np.isfinite(distance) & (distance >= sensor.min_range_m) & (distance <= limit)
    rng = np.random.default_rng(seed)
    if dropout > 0:
        keep &= rng.random(len(keep)) >= dropout
    kept_distance = distance[keep]
    if range_scale != 1.0 or range_offset_m != 0.0:
        kept_distance = range_scale * kept_distance + range_offset_m
    if range_noise_m > 0:
        kept_distance = kept_distance + rng.normal(0.0, range_noise_m, len(kept_distance))

    ring = np.tile(np.arange(sensor.channels, dtype=np.int32), len(steps))
    time = np.repeat(firing_time, sensor.channels)
    xyz = nominal.reshape(-1, 3)[keep] * kept_distance[:, None]
    source = _describe(
        scene,
        sensor,
        time_s,
        seed,
        range_noise_m,
        dropout,
        max_range_m,
        rolling_shutter,
        linear_velocity_mps,
        angular_velocity_rps,
        range_scale,
        range_offset_m,
        elevation_offsets_deg,
    )
    scan = Scan(
        xyz,
        {"ring": ring[keep], "time": time[keep], "object": label[keep]},
        sensor,
        pose,
        source,
        stamp_s=float(time_s),
    )
    scan.sweep_motion = motion_record(pose, linear_velocity_mps, angular_velocity_rps, rolling_shutter)
    return scan


def _scene_hits(
    scene: Scene, time_s: float, origins: np.ndarray, directions: np.ndarray, ray_time: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Distance to the first hit over the world's objects, and the ``object`` label of what each
    ray hit (0: the static scene or a miss). The static objects are cast together, once; a
    moving object is cast alone at its place at ``time_s``, with each ray's origin shifted by
    -velocity x (the ray's own time offset): the same as moving the object, per ray."""
    static = [o.mesh for o in scene.objects if not o.moving and not o.carried]
    distance = np.full(len(origins), np.inf)
    if static:
        distance = first_hits(trimesh.util.concatenate(static), origins, directions)[0]
    label = np.zeros(len(origins), dtype=np.int32)
    for number, obj in scene.labelled_objects():
        if obj.carried:
            continue
        shifted = origins - ray_time[:, None] * obj.velocity_mps
        _keep_nearer(distance, label, first_hits(obj.mesh_at(time_s), shifted, directions)[0], number)
    return distance, label


def _carried_hits(scene: Scene, local_directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance to the first hit on the objects the sensor carries, and their labels, cast in
    the sensor frame of each firing (where they do not move, rolling shutter or not)."""
    distance = np.full(len(local_directions), np.inf)
    label = np.zeros(len(local_directions), dtype=np.int32)
    origins = np.zeros_like(local_directions)
    for number, obj in scene.labelled_objects():
        if obj.carried:
            _keep_nearer(distance, label, first_hits(obj.mesh, origins, local_directions)[0], number)
    return distance, label


def _keep_nearer(distance: np.ndarray, label: np.ndarray, hits: np.ndarray, number: int) -> None:
    """Where ``hits`` is nearer than ``distance``: take it, and label the ray ``number`` (in place)."""
    nearer = hits < distance
    distance[nearer] = hits[nearer]
    label[nearer] = number


def _checked_max_range(sensor: SensorModel, max_range_m: float | None) -> float:
    if max_range_m is None:
        return sensor.max_range_m
    if not max_range_m > 0:
        raise ConfigError(f"simulate: max range must be positive, got {max_range_m}")
    return min(sensor.max_range_m, float(max_range_m))


def _describe(
    scene, sensor, time_s, seed, noise, dropout, max_range, rolling, velocity, angular, scale, offset, elevation
) -> str:
    parts = [f"{SIMULATED} scene={scene.source} sensor={sensor.name} time_s={time_s:g} seed={seed}"]
    if noise:
        parts.append(f"range_noise_m={noise:g}")
    if dropout:
        parts.append(f"dropout={dropout:g}")
    if max_range is not None:
        parts.append(f"max_range_m={max_range:g}")
    if rolling:
        parts.append(f"rolling_shutter v={list(map(float, velocity))} w={list(map(float, angular))}")
    # The calibration faults applied: the truth a test or a hypothesis checks against.
    if scale != 1.0:
        parts.append(f"range_scale={scale!r}")
    if offset != 0.0:
        parts.append(f"range_offset_m={offset!r}")
    if elevation is not None:
        parts.append(f"elevation_offsets_deg={[float(v) for v in elevation]}")
    return " ".join(parts)
