"""The discrepancy field: analytic fields, validity rules, kernel vs reference, Parquet round trip."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.clouds import voxel_centre_clouds
from lidarfield.analysis.field_stats import field_statistics
from lidarfield.field.file import read_field, write_field
from lidarfield.field.grid import CartesianGrid, FieldSettings, SphericalGrid
from lidarfield.field.kernel import discrepancy_field, field_columns, field_from_voxel_ids
from lidarfield.field.reference import discrepancy_field_reference, field_from_voxel_ids_reference
from lidarfield.field.significance import Viewpoint, crosses_line_of_sight

GRID = SphericalGrid()  # the experimental grid: 36 x 10 deg, 5 x 8 deg from -20 to +20


def test_small_translation_appears_in_every_voxel():
    xyz1 = voxel_centre_clouds()
    shift = np.array([0.004, -0.003, 0.002])
    field = discrepancy_field(xyz1, xyz1 + shift, FieldSettings(GRID))
    assert list(field) == list(field_columns(GRID))
    assert field["valid"].all() and len(field["voxel"]) == 180
    assert (field["n1"] == field["n2"]).all()
    uvw = np.column_stack([field["u"], field["v"], field["w"]])
    np.testing.assert_allclose(uvw, np.broadcast_to(shift, uvw.shape), atol=1e-9, rtol=0)
    np.testing.assert_allclose(field["magnitude"], np.linalg.norm(shift), atol=1e-9)


def test_scaling_about_the_origin_points_outward():
    xyz1 = voxel_centre_clouds()
    field = discrepancy_field(xyz1, 1.002 * xyz1, FieldSettings(GRID))
    valid = field["valid"]
    assert valid.all()
    uvw = np.column_stack([field["u"], field["v"], field["w"]])
    mean1 = np.column_stack([field["x1"], field["y1"], field["z1"]])
    # Each vector is 0.002 * mean1: parallel to it and pointing away from the sensor.
    np.testing.assert_allclose(uvw, 0.002 * mean1, atol=1e-9)
    assert (np.einsum("ij,ij->i", uvw, mean1) > 0).all()
    stats = field_statistics(field)
    assert stats["rigid_energy_share"] < 0.2
    assert stats["mean_resultant_length"] < 0.1


def test_identical_clouds_give_a_zero_field():
    xyz = voxel_centre_clouds(seed=4)
    field = discrepancy_field(xyz, xyz.copy(), FieldSettings(GRID))
    assert field["valid"].all()
    for c in ("u", "v", "w", "magnitude"):
        assert (field[c] == 0.0).all()
    stats = field_statistics(field)
    assert stats["max_magnitude"] == 0.0 and stats["paper_max_metric"] == 0.0


def test_min_points_and_max_component_invalidate_but_keep_rows():
    xyz1 = voxel_centre_clouds(per_voxel=40)
    # Cloud 2: only 10 points in voxel 0's blob, the others as cloud 1, one voxel far off.
    in_voxel0 = GRID.assign(xyz1) == 0
    xyz2 = np.vstack([xyz1[~in_voxel0], xyz1[in_voxel0][:10]])
    far_voxel = GRID.assign(xyz2) == 7
    xyz2[far_voxel] *= 1.5  # stays in voxel 7 (same direction, 12-18 m), |vector| > 4 m
    field = discrepancy_field(xyz1, xyz2, FieldSettings(GRID, min_points=30, max_component_m=2.0))
    assert len(field["voxel"]) == 180
    row0, row7 = np.searchsorted(field["voxel"], [0, 7])
    assert field["n2"][row0] == 10 and not field["valid"][row0]
    assert not field["valid"][row7] and field["n1"][row7] == field["n2"][row7] == 40
    for row in (row0, row7):
        assert np.isnan([field["u"][row], field["v"][row], field["w"][row], field["magnitude"][row]]).all()
        assert np.isfinite([field["x1"][row], field["x2"][row]]).all()  # the means are kept
    assert field["valid"].sum() == 178
    # Without the outlier limit voxel 7 is valid.
    assert discrepancy_field(xyz1, xyz2, FieldSettings(GRID, min_points=30))["valid"][row7]


def test_voxel_of_one_cloud_only_has_nan_means_of_the_other():
    xyz1 = voxel_centre_clouds(per_voxel=5)
    xyz2 = xyz1[GRID.assign(xyz1) != 3]
    field = discrepancy_field(xyz1, xyz2, FieldSettings(GRID, min_points=1))
    row = np.searchsorted(field["voxel"], 3)
    assert field["voxel"][row] == 3 and field["n2"][row] == 0
    assert np.isnan([field["x2"][row], field["y2"][row], field["z2"][row]]).all()
    assert not field["valid"][row]


def test_points_outside_elevation_are_counted_not_folded():
    xyz1 = voxel_centre_clouds(per_voxel=40)
    high = np.array([[10.0, 0.0, 10.0], [10.0, 1.0, -9.0], [5.0, 5.0, 100.0]])  # 45, -42, 86 deg
    field = discrepancy_field(np.vstack([xyz1, high]), xyz1, FieldSettings(GRID))
    assert field["n1"].sum() == len(xyz1)
    assert (field["n1"] == field["n2"]).all()
    assert (field["magnitude"] == 0.0).all()


GRIDS = {
    "spherical": SphericalGrid(azimuth_bins=12, azimuth_offset_deg=7.0, elevation_deg=(-30.0, 25.0), elevation_bins=6),
    "spherical-shells": SphericalGrid(range_edges_m=(1.0, 4.0, 8.0, 15.0, 30.0)),
    # channel-aware edges (field.channels): uneven, looked up rather than computed; the
    # columns start at -170 deg and wrap past +180
    "spherical-uneven": SphericalGrid(
        elevation_edges_deg=(-30.0, -22.4, -10.1, -3.3, 0.2, 8.7, 25.0),
        azimuth_edges_deg=(-170.0, -100.5, -20.0, 3.3, 77.0, 150.0, 190.0),
        range_edges_m=(1.0, 8.0, 30.0),
    ),
    "cartesian": CartesianGrid(cell_m=2.5, origin=(0.3, -0.2, 0.1)),
    "cartesian-sparse": CartesianGrid(cell_m=0.2),  # a bounding box too large for dense counting
}


@pytest.mark.parametrize("name", GRIDS)
def test_kernel_matches_reference(name):
    rng = np.random.default_rng(11)
    xyz1 = rng.normal(scale=[12.0, 12.0, 4.0], size=(30_000, 3))
    xyz2 = np.vstack([xyz1[5000:], rng.normal(scale=8.0, size=(2000, 3))]) + rng.normal(scale=0.3, size=(27_000, 3))
    xyz1[::997] = np.nan  # NaN points are out of any grid
    settings = FieldSettings(GRIDS[name], min_points=1 if name == "cartesian-sparse" else 8, max_component_m=0.5)
    origin = (0.7, -1.1, 0.4)
    fast = discrepancy_field(xyz1, xyz2, settings, origin)
    reference = discrepancy_field_reference(xyz1, xyz2, settings, origin)
    assert list(fast) == list(reference) == list(field_columns(settings.grid))
    assert len(fast["voxel"]) > 50 and 0 < fast["valid"].sum() < len(fast["voxel"])
    # se and z are compared too: finite wherever a valid voxel has a spread to estimate (a
    # cloud with 5 points), NaN where neither has (every voxel of the 0.2 m grid).
    spread = fast["valid"] & ((fast["n1"] >= 5) | (fast["n2"] >= 5))
    assert spread.any() or name == "cartesian-sparse"
    assert np.isfinite(fast["se"][spread]).all() and (fast["se"][spread] > 0).all()
    assert np.isnan(fast["se"][fast["valid"] & ~spread]).all()
    # The local surface: a unit normal facing the origin and a planarity in [0, 1] for every
    # valid voxel with 3 points (all of them but the 0.2 m grid's), NaN elsewhere.
    normal = np.column_stack([fast["nx"], fast["ny"], fast["nz"]])
    surface = np.isfinite(fast["planarity"])
    assert surface.any() or name == "cartesian-sparse"
    assert not surface[~fast["valid"]].any()
    np.testing.assert_allclose(np.linalg.norm(normal[surface], axis=1), 1.0, atol=1e-12)
    assert ((fast["planarity"][surface] >= 0) & (fast["planarity"][surface] <= 1)).all()
    centre = np.column_stack([fast["x1"] + fast["x2"], fast["y1"] + fast["y2"], fast["z1"] + fast["z2"]]) / 2
    assert (np.einsum("ij,ij->i", normal[surface], centre[surface] - origin) <= 0).all()
    assert_same_field(fast, reference)
    # From precomputed ids (one binning, several subsets): the same field, both implementations.
    grid = settings.grid
    ids1, ids2 = grid.assign(xyz1, origin), grid.assign(xyz2, origin)
    assert_same_field(field_from_voxel_ids(ids1, xyz1, ids2, xyz2, settings, origin), fast)
    keep = slice(0, 20_000)
    assert_same_field(
        field_from_voxel_ids(ids1[keep], xyz1[keep], ids2, xyz2, settings),
        field_from_voxel_ids_reference(ids1[keep], xyz1[keep], ids2, xyz2, settings),
    )
    # With sensor 2's origin and which points both sensors saw (the change of viewpoint on what
    # both saw, in the vectors' covariance): the same field from both implementations, with the
    # same vectors and larger se; no change when both are one place or when no point is shared.
    shared = Viewpoint((1.2, -0.3, 0.4), rng.random(len(xyz1)) < 0.7, rng.random(len(xyz2)) < 0.7)
    moved = discrepancy_field(xyz1, xyz2, settings, origin, shared)
    assert_same_field(moved, discrepancy_field_reference(xyz1, xyz2, settings, origin, shared))
    assert_same_field(field_from_voxel_ids(ids1, xyz1, ids2, xyz2, settings, origin, viewpoint=shared), moved)
    assert_same_field(discrepancy_field(xyz1, xyz2, settings, origin, shared._replace(origin2=origin)), fast)
    # No point shared: no viewpoint term, but two places, so a surface the line of sight crosses
    # is read by its normal part (these blobs, long along the rays on a spherical grid, are not).
    unseen = discrepancy_field(
        xyz1, xyz2, settings, origin, Viewpoint(shared.origin2, np.zeros(len(xyz1), bool), np.zeros(len(xyz2), bool))
    )
    read = ("wu", "wv", "ww", "read_normal")
    assert_same_field(*({k: v for k, v in f.items() if k not in read} for f in (unseen, fast)))
    crossing = crosses_line_of_sight(normal.T, centre.T, origin)
    np.testing.assert_array_equal(unseen["read_normal"], np.isfinite(fast["se_normal"]) & crossing)
    assert not fast["read_normal"].any()
    np.testing.assert_array_equal(moved["magnitude"], fast["magnitude"])
    assert (moved["se"][spread] > fast["se"][spread]).all()


def test_kernel_matches_reference_on_surfaces():
    """Where voxels hold one surface (the ground 2 m below and a wall 12 m ahead, 1 cm of
    noise), ``se_normal`` is the standard error of the normal part, and from two places the
    whitened vector is that part over it, along the normal: the same from both implementations,
    with and without the change of viewpoint."""
    rng = np.random.default_rng(4)

    def sampled(n: int) -> np.ndarray:
        r, az = np.sqrt(rng.uniform(9.0, 400.0, n)), rng.uniform(-np.pi, np.pi, n)
        ground = np.column_stack([r * np.cos(az), r * np.sin(az), np.full(n, -2.0)])
        wall = np.column_stack([np.full(n, 12.0), rng.uniform(-8, 8, n), rng.uniform(-2, 2, n)])
        points = np.vstack([ground[ground[:, 0] < 12.0], wall])
        return points + rng.normal(scale=0.01, size=points.shape)

    xyz1, xyz2 = sampled(40_000), sampled(40_000) + [0.01, 0.0, 0.005]
    settings = FieldSettings(SphericalGrid(), min_points=20)
    shared = Viewpoint((0.5, 0.2, 0.0), rng.random(len(xyz1)) < 0.8, rng.random(len(xyz2)) < 0.8)
    for viewpoint in (None, shared):
        fast = discrepancy_field(xyz1, xyz2, settings, viewpoint=viewpoint)
        reference = discrepancy_field_reference(xyz1, xyz2, settings, (0.0, 0.0, 0.0), viewpoint)
        # Readings of 10 to 30 standard errors: the two sums' last digits agree to 1e-8 of them.
        read = ("wu", "wv", "ww", "se_normal")
        assert_same_field(*({k: v for k, v in field.items() if k not in read} for field in (fast, reference)))
        for column in read:
            np.testing.assert_allclose(
                fast[column], reference[column], rtol=1e-8, atol=1e-6, equal_nan=True, err_msg=column
            )
        surface = np.isfinite(fast["se_normal"])
        assert (
            surface.sum() > 50 and (fast["planarity"][surface] >= 0.9).all() and (fast["se_normal"][surface] > 0).all()
        )
        # Read by the normal part from two places only (one place: the scan pattern's term models
        # the in-plane sampling).
        np.testing.assert_array_equal(fast["read_normal"], surface & (viewpoint is not None))
        if viewpoint is None:
            continue
        normal = np.column_stack([fast["nx"], fast["ny"], fast["nz"]])[surface]
        whitened = np.column_stack([fast["wu"], fast["wv"], fast["ww"]])[surface]
        vector = np.column_stack([fast["u"], fast["v"], fast["w"]])[surface]
        reading = np.einsum("ij,ij->i", vector, normal) / fast["se_normal"][surface]
        np.testing.assert_allclose(whitened, normal * reading[:, None], atol=1e-9)


def assert_same_field(a: dict, b: dict) -> None:
    assert list(a) == list(b)
    for column in a:
        assert a[column].dtype == b[column].dtype, column
        np.testing.assert_allclose(a[column], b[column], atol=1e-9, rtol=0, equal_nan=True, err_msg=column)


def test_write_read_round_trip(tmp_path):
    xyz1 = voxel_centre_clouds(per_voxel=20)
    settings = FieldSettings(CartesianGrid(cell_m=3.0), min_points=3)
    field = discrepancy_field(xyz1, xyz1 + 0.01, settings)
    write_field(tmp_path / "field.parquet", field, {"grid": settings.grid.to_config(), "stage": "00-none-x"})
    columns, meta = read_field(tmp_path / "field.parquet")
    assert list(columns) == list(field)
    for name in field:
        np.testing.assert_array_equal(columns[name], field[name])
        assert columns[name].dtype == field[name].dtype
    assert meta == {"grid": settings.grid.to_config(), "stage": "00-none-x"}
