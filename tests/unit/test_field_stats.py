"""Field statistics: magnitudes, paper metric, rigid part and directional randomness."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from helpers.clouds import voxel_centre_clouds
from lidarfield.analysis.field_stats import field_statistics, summary_json_safe, weighted_rigid_transform
from lidarfield.analysis.tags import vector_tags
from lidarfield.field.grid import FieldSettings, SphericalGrid
from lidarfield.field.kernel import discrepancy_field
from lidarfield.field.rigid_fit import field_rigid_part

GRID = SphericalGrid()  # the grid voxel_centre_clouds fills: 36 x 10 deg, 5 x 8 deg from -20 to +20


def yaw(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def columns_from_vectors(uvw: np.ndarray, weight=None, valid=None) -> dict[str, np.ndarray]:
    """Field columns with the given vectors (means on a sphere of 10 m) and counts."""
    n = len(uvw)
    rng = np.random.default_rng(1)
    mean1 = rng.normal(size=(n, 3))
    mean1 *= 10.0 / np.linalg.norm(mean1, axis=1, keepdims=True)
    counts = np.full(n, 50) if weight is None else np.asarray(weight)
    valid = np.ones(n, bool) if valid is None else valid
    mean2 = mean1 + uvw
    columns = {"voxel": np.arange(n), "n1": counts, "n2": counts + 5}
    for i, axis in enumerate("xyz"):
        columns[f"{axis}1"], columns[f"{axis}2"] = mean1[:, i], mean2[:, i]
    u = np.where(valid[:, None], uvw, np.nan)
    columns["u"], columns["v"], columns["w"] = u.T
    columns["magnitude"] = np.linalg.norm(u, axis=1)
    columns["se"] = np.where(valid, 0.01, np.nan)
    columns["z"] = columns["magnitude"] / columns["se"]
    columns["wu"], columns["wv"], columns["ww"] = u.T / columns["se"]  # an isotropic C = se^2 I
    columns["valid"] = valid
    return columns


def test_magnitudes_and_paper_metric_by_hand():
    uvw = np.array([[3.0, 0.0, 0.0], [0.0, -4.0, 0.0], [0.0, 0.0, 12.0], [100.0, 100.0, 100.0]])
    stats = field_statistics(columns_from_vectors(uvw, valid=np.array([True, True, True, False])))
    assert stats["voxels"] == 4 and stats["voxels_valid"] == 3
    assert stats["max_magnitude"] == 12.0
    assert math.isclose(stats["mean_magnitude"], 19.0 / 3.0)
    assert math.isclose(stats["rms_magnitude"], math.sqrt((9 + 16 + 144) / 3.0))
    assert math.isclose(stats["p95_magnitude"], float(np.percentile([3.0, 4.0, 12.0], 95)))
    assert math.isclose(stats["paper_max_metric"], 13.0)  # |(3, 4, 12)|


def test_rigid_part_recovers_a_small_yaw():
    xyz1 = voxel_centre_clouds(per_voxel=40, seed=2)
    xyz2 = xyz1 @ yaw(2.0).T  # 2 deg < the 4 deg margin: no point changes voxel
    field = discrepancy_field(xyz1, xyz2, FieldSettings(GRID))
    assert field["valid"].all()
    stats = field_statistics(field)
    assert abs(stats["rigid_rotation_deg"] - 2.0) < 0.05
    assert np.allclose(stats["rigid_translation_m"], 0.0, atol=1e-6)
    assert stats["rigid_energy_share"] > 0.999999


def test_the_rigid_part_given_is_the_one_the_statistics_and_tags_read():
    """analyse_field fits the rigid part once and hands it to the tags and the statistics: with
    the field's own part they are those computed without it, to the bit; with another field's
    part, that part is what they report (it is read, not fitted again)."""
    xyz1 = voxel_centre_clouds(per_voxel=40, seed=2)
    field = discrepancy_field(xyz1, xyz1 @ yaw(2.0).T, FieldSettings(GRID))
    settings = FieldSettings(GRID)
    own = field_rigid_part(field)
    assert json.dumps(field_statistics(field, settings, own)) == json.dumps(field_statistics(field, settings))
    for tag, flags in vector_tags(field, own).items():
        assert np.array_equal(flags, vector_tags(field)[tag]), tag
    assert vector_tags(field)["rigid"].all()  # a yaw: every vector is the rigid part's
    shifted = discrepancy_field(xyz1, xyz1 + [0.01, 0.0, 0.0], FieldSettings(GRID))
    other = field_rigid_part(shifted)
    stats = field_statistics(field, settings, other)
    np.testing.assert_allclose(stats["rigid_translation_m"], [-0.01, 0.0, 0.0], atol=1e-9)
    assert stats["rigid_rotation_deg"] < 1e-6
    far = (own[0], np.ones_like(own[1]))  # residuals of 1 m: no vector is its rigid part's
    assert not vector_tags(field, far)["rigid"].any()


def test_rigid_part_of_a_translation_is_its_inverse():
    xyz1 = voxel_centre_clouds(per_voxel=40, seed=5)
    shift = np.array([0.005, 0.002, -0.001])
    stats = field_statistics(discrepancy_field(xyz1, xyz1 + shift, FieldSettings(GRID)))
    np.testing.assert_allclose(stats["rigid_translation_m"], -shift, atol=1e-9)
    assert stats["rigid_rotation_deg"] < 1e-6
    assert stats["rigid_energy_share"] > 0.999999
    assert stats["mean_resultant_length"] > 0.99


def test_weighted_kabsch_ignores_zero_weights():
    rng = np.random.default_rng(8)
    source = rng.normal(size=(50, 3)) * 10
    target = source @ yaw(-7.0).T + [1.0, 2.0, 3.0]
    target[:5] += 50.0  # corrupted, weight 0
    weight = np.r_[np.zeros(5), rng.uniform(1, 5, 45)]
    rotation, translation = weighted_rigid_transform(source, target, weight)
    np.testing.assert_allclose(rotation, yaw(-7.0), atol=1e-12)
    np.testing.assert_allclose(translation, [1.0, 2.0, 3.0], atol=1e-12)


def test_mean_resultant_length_separates_uniform_from_random():
    rng = np.random.default_rng(9)
    n = 2000
    uniform = np.tile([0.1, -0.2, 0.05], (n, 1)) * rng.uniform(0.5, 2.0, (n, 1))
    random = rng.normal(size=(n, 3)) * 0.1
    weight = rng.integers(30, 300, n)
    assert field_statistics(columns_from_vectors(uniform, weight))["mean_resultant_length"] > 0.99
    assert field_statistics(columns_from_vectors(random, weight))["mean_resultant_length"] < 0.1


def test_no_valid_voxel_gives_nan_and_strict_json():
    xyz = voxel_centre_clouds(per_voxel=5)
    stats = field_statistics(discrepancy_field(xyz, xyz + 0.001, FieldSettings(SphericalGrid(), min_points=30)))
    assert stats["voxels"] == 180 and stats["voxels_valid"] == 0
    assert math.isnan(stats["max_magnitude"]) and math.isnan(stats["rigid_energy_share"])
    text = json.dumps(summary_json_safe(stats), allow_nan=False)
    assert json.loads(text)["p95_magnitude"] is None


@pytest.mark.parametrize("source", ["rig", "hdl32"])
def test_a_fields_depth_edges_found_by_a_second_thread_are_those_found_alone(source, monkeypatch, request):
    """``analyse_field`` finds the depth edges by a second thread where two cores are usable:
    the same columns and statistics to the bit as on one, on the two-lidar rig (two VLP-32C,
    one upside down) and the real HDL-32E pair, whose depth-edge tags are not empty."""
    from dataclasses import replace

    from helpers.fault_zoo import traffic_rig_pair
    from helpers.real_pairs import pair_at, real_pair
    from lidarfield.analysis.field_stats import analyse_field
    from lidarfield.analysis.tags import tag_column

    if source == "rig":
        pair = traffic_rig_pair()
    else:
        pair = pair_at(real_pair(request.getfixturevalue("shared_data"), source))
    settings = FieldSettings(SphericalGrid(), min_points=10)
    found = {}
    for threads in ("1", "2"):
        monkeypatch.setenv("OMP_NUM_THREADS", threads)
        found[threads] = analyse_field(replace(pair), settings)  # a copy: nothing remembered from the other
    (alone, stats_alone), (beside, stats_beside) = found["1"], found["2"]
    assert alone.keys() == beside.keys()
    for name in alone:
        np.testing.assert_array_equal(alone[name], beside[name], err_msg=name)
    assert json.dumps(summary_json_safe(stats_alone)) == json.dumps(summary_json_safe(stats_beside))
    assert np.count_nonzero(alone[tag_column("depth_edge")]) > 0
