"""What a pair derives from its clouds made once (``RegisteredPair.remembered``, issue 38): its
range images and k-d trees are those made afresh (the plain path), on a two-lidar rig (two
VLP-32C, uneven channels, one upside down) and a real pair; made again once the points or the
pose change; not passed on by ``replace`` or a pickle, passed on by ``subset`` for a cloud kept
whole (a correction's stage); and ``moving_objects``,
``shadow``, the carried body and the field's shared points find the same on a pair that
remembers them as on one that does not."""

from __future__ import annotations

import pickle
from dataclasses import replace

import numpy as np
import pytest

from helpers.real_pairs import pair_at, real_pair
from lidarfield.analysis.carried import carried_points
from lidarfield.field import free_space as fs
from lidarfield.hypotheses import apply_step
from lidarfield.hypotheses.geometry import cloud_tree, own_frame_points
from lidarfield.poses import pose_from_xyzrpy


@pytest.fixture(scope="module")
def rig_pair():
    from helpers.fault_zoo import traffic_rig_pair

    pair = traffic_rig_pair()
    assert len(pair.lidars(1)) == len(pair.lidars(2)) == 2
    return pair


def fresh_images(pair, cloud: int):
    """The plain path: each lidar's image made now, on its model."""
    return fs.lidar_images(pair, cloud, lambda own, view, ring: fs.sensor_image(own, view.sensor, ring))


def assert_same_images(remembered, fresh) -> None:
    assert len(remembered) == len(fresh)
    for (view, image), (fresh_view, fresh_image) in zip(remembered, fresh):
        assert view.name == fresh_view.name
        np.testing.assert_array_equal(image.nearest, fresh_image.nearest)
        np.testing.assert_array_equal(image.channels, fresh_image.channels)
        assert image.azimuth_step == fresh_image.azimuth_step and image.min_range_m == fresh_image.min_range_m


def test_the_remembered_images_are_those_made_afresh(rig_pair):
    pair = replace(rig_pair)
    for cloud in (1, 2):
        images = fs.lidar_images(pair, cloud)
        assert fs.lidar_images(pair, cloud) is images  # made once
        assert_same_images(images, fresh_images(rig_pair, cloud))


def test_moved_points_or_pose_are_imaged_again(rig_pair):
    pair = replace(rig_pair)
    before = fs.lidar_images(pair, 2)
    pair.xyz2 = pair.xyz2 + [0.5, 0.0, 0.0]  # as a correcting stage moves its survivors in place
    moved = fs.lidar_images(pair, 2)
    assert moved is not before
    assert_same_images(moved, fresh_images(pair, 2))
    pair.T_1_2 = pose_from_xyzrpy([0.5, 0, 0, 0, 0, 0]) @ pair.T_1_2  # sensor 2 moved with them
    again = fs.lidar_images(pair, 2)
    assert again is not moved
    assert_same_images(again, fresh_images(pair, 2))
    # in sensor 2's frame the points did not move: the same image as before both changes
    for (_, image), (_, first) in zip(again, before):
        np.testing.assert_allclose(image.nearest, first.nearest, rtol=0, atol=1e-9)


def test_the_memo_is_not_passed_on(rig_pair):
    pair = replace(rig_pair)
    fs.lidar_images(pair, 1)
    assert pair.derived
    assert not replace(pair).derived
    back = pickle.loads(pickle.dumps(pair))
    assert not back.derived and np.array_equal(back.xyz2, pair.xyz2) and np.array_equal(back.T_1_2, pair.T_1_2)


def test_a_subset_keeps_a_whole_cloud_and_what_was_made_of_it(rig_pair):
    """``subset`` of every point of cloud 1 and some of cloud 2 (a stage that removed points of
    cloud 2 only, or a correction's, which keeps all): cloud 1 is the same array with its
    images and trees, still those made afresh; cloud 2's are made again for its survivors;
    the pair it came from keeps its own."""
    pair = replace(rig_pair)
    images1, images2 = fs.lidar_images(pair, 1), fs.lidar_images(pair, 2)
    tree1, tree2 = cloud_tree(pair, 1, own_frame=True), cloud_tree(pair, 2, own_frame=False)
    every1 = np.ones(len(pair.xyz1), bool)
    some2 = np.arange(len(pair.xyz2)) % 7 != 0
    kept = pair.subset(every1, some2)
    assert kept.xyz1 is pair.xyz1 and all(kept.attributes1[k] is v for k, v in pair.attributes1.items())
    np.testing.assert_array_equal(kept.xyz2, pair.xyz2[some2])
    assert fs.lidar_images(kept, 1) is images1 and cloud_tree(kept, 1, own_frame=True) is tree1
    assert_same_images(fs.lidar_images(kept, 1), fresh_images(kept, 1))
    assert fs.lidar_images(kept, 2) is not images2 and cloud_tree(kept, 2, own_frame=False) is not tree2
    assert_same_images(fs.lidar_images(kept, 2), fresh_images(kept, 2))
    assert fs.lidar_images(pair, 2) is images2 and cloud_tree(pair, 2, own_frame=False) is tree2
    # kept whole, both: everything passed on; the same mask as rows (not a mask): copies, nothing
    both = pair.subset(every1, np.ones(len(pair.xyz2), bool))
    assert both.xyz2 is pair.xyz2 and fs.lidar_images(both, 2) is images2
    rows = pair.subset(np.arange(len(pair.xyz1)), np.arange(len(pair.xyz2)))
    assert rows.xyz1 is not pair.xyz1 and not rows.derived
    # a correction then moving sensor 2 (as parsed_stage does): what needs the pose is made again
    both.T_1_2 = pose_from_xyzrpy([0.5, 0, 0, 0, 0, 0]) @ both.T_1_2
    assert cloud_tree(both, 2, own_frame=True) is not cloud_tree(pair, 2, own_frame=True)


@pytest.mark.parametrize("source", ["rig", "hdl32"])
def test_what_uses_the_images_finds_the_same_with_them_remembered(rig_pair, source, request):
    if source == "rig":
        pair = rig_pair
    else:
        pair = pair_at(real_pair(request.getfixturevalue("shared_data"), source))
    warm = replace(pair)
    shared = fs.shared_points(warm)  # the field's: the images made here, used by what follows
    assert warm.derived
    for mine, theirs in zip(shared, fs.shared_points(replace(pair))):
        np.testing.assert_array_equal(mine, theirs)
    for step in ({"moving_objects": {}}, {"shadow": {}}):
        reused, alone = apply_step(warm, step), apply_step(replace(pair), step)  # alone: its own made inside
        np.testing.assert_array_equal(reused.keep1, alone.keep1)
        np.testing.assert_array_equal(reused.keep2, alone.keep2)
    everything = (np.ones(len(pair.xyz1), bool), np.ones(len(pair.xyz2), bool))
    for mine, theirs in zip(carried_points(warm, everything), carried_points(replace(pair), everything)):
        np.testing.assert_array_equal(mine, theirs)
    moved = apply_step(warm, {"moving_objects": {}})
    if source == "rig":  # the cars moved 0.3 s on: something is removed, so the masks say something
        assert np.count_nonzero(~moved.keep1) + np.count_nonzero(~moved.keep2) > 0


def test_the_remembered_trees_answer_as_trees_made_afresh(rig_pair):
    from scipy.spatial import cKDTree

    pair = replace(rig_pair)
    rng = np.random.default_rng(0)
    queries = rng.uniform(-30, 30, size=(2000, 3))
    for cloud in (1, 2):
        for own_frame, xyz in ((False, (pair.xyz1, pair.xyz2)[cloud - 1]), (True, own_frame_points(pair)[cloud - 1])):
            tree = cloud_tree(pair, cloud, own_frame)
            assert cloud_tree(pair, cloud, own_frame) is tree
            np.testing.assert_array_equal(tree.query(queries)[0], cKDTree(xyz).query(queries)[0])
    own2 = cloud_tree(pair, 2, own_frame=True)
    pair.T_1_2 = pose_from_xyzrpy([0.5, 0, 0, 0, 0, 0]) @ pair.T_1_2  # cloud 2 in its own frame moves
    assert cloud_tree(pair, 2, own_frame=True) is not own2
    np.testing.assert_array_equal(
        cloud_tree(pair, 2, own_frame=True).query(queries)[0], cKDTree(own_frame_points(pair)[1]).query(queries)[0]
    )


def test_what_depends_on_cloud_1_alone_survives_moving_cloud_2(rig_pair):
    """``with_cloud2`` (``realign``'s moved pairs): cloud 1's images and trees are passed on and
    still those made afresh, cloud 2's are made again for its new place."""
    pair = replace(rig_pair)
    images1, images2 = fs.lidar_images(pair, 1), fs.lidar_images(pair, 2)
    tree1 = cloud_tree(pair, 1, own_frame=True)
    T = pose_from_xyzrpy([0.3, -0.2, 0, 0, 0, 0.02])
    moved = pair.with_cloud2(pair.xyz2 @ T[:3, :3].T + T[:3, 3], T @ pair.T_1_2)
    assert fs.lidar_images(moved, 1) is images1 and cloud_tree(moved, 1, own_frame=True) is tree1
    assert_same_images(fs.lidar_images(moved, 1), fresh_images(moved, 1))
    assert fs.lidar_images(moved, 2) is not images2
    assert_same_images(fs.lidar_images(moved, 2), fresh_images(moved, 2))
    assert fs.lidar_images(pair, 2) is images2  # the pair it came from keeps its own


def test_only_the_last_pairs_asked_for_keep_what_they_derived(rig_pair):
    """A caller holding every stage's pair holds about one stage's images and trees: the pairs
    before the last ``DERIVED_PAIRS`` asked for let theirs go (and make them again if asked)."""
    from lidarfield.pair import DERIVED_PAIRS

    pairs = [replace(rig_pair) for _ in range(DERIVED_PAIRS + 2)]
    images = [fs.lidar_images(p, 1) for p in pairs]
    assert [bool(p.derived) for p in pairs] == [False] * 2 + [True] * DERIVED_PAIRS
    assert fs.lidar_images(pairs[-1], 1) is images[-1]  # still kept: the same object
    again = fs.lidar_images(pairs[0], 1)  # let go: made again, the same image
    assert again is not images[0]
    assert_same_images(again, images[0])


def test_an_image_shared_by_threads_gives_each_the_extremes_it_gives_alone(rig_pair):
    """A pair's images are shared by the candidates' threads: their sparse tables, made as
    asked for, are extended by one thread at a time (two appending the same level at once made
    a wrong table, and moving_objects' evidence wrong, on the real OS1-128 pair)."""
    from concurrent.futures import ThreadPoolExecutor

    (_, image), *_ = fresh_images(rig_pair, 1)
    rows, columns = image.nearest.shape
    rng = np.random.default_rng(2)
    first = rng.integers(0, rows, 5000)
    last = np.minimum(first + rng.integers(0, rows, 5000), rows - 1)
    column = rng.integers(0, columns, 5000)
    alone = {(c, f): image.extreme(first, last, column, c, f) for c in (0, 1, 3) for f in (False, True)}
    for _ in range(30):
        (_, shared), *_ = fresh_images(rig_pair, 1)
        jobs = [(c, f) for c in (0, 1, 3) for f in (False, True) for _ in range(4)]
        with ThreadPoolExecutor(8) as pool:
            got = list(pool.map(lambda job: shared.extreme(first, last, column, *job), jobs))
        for job, values in zip(jobs, got):
            np.testing.assert_array_equal(values, alone[job])
