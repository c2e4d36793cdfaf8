"""Free space on uneven channel layouts: one range-image row per channel, rings in either
numbering, no evidence deep in a gap, the kernels against their per-point references, and
moving_objects on the simulated traffic seen by the VLP-32C, the Pandar40P and the HDL-64E."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from lidarfield import read_scan
from lidarfield.field import free_space as fs
from lidarfield.hypotheses import apply_step
from lidarfield.io.pose_files import read_kitti_poses
from lidarfield.pair import RegisteredPair
from lidarfield.poses import apply_pose, pose_from_xyzrpy, relative_pose
from lidarfield.registration.core import register_pair
from lidarfield.sensors.models import PRESETS, SensorModel
from lidarfield.simulation.raycast import simulate_scan
from lidarfield.simulation.scene import load_scene


def traffic_pair(sensor: str, y: float):
    """The two crossing cars seen from the south arm at a car roof's height (1.9 m), 0.1 s and
    0.7 m apart; 2 cm range noise; registered by the true poses."""
    scene, model = load_scene("paper-intersection-traffic"), PRESETS[sensor]
    poses = pose_from_xyzrpy([2, y, 1.9, 0, 0, 1.5708]), pose_from_xyzrpy([2.5, y + 0.5, 1.9, 0, 0, 1.62])
    scans = [
        simulate_scan(scene, model, pose, time_s=t, range_noise_m=0.02, seed=seed)
        for pose, t, seed in zip(poses, (0.0, 0.1), (1, 2))
    ]
    return register_pair(*scans, "truth")


def moved_removed_and_static_kept(pair) -> tuple[float, float]:
    outcome = apply_step(pair, {"moving_objects": {}})
    label = np.concatenate([pair.attributes1["object"], pair.attributes2["object"]])
    removed = ~np.concatenate([outcome.keep1, outcome.keep2])
    return removed[label > 0].mean(), 1 - removed[label == 0].mean()


@pytest.mark.parametrize(
    "sensor, y",
    # The cars 7-11 m ahead, then 18-22 m ahead. With a range-image row as tall as the widest
    # gap between channels (9.4 deg on the VLP-32C, 6 deg on the Pandar40P) 51% / 54% of the
    # cars' points went near, none far: the rows above and below reached the ground.
    [("vlp32c", -9), ("pandar40p", -9), ("hdl64", -9), ("vlp32c", -20), ("pandar40p", -20)],
)
def test_moving_cars_are_removed_on_uneven_layouts(sensor, y):
    moved, static = moved_removed_and_static_kept(traffic_pair(sensor, y))
    assert moved >= 0.7 and static >= 0.99


@pytest.fixture(scope="module")
def vlp32c_pair():
    return traffic_pair("vlp32c", -9)


def test_rows_follow_the_rings_in_either_numbering(vlp32c_pair):
    """The VLP-32C's rings by laser ID (as Argoverse 2 numbers them) and renumbered by elevation
    (as ROS drivers do) give the same image; so does no ring (the nearest channel): the
    simulated returns lie on their beams. A ring whose returns a tilt moved off their beam still
    lands on its channel."""
    model, xyz, ring = PRESETS["vlp32c"], vlp32c_pair.xyz1, vlp32c_pair.attributes1["ring"]
    by_elevation = np.argsort(np.argsort(model.elevation_deg))[ring]
    images = [fs.sensor_image(xyz, model, r).nearest for r in (ring, by_elevation, None)]
    assert np.array_equal(images[0], images[1]) and np.array_equal(images[0], images[2])
    rows = fs.channel_rows(fs.directions(xyz)[1], fs.sensor_channels(model), ring)
    assert len(np.unique(rows)) == 32
    lifted = xyz.copy()  # every return raised by 0.2 deg: the near rings' nearest channel changes
    lifted[:, 2] += np.hypot(xyz[:, 0], xyz[:, 1]) * math.tan(math.radians(0.2))
    assert np.array_equal(fs.channel_rows(fs.directions(lifted)[1], fs.sensor_channels(model), ring), rows)
    assert not np.array_equal(fs.channel_rows(fs.directions(lifted)[1], fs.sensor_channels(model)), rows)


def _directions_at(r: float, elevation_deg: np.ndarray, azimuth_deg: np.ndarray) -> np.ndarray:
    e, a = np.radians(elevation_deg), np.radians(azimuth_deg)
    return r * np.column_stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


def test_no_evidence_deep_in_the_gap_below_minus_15_6_degrees():
    """Every VLP-32C ray returned at 50 m. A point 10 m away on the -15.64 deg channel (or
    0.5 deg off it, within the 0.35 m margin's 2 deg) is in free space and not co-visible; one at
    -20 deg, 4.4 deg from the nearest beam, has no ray near it: no evidence, not co-visible
    either. One channel per row: the 0.33 deg rows near the horizon are rows of their own."""
    model = PRESETS["vlp32c"]
    azimuth = np.arange(-180, 180, model.azimuth_resolution_deg)
    elevation = np.repeat(model.elevation_deg, len(azimuth))
    image = fs.sensor_image(_directions_at(50.0, elevation, np.tile(azimuth, 32)), model)
    assert image.nearest.shape == (32, 1800) and np.isfinite(image.nearest).all()
    points = _directions_at(10.0, np.array([-15.639, -16.139, -20.0, -0.333]), np.array([10.1, 10.1, 10.1, 10.1]))
    assert list(fs.free_space_evidence(points, image, 0.2, 0.2)) == [True, True, False, True]
    assert not fs.co_visible(points, image, 0.2, 0.2).any()
    # the same directions on the wall at 50 m: co-visible, but the one in the gap and the one
    # 0.5 deg off its channel, beyond the margin's 0.43 deg there and the usual 1/3 deg spacing
    assert list(fs.co_visible(points * 5, image, 0.2, 0.2)) == [True, False, False, True]


def test_the_kernels_agree_with_their_references_on_an_uneven_layout(vlp32c_pair):
    """Sensor 1's VLP-32C image (rows from its rings) asked about static points, the cars that
    moved, points in its 9.4 deg gap and out of view: the vectorised tests and the per-point
    references agree point for point."""
    rng = np.random.default_rng(0)
    pair = vlp32c_pair
    image = fs.sensor_image(pair.xyz1, pair.sensor1, pair.attributes1["ring"])
    cars = np.flatnonzero(pair.attributes2["object"] > 0)
    chosen = np.concatenate([rng.choice(len(pair.xyz2), 300, replace=False), rng.choice(cars, 300, replace=False)])
    gap = _directions_at(3.0, rng.uniform(-26, -14, 100), rng.uniform(-180, 180, 100))
    sample = np.vstack([pair.xyz2[chosen], gap, [[0.0, 0.0, -5.0], [5.0, 0.0, 50.0]]])
    ring = pair.attributes1["ring"]
    fast = fs.free_space_evidence(sample, image, 0.2, 0.2)
    assert np.array_equal(fast, fs.free_space_evidence_loop(sample, pair.xyz1, image, 0.2, 0.2, ring))
    assert fast[300:600].sum() > 20 and fast[600:700].any() and not fast[-2:].any()
    seen = fs.co_visible(sample, image, 0.2, 0.2, 200.0)
    assert np.array_equal(seen, fs.co_visible_loop(sample, pair.xyz1, image, 0.2, 0.2, 200.0, ring))
    assert seen[:300].mean() > 0.9 and not (seen & fast).any()


def test_on_the_real_os1_128_frames_it_removes_the_object_that_approached(shared_data):
    """Frames 0, 1, 2 of the OS1-128 at an urban intersection (0.1 s and about 0.25 m apart,
    placed by the recording's poses), on the recording's own beam angles: frame 2's copy of a
    low object 27 m away that comes about 0.6 m nearer per frame (docs/hypotheses.md) is all
    that goes from pair 1-2; pair 0-1 takes 13 points of a thin line 7 m up from frame 0 (most
    likely a static cable that the beams graze), nothing else."""
    folder = shared_data / "ouster-os1-128"
    beams = json.loads((folder / "OS-1-128_v2.3.0_1024x10.json").read_text())["beam_altitude_angles"]
    model = SensorModel("os1-128-recorded", tuple(beams), 360 / 1024, 0.3, 200.0, 10.0)
    poses = read_kitti_poses(folder / "OS-1-128_v2.3.0_1024x10_lb_n3_poses_kitti.txt")
    xyz = [read_scan(folder / f"lb_n3_scan{k}_xyz_refl_float32.bin").xyz for k in range(3)]

    def removed(a: int, b: int):
        T = relative_pose(poses[a], poses[b])
        pair = RegisteredPair(xyz[a], apply_pose(T, xyz[b]), T, model, model, registration={"method": "truth"})
        outcome = apply_step(pair, {"moving_objects": {}})
        return pair.xyz1[~outcome.keep1], pair.xyz2[~outcome.keep2]

    first, second = removed(1, 2)
    assert len(first) == 0 and 20 <= len(second) <= 40
    assert np.abs(second[:, :2] - [-26.9, -1.1]).max() < 1.5  # one object, about 1.7 m long
    first, second = removed(0, 1)
    assert 5 <= len(first) <= 20 and len(second) == 0
    assert np.abs(first - [2.1, 14.15, 4.8]).max() < 1.2  # the thin line 15 m away


def test_a_ring_that_is_no_channel_is_read_as_the_nearest_channel():
    """A driver that writes ring 0 for every point (as a bag of a scan without rings does), or
    rings of another layout: a ring whose returns lie farther from its channel than a gap is
    ignored, so the rows are those of no ring at all; real rings are kept."""
    channels = np.radians(np.arange(-15.0, 16.0, 2.0))
    rng = np.random.default_rng(7)
    true = rng.integers(0, len(channels), 5000)
    elevation = channels[true] + rng.normal(0.0, np.radians(0.05), len(true))
    assert np.array_equal(
        fs.channel_rows(elevation, channels, np.zeros(len(true))), fs.channel_rows(elevation, channels)
    )
    assert np.array_equal(fs.channel_rows(elevation, channels, true.astype(float)), true)
    reversed_ids = (len(channels) - 1 - true).astype(float)  # another numbering: matched by elevation
    assert np.array_equal(fs.channel_rows(elevation, channels, reversed_ids), true)


def test_a_ring_with_mixed_returns_is_matched_by_its_median_elevation():
    """A ring a third of whose returns lie two gaps above its beam (mixed returns at depth
    edges; the real HDL-32E capture's lowest rings reach 5 deg above theirs near the sensor):
    its median elevation is its beam's, so it keeps its channel where its mean (over half a gap
    up) would be matched to the next one; channel-aware binning measures the same elevation."""
    from lidarfield.field.channels import measured_rings, ring_elevations

    channels = np.radians(np.arange(-15.0, 16.0, 2.0))
    rng = np.random.default_rng(3)
    true = rng.integers(1, len(channels), 6000)  # ring 0 has no returns: rings matched by nearness
    true[:900] = 3
    elevation = channels[true] + rng.normal(0.0, np.radians(0.02), len(true))
    elevation[:400] += 2 * np.radians(2.0)
    rings = measured_rings(elevation, true.astype(float))
    assert np.degrees(rings.elevation[rings.names == 3][0]) == pytest.approx(-9.0, abs=0.05)
    # each ring's spread (computed when asked for) against a plain per-ring reference
    plain = [np.median(np.abs(elevation[true == n] - np.median(elevation[true == n]))) for n in rings.names]
    assert np.array_equal(rings.spread, plain) and rings.spread[rings.names == 3][0] > np.radians(0.01)
    mean = np.degrees(elevation[true == 3].mean())
    assert abs(mean + 9.0) > 1.0  # nearer the channel above than its own
    assert np.array_equal(fs.channel_rows(elevation, channels, true.astype(float)), true)
    xyz = _directions_at(20.0, np.degrees(elevation), rng.uniform(-180, 180, len(true)))
    measured = ring_elevations(xyz, true, np.eye(4))
    np.testing.assert_allclose(measured, np.degrees(channels[1:]), atol=0.05)
