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
    table = pa.table({name: np.asarray(col) for name, col in columns.items()})
    if meta is not None:
        table = table.replace_schema_metadata({METADATA_KEY: json.dumps(meta, default=_json_default)})
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)


def read_table(path: str | Path, required: tuple[str, ...] = (), columns: tuple[str, ...] | None = None) -> tuple[dict[str, np.ndarray], dict]:
    """Columns as numpy arrays (only ``columns`` when given, each of them required), and the
    lidarfield metadata ({} when absent)."""
    path = Path(path)
    if not path.is_file():
        raise InputError("file not found", path)
    required = tuple(required) + tuple(c for c in columns or () if c not in required)
    try:
        with pq.ParquetFile(path) as file:  # one open for the schema and the columns
            names = file.schema_arrow.names
            missing = [c for c in required if c not in names]
            if missing:
                raise InputError(f"missing column(s) {missing}; has {names}", path)
            table = file.read(columns=list(columns) if columns is not None else None)
    except (pa.ArrowException, OSError) as e:
        raise InputError(f"not a readable Parquet file ({e})", path) from None
    raw = (table.schema.metadata or {}).get(METADATA_KEY)
    meta = json.loads(raw) if raw else {}
    columns = {name: table.column(name).to_numpy(zero_copy_only=False) for name in table.column_names}
    return columns, meta


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
