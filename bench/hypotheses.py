"""Benchmark: shadow, field_of_view and moving_objects on a pair of 1,000,000-point clouds
(target < 1 s each, one core), each against a baseline measured in the same run.

- shadow (origins [1, 2]: four binnings + first-cluster passes) vs the same work with the plain
  per-cell loop reference of the kernel (``first_cluster_keep_loop``);
- field_of_view vs a naive version (homogeneous 4x4 inverse, arcsin elevation, norm for the
  range limits), the way the tests compute it independently;
- moving_objects vs its per-point loop reference of the free-space test
  (``free_space_evidence_loop``, timed on 1,000 points of each cloud and scaled), and vs the
  example plugin ``hypotheses/moving_cars.py`` (a k-d tree query per point); then on the
  simulated traffic pair (``paper-intersection-traffic``, two cars crossing, 2 cm noise) seen by
  an HDL-32E (about 110,000 points; target < 1 s for 120,000), with the share of the cars' and
  of the static points it removes.

Run: ``python bench/hypotheses.py [n_points]``. Pin to one core with ``taskset -c 0``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from lidarfield.field import free_space
from lidarfield.field.free_space import ranges
from lidarfield.hypotheses import apply_step, parse_step
from lidarfield.hypotheses import moving_objects as mo
from lidarfield.hypotheses.field_of_view import field_of_view
from lidarfield.hypotheses.geometry import in_sensor_frame
from lidarfield.hypotheses.shadow import first_cluster_keep, first_cluster_keep_loop, shadow
from lidarfield.pair import RegisteredPair
from lidarfield.poses import pose_from_xyzrpy
from lidarfield.registration.core import register_pair
from lidarfield.sensors.models import PRESETS
from lidarfield.simulation.raycast import simulate_scan
from lidarfield.simulation.scene import load_scene
from timing import best_time, machine  # bench/timing.py


def street_scan(n: int, pose: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``n`` returns of a level sensor 2 m up in a street: ground, facades 8-14 m away and
    poles; points in frame 1 (the sensor at ``pose``)."""
    az = rng.uniform(-np.pi, np.pi, n)
    el = np.radians(rng.uniform(-15.0, 15.0, n))
    direction = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    facade = (11.0 + 3.0 * np.sin(3 * az)) / np.cos(el)
    ground = np.where(el < 0, 2.0 / np.maximum(np.sin(-el), 1e-9), np.inf)
    pole = np.where(np.cos(7 * az) > 0.98, 5.0 / np.cos(el), np.inf)
    r = np.minimum(np.minimum(facade, ground), pole) + rng.normal(0, 0.01, n)
    local = direction * r[:, None]
    return local @ pose[:3, :3].T + pose[:3, 3]


def shadow_with(kernel, pair: RegisteredPair, params) -> tuple[np.ndarray, np.ndarray]:
    """``shadow`` with another first-cluster kernel (same binning, same union)."""
    grid = params.angular_grid()
    keeps = [np.ones(len(pair.xyz1), bool), np.ones(len(pair.xyz2), bool)]
    for origin in params.origins:
        for xyz, keep in zip((pair.xyz1, pair.xyz2), keeps):
            local = xyz if origin == 1 else in_sensor_frame(xyz, pair.T_1_2)
            keep &= kernel(grid.assign(local), ranges(local), params.jump_m, params.min_points)
    return keeps[0], keeps[1]


def naive_field_of_view(
    pair: RegisteredPair, lo: float, hi: float, r_min: float, r_max: float
) -> tuple[np.ndarray, np.ndarray]:
    def inside(xyz, pose):
        local = (np.linalg.inv(pose) @ np.column_stack([xyz, np.ones(len(xyz))]).T).T[:, :3]
        r = np.linalg.norm(local, axis=1)
        el = np.degrees(np.arcsin(local[:, 2] / r))
        return (el >= lo) & (el <= hi) & (r >= r_min) & (r <= r_max)

    return inside(pair.xyz1, pair.T_1_2), inside(pair.xyz2, np.eye(4))


def main(n: int) -> None:
    rng = np.random.default_rng(0)
    T_1_2 = pose_from_xyzrpy([0.3, 3.0, 0.0, 0.0, 0.01, 0.02])
    pair = RegisteredPair(
        street_scan(n, np.eye(4), rng), street_scan(n, T_1_2, rng), T_1_2, PRESETS["vlp16"], PRESETS["vlp16"]
    )
    grid = {"azimuth_bins": 36, "elevation_deg": [-20, 20], "elevation_bins": 5}
    _, shadow_params = parse_step({"shadow": {"origins": [1, 2], "grid": grid}})
    _, fov_params = parse_step({"field_of_view": {}})

    print(machine())
    print(f"pair: {n:,} + {n:,} points; shadow origins [1, 2], 36 x 5 cells; field_of_view VLP-16 limits")

    fast = shadow(pair, shadow_params)
    t_shadow = best_time(lambda: shadow(pair, shadow_params))[0]
    start = time.perf_counter()
    reference = shadow_with(first_cluster_keep_loop, pair, shadow_params)
    t_loop = time.perf_counter() - start
    same = all(np.array_equal(a, b) for a, b in zip(fast, reference))
    removed = sum(int((~k).sum()) for k in fast)
    print(
        f"shadow          {t_shadow:7.3f} s   loop reference {t_loop:7.2f} s   speed-up {t_loop / t_shadow:6.1f}x   "
        f"same masks: {same}   removed {removed:,}"
    )

    cells, r = shadow_params.angular_grid().assign(pair.xyz1), ranges(pair.xyz1)
    t_kernel = best_time(lambda: first_cluster_keep(cells, r, 1.0, 30))[0]
    print(f"  kernel alone (one cloud, one origin) {t_kernel:.3f} s")

    fov = field_of_view(pair, fov_params)
    t_fov = best_time(lambda: field_of_view(pair, fov_params))[0]
    vlp16 = (-15.0, 15.0, PRESETS["vlp16"].min_range_m, PRESETS["vlp16"].max_range_m)
    t_naive = best_time(lambda: naive_field_of_view(pair, *vlp16))[0]
    same = all(np.array_equal(a, b) for a, b in zip(fov, naive_field_of_view(pair, *vlp16)))
    print(
        f"field_of_view   {t_fov:7.3f} s   naive          {t_naive:7.3f} s   speed-up {t_naive / t_fov:6.1f}x   same "
        f"masks: {same}"
    )
    bench_moving_objects(pair)


def bench_moving_objects(pair: RegisteredPair) -> None:
    """moving_objects on ``pair`` against its loop reference and the example plugin; then on
    the simulated traffic pair seen by an HDL-32E."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "hypotheses"))
    import moving_cars  # the example plugin

    params = mo.Params()
    t_fast = best_time(lambda: apply_step(pair, {"moving_objects": {}}))[0]
    images = [
        mo.sensor_range_image(xyz, model, params, f"sensor {k}")
        for k, (xyz, model) in enumerate(
            ((pair.xyz1, pair.sensor1), (in_sensor_frame(pair.xyz2, pair.T_1_2), pair.sensor2)), 1
        )
    ]
    sample = np.random.default_rng(1).choice(len(pair.xyz2), 1000, replace=False)
    start = time.perf_counter()
    free_space.free_space_evidence_loop(pair.xyz2[sample], pair.xyz1, images[0], params.margin_m, params.beam_width_deg)
    t_loop = (time.perf_counter() - start) / 1000 * (len(pair.xyz1) + len(pair.xyz2))
    t_plugin = best_time(lambda: moving_cars.remove(pair, {}), 1)[0]
    # (what it removes here means nothing: each street cloud is drawn about its own sensor, so
    # the two do not show one scene)
    print(
        f"moving_objects  {t_fast:7.3f} s   loop reference {t_loop:7.0f} s (scaled from 1,000 points)   speed-up "
        f"{t_loop / t_fast:6.0f}x   plugin moving_cars {t_plugin:6.3f} s"
    )

    scene, sensor = load_scene("paper-intersection-traffic"), PRESETS["hdl32"]
    scans = [
        simulate_scan(scene, sensor, pose_from_xyzrpy(pose), time_s=time_s, range_noise_m=0.02, seed=seed)
        for pose, time_s, seed in (([2, -9, 3, 0, 0, 1.5708], 0.0, 1), ([2.5, -8.5, 3, 0, 0, 1.62], 0.1, 2))
    ]
    traffic = register_pair(*scans, "truth")
    t_traffic, outcome = best_time(lambda: apply_step(traffic, {"moving_objects": {}}))
    label = np.concatenate([traffic.attributes1["object"], traffic.attributes2["object"]])
    removed = ~np.concatenate([outcome.keep1, outcome.keep2])
    print(
        f"moving_objects on the traffic pair seen by an HDL-32E, {len(traffic.xyz1):,} + {len(traffic.xyz2):,} "
        f"points: {t_traffic:.3f} s (target < 1 s: {'met' if t_traffic < 1 else 'MISSED'}); removes "
        f"{removed[label > 0].mean():.1%} of the cars' points, {removed[label == 0].mean():.2%} of the static ones"
    )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 1_000_000)
