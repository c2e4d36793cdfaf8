"""Parquet columns converted through their buffers agree with pyarrow's own conversions, and
leave pandas unimported (it costs every job half a second)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pyarrow as pa
import pytest

from lidarfield.io.parquet_table import arrow_array, numpy_array

RNG = np.random.default_rng(7)
COLUMNS = {
    "float64": RNG.normal(size=1001),
    "float64_nan": np.where(RNG.random(1001) < 0.3, np.nan, RNG.normal(size=1001)),
    "float32": RNG.normal(size=1001).astype(np.float32),
    "int64": RNG.integers(-(10**12), 10**12, 1001),
    "int32": RNG.integers(-1000, 1000, 1001).astype(np.int32),
    "uint8": RNG.integers(1, 3, 1001).astype(np.uint8),
    "bool": RNG.random(1001) < 0.5,
    "str": np.array(["field_of_view", "shadow", "é", ""])[RNG.integers(0, 4, 1001)],
    "object_str": np.array(["a", "bc", "def"], dtype=object)[RNG.integers(0, 3, 1001)],
    "empty": np.empty(0),
}


def same(a: np.ndarray, b: np.ndarray) -> bool:
    return (
        a.dtype == b.dtype
        and a.shape == b.shape
        and all(x == y or (x != x and y != y) for x, y in zip(a.tolist(), b.tolist()))
    )


@pytest.mark.parametrize("name", COLUMNS)
def test_arrow_array_equals_pyarrows_conversion(name):
    expected = pa.array(COLUMNS[name])
    got = arrow_array(COLUMNS[name])
    assert got.type == expected.type
    assert got.equals(expected) or same(got.to_numpy(zero_copy_only=False), expected.to_numpy(zero_copy_only=False))


@pytest.mark.parametrize("name", COLUMNS)
@pytest.mark.parametrize("layout", ["one chunk", "sliced", "three chunks"])
def test_numpy_array_equals_pyarrows_conversion(name, layout):
    array = pa.array(COLUMNS[name])
    column = {
        "one chunk": pa.chunked_array([array]),
        "sliced": pa.chunked_array([array.slice(13, 500)]) if len(array) else pa.chunked_array([array]),
        "three chunks": pa.chunked_array([array.slice(0, 3), array.slice(3, 400), array.slice(403)], type=array.type),
    }[layout]
    assert same(numpy_array(column), column.to_numpy(zero_copy_only=False))


def test_a_column_with_nulls_takes_pyarrows_path():
    column = pa.chunked_array([pa.array([1.0, None, 3.0])])
    assert same(numpy_array(column), np.array([1.0, np.nan, 3.0]))


def test_writing_and_reading_a_table_imports_no_pandas(tmp_path):
    code = (
        "import sys, numpy as np; from lidarfield.io.parquet_table import read_table, write_table; "
        f"write_table({str(tmp_path / 't.parquet')!r}, "
        f"{{'x': np.arange(3.0), 'h': np.array(['a', 'b', 'c']), 'v': np.ones(3, bool)}}, {{'k': 1}}); "
        f"columns, meta = read_table({str(tmp_path / 't.parquet')!r}); "
        "print(columns['x'].tolist(), columns['h'].tolist(), columns['v'].tolist(), meta, 'pandas' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[0.0, 1.0, 2.0] ['a', 'b', 'c'] [True, True, True] {'k': 1} False"
