"""The registered-pair table: a round trip through Parquet, whichever order its rows are in."""

from __future__ import annotations

import numpy as np

from lidarfield.io.parquet_table import read_table, write_table
from lidarfield.pair import RegisteredPair, read_pair, write_pair


def test_a_pair_round_trips_through_its_points_file(tmp_path):
    rng = np.random.default_rng(0)
    pair = RegisteredPair(
        rng.normal(size=(50, 3)),
        rng.normal(size=(70, 3)),
        np.eye(4),
        attributes1={"ring": np.arange(50)},
        attributes2={"ring": np.arange(70) + 100},
    )
    write_pair(tmp_path / "points.parquet", pair)
    back, _ = read_pair(tmp_path / "points.parquet")
    np.testing.assert_array_equal(back.xyz1, pair.xyz1)
    np.testing.assert_array_equal(back.xyz2, pair.xyz2)
    np.testing.assert_array_equal(back.attributes2["ring"], pair.attributes2["ring"])
    assert back.xyz1.flags["C_CONTIGUOUS"] and back.xyz2.flags["C_CONTIGUOUS"]


def test_rows_of_both_clouds_interleaved_are_split_by_the_cloud_column(tmp_path):
    """A file written by another tool need not hold cloud 1 first: the cloud column decides."""
    rng = np.random.default_rng(1)
    pair = RegisteredPair(
        rng.normal(size=(40, 3)),
        rng.normal(size=(30, 3)),
        np.eye(4),
        attributes1={"t": np.arange(40.0)},
        attributes2={"t": -np.arange(30.0)},
    )
    columns = pair.to_columns()
    order = rng.permutation(70)
    write_table(tmp_path / "shuffled.parquet", {k: v[order] for k, v in columns.items()}, pair.metadata())
    back, _ = read_pair(tmp_path / "shuffled.parquet")
    kept1 = np.sort(order[order < 40])  # the rows of cloud 1, in the file's order
    np.testing.assert_array_equal(back.xyz1, pair.xyz1[[i for i in order if i < 40]])
    np.testing.assert_array_equal(back.xyz2, pair.xyz2[[i - 40 for i in order if i >= 40]])
    np.testing.assert_array_equal(np.sort(back.attributes1["t"]), kept1.astype(float))
    assert read_table(tmp_path / "shuffled.parquet")[0]["cloud"][:40].tolist() != [1] * 40
