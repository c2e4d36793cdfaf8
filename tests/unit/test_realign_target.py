"""``realign``'s second fit takes cloud 1's normals from its first (``Target.subset``): they must
be those made afresh on the kept points, to the bit, on the drive's 80-channel pair, the zoo's
two-lidar rig (two VLP-32C, uneven channels, one upside down) and the real shared pairs (VLP-16,
HDL-32E, OS1-128), for the points both sensors saw and for a dropped block."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.drive import drive_pair
from helpers.real_pairs import pair_at, real_pair
from lidarfield.field.free_space import shared_points
from lidarfield.hypotheses.realign import Params, Target


def assert_same_target(carried: Target, fresh: Target) -> None:
    np.testing.assert_array_equal(np.asarray(carried.cloud.points), np.asarray(fresh.cloud.points))
    np.testing.assert_array_equal(np.asarray(carried.cloud.normals), np.asarray(fresh.cloud.normals))
    np.testing.assert_array_equal(carried.one_ring, fresh.one_ring)


def kept_sets(xyz: np.ndarray, shared: np.ndarray) -> dict[str, np.ndarray]:
    """The points both sensors saw, and all but a 4 m block about a point of the cloud."""
    centre = xyz[len(xyz) // 3]
    return {"shared": shared, "block dropped": np.any(np.abs(xyz - centre) > 2.0, axis=1)}


@pytest.fixture(scope="module")
def drive():
    return drive_pair()


@pytest.mark.parametrize("kept", ["shared", "block dropped"])
def test_a_subset_of_the_drive_target_is_the_target_made_afresh(drive, kept):
    params = Params()
    full = Target.of(drive.xyz1, drive.sensor1, params)
    keep = kept_sets(drive.xyz1, shared_points(drive)[0])[kept]
    assert 0 < np.count_nonzero(~keep) < len(keep)
    carried = full.subset(drive.xyz1, keep, drive.sensor1, params)
    assert_same_target(carried, Target.of(drive.xyz1[keep], drive.sensor1, params))


def test_without_a_sensor_model_or_with_voxels_a_subset_is_made_afresh_the_same(drive):
    keep = kept_sets(drive.xyz1, shared_points(drive)[0])["block dropped"]
    for sensor, params in ((None, Params()), (drive.sensor1, Params(voxel_m=0.2))):
        carried = Target.of(drive.xyz1, sensor, params).subset(drive.xyz1, keep, sensor, params)
        fresh = Target.of(drive.xyz1[keep], sensor, params)
        np.testing.assert_array_equal(np.asarray(carried.cloud.normals), np.asarray(fresh.cloud.normals))


def test_a_subset_of_a_two_lidar_rig_target_is_the_target_made_afresh():
    from helpers.fault_zoo import _sim_rig_scan
    from lidarfield.poses import pose_from_xyzrpy
    from lidarfield.registration import register_pair
    from lidarfield.simulation.scene import load_scene

    scene = load_scene("paper-intersection")
    scans = [
        _sim_rig_scan(scene, pose_from_xyzrpy(p), 0.0, k)
        for k, p in enumerate(([0, 0, 2, 0, 0, 0], [2, 1, 2, 0, 0, 0.1]))
    ]
    pair = register_pair(*scans, "truth")
    assert len(pair.lidars(1)) == 2
    params = Params()
    full = Target.of(pair.xyz1, pair.sensor1, params)
    for keep in kept_sets(pair.xyz1, shared_points(pair)[0]).values():
        assert 0 < np.count_nonzero(~keep) < len(keep)
        carried = full.subset(pair.xyz1, keep, pair.sensor1, params)
        assert_same_target(carried, Target.of(pair.xyz1[keep], pair.sensor1, params))


@pytest.mark.parametrize("name", ["expd", "hdl32", "os1 0->1"])
def test_a_subset_of_a_real_target_is_the_target_made_afresh(shared_data, name):
    pair = pair_at(real_pair(shared_data, name))
    params = Params()
    full = Target.of(pair.xyz1, pair.sensor1, params)
    assert full.one_ring.any()  # the rings' normals are exercised, not only the neighbours'
    for keep in kept_sets(pair.xyz1, shared_points(pair)[0]).values():
        carried = full.subset(pair.xyz1, keep, pair.sensor1, params)
        assert_same_target(carried, Target.of(pair.xyz1[keep], pair.sensor1, params))
