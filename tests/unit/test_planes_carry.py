"""The calibrations' normals carried past removed points (``carried_planes``, the fast path)
against normals computed anew on the survivors (the plain reference): equal to the bit, on
synthetic clouds with duplicates, on a real scan, and from stage to stage (``explain``,
``lidarfield run``) on the two-lidar rig and the real HDL-32E pair."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.clouds import removals, synthetic_cloud
from lidarfield.hypotheses import apply_step, parse_step
from lidarfield.hypotheses import range_calibration as module
from lidarfield.hypotheses.range_calibration import CarriedPlanes, Planes, carried_planes, planes_of
from lidarfield.io import read_scan

K = 12  # the calibrations' default normal_k


def asked(planes: Planes, rows: np.ndarray) -> None:
    """Have ``planes`` compute the normals of ``rows``, as a fit pairing points with them does."""
    planes.on_planes(np.ones(len(rows), dtype=bool), rows)


def computed(planes: Planes) -> np.ndarray:
    return ~np.isnan(planes.normals[:, 0])


def carried_as_computed(xyz: np.ndarray, keep: np.ndarray, rows: np.ndarray) -> tuple[int, int]:
    """Normals of ``rows`` computed, carried to the survivors ``keep`` and compared with planes
    of the survivors made anew, where carried and then where every survivor's is asked for;
    (normals carried, survivors' normals that could be: computed before, no tie)."""
    before = Planes(xyz, K)
    asked(before, rows)
    carried = carried_planes(before, xyz[keep], keep)
    fresh = Planes(xyz[keep], K)
    taken = np.flatnonzero(computed(carried))
    asked(fresh, taken)
    np.testing.assert_array_equal(carried.normals[taken], fresh.normals[taken])
    np.testing.assert_array_equal(carried.neighbours[taken], fresh.neighbours[taken])
    every = np.arange(len(fresh.other))
    asked(carried, every)
    asked(fresh, every)
    np.testing.assert_array_equal(carried.normals, fresh.normals)
    carryable = np.count_nonzero(keep & (before.neighbours[:, 0] >= 0))
    return len(taken), carryable


@pytest.mark.parametrize("seed", range(3))
def test_carried_normals_equal_normals_computed_anew_on_synthetic_clouds(seed):
    """A surface with a point repeated 30 times, doubled points, a tight cluster and isolated
    points, after each kind of removal: a normal whose neighbourhood has equally near points
    is not carried (which of them a search picks may change; here most have a doubled point
    among their 13 nearest), the others are where none of their 12 nearest was removed."""
    rng = np.random.default_rng(seed)
    xyz = synthetic_cloud(rng)
    rows = np.flatnonzero(rng.random(len(xyz)) < 0.5)
    for label, keep in removals(xyz, rng).items():
        if np.count_nonzero(keep) <= K:
            continue  # too few points to fit a calibration (check_clouds)
        taken, carryable = carried_as_computed(xyz, keep, rows)
        assert 0 < taken <= carryable, (label, taken, carryable)
        if label in ("nothing", "some copies of duplicates"):  # no carried neighbourhood holds one removed
            assert taken == carryable, label
        else:
            assert taken < carryable, label


def test_carried_normals_on_a_real_scan(expd):
    """The ExpD VLP-16 scan after a field-of-view sector and after a crop at 20 m: the same
    normals as computed anew; most of those computed before are carried, not those next to
    what was removed."""
    xyz = read_scan(expd / "Cloud1_ExpD.txt").xyz.astype(np.float64)
    rows = np.arange(0, len(xyz), 3)
    azimuth = np.degrees(np.arctan2(xyz[:, 1], xyz[:, 0]))
    for keep in (~((azimuth > 100) & (azimuth < 160)), np.linalg.norm(xyz, axis=1) < 20):
        taken, carryable = carried_as_computed(xyz, keep, rows)
        assert 0.8 * carryable < taken < carryable, (taken, carryable)


@pytest.mark.parametrize("source", ["rig", "hdl32"])
def test_a_stages_calibrations_take_the_normals_carried_from_the_stage_before(source, request, monkeypatch):
    """A stage that removes points passes the planes of the stage before on (``carry_planes``,
    made when first asked for), and its calibrations fit what they fit with planes made anew,
    to the bit, computing a quarter fewer normals at least: on the two-lidar rig (two VLP-32C) and the real
    HDL-32E pair."""
    from helpers.fault_zoo import traffic_rig_pair
    from helpers.real_pairs import pair_at, real_pair
    from lidarfield.study.stack import following_stage, initial_stage

    if source == "rig":
        pair = traffic_rig_pair()
    else:
        pair = pair_at(real_pair(request.getfixturevalue("shared_data"), source))
    fits = [{"range_calibration": {}}, {"range_calibration": {"with_pose": True}}]
    module.SHARED_PLANES.clear()
    stage = initial_stage(pair)
    for step in fits:
        apply_step(stage.pair, step)  # the stage's planes, as its suggestions make them
    following = following_stage(stage, *parse_step({"crop": {"max_range_m": 25.0}}), 1)
    cloud1 = following.pair.xyz1
    assert len(cloud1) < len(stage.pair.xyz1)
    assert isinstance(module.SHARED_PLANES[(id(cloud1), K)], CarriedPlanes)

    normals = module._normals
    counted = []
    monkeypatch.setattr(module, "_normals", lambda *a: counted.append(len(a[2])) or normals(*a))

    def fitted() -> tuple[list[dict], int]:
        counted.clear()
        return [apply_step(following.pair, step).fitted for step in fits], sum(counted)

    carried, computed_carried = fitted()
    planes = planes_of(cloud1, K)
    assert isinstance(planes, Planes) and planes.other is cloud1
    module.SHARED_PLANES.clear()
    anew, computed_anew = fitted()
    assert carried == anew
    assert planes_of(cloud1, K) is not planes
    assert computed_carried < 0.75 * computed_anew, (computed_carried, computed_anew)


def test_a_cloud_the_stage_moved_takes_no_planes():
    """A correction moves its cloud (``realign``, cloud 2): the planes of the points before are
    not passed on to it."""
    from helpers.fault_zoo import traffic_rig_pair
    from lidarfield.study.stack import following_stage, initial_stage

    stage = initial_stage(traffic_rig_pair())
    module.SHARED_PLANES.clear()
    planes_of(stage.pair.xyz2, K)
    moved = following_stage(stage, *parse_step({"realign": {}}), 1)
    assert moved.pair.xyz2 is not stage.pair.xyz2 and len(moved.pair.xyz2) == len(stage.pair.xyz2)
    assert set(module.SHARED_PLANES) == {(id(stage.pair.xyz2), K)}
