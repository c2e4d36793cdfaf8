"""The pair explorer's data files: the blob format round-trips, the sample is fixed, and a stage's
file draws exactly the sampled points its changes name, and its field's valid voxels."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.synthetic_study import write_synthetic_pair
from lidarfield.io.parquet_table import read_table
from lidarfield.pair import read_pair
from lidarfield.report.explorer import points_script, rest_script, stage_script, write_explorer_data
from lidarfield.report.explorer_data import (
    ALIGN,
    change_arrays,
    decode,
    draw_order,
    encode,
    read_script,
    sample_rows,
    wrap_script,
)


def test_blob_round_trip_keeps_every_dtype_and_aligns_the_arrays():
    rng = np.random.default_rng(1)
    arrays = {
        "a": rng.normal(size=(5, 3)).astype(np.float32),
        "b": np.array([2**53, -1.5]),
        "c": np.arange(7, dtype=np.uint8),
        "d": np.array([-3, 4], dtype=np.int32),
        "e": np.array([], dtype=np.uint32),
    }
    blob = encode({"kind": "test", "name": "ü"}, arrays)
    header, back = decode(blob)
    assert header == {"kind": "test", "name": "ü"}
    for name, values in arrays.items():
        assert back[name].dtype == values.dtype and np.array_equal(back[name], values)
        # the page views each array in place: its start is a multiple of ALIGN bytes
        assert (back[name].__array_interface__["data"][0] - np.frombuffer(blob, np.uint8).ctypes.data) % ALIGN == 0
    with pytest.raises(ValueError, match="int64"):
        encode({}, {"x": np.arange(3, dtype=np.int64)})


def test_script_wraps_the_blob(tmp_path):
    path = tmp_path / "s.js"
    path.write_text(wrap_script("02-shadow-0123abcd", encode({"k": 1}, {"x": np.ones(3, np.float32)})))
    key, header, arrays = read_script(path)
    assert key == "02-shadow-0123abcd" and header == {"k": 1} and arrays["x"].tolist() == [1, 1, 1]


def test_sample_is_fixed_sorted_and_within_budget():
    assert np.array_equal(sample_rows(10, 0), np.arange(10))
    assert np.array_equal(sample_rows(10, 10), np.arange(10))
    rows = sample_rows(1000, 300)
    assert len(rows) == 300 and len(np.unique(rows)) == 300 and np.all(np.diff(rows) > 0)
    assert np.array_equal(rows, sample_rows(1000, 300))


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """A three-stage synthetic pair with its explorer files (a budget of 1,000 points a cloud)."""
    pair_dir = tmp_path_factory.mktemp("pair") / "p"
    dirs = write_synthetic_pair(pair_dir, "p", seed=3, levels=3, n=3000)
    write_explorer_data(pair_dir, dirs, 1000)
    return pair_dir, dirs


def test_draw_order_is_the_sample_then_the_rest():
    order = draw_order(1000, 300)
    assert np.array_equal(order[:300], sample_rows(1000, 300))
    assert np.all(np.diff(order[300:]) > 0) and np.array_equal(np.sort(order), np.arange(1000))
    assert np.array_equal(draw_order(10, 0), np.arange(10))


def test_points_are_the_sampled_rows_of_each_cloud_and_the_rest_the_others(pair):
    pair_dir, _ = pair
    registered, _ = read_pair(pair_dir / "registered.parquet")
    _, header, arrays = read_script(points_script(pair_dir))
    key, rest_header, rest = read_script(rest_script(pair_dir))
    assert key == "rest" and rest_header["clouds"] == header["clouds"]
    for c, xyz in ((1, registered.xyz1), (2, registered.xyz2)):
        assert header["clouds"][c - 1] == {"total": len(xyz), "drawn": 1000}
        sample = sample_rows(len(xyz), 1000)
        assert np.array_equal(arrays[f"xyz{c}"], xyz[sample].astype(np.float32))
        others = np.setdiff1d(np.arange(len(xyz)), sample)
        assert np.array_equal(rest[f"xyz{c}"], xyz[others].astype(np.float32))


def test_a_stage_names_the_points_it_removed_where_they_were(pair):
    pair_dir, dirs = pair
    _, _, points = read_script(points_script(pair_dir))
    _, _, rest = read_script(rest_script(pair_dir))
    registered, _ = read_pair(pair_dir / "registered.parquet")
    for d in dirs[1:]:
        changes, _ = read_table(d / "changes.parquet")
        removed, _ = read_table(d / "removed.parquet")
        _, header, arrays = read_script(stage_script(pair_dir, d.name))
        for c in (1, 2):
            gone = changes["row"][(changes["cloud"] == c) & changes["removed"]]
            count = len(registered.xyz1 if c == 1 else registered.xyz2)
            sample = sample_rows(count, 1000)
            # the plain reference: a row's position is its index in the sample, else 1000 + its
            # index among the rows left out
            others = [r for r in range(count) if r not in set(sample.tolist())]
            position = {**{r: i for i, r in enumerate(sample)}, **{r: 1000 + i for i, r in enumerate(others)}}
            expected = np.array([position[r] for r in gone])
            assert np.array_equal(np.sort(arrays[f"removed{c}"]), np.sort(expected))
            in_sample = int(np.count_nonzero(expected < 1000))
            assert header["clouds"][c - 1]["removed"] == {"total": len(gone), "drawn": in_sample}
            assert 0 < in_sample < len(gone)
            # where the page draws them (sample and rest, in draw order) is where removed.parquet says they were
            everything = np.vstack([points[f"xyz{c}"], rest[f"xyz{c}"]])
            drawn = everything[arrays[f"removed{c}"]].astype(np.float64)
            mine = removed["cloud"] == c
            there = np.column_stack([removed[a][mine] for a in "xyz"])
            nearest = np.min(np.linalg.norm(drawn[:, None, :] - there[None, :, :], axis=2), axis=1)
            assert nearest.max() < 1e-5


def test_a_stage_holds_its_fields_valid_voxels(pair):
    pair_dir, dirs = pair
    for d in dirs:
        field, _ = read_table(d / "field.parquet")
        valid = field["valid"] & np.isfinite(field["magnitude"])
        _, header, arrays = read_script(stage_script(pair_dir, d.name))
        assert header["stage"] == d.name and header["bins"] == ["az_bin", "el_bin", "r_bin"]
        assert np.array_equal(arrays["voxel"], field["voxel"][valid].astype(np.float64))
        assert np.array_equal(arrays["n"], np.column_stack([field["n1"][valid], field["n2"][valid]]))
        assert np.array_equal(arrays["magnitude"], field["magnitude"][valid])
        assert np.array_equal(arrays["bins"][:, 0], field["az_bin"][valid])
        for bit, tag in enumerate(header["tags"]):
            assert np.array_equal((arrays["tags"] >> bit) & 1, field[f"tag_{tag}"][valid].astype(np.uint32))


def test_appending_a_stage_leaves_the_other_files_as_they_were(pair, tmp_path):
    """The same pair with one stage fewer: its files are byte for byte the longer stack's."""
    pair_dir, dirs = pair
    short_dir = tmp_path / "p"
    short = write_synthetic_pair(short_dir, "p", seed=3, levels=2, n=3000)
    write_explorer_data(short_dir, short, 1000)
    assert points_script(short_dir).read_bytes() == points_script(pair_dir).read_bytes()
    for d in short:
        assert stage_script(short_dir, d.name).read_bytes() == stage_script(pair_dir, d.name).read_bytes()


def test_moved_points_carry_their_new_coordinates():
    orders = (np.array([2, 5, 9, 0, 1, 3, 4, 6, 7, 8]), np.array([0, 1, 2]))  # samples of 3 and 2 rows first
    changes = {
        "cloud": np.array([1, 1, 1, 2], np.uint8),
        "row": np.array([5, 6, 9, 1]),
        "removed": np.array([True, False, False, False]),
        "x": np.array([np.nan, 1.0, 2.0, 3.0]),
        "y": np.array([np.nan, 4.0, 5.0, 6.0]),
        "z": np.array([np.nan, 7.0, 8.0, 9.0]),
    }
    arrays, header = change_arrays(changes, orders, (3, 2))
    assert arrays["removed1"].tolist() == [1] and arrays["moved1"].tolist() == [7, 2]  # row 6 is in the rest
    assert arrays["moved1_xyz"].tolist() == [[1.0, 4.0, 7.0], [2.0, 5.0, 8.0]]
    assert arrays["moved2"].tolist() == [1] and arrays["moved2_xyz"].tolist() == [[3.0, 6.0, 9.0]]
    assert header["clouds"][0] == {"removed": {"total": 1, "drawn": 1}, "moved": {"total": 2, "drawn": 1}}
