"""shadow: the first radial cluster kernel against its loop reference, and on a scene with a
pole in front of a wall seen from two sensor positions; the occlusion rule (the z-buffer test
from the other sensor) on the same scene against ray-cast truth, at full density and thinned."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

from lidarfield.errors import HypothesisError, NotApplicableError
from lidarfield.field.free_space import BEAM_WIDTH_DEG, MARGIN_M, co_visible, hidden, range_image, thinned_columns
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


def _shadow_keep(pair, origins, rule="first_cluster"):
    _, params = parse_step({"shadow": {"grid": GRID, "origins": origins, "rule": rule}})
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


# --- rule occlusion: the z-buffer test from the other sensor ----------------------------------


def _removed_against_truth(pair, mesh, keeps) -> list[tuple[int, int, int]]:
    """Per cloud: (points hidden from the other sensor by ray casting, of them removed, points
    it could see removed), the ground at the plane's edge left out (the rays past the edge
    returned nothing, so the ring below, nearer, is all that sensor measured there)."""
    out = []
    for xyz, keep, other in ((pair.xyz1, keeps[0], ORIGIN2), (pair.xyz2, keeps[1], ORIGIN1)):
        world = xyz + ORIGIN1
        hidden = ~_seen_from(mesh, world, other)
        edge = (world[:, 2] < 1e-6) & (np.abs(world[:, :2]).max(axis=1) > 11.0)
        out.append((int(hidden.sum()), int((hidden & ~keep).sum()), int((~hidden & ~keep & ~edge).sum())))
    return out


def _thinned(pair, every: int):
    rng = np.random.default_rng(0)
    keeps = []
    for xyz in (pair.xyz1, pair.xyz2):
        keep = np.zeros(len(xyz), dtype=bool)
        keep[rng.choice(len(xyz), len(xyz) // every, replace=False)] = True
        keeps.append(keep)
    return pair.subset(*keeps)


def test_occlusion_removes_what_the_other_sensor_had_hidden_and_keeps_the_wall_both_see(pole_scene):
    pair, mesh = pole_scene
    occlusion = _removed_against_truth(pair, mesh, _shadow_keep(pair, [1, 2], rule="occlusion"))
    first_cluster = _removed_against_truth(pair, mesh, _shadow_keep(pair, [1, 2]))
    for (shadowed, removed, wrong), (_, _, wrong_first_cluster) in zip(occlusion, first_cluster):
        # measured 1151 of 1227, 1150 of 1231: the shadow's edges within the window are kept
        assert shadowed > 1000 and removed >= 0.9 * shadowed
        # Nothing both sensors see removed (measured 0, 0); the first radial cluster removes the
        # wall both see in the pole's cells too (1489, 1434).
        assert wrong <= 0.01 * shadowed and wrong_first_cluster > 10 * max(wrong, 10)


def test_occlusion_on_thinned_clouds_reads_a_missing_return_as_nothing_seen(pole_scene):
    """A cloud thinned to a fifth leaves most cells of its model's range image empty; the
    window of ``thinned_columns`` finds the rays nearest a direction among the returns left.
    With no window (each cell alone), 100 and 115 of 203 and 244 hidden points were removed
    and 389 and 353 points both sensors see; with cells as wide as the thinned cloud fills, a
    cell's nearest return hid oblique walls: 105 and 160."""
    pair, mesh = pole_scene
    thinned = _thinned(pair, 5)
    keeps = _shadow_keep(thinned, [1, 2], rule="occlusion")
    for shadowed, removed, wrong in _removed_against_truth(thinned, mesh, keeps):
        assert shadowed > 150 and removed >= 0.65 * shadowed  # measured 151 of 203, 184 of 244
        assert wrong < 0.1 * shadowed  # measured 14, 13


def test_thinned_columns_is_half_the_mean_gap_of_a_row_s_returns():
    image = range_image(np.array([[1.0, 0, 0]]), np.radians(0.2), np.radians(np.arange(16.0)))  # 16 x 1800
    assert thinned_columns(image, 28_800) == 0  # a return in every cell
    assert thinned_columns(image, 28_800 // 5) == 2  # one in five: 5 columns between returns
    assert thinned_columns(image, 0) == 14_400


def test_hidden_is_the_z_buffer_test_on_known_geometry():
    # One channel at 0 deg, columns of 1 deg: a wall at 5 m over azimuth -10..10 deg.
    azimuth = np.radians(np.arange(-10, 10.5, 0.5))
    wall = 5.0 * np.column_stack([np.cos(azimuth), np.sin(azimuth), np.zeros_like(azimuth)])
    image = range_image(wall, np.radians(1.0), np.zeros(1))
    behind, just_behind, before = (
        np.array([[r * np.cos(np.radians(3)), r * np.sin(np.radians(3)), 0.0]]) for r in (9.0, 5.1, 3.0)
    )
    beside = np.array([[0.0, 9.0, 0.0]])  # at 90 deg: no ray returned there, nothing said
    above = np.array([[9.0, 0.0, 9.0]])  # 45 deg up: outside the sensor's view
    points = np.vstack([behind, just_behind, before, beside, above])
    assert hidden(points, image, MARGIN_M, BEAM_WIDTH_DEG).tolist() == [True, False, False, False, False]
    # The wall thinned to every third degree (-10, -7, ..., 2, 5, 8): behind it at 4 deg (an
    # empty cell) nothing is said, unless the window reaches the return at 5 deg.
    thinned = range_image(wall[::6], np.radians(1.0), np.zeros(1))
    behind_gap = np.array([[9.0 * np.cos(np.radians(4)), 9.0 * np.sin(np.radians(4)), 0.0]])
    assert not hidden(behind_gap, thinned, MARGIN_M, BEAM_WIDTH_DEG).any()
    assert hidden(behind_gap, thinned, MARGIN_M, BEAM_WIDTH_DEG, columns=1).all()
    # Never hidden where co-visible: hidden means the rays stopped short of the point.
    assert not (
        hidden(points, image, MARGIN_M, BEAM_WIDTH_DEG) & co_visible(points, image, MARGIN_M, BEAM_WIDTH_DEG)
    ).any()


def test_occlusion_from_one_place_removes_nothing(pole_scene):
    """From one place a change of viewpoint hides nothing: what one scan hides of the other's
    there moved, for moving_objects. Both scans of the pole scene put at sensor 1's place."""
    pair, _ = pole_scene
    assert (~_shadow_keep(pair, [1, 2], rule="occlusion")[1]).sum() > 1000
    one_place = dataclasses.replace(pair, T_1_2=np.eye(4))
    assert all(keep.all() for keep in _shadow_keep(one_place, [1, 2], rule="occlusion"))


def test_occlusion_needs_the_sensor_models_and_rule_is_checked(pole_scene):
    pair, _ = pole_scene
    _, params = parse_step({"shadow": {"rule": "occlusion", "origins": [2]}})
    no_model = dataclasses.replace(pair, sensor2=None)
    with pytest.raises(NotApplicableError, match="a scan has no sensor model"):
        shadow(no_model, params)
    with pytest.raises(HypothesisError, match="rule must be one of first_cluster, occlusion, auto"):
        parse_step({"shadow": {"rule": "zbuffer"}})


def test_auto_is_occlusion_with_the_sensor_models_and_the_first_cluster_without(pole_scene):
    """explain's default candidate: the z-buffer test where the channels are known, the DESIGN's
    segmentation where a scan has no sensor model (text scans run without --sensor)."""
    pair, _ = pole_scene
    with_models = _shadow_keep(pair, [1, 2], rule="auto")
    assert all((a == b).all() for a, b in zip(with_models, _shadow_keep(pair, [1, 2], rule="occlusion")))
    no_model = dataclasses.replace(pair, sensor2=None)
    auto = _shadow_keep(no_model, [1, 2], rule="auto")
    first = _shadow_keep(no_model, [1, 2], rule="first_cluster")
    assert all((a == b).all() for a, b in zip(auto, first))
    assert (~first[0]).sum() + (~first[1]).sum() > 100
