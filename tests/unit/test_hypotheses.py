"""The hypothesis registry (validation, normalisation) and the built-ins ego_vehicle,
field_of_view, crop and outliers, each against an independent computation."""

from __future__ import annotations

import numpy as np
import pytest

from lidarfield.errors import HypothesisError
from lidarfield.hypotheses import (
    apply_step,
    available_hypotheses,
    describe_hypotheses,
    validate_stack,
    validate_step,
)
from lidarfield.pair import RegisteredPair
from lidarfield.poses import pose_from_xyzrpy
from lidarfield.registration import register_pair
from lidarfield.sensors.models import PRESETS
from lidarfield.simulation.raycast import simulate_scan
from lidarfield.simulation.scene import load_scene

STUDY_GRID = {
    "kind": "spherical",
    "azimuth_bins": 36,
    "azimuth_offset_deg": 0.0,
    "elevation_deg": [-25.0, 12.5],
    "elevation_bins": 5,
    "range_edges_m": None,
    "cell_m": 2.0,
    "origin": [0, 0, 0],
    "min_points": 30,
    "max_component_m": None,
}


def _unit_vectors(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


# --- validation ----------------------------------------------------------------------------


def test_available_and_described():
    assert available_hypotheses() == [
        "ego_vehicle",
        "field_of_view",
        "shadow",
        "crop",
        "outliers",
        "moving_objects",
        "realign",
        "range_calibration",
        "deskew",
        "elevation_calibration",
        "plugin",
    ]
    described = describe_hypotheses()
    assert ("radius_m", "number or null", 3.0) == described["ego_vehicle"][0][:3]
    assert all(doc for params in described.values() for *_, doc in params)


def test_defaults_filled_and_study_grid_injected_into_shadow():
    stack = validate_stack([{"ego_vehicle": None}, {"shadow": {"origins": [1]}}], ".", STUDY_GRID)
    assert stack[0] == {"ego_vehicle": {"radius_m": 3.0, "box_m": None}}
    assert stack[1] == {
        "shadow": {
            "jump_m": 1.0,
            "min_points": 30,
            "origins": [1],
            "grid": {
                "azimuth_bins": 36,
                "azimuth_offset_deg": 0.0,
                "elevation_deg": [-25.0, 12.5],
                "elevation_bins": 5,
            },
        }
    }
    # The rule is written only where set (stage ids written before it stay), and read back.
    occlusion = validate_stack([{"shadow": {"rule": "occlusion"}}], ".", STUDY_GRID)
    assert occlusion[0]["shadow"]["rule"] == "occlusion" and validate_stack(occlusion, ".", STUDY_GRID) == occlusion
    # Idempotent, and a grid of its own wins over the study's, key by key.
    assert validate_stack(stack, ".", {**STUDY_GRID, "azimuth_bins": 72}) == stack
    own = validate_step({"shadow": {"grid": {"elevation_bins": 4}}}, ".", STUDY_GRID)
    assert own["shadow"]["grid"]["elevation_bins"] == 4 and own["shadow"]["grid"]["azimuth_bins"] == 36


@pytest.mark.parametrize(
    "step, message",
    [
        (
            {"ego_vehicel": {}},
            "hypothesis 1 (ego_vehicel): unknown hypothesis; available: ego_vehicle, field_of_view, shadow, crop, "
            "outliers, moving_objects, realign, range_calibration, deskew, elevation_calibration, plugin",
        ),
        (
            {"shadow": {"jump": 1}},
            "unknown parameter(s) jump; expected: jump_m (number), min_points (integer), origins (list of integers), "
            "rule (string), grid (mapping or null)",
        ),
        ({"shadow": {"jump_m": "far"}}, "parameter 'jump_m': expected number, got 'far'"),
        ({"shadow": {"min_points": 2.5}}, "parameter 'min_points': expected integer, got 2.5"),
        ({"shadow": {"min_points": True}}, "parameter 'min_points': expected integer, got True"),
        ({"shadow": {"origins": [1, 3]}}, "origins must list sensor 1, sensor 2 or both"),
        ({"shadow": {"grid": {"range_edges_m": [0, 10]}}}, "grid takes the angular keys"),
        (
            {"ego_vehicle": {"box_m": [0, 1, 0, 1]}},
            "parameter 'box_m': expected list of 6 numbers or null, got [0, 1, 0, 1]",
        ),
        ({"ego_vehicle": {"box_m": [1, 0, 0, 1, 0, 1]}}, "each min <= max"),
        ({"field_of_view": {"elevation_deg": [15, -15]}}, "lo < hi"),
        ({"outliers": {"std_ratio": 0}}, "std_ratio > 0"),
        ({"plugin": {"function": "remove"}}, "missing parameter(s) file (string)"),
        ({"crop": "all"}, "parameters must be a mapping"),
        ({"crop": {}, "shadow": {}}, "one-key mapping"),
    ],
)
def test_validation_errors_name_the_problem(step, message):
    with pytest.raises(HypothesisError) as error:
        validate_stack([step])
    assert message in str(error.value)


def test_validation_names_the_entry_position():
    with pytest.raises(HypothesisError, match=r"^hypothesis 2 \(crop\): parameter 'max_range_m'"):
        validate_stack([{"crop": {}}, {"crop": {"max_range_m": "10 m"}}])


# --- ego_vehicle ---------------------------------------------------------------------------


def test_ego_vehicle_removes_exactly_the_points_within_the_radius_of_their_own_sensor():
    rng = np.random.default_rng(1)
    radius, eps = 4.1, 1e-9
    T = pose_from_xyzrpy([3.0, -1.0, 0.2, 0.0, 0.1, 0.7])
    direction1, direction2 = _unit_vectors(rng, 400), _unit_vectors(rng, 400)
    offset1 = np.where(np.arange(400) % 2 == 0, -eps, eps)
    offset2 = -offset1
    xyz1 = direction1 * (radius + offset1)[:, None]
    xyz2 = T[:3, 3] + direction2 * (radius + offset2)[:, None]  # about sensor 2's origin, frame 1
    keep1, keep2 = apply_step(RegisteredPair(xyz1, xyz2, T), {"ego_vehicle": {"radius_m": radius}})
    assert np.array_equal(keep1, offset1 > 0)
    assert np.array_equal(keep2, offset2 > 0)
    # Cloud 2 is measured from its own origin: these points are far from sensor 1.
    assert np.linalg.norm(xyz2[~keep2], axis=1).min() > 0.5


def test_ego_vehicle_box_is_in_each_sensors_frame():
    T = pose_from_xyzrpy([10.0, 0.0, 0.0, 0.0, 0.0, np.pi / 2])  # sensor 2 turned 90 deg
    box = [-2.0, 1.0, -0.5, 0.5, -2.0, 0.0]  # longer backwards (-x) than forwards
    local = np.array([[-1.5, 0, -1], [0.5, 0, -1], [1.5, 0, -1], [0, 0.8, -1], [0, 0, 0.5]])
    inside = np.array([True, True, False, False, False])
    xyz2 = local @ T[:3, :3].T + T[:3, 3]
    keep1, keep2 = apply_step(RegisteredPair(local, xyz2, T), {"ego_vehicle": {"radius_m": None, "box_m": box}})
    assert np.array_equal(keep1, ~inside) and np.array_equal(keep2, ~inside)


# --- field_of_view -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def simulated_pair():
    """The paper's intersection from two poses, sensor 2 pitched and yawed."""
    scene, sensor = load_scene("paper-intersection"), PRESETS["paper-sim-80"]
    poses = [pose_from_xyzrpy([0, 0, 3, 0, 0, 0]), pose_from_xyzrpy([1, 1, 3, 0.0, 0.04, 0.05])]
    scans = [simulate_scan(scene, sensor, pose) for pose in poses]
    return register_pair(scans[0], scans[1], "truth")


def _elevation_about(xyz_frame1: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Elevation (deg) of frame-1 points about a sensor at ``pose``, computed another way."""
    homogeneous = np.column_stack([xyz_frame1, np.ones(len(xyz_frame1))])
    local = (np.linalg.inv(pose) @ homogeneous.T).T[:, :3]
    return np.degrees(np.arcsin(local[:, 2] / np.linalg.norm(local, axis=1)))


def test_field_of_view_removes_exactly_the_points_outside_the_other_sensors_elevation(simulated_pair):
    pair = simulated_pair
    lo, hi = -22.0, 9.6  # paper-sim-80: 80 channels 0.4 deg apart from -22 deg
    keep1, keep2 = apply_step(pair, {"field_of_view": {}})
    el1 = _elevation_about(pair.xyz1, pair.T_1_2)
    el2 = _elevation_about(pair.xyz2, np.eye(4))
    expected1 = (el1 >= lo) & (el1 <= hi)
    expected2 = (el2 >= lo) & (el2 <= hi)
    assert (~expected1).sum() > 100 and (~expected2).sum() > 100
    assert np.array_equal(keep1, expected1)
    assert np.array_equal(keep2, expected2)
    # Sensor 2's pitch matters: translating only (no rotation) would give another answer.
    shifted = pair.xyz1 - pair.origin2
    el_translated = np.degrees(np.arctan2(shifted[:, 2], np.hypot(shifted[:, 0], shifted[:, 1])))
    assert not np.array_equal(keep1, (el_translated >= lo) & (el_translated <= hi))


def test_field_of_view_keeps_everything_when_the_sensors_share_their_origin():
    # A pure turn on the spot: each sensor sees exactly what the other sees, including the
    # points of the lowest and highest channels, which lie on the limits themselves.
    scene, sensor = load_scene("paper-intersection"), PRESETS["paper-sim-80"]
    poses = [pose_from_xyzrpy([0, 0, 3, 0, 0, 0]), pose_from_xyzrpy([0, 0, 3, 0, 0, 0.3])]
    pair = register_pair(*(simulate_scan(scene, sensor, pose) for pose in poses), "truth")
    keep1, keep2 = apply_step(pair, {"field_of_view": {}})
    assert keep1.all() and keep2.all()


def test_field_of_view_parameters_override_the_models_and_margin_widens(simulated_pair):
    pair = simulated_pair
    narrow1, narrow2 = apply_step(pair, {"field_of_view": {"elevation_deg": [-15, 5]}})
    el2 = _elevation_about(pair.xyz2, np.eye(4))
    assert np.array_equal(narrow2, (el2 >= -15) & (el2 <= 5))
    wide1, wide2 = apply_step(pair, {"field_of_view": {"elevation_deg": [-15, 5], "margin_deg": 2.0}})
    assert np.array_equal(wide2, (el2 >= -17) & (el2 <= 7))
    assert wide1.sum() > narrow1.sum()


def test_field_of_view_range_and_azimuth_limits():
    # Sensor 1 sees 1..20 m over azimuth [-45, 45] deg; sensor 2 (the preset) everything.
    sensor1 = PRESETS["vlp16"].__class__("front", (-15.0, 15.0), 0.2, 1.0, 20.0, 10.0, (-45.0, 45.0))
    xyz2 = np.array([[10, 0, 0], [0.5, 0, 0], [25, 0, 0], [10, 9, 0], [10, 11, 0], [-10, 0, 0], [10, -9, 0]], float)
    expected2 = [True, False, False, True, False, False, True]
    pair = RegisteredPair(np.zeros((0, 3)), xyz2, np.eye(4), sensor1, PRESETS["vlp16"])
    _, keep2 = apply_step(pair, {"field_of_view": {}})
    assert keep2.tolist() == expected2


def test_field_of_view_without_sensor_model_says_what_to_give():
    xyz = np.array([[10.0, 0, 0], [10.0, 0, 1.0], [1.0, 1.0, 1.0]])  # elevation 0, 5.7, 35.3 deg
    pair = RegisteredPair(xyz, xyz)
    with pytest.raises(HypothesisError, match="sensor 1 has no sensor model.*--sensor.*elevation_deg"):
        apply_step(pair, {"field_of_view": {}})
    keep1, keep2 = apply_step(pair, {"field_of_view": {"elevation_deg": [-15, 15]}})
    assert keep1.tolist() == keep2.tolist() == [True, True, False]


# --- crop and outliers ---------------------------------------------------------------------


def test_crop_range_about_own_sensor_and_box_in_frame_1():
    T = pose_from_xyzrpy([5.0, 0, 0, 0, 0, 0])
    xyz1 = np.array([[1.0, 0, 0], [3.0, 0, 0], [9.0, 0, 0]])
    xyz2 = np.array([[6.0, 0, 0], [8.0, 0, 0], [14.5, 0, 0]])  # ranges 1, 3, 9.5 from sensor 2
    keep1, keep2 = apply_step(RegisteredPair(xyz1, xyz2, T), {"crop": {"min_range_m": 2, "max_range_m": 9}})
    assert keep1.tolist() == [False, True, True] and keep2.tolist() == [False, True, False]
    keep1, keep2 = apply_step(RegisteredPair(xyz1, xyz2, T), {"crop": {"box_m": [0, 7, -1, 1, -1, 1]}})
    assert keep1.tolist() == [True, True, False] and keep2.tolist() == [True, False, False]


def test_outliers_removes_isolated_points_of_each_cloud():
    rng = np.random.default_rng(3)
    dense = rng.normal(scale=0.2, size=(2000, 3))
    far = np.array([[30.0, 0, 0], [0, -40.0, 5]])
    xyz1 = np.vstack([dense, far])
    keep1, keep2 = apply_step(RegisteredPair(xyz1, dense[:500]), {"outliers": {"nb_neighbors": 20, "std_ratio": 2.0}})
    assert not keep1[-2:].any()
    assert keep1[:-2].mean() > 0.9 and keep2.mean() > 0.9
    # Too few points for the statistic: nothing removed.
    keep1, _ = apply_step(RegisteredPair(far, dense[:5]), {"outliers": {}})
    assert keep1.all()
