"""The ``outliers`` hypothesis (scipy's k-d tree) against Open3D's ``remove_statistical_outlier``,
the plain reference: the same keep-masks on real scans and on synthetic clouds."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.clouds import synthetic_cloud
from lidarfield.hypotheses import apply_step
from lidarfield.hypotheses.outliers import (
    neighbour_distances,
    open3d_threshold,
    statistical_inliers,
)
from lidarfield.io import read_scan
from lidarfield.pair import RegisteredPair

o3d = pytest.importorskip("open3d")


def open3d_inliers(xyz: np.ndarray, nb_neighbors: int, std_ratio: float) -> np.ndarray:
    """The reference: Open3D's own statistical outlier removal, as a keep-mask."""
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(xyz, dtype=np.float64)))
    _, index = cloud.remove_statistical_outlier(nb_neighbors=nb_neighbors, std_ratio=std_ratio)
    keep = np.zeros(len(xyz), dtype=bool)
    keep[np.asarray(index, dtype=np.int64)] = True
    return keep


@pytest.mark.parametrize(
    "path, settings",
    [
        ("expd-vlp16/Cloud1_ExpD.txt", [(20, 2.0), (5, 0.5), (50, 1.0), (1, 1.0)]),
        ("ouster-os1-128/lb_n3_scan0_xyz_refl_float32.bin", [(20, 2.0)]),
        ("hdl32-pair/251370668.pcd", [(20, 2.0), (8, 0.3)]),  # 5,032 returns at the origin: duplicates
    ],
)
def test_same_masks_as_open3d_on_real_scans(shared_data, path, settings):
    xyz = read_scan(shared_data / path).xyz.astype(np.float64)
    for nb_neighbors, std_ratio in settings:
        expected = open3d_inliers(xyz, nb_neighbors, std_ratio)
        if nb_neighbors == 1:
            assert not expected.any()  # its only neighbour is itself: every score is 0
        else:
            assert 0 < np.count_nonzero(~expected) < len(xyz) / 4  # the rule removes something, not everything
        np.testing.assert_array_equal(statistical_inliers(xyz, nb_neighbors, std_ratio, workers=1), expected)
    # The threads share the points, not the sums: the same mask on two.
    np.testing.assert_array_equal(statistical_inliers(xyz, 20, 2.0, workers=2), open3d_inliers(xyz, 20, 2.0))


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("nb_neighbors, std_ratio", [(20, 2.0), (4, 1.0), (30, 0.2)])
def test_same_masks_as_open3d_on_duplicates_and_isolated_points(seed, nb_neighbors, std_ratio):
    xyz = synthetic_cloud(np.random.default_rng(seed))
    expected = open3d_inliers(xyz, nb_neighbors, std_ratio)
    keep = statistical_inliers(xyz, nb_neighbors, std_ratio, workers=1)
    np.testing.assert_array_equal(keep, expected)
    far = np.abs(xyz).max(axis=1) > 12
    assert not keep[far].any()  # the isolated points go
    if nb_neighbors <= 30:
        _, inverse, counts = np.unique(xyz, axis=0, return_inverse=True, return_counts=True)
        repeated = counts[inverse.ravel()] == 30
        assert repeated.sum() == 30 and not keep[repeated].any()  # score 0: Open3D removes it


def test_mean_distance_counts_the_point_itself():
    xyz = np.array([[0.0, 0, 0], [1.0, 0, 0], [3.0, 0, 0], [7.0, 0, 0]])
    # Nearest two of point 0: itself (0) and point 1 (1): mean 0.5; of point 3: itself and point 2.
    np.testing.assert_allclose(neighbour_distances(xyz, 2).mean, [0.5, 0.5, 1.0, 2.0])
    scores = np.array([0.0, 2.0, 2.0, 6.0, 0.0])
    # Open3D: mean (2 + 2 + 6) / 5 = 2 over all points, std sqrt((0 + 0 + 4^2) / (5 - 1)) = 2 over
    # the positive scores; summing the zeros' squares too, or dividing by the 3 positive scores
    # only, would put the threshold above 6 at std_ratio 2.
    assert open3d_threshold(scores, 1.0).tolist() == [False, True, True, False, False]  # 6 < 4 fails
    assert open3d_threshold(scores, 2.0).tolist() == [False, True, True, False, False]  # 6 < 6 is strict
    assert open3d_threshold(scores, 2.01).tolist() == [False, True, True, True, False]


@pytest.mark.parametrize("n", [1, 2, 5, 20])
def test_clouds_of_at_most_k_points(n):
    """Open3D averages over the whole cloud when it has no more than k points (one point: 0 / 0,
    removed); the hypothesis keeps such a cloud whole instead."""
    xyz = np.random.default_rng(n).normal(size=(n, 3))
    scores = neighbour_distances(xyz, 20).mean
    np.testing.assert_array_equal(open3d_threshold(scores, 2.0), open3d_inliers(xyz, 20, 2.0))
    assert statistical_inliers(xyz, 20, 2.0).all()
    keep1, keep2 = apply_step(RegisteredPair(xyz, xyz[:1]), {"outliers": {}})
    assert keep1.all() and keep2.all()
