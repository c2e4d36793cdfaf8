"""A stage whose hypothesis removed and moved nothing takes the field of the stage before (the
same ``points_digest``) instead of computing it again: the same columns, statistics and summary
row as a field computed anew; a stage that removed points computes its own."""

from __future__ import annotations

import json
import logging

import numpy as np

from lidarfield.commands.jobs import field_stage, stack_jobs
from lidarfield.field.file import read_field
from lidarfield.pair import RegisteredPair, write_pair

GRID = {"kind": "spherical", "azimuth_bins": 12, "elevation_deg": [-60, 60], "elevation_bins": 3, "min_points": 5}
KEEP_ALL = {"crop": {"max_range_m": 10_000}}  # removes no point of the pair below
CROP = {"crop": {"max_range_m": 25}}


def test_a_stage_that_changed_nothing_takes_the_field_before_it(tmp_path, caplog):
    rng = np.random.default_rng(7)
    xyz1 = rng.uniform(-30, 30, size=(4000, 3))
    registered = tmp_path / "registered.parquet"
    write_pair(registered, RegisteredPair(xyz1, xyz1 + rng.normal(0, 0.05, size=xyz1.shape)))
    dirs = [tmp_path / f"0{level}-x-0000000{level}" for level in range(4)]
    with caplog.at_level(logging.INFO, logger="lidarfield.commands.jobs"):
        changes = stack_jobs(registered, [KEEP_ALL, CROP, KEEP_ALL], dirs, GRID, "demo")
    reused = [d for d in dirs if f"the field of {d / 'field.parquet'}" in caplog.text]
    assert reused == [dirs[0], dirs[2]]  # taken by stages 1 and 3; stage 2's crop removed points

    # stage 1 and 3 computed anew: the same files, but for the stage they name
    for level in (1, 3):
        fresh = tmp_path / "fresh" / dirs[level].name
        fresh.mkdir(parents=True)
        removed = dirs[level] / "removed.parquet"
        args = (registered, changes[:level], removed, GRID, "demo", fresh / "field.parquet", fresh / "stats.json")
        field_stage(*args, dirs[level].name)
        (columns, meta), (fresh_columns, fresh_meta) = read_field(dirs[level] / "field.parquet"), read_field(args[5])
        assert list(columns) == list(fresh_columns)
        for name, values in fresh_columns.items():
            np.testing.assert_array_equal(columns[name], values, err_msg=name)
        assert meta == fresh_meta and meta["stage"] == dirs[level].name
        assert json.loads((dirs[level] / "stats.json").read_text()) == json.loads(args[6].read_text())

    before, after = read_field(dirs[1] / "field.parquet")[0], read_field(dirs[2] / "field.parquet")[0]
    assert after["n1"].sum() < before["n1"].sum()  # the crop's own field: fewer points
