"""Ray-cast scans: geometry against analytic answers, options, reproducibility."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest
import trimesh

from lidarfield.errors import ConfigError
from lidarfield.io import read_scan, write_scan
from lidarfield.poses import pose_from_xyzrpy as pose_from_values
from lidarfield.sensors.models import PRESETS, SensorModel
from lidarfield.simulation.raycast import azimuth_steps, first_hits, first_hits_reference, simulate_scan
from lidarfield.simulation.scene import load_scene, scene_from_dict

SENSOR = PRESETS["paper-sim-80"]
POSE1 = pose_from_values([0, 0, 3, 0, 0, 0])
POSE2 = pose_from_values([1, 1, 3, 0, 0, 0.05])
GROUND_RING_M = 3 / np.tan(np.radians(22))  # 7.4253 m


@pytest.fixture(scope="module")
def paper():
    return load_scene("paper-intersection")


@pytest.fixture(scope="module")
def scan1(paper):
    return simulate_scan(paper, SENSOR, POSE1)


def _world(scan, pose=None):
    pose = scan.pose if pose is None else pose
    return scan.xyz @ pose[:3, :3].T + pose[:3, 3]


def _surface_distance(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    caster = o3d.t.geometry.RaycastingScene()
    caster.add_triangles(
        o3d.core.Tensor(mesh.vertices.astype(np.float32)), o3d.core.Tensor(mesh.faces.astype(np.uint32))
    )
    return caster.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()


def _exact_surface_distance(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """Float64 distance to the nearest triangle, by brute force over all triangles."""
    n, m = len(points), len(mesh.faces)
    closest = trimesh.triangles.closest_point(np.tile(mesh.triangles, (n, 1, 1)), np.repeat(points, m, axis=0))
    return np.linalg.norm(closest - np.repeat(points, m, axis=0), axis=1).reshape(n, m).min(axis=1)


def _azimuth_deg(xyz):
    return np.degrees(np.arctan2(xyz[:, 1], xyz[:, 0])) % 360


def _elevation_deg(xyz):
    return np.degrees(np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1])))


def test_paper_scan_point_count_and_attributes(scan1):
    print(f"\npaper-intersection, paper-sim-80 at (0, 0, 3): {len(scan1)} points of {SENSOR.channels * 1800} rays")
    assert 80_000 < len(scan1) < 100_000  # ground + four buildings; the sky above them is a miss
    assert scan1.sensor == SENSOR and np.array_equal(scan1.pose, POSE1)
    assert "paper-intersection" in scan1.source and "paper-sim-80" in scan1.source
    ring, time = scan1.attributes["ring"], scan1.attributes["time"]
    assert ring.dtype == np.int32 and ring.min() == 0 and ring.max() <= 79
    assert time.min() == 0 and time.max() == pytest.approx(1799 / 1800 / SENSOR.rotation_hz)
    # each point lies along its own beam: ring -> elevation, time -> azimuth
    assert np.allclose(_elevation_deg(scan1.xyz), np.asarray(SENSOR.elevation_deg)[ring], atol=1e-9)
    assert np.allclose(_azimuth_deg(scan1.xyz), time * SENSOR.rotation_hz * 360, atol=1e-7)


def test_every_hit_lies_on_the_scene_surface(paper, scan1):
    mesh = paper.mesh_at(0.0)
    world = _world(scan1)
    assert _surface_distance(mesh, world).max() < 1e-4
    sample = world[np.random.default_rng(1).choice(len(world), 200, replace=False)]
    assert _exact_surface_distance(mesh, sample).max() < 1e-9  # the float64 range refinement


def test_ground_ring_starts_at_3_over_tan_22_in_open_directions(scan1):
    world = _world(scan1)
    ground = np.abs(world[:, 2]) < 1e-9
    step = 360 / 1800 + 1e-9  # one azimuth step, with room for rounding
    horizontal = np.hypot(world[:, 0], world[:, 1])
    azimuth = _azimuth_deg(scan1.xyz)
    for street in (0, 90, 180, 270):
        near = ground & (np.abs((azimuth - street + 180) % 360 - 180) <= step)
        nearest = np.argmin(np.where(near, horizontal, np.inf))
        assert horizontal[nearest] == pytest.approx(GROUND_RING_M, abs=1e-9)
        assert scan1.attributes["ring"][nearest] == 0
    # towards the buildings (diagonals) the lowest beam hits a wall before the ground ring
    lowest = scan1.attributes["ring"] == 0
    for diagonal in (45, 135, 225, 315):
        towards = lowest & (np.abs((azimuth - diagonal + 180) % 360 - 180) <= step)
        assert towards.sum() == 3 and not ground[towards].any() and horizontal[towards].max() < GROUND_RING_M


def test_no_return_outside_the_beams(scan1):
    elevation = _elevation_deg(scan1.xyz)
    assert elevation.max() <= max(SENSOR.elevation_deg) + 1e-9
    assert elevation.min() >= min(SENSOR.elevation_deg) - 1e-9


def test_open3d_kernel_matches_the_reference(paper):
    rng = np.random.default_rng(7)
    origins = rng.uniform([-3, -3, 0.5], [3, 3, 8], size=(4000, 3))
    directions = rng.normal(size=(4000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    mesh = paper.mesh_at(0.0)
    fast, _ = first_hits(mesh, origins, directions)
    plain, _ = first_hits_reference(mesh, origins, directions)
    assert np.isfinite(fast).sum() > 2000
    assert np.array_equal(np.isfinite(fast), np.isfinite(plain))
    hit = np.isfinite(fast)
    assert np.abs(fast[hit] - plain[hit]).max() < 1e-9


def test_range_limits_of_model_and_option(paper, scan1):
    ranges = np.linalg.norm(scan1.xyz, axis=1)
    limited = simulate_scan(paper, SENSOR, POSE1, max_range_m=9.0)
    assert np.linalg.norm(limited.xyz, axis=1).max() <= 9.0
    assert len(limited) == np.count_nonzero(ranges <= 9.0)
    near_blind = SensorModel("near-blind", SENSOR.elevation_deg, 0.2, min_range_m=10.0)
    assert np.linalg.norm(simulate_scan(paper, near_blind, POSE1).xyz, axis=1).min() >= 10.0
    with pytest.raises(ConfigError):
        simulate_scan(paper, SENSOR, POSE1, max_range_m=-1)
    with pytest.raises(ConfigError):
        simulate_scan(paper, SENSOR, POSE1, dropout=1.5)


def test_azimuth_limits(paper):
    front = SensorModel("front", (-10.0, 0.0), 1.0, azimuth_limits_deg=(-45.0, 45.0))
    steps, n = azimuth_steps(front)
    assert n == 360 and len(steps) == 91
    azimuth = _azimuth_deg(simulate_scan(paper, front, POSE1).xyz)
    assert np.all((azimuth <= 45 + 1e-9) | (azimuth >= 315 - 1e-9))


def test_rolling_shutter_without_motion_is_the_instantaneous_scan(paper, scan1):
    rolled = simulate_scan(paper, SENSOR, POSE1, rolling_shutter=True)
    assert np.array_equal(rolled.xyz, scan1.xyz)
    for name in ("ring", "time"):
        assert np.array_equal(rolled.attributes[name], scan1.attributes[name])


@pytest.fixture(scope="module")
def wall():
    """A wall facing the sensor at x = 10 m (a plane turned about y)."""
    return scene_from_dict(
        {
            "objects": [
                {"kind": "plane", "size": [40, 40], "transform": {"translation": [10, 0, 0], "rpy": [0, np.pi / 2, 0]}}
            ]
        }
    )


def test_rolling_shutter_seam_gap_is_velocity_times_period(wall):
    velocity = 2.0
    scan = simulate_scan(wall, SENSOR, np.eye(4), rolling_shutter=True, linear_velocity_mps=(velocity, 0, 0))
    time = scan.attributes["time"]
    first, last = time == time.min(), time == time.max()
    gap = scan.xyz[first, 0].mean() - scan.xyz[last, 0].mean()
    period = 1 / SENSOR.rotation_hz
    assert np.allclose(scan.xyz[first, 0], 10.0)
    assert gap == pytest.approx(velocity * period, abs=velocity * period / 1800 + 1e-9)
    # every point: the wall seen from where the sensor was at its firing time
    assert np.allclose(scan.xyz[:, 0], 10.0 - velocity * time, atol=1e-9)


def test_rolling_shutter_turning_sensor_sees_the_wall_at_its_turned_azimuth(wall):
    yaw_rate = 2.0
    scan = simulate_scan(wall, SENSOR, np.eye(4), rolling_shutter=True, angular_velocity_rps=(0, 0, yaw_rate))
    ring, time = scan.attributes["ring"], scan.attributes["time"]
    elevation = np.radians(np.asarray(SENSOR.elevation_deg)[ring])
    azimuth = 2 * np.pi * time * SENSOR.rotation_hz
    expected_range = 10.0 / (np.cos(elevation) * np.cos(azimuth + yaw_rate * time))
    assert np.allclose(np.linalg.norm(scan.xyz, axis=1), expected_range, rtol=1e-12)


def test_noise_and_dropout_are_seeded(paper, scan1, tmp_path):
    sigma = 0.02
    noisy = simulate_scan(paper, SENSOR, POSE1, range_noise_m=sigma, seed=3)
    assert len(noisy) == len(scan1)
    residual = np.linalg.norm(noisy.xyz, axis=1) - np.linalg.norm(scan1.xyz, axis=1)
    assert np.std(residual) == pytest.approx(sigma, rel=0.03) and abs(residual.mean()) < 1e-3
    again = simulate_scan(paper, SENSOR, POSE1, range_noise_m=sigma, seed=3)
    other = simulate_scan(paper, SENSOR, POSE1, range_noise_m=sigma, seed=4)
    assert np.array_equal(noisy.xyz, again.xyz) and not np.allclose(noisy.xyz, other.xyz)

    dropped = simulate_scan(paper, SENSOR, POSE1, dropout=0.25, seed=3)
    kept = len(dropped) / len(scan1)
    assert kept == pytest.approx(0.75, abs=3 * np.sqrt(0.25 * 0.75 / len(scan1)))

    paths = [tmp_path / f"{name}.parquet" for name in ("a", "b", "c")]
    for path, seed in zip(paths, (5, 5, 6)):
        write_scan(simulate_scan(paper, SENSOR, POSE1, range_noise_m=sigma, dropout=0.1, seed=seed), path)
    a, b, c = (p.read_bytes() for p in paths)
    assert a == b and a != c


def _car_points(scan):
    """World points off the ground in the car's lane (the buildings are at |y| >= 4), and their times."""
    world = _world(scan)
    car = (world[:, 2] > 1e-6) & (np.abs(world[:, 1] - 2) <= 0.9)
    return world[car], scan.attributes["time"][car]


def test_moving_object_is_displaced_by_velocity_times_dt():
    scene = load_scene("paper-intersection-moving-car")  # car front face at x = 6.75 - 5 t
    early, _ = _car_points(simulate_scan(scene, SENSOR, POSE1, time_s=0.0))
    late, _ = _car_points(simulate_scan(scene, SENSOR, POSE1, time_s=0.2))
    assert len(early) > 100 and len(late) > 100
    assert early[:, 0].min() == pytest.approx(6.75, abs=1e-9)
    assert late[:, 0].min() == pytest.approx(5.75, abs=1e-9)
    assert _surface_distance(scene.mesh_at(0.2), _world(simulate_scan(scene, SENSOR, POSE1, time_s=0.2))).max() < 1e-4
    # with rolling shutter the car also moves during the sweep: each point at its own time
    rolled, time = _car_points(simulate_scan(scene, SENSOR, POSE1, time_s=0.2, rolling_shutter=True))
    front = np.abs(rolled[:, 0] - (5.75 - 5 * time)) < 1e-9
    assert front.sum() > 50 and time[front].min() > 0


@pytest.mark.parametrize("rolling_shutter", [False, True])
def test_each_point_is_labelled_with_the_moving_object_it_hit(rolling_shutter):
    """object = the car's place in the scene's objects on the car's surface (where it is at the
    point's own time), 0 everywhere else; the static scene is cast as before."""
    scene = load_scene("paper-intersection-traffic")
    numbers = {o.name: n for n, o in scene.labelled_objects()}
    assert numbers == {"car-west": 10, "car-east": 11}
    scan = simulate_scan(scene, SENSOR, POSE2, time_s=0.1, rolling_shutter=rolling_shutter, seed=3)
    label, time, world = scan.attributes["object"], scan.attributes["time"], _world(scan)
    assert label.dtype == np.int32 and set(np.unique(label)) == {0, 10, 11}
    for number, obj in scene.labelled_objects():
        moved = time[:, None] * obj.velocity_mps if rolling_shutter else 0.0
        own = world - moved  # where the point is relative to the car at time_s
        lo, hi = obj.mesh_at(0.1).bounds
        on_car = np.all((own >= lo - 1e-6) & (own <= hi + 1e-6), axis=1)
        assert (label == number).sum() > 100
        assert np.array_equal(on_car, label == number)
    static = simulate_scan(load_scene("paper-intersection"), SENSOR, POSE2, time_s=0.1, seed=3)
    assert not static.attributes["object"].any()


@pytest.mark.parametrize("suffix", ["parquet", "pcd", "ply", "csv", "npy", "las"])
def test_the_object_label_survives_the_scan_files(tmp_path, suffix):
    scan = simulate_scan(load_scene("paper-intersection-traffic"), PRESETS["vlp16"], POSE1)
    assert scan.attributes["object"].any()
    write_scan(scan, tmp_path / f"scan.{suffix}")
    assert np.array_equal(read_scan(tmp_path / f"scan.{suffix}").attributes["object"], scan.attributes["object"])


def test_a_carried_body_is_labelled_with_its_place_in_the_scene():
    truck = load_scene("paper-intersection-ego-truck")
    scan = simulate_scan(truck, SENSOR, POSE1)
    lo, hi = np.array([-5.3, -1.1, -2.8]) - 1e-6, np.array([-0.3, 1.1, 0.4]) + 1e-6
    on_body = np.all((scan.xyz >= lo) & (scan.xyz <= hi), axis=1)
    assert on_body.sum() > 10_000
    assert np.array_equal(scan.attributes["object"], np.where(on_body, -len(truck.objects), 0))  # carried: < 0


def test_paper_pair_by_true_pose_agrees_on_the_building_faces(paper, scan1):
    scan2 = simulate_scan(paper, SENSOR, POSE2)
    T_1_2 = np.linalg.inv(POSE1) @ POSE2
    in_frame1 = scan2.xyz @ T_1_2[:3, :3].T + T_1_2[:3, 3]
    mesh_in_frame1 = paper.mesh_at(0.0).copy().apply_transform(np.linalg.inv(POSE1))
    buildings = in_frame1[:, 2] > -3 + 1e-6  # above the ground plane (z = -3 in frame 1)
    assert buildings.sum() > 20_000
    assert _surface_distance(mesh_in_frame1, in_frame1[buildings]).max() < 1e-3
    # and a wrong pose (scan 2 left where it is) does not agree: the check can fail
    assert np.median(_surface_distance(mesh_in_frame1, scan2.xyz[buildings])) > 0.1


def test_a_carried_body_is_at_the_same_place_in_every_scan_and_hides_what_is_behind_it():
    """The ego-truck scene: the cargo body moves with the sensor (frame: sensor)."""
    truck, paper = load_scene("paper-intersection-ego-truck"), load_scene("paper-intersection")
    sensor = SensorModel("test-16", elevation_deg=tuple(np.linspace(-22, 9.6, 16)), azimuth_resolution_deg=1.0)
    assert len(truck.mesh_at(0.0).faces) == len(paper.mesh_at(0.0).faces)  # the world holds no truck
    body_min, body_max = np.array([-5.3, -1.1, -2.8]), np.array([-0.3, 1.1, 0.4])
    on_body = []
    for pose in (POSE1, POSE2, pose_from_values([3, -2, 3, 0.02, 0, 1.0])):
        scan = simulate_scan(truck, sensor, pose)
        inside = np.all((scan.xyz >= body_min - 1e-6) & (scan.xyz <= body_max + 1e-6), axis=1)
        on_body.append(scan.xyz[inside])
        # every ray the body does not stop sees the scene as it is without the body
        open_scene = simulate_scan(paper, sensor, pose)
        seen = {
            (r, t): p for r, t, p in zip(open_scene.attributes["ring"], open_scene.attributes["time"], open_scene.xyz)
        }
        rays = zip(scan.attributes["ring"][~inside], scan.attributes["time"][~inside], scan.xyz[~inside])
        assert all(np.array_equal(seen[(r, t)], p) for r, t, p in rays)
    assert len(on_body[0]) > 0.3 * 16 * 360  # the sensor's rear view, behind a 0.3 m gap
    for other in on_body[1:]:
        assert np.array_equal(other, on_body[0])


# Calibration faults: the ray is the truth, the reported point the measurement.
FAULT_SENSOR = SensorModel("test-8", elevation_deg=tuple(np.linspace(-20, -6, 8)), azimuth_resolution_deg=2.0)


@pytest.fixture(scope="module")
def ground():
    """A flat ground at z = 0, 200 x 200 m; the sensor 3 m above it."""
    return scene_from_dict({"objects": [{"kind": "plane", "size": [200, 200]}]})


def _wall_true_range(scan, sensor):
    """The range to the wall x = 10 of each point's ray at its nominal elevation and azimuth."""
    ring, time = scan.attributes["ring"], scan.attributes["time"]
    elevation = np.radians(np.asarray(sensor.elevation_deg)[ring])
    azimuth = 2 * np.pi * time * sensor.rotation_hz
    return 10.0 / (np.cos(elevation) * np.cos(azimuth))


def test_range_fault_reports_scale_times_true_range_plus_offset_on_a_wall(wall):
    clean = simulate_scan(wall, FAULT_SENSOR, np.eye(4))
    scale, offset = 1.003, -0.04
    faulted = simulate_scan(wall, FAULT_SENSOR, np.eye(4), range_scale=scale, range_offset_m=offset)
    for name in ("ring", "time"):  # the same rays return: limits act on the true range
        assert np.array_equal(faulted.attributes[name], clean.attributes[name])
    true_range = _wall_true_range(faulted, FAULT_SENSOR)
    assert np.allclose(np.linalg.norm(clean.xyz, axis=1), true_range, rtol=0, atol=1e-9)
    assert np.allclose(np.linalg.norm(faulted.xyz, axis=1), scale * true_range + offset, rtol=0, atol=1e-9)
    # along the same (nominal) direction as the fault-free point
    unit = clean.xyz / np.linalg.norm(clean.xyz, axis=1)[:, None]
    assert np.allclose(faulted.xyz, unit * (scale * true_range + offset)[:, None], rtol=0, atol=1e-9)
    assert f"range_scale={scale!r}" in faulted.source and f"range_offset_m={offset!r}" in faulted.source


def test_range_fault_on_the_ground_scales_the_ground_rings(ground):
    pose = pose_from_values([0, 0, 3, 0, 0, 0])
    scan = simulate_scan(ground, FAULT_SENSOR, pose, range_scale=0.99, range_offset_m=0.25)
    elevation = np.radians(np.asarray(FAULT_SENSOR.elevation_deg)[scan.attributes["ring"]])
    true_range = 3.0 / np.sin(-elevation)
    assert len(scan) == FAULT_SENSOR.channels * 180
    assert np.allclose(np.linalg.norm(scan.xyz, axis=1), 0.99 * true_range + 0.25, rtol=0, atol=1e-9)


def test_elevation_offsets_cast_the_actual_beam_and_report_it_at_the_nominal_elevation(ground):
    pose = pose_from_values([0, 0, 3, 0, 0, 0])
    offsets = np.linspace(-0.5, 0.5, FAULT_SENSOR.channels)
    scan = simulate_scan(ground, FAULT_SENSOR, pose, elevation_offsets_deg=offsets)
    ring = scan.attributes["ring"]
    nominal = np.asarray(FAULT_SENSOR.elevation_deg)[ring]
    actual = nominal + offsets[ring]
    # reported: the nominal elevation, at the true range of the beam that fired at the actual one
    assert np.allclose(_elevation_deg(scan.xyz), nominal, rtol=0, atol=1e-9)
    true_range = 3.0 / np.sin(np.radians(-actual))
    assert np.allclose(np.linalg.norm(scan.xyz, axis=1), true_range, rtol=0, atol=1e-9)
    # so a beam fired lower than it believes (negative offset) reports the ground too high
    height = scan.xyz[:, 2] + 3.0
    assert np.allclose(height, 3.0 - 3.0 * np.sin(np.radians(nominal)) / np.sin(np.radians(actual)), atol=1e-9)
    assert np.all(height[offsets[ring] < 0] > 1e-3) and np.all(height[offsets[ring] > 0] < -1e-3)
    assert "elevation_offsets_deg=[-0.5," in scan.source


def test_elevation_offsets_on_a_wall_hit_at_the_actual_elevation(wall):
    offsets = np.full(FAULT_SENSOR.channels, 0.3)
    scan = simulate_scan(wall, FAULT_SENSOR, np.eye(4), elevation_offsets_deg=offsets, range_scale=1.01)
    ring, time = scan.attributes["ring"], scan.attributes["time"]
    azimuth = 2 * np.pi * time * FAULT_SENSOR.rotation_hz
    actual = np.radians(np.asarray(FAULT_SENSOR.elevation_deg)[ring] + 0.3)
    true_range = 10.0 / (np.cos(actual) * np.cos(azimuth))
    assert np.allclose(np.linalg.norm(scan.xyz, axis=1), 1.01 * true_range, rtol=0, atol=1e-9)
    assert np.allclose(_elevation_deg(scan.xyz), np.asarray(FAULT_SENSOR.elevation_deg)[ring], atol=1e-9)


def test_zero_faults_are_the_fault_free_scan(wall):
    clean = simulate_scan(wall, FAULT_SENSOR, np.eye(4))
    zero = simulate_scan(
        wall, FAULT_SENSOR, np.eye(4), range_scale=1.0, range_offset_m=0.0, elevation_offsets_deg=[0.0] * 8
    )
    assert np.array_equal(zero.xyz, clean.xyz)
    assert "range_scale" not in zero.source and "range_offset_m" not in zero.source


@pytest.mark.parametrize(
    "kwargs, expected",
    [
        ({"range_scale": 0.0}, "range scale must be positive"),
        ({"range_scale": -1.0}, "range scale must be positive"),
        ({"range_offset_m": float("nan")}, "range offset finite"),
        (
            {"elevation_offsets_deg": [0.1] * 7},
            "elevation offsets: need one value per beam of sensor test-8 (8 beams), got 7",
        ),
        ({"elevation_offsets_deg": [[0.1] * 8]}, "need one value per beam of sensor test-8 (8 beams), got 8"),
        ({"elevation_offsets_deg": [0.1] * 7 + [float("inf")]}, "must be finite"),
        ({"elevation_offsets_deg": ["a"] * 8}, "must be numbers"),
    ],
)
def test_bad_faults_are_one_line_errors(wall, kwargs, expected):
    with pytest.raises(ConfigError) as e:
        simulate_scan(wall, FAULT_SENSOR, np.eye(4), **kwargs)
    assert expected in str(e.value) and "\n" not in str(e.value)
