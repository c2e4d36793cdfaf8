"""Voxel grids: analytic bins, out-of-grid points, Cartesian negative indices, config parsing."""

from __future__ import annotations

import numpy as np
import pytest

from lidarfield.errors import ConfigError
from lidarfield.field.grid import (
    CartesianGrid,
    FieldSettings,
    SphericalGrid,
    count_out_of_grid,
    field_settings_from_config,
    grid_from_config,
)


def direction(azimuth_deg, elevation_deg, r=10.0):
    az, el, r = np.broadcast_arrays(np.radians(azimuth_deg), np.radians(elevation_deg), np.asarray(r, dtype=float))
    return np.column_stack([r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)])


def test_spherical_bins_of_known_directions():
    grid = SphericalGrid()  # 36 x 10 deg, 5 x 8 deg from -20 to +20
    points = direction([5.0, 15.0, 355.0, -5.0, 185.0], [-19.0, -5.0, 1.0, 19.0, 12.5])
    bins = grid.bins(grid.assign(points))
    assert bins["az_bin"].tolist() == [0, 1, 35, 35, 18]
    assert bins["el_bin"].tolist() == [0, 1, 2, 4, 4]
    assert bins["r_bin"].tolist() == [-1] * 5
    assert grid.assign(points).max() < grid.n_voxels == 180


def test_uneven_edges_known_bins_and_uniform_edges_bin_as_arithmetic():
    """Explicit edges (channel-aware binning): known bins on both sides of each edge, and
    explicit edges that are uniform give the ids of the uniform grid (``with_edges`` then
    returns the uniform grid itself, binned by arithmetic)."""
    grid = SphericalGrid(elevation_edges_deg=(-31.333, -24.667, -3.333, 11.333), azimuth_edges_deg=(-0.1, 9.9, 359.9))
    assert (grid.elevation_bins, grid.elevation_deg, grid.azimuth_bins, grid.azimuth_offset_deg) == (
        3,
        (-31.333, 11.333),
        2,
        -0.1,
    )
    points = direction([-0.05, -0.15, 9.85, 9.95, 200.0, 200.0], [-24.6, -24.7, -3.3, -3.4, 11.3, -31.3])
    bins = grid.bins(grid.assign(points))
    assert bins["az_bin"].tolist() == [0, 1, 0, 1, 1, 1]
    assert bins["el_bin"].tolist() == [1, 0, 2, 1, 2, 0]
    assert grid.assign(direction(0.0, [11.4, -31.4])).tolist() == [-1, -1]
    uniform = SphericalGrid(azimuth_bins=12, azimuth_offset_deg=7.0, elevation_deg=(-30.0, 25.0), elevation_bins=6)
    explicit = SphericalGrid(
        elevation_edges_deg=tuple(np.linspace(-30.0, 25.0, 7)), azimuth_edges_deg=tuple(7.0 + np.arange(13) * 30.0)
    )
    rng = np.random.default_rng(3)
    points = rng.normal(scale=[10.0, 10.0, 3.0], size=(20_000, 3))
    np.testing.assert_array_equal(explicit.assign(points), uniform.assign(points))
    assert explicit.with_edges(explicit.elevation_edges(), explicit.azimuth_edges()) == uniform
    assert grid_from_config(grid.to_config()) == grid  # the field file's metadata round trip


def test_azimuth_offset_and_origin_shift():
    grid = SphericalGrid(azimuth_bins=4, azimuth_offset_deg=-45.0)  # bin 0 = [-45, 45)
    points = direction([0.0, 60.0, 170.0, 260.0, 314.0], 0.0)
    assert grid.bins(grid.assign(points))["az_bin"].tolist() == [0, 1, 2, 3, 3]
    origin = np.array([100.0, -50.0, 3.0])
    np.testing.assert_array_equal(grid.assign(points + origin, origin=origin), grid.assign(points))


def test_points_outside_elevation_or_range_are_out_not_folded():
    grid = SphericalGrid(elevation_deg=(-10.0, 10.0), elevation_bins=2, range_edges_m=(2.0, 5.0, 20.0))
    points = np.vstack(
        [
            direction(0.0, [-10.5, 10.5, 45.0, -80.0], 10.0),  # outside elevation
            direction(0.0, 0.0, [1.0, 25.0]),  # inside the cone, outside the shells
            direction(0.0, [-10.0, 10.0], 10.0),  # on the limits: the grid is closed
            direction(0.0, 5.0, [2.0, 4.9, 5.0, 20.0]),  # shells [2, 5), [5, 20]
            [[np.nan, 0.0, 0.0]],
        ]
    )
    ids = grid.assign(points)
    assert (ids[:6] == -1).all() and ids[-1] == -1
    assert count_out_of_grid(ids) == 7
    bins = grid.bins(ids)
    assert bins["el_bin"][6:8].tolist() == [0, 1]
    assert bins["r_bin"][8:12].tolist() == [0, 0, 1, 1]
    assert bins["az_bin"][:6].tolist() == [-1] * 6


def test_cartesian_negative_indices_round_trip_and_order():
    grid = CartesianGrid(cell_m=0.5, origin=(1.0, 0.0, -2.0))
    rng = np.random.default_rng(3)
    points = rng.uniform(-40.0, 40.0, size=(2000, 3))
    ids = grid.assign(points)
    bins = grid.bins(ids)
    expected = np.floor((points - np.array(grid.origin)) / 0.5).astype(np.int64)
    np.testing.assert_array_equal(np.column_stack([bins["ix"], bins["iy"], bins["iz"]]), expected)
    assert (expected < 0).any()
    # Sorting by id sorts by (iz, iy, ix).
    order = np.argsort(ids, kind="stable")
    np.testing.assert_array_equal(order, np.lexsort((expected[:, 0], expected[:, 1], expected[:, 2])))
    far = grid.assign(np.array([[1e9, 0.0, 0.0], [np.inf, 0.0, 0.0]]))
    assert far.tolist() == [-1, -1]


def test_config_round_trip_and_defaults():
    for grid in (SphericalGrid(range_edges_m=(0, 10, 50)), CartesianGrid(cell_m=2.0, origin=(1, 2, 3))):
        assert grid_from_config(grid.to_config()) == grid
    settings = field_settings_from_config({"kind": "spherical", "elevation_deg": [-15, 15], "cell_m": 2.0})
    assert settings == FieldSettings(SphericalGrid(elevation_deg=(-15.0, 15.0)), min_points=30, max_component_m=None)
    assert field_settings_from_config(settings.to_config()) == settings


@pytest.mark.parametrize(
    "config, key",
    [
        ({"kind": "hexagonal"}, "grid.kind"),
        ({"azimuth_bin": 36}, "grid.azimuth_bin"),
        ({"azimuth_bins": 0}, "grid.azimuth_bins"),
        ({"elevation_deg": [20, -20]}, "grid.elevation_deg"),
        ({"elevation_bins": 2.5}, "grid.elevation_bins"),
        ({"range_edges_m": [0, 10, 5]}, "grid.range_edges_m"),
        ({"kind": "cartesian", "cell_m": 0}, "grid.cell_m"),
        ({"kind": "cartesian", "origin": [0, 0]}, "grid.origin"),
        ({"min_points": 0}, "min_points"),
        ({"max_component_m": -1}, "max_component_m"),
    ],
)
def test_bad_config_names_the_key(config, key):
    with pytest.raises(ConfigError, match=key):
        field_settings_from_config(config)
