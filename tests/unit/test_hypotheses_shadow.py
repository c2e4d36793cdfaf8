"""shadow: the first radial cluster kernel against its loop reference, and on a scene with a
pole in front of a wall seen from two sensor positions."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from lidarfield.hypotheses import parse_step
from lidarfield.hypotheses.shadow import first_cluster_keep, first_cluster_keep_loop, shadow
from lidarfield.poses import pose_from_xyzrpy
from lidarfield.registration import register_pair
from lidarfield.sensors.models import PRESETS
from lidarfield.simulation.raycast import first_hits, simulate_scan
from lidarfield.simulation.scene import scene_from_dict


@pytest.mark.parametrize("seed", range(12))
def test_kernel_equals_loop_reference_on_random_cells(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 4000))
    cells = rng.integers(-1, 25, n)
    r = rng.exponential(6.0, n)
    if seed % 3 == 0:
        r = np.round(r)  # ties, and consecutive gaps exactly equal to jump_m (not a split)
    min_points = int(rng.integers(0, 12))
    fast = first_cluster_keep(cells, r, 1.0, min_points)
    assert np.array_equal(fast, first_cluster_keep_loop(cells, r, 1.0, min_points))
    assert fast[cells < 0].all()


def test_kernel_on_one_cell_by_hand():
    # Segments [1, 1.5, 2] (3 points), [4, 4.2, 4.9, 5.5] (4 points), [9]: with min_points 3
    # the first segment of more than 3 points is the second one.
    r = np.array([4.2, 1.0, 9.0, 1.5, 5.5, 2.0, 4.0, 4.9])
    cells = np.zeros(len(r), dtype=np.int64)
    keep = first_cluster_keep(cells, r, 1.0, 3)
    assert keep.tolist() == [True, False, False, False, True, False, True, True]
    # No segment long enough: the cell is left alone.
    assert first_cluster_keep(cells, r, 1.0, 4).all()
    # An empty grid, and points outside it.
    assert first_cluster_keep(np.full(3, -1), np.ones(3), 1.0, 0).all()


# --- a pole in front of a wall, two sensors ---------------------------------------------------

POLE_XY = 8.0 * np.array([np.cos(np.radians(85)), np.sin(np.radians(85))])  # 85 deg, 8 m from sensor 1
ORIGIN1, ORIGIN2 = np.array([0.0, 0.0, 3.0]), np.array([1.5, 0.0, 3.0])
WALL_Y = 11.75  # the wall's face
# Cells of 10 deg azimuth; elevation bands of 8 deg with an edge at -14 deg, so that the bands
# above it hold only wall and pole in the wall's direction. The pole lies inside one azimuth
# cell about each sensor (80-90 deg about sensor 1, 90-100 deg about sensor 2).
GRID = {"azimuth_bins": 36, "elevation_deg": [-22, 10], "elevation_bins": 4}


@pytest.fixture(scope="module")
def pole_scene():
    scene = scene_from_dict(
        {
            "objects": [
                {"name": "ground", "kind": "plane", "size": [24, 24]},
                {"name": "wall", "kind": "box", "size": [24, 0.5, 6], "center": [0, WALL_Y + 0.25, 3]},
                {"name": "pole", "kind": "cylinder", "radius": 0.3, "height": 8, "center": [*POLE_XY, 4]},
            ]
        }
    )
    sensor = PRESETS["paper-sim-80"]
    scans = [simulate_scan(scene, sensor, pose_from_xyzrpy([*o, 0, 0, 0])) for o in (ORIGIN1, ORIGIN2)]
    pair = register_pair(scans[0], scans[1], "truth")
    mesh = trimesh.util.concatenate([o.mesh for o in scene.objects])
    return pair, mesh


def _seen_from(mesh, points_world: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Ground truth by ray casting: is each point the first hit of a ray from ``origin``?"""
    offset = points_world - origin
    distance = np.linalg.norm(offset, axis=1)
    hit, _ = first_hits(mesh, np.repeat(origin[None], len(offset), axis=0), offset / distance[:, None])
    return hit >= distance - 1e-3


def _shadow_keep(pair, origins):
    _, params = parse_step({"shadow": {"grid": GRID, "origins": origins}})
    return shadow(pair, params)


def test_shadow_removes_the_wall_only_one_sensor_sees_and_keeps_ground_and_pole(pole_scene):
    pair, mesh = pole_scene
    keeps = _shadow_keep(pair, [1, 2])
    for xyz, keep, other in ((pair.xyz1, keeps[0], ORIGIN2), (pair.xyz2, keeps[1], ORIGIN1)):
        world = xyz + ORIGIN1  # frame 1 is sensor 1's, 3 m above the ground
        ground = world[:, 2] < 1e-6
        wall = world[:, 1] > WALL_Y - 1e-6
        pole = ~ground & ~wall
        hidden = wall & ~_seen_from(mesh, world, other)  # the other sensor's view is blocked by the pole
        assert hidden.sum() > 500
        assert not keep[hidden].any()
        assert keep[ground].all() and keep[pole].all()
        # Wall that both see is kept outside the two azimuth cells that hold the pole
        # (they cover the wall for |x| < 2.3 m); inside them it is removed with the shadow.
        assert keep[wall & (np.abs(world[:, 0]) > 3.0)].all()
        assert set(np.flatnonzero(~keep)) <= set(np.flatnonzero(wall & (np.abs(world[:, 0]) < 3.0)))


def test_removals_about_both_origins_are_the_union_of_each(pole_scene):
    pair, _ = pole_scene
    both = _shadow_keep(pair, [1, 2])
    one, two = _shadow_keep(pair, [1]), _shadow_keep(pair, [2])
    for cloud in (0, 1):
        assert np.array_equal(both[cloud], one[cloud] & two[cloud])
        assert (~one[cloud]).sum() > 0 and (~two[cloud]).sum() > 0
