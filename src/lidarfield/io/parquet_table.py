"""Parquet tables with lidarfield's JSON metadata (key ``lidarfield``), written atomically."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from ..errors import InputError
from .atomic import atomic_path

METADATA_KEY = b"lidarfield"


def write_table(path: str | Path, columns: dict[str, np.ndarray], meta: dict | None = None) -> None:
    table = pa.Table.from_arrays([arrow_array(col) for col in columns.values()], names=list(columns))
    if meta is not None:
        table = table.replace_schema_metadata({METADATA_KEY: json.dumps(meta, default=_json_default)})
    # Dictionary encoding only where values repeat (ids, labels): tried on float coordinates
    # it fails and costs half of a points file's write time. Floats split into byte streams
    # (their exponent bytes repeat) and zstd: a registered pair, its neighbour distances and a
    # scan 19-23% smaller than snappy's plain floats, written and read no slower (lossless).
    floats = [name for name, col in zip(table.column_names, table.columns) if pa.types.is_floating(col.type)]
    repeating = [name for name in table.column_names if name not in floats]
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp, use_dictionary=repeating, use_byte_stream_split=floats, compression="zstd")


def read_table(
    path: str | Path, required: tuple[str, ...] = (), columns: tuple[str, ...] | None = None
) -> tuple[dict[str, np.ndarray], dict]:
    """Columns as numpy arrays (only ``columns`` when given, each of them required), and the
    lidarfield metadata ({} when absent)."""
    path = Path(path)
    if not path.is_file():
        raise InputError("file not found", path)
    required = tuple(required) + tuple(c for c in columns or () if c not in required)
    try:
        # ParquetFile, not pq.read_table: that one loads pyarrow.dataset, which imports pandas
        # (half a second of every job's start). One open for the schema and the columns.
        with pq.ParquetFile(path) as file:
            names = file.schema_arrow.names
            missing = [c for c in required if c not in names]
            if missing:
                raise InputError(f"missing column(s) {missing}; has {names}", path)
            table = file.read(columns=list(columns) if columns is not None else None)
    except (pa.ArrowException, OSError) as e:
        raise InputError(f"not a readable Parquet file ({e})", path) from None
    raw = (table.schema.metadata or {}).get(METADATA_KEY)
    meta = json.loads(raw) if raw else {}
    columns = {name: numpy_array(table.column(name)) for name in table.column_names}
    return columns, meta


def read_metadata(path: str | Path) -> dict:
    """A Parquet file's lidarfield metadata ({} when absent), without reading its columns."""
    path = Path(path)
    if not path.is_file():
        raise InputError("file not found", path)
    try:
        raw = (pq.read_schema(path).metadata or {}).get(METADATA_KEY)
    except (pa.ArrowException, OSError) as e:
        raise InputError(f"not a readable Parquet file ({e})", path) from None
    return json.loads(raw) if raw else {}


# pyarrow's own conversions (pa.array, to_numpy) import pandas to look at their input: half a
# second of every job's start. Numeric, boolean and string columns without nulls, all of
# lidarfield's, go through their buffers instead: the same values and dtypes as pyarrow's.


def arrow_array(values) -> pa.Array:
    values = np.asarray(values)
    if values.ndim == 1 and values.dtype.kind in "UO" and all(isinstance(v, str) for v in values.tolist()):
        encoded = [v.encode() for v in values.tolist()]
        offsets = np.zeros(len(encoded) + 1, np.int64)
        np.cumsum([len(b) for b in encoded], out=offsets[1:])
        return pa.Array.from_buffers(
            pa.large_string(), len(encoded), [None, pa.py_buffer(offsets), pa.py_buffer(b"".join(encoded))]
        ).cast(pa.string())
    if values.ndim != 1 or values.dtype.kind not in "biuf":
        return pa.array(values)
    values = np.ascontiguousarray(values)
    if values.dtype.kind == "b":
        bits = np.packbits(values, bitorder="little")
        return pa.Array.from_buffers(pa.bool_(), len(values), [None, pa.py_buffer(bits)])
    return pa.Array.from_buffers(pa.from_numpy_dtype(values.dtype), len(values), [None, pa.py_buffer(values)])


def numpy_array(column: pa.ChunkedArray) -> np.ndarray:
    array = column.chunk(0) if column.num_chunks == 1 else column.combine_chunks()
    kind = array.type
    if array.null_count == 0 and (pa.types.is_string(kind) or pa.types.is_large_string(kind)):
        return np.array(array.to_pylist(), dtype=object)
    if array.null_count or not (pa.types.is_integer(kind) or pa.types.is_floating(kind) or pa.types.is_boolean(kind)):
        return column.to_numpy(zero_copy_only=False)
    data, n, offset = array.buffers()[1], len(array), array.offset
    if pa.types.is_boolean(kind):
        bits = np.frombuffer(data, np.uint8) if n else np.empty(0, np.uint8)
        return np.unpackbits(bits, count=offset + n, bitorder="little")[offset:].astype(bool)
    dtype = np.dtype(kind.to_pandas_dtype())
    return np.frombuffer(data, dtype, count=n, offset=offset * dtype.itemsize) if n else np.empty(0, dtype)


def _json_default(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating,)):
        return float(obj)
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")
