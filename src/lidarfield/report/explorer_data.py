"""The pair explorer's data: one file of the pair's points, one file per stage.

A pair's explorer (``{pair}/explorer/``) reads ``points.js`` (a sample of both clouds of the
registered pair, at most ``budget`` points of each) and one ``{stage}.js`` per stage (its
field's valid vectors, and which points it removed or moved). ``rest.js`` holds the points
left out of the sample; the page loads it only when the analyst asks for every point. A
stage's file depends only on the registered pair's point counts, its own ``changes.parquet``
and its own ``field.parquet``: appending a hypothesis writes its stage's file and rewrites no other.

The page holds a cloud's points in its draw order (:func:`draw_order`): the sample, then the
rest. A stage's file names its points by their position in that order, so those below the
sample's size are in ``points.js``. The order is a pure function of a cloud's point count and
the budget, so a stage's job finds its rows' positions without reading ``points.js``.

Each file is one binary blob (:func:`encode`): ``LFX1``, a little-endian uint32 header length,
a JSON header, then little-endian typed arrays, each starting at a multiple of 8 bytes. A page
opened from ``file://`` may not ``fetch`` a file beside it, but it may load a script: the blob
is wrapped, base64-encoded, in a one-line script (:func:`wrap_script`) that hands it to the
page's ``lidarfieldExplorer.add``.
"""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path

import numpy as np

from ..analysis.tags import TAGS
from ..errors import InputError
from ..io.atomic import write_text
from ..io.parquet_table import read_metadata, read_table
from ..plots.stage_data import read_vector_field
from ..storage.layout import level_of
from ..storage.stage_points import NO_MITIGATION

MAGIC = b"LFX1"
ALIGN = 8
# The dtypes a blob may hold, by the name its header gives them (the page's typed arrays).
DTYPES = {"f8": "<f8", "f4": "<f4", "i4": "<i4", "u4": "<u4", "u1": "u1"}
SAMPLE_SEED = 0
POINTS = "points"  # the key and file stem of the pair's sampled points
REST = "rest"  # the key and file stem of the points left out of the sample
FOLDER = "explorer"  # a pair's explorer files: {pair}/explorer/
SCRIPT_PREFIX = "lidarfieldExplorer.add("


def encode(header: dict, arrays: dict[str, np.ndarray]) -> bytes:
    """A blob of ``header`` (JSON) and ``arrays`` (their dtypes among DTYPES', little-endian)."""
    layout, chunks, offset = [], [], 0
    for name, values in arrays.items():
        values = np.ascontiguousarray(values)
        kind = next((k for k, v in DTYPES.items() if values.dtype == np.dtype(v)), None)
        if kind is None:
            raise ValueError(f"{name}: dtype {values.dtype} is not one of {sorted(DTYPES.values())}")
        data = values.tobytes()
        layout.append({"name": name, "dtype": kind, "shape": list(values.shape), "offset": offset})
        chunks.append(data + b"\0" * (-len(data) % ALIGN))
        offset += len(chunks[-1])
    head = json.dumps({**header, "arrays": layout}, separators=(",", ":"), allow_nan=False).encode()
    # the arrays start at a multiple of ALIGN from the blob's start, so the page views them in place
    head += b" " * (-(len(MAGIC) + 4 + len(head)) % ALIGN)
    return MAGIC + struct.pack("<I", len(head)) + head + b"".join(chunks)


def decode(blob: bytes) -> tuple[dict, dict[str, np.ndarray]]:
    """The header and arrays of a blob (what the page reads, for the tests and the Python side)."""
    if blob[:4] != MAGIC:
        raise ValueError("not an explorer blob (no LFX1 magic)")
    (length,) = struct.unpack("<I", blob[4:8])
    header = json.loads(blob[8 : 8 + length])
    start = 8 + length
    arrays = {}
    for a in header.pop("arrays"):
        dtype = np.dtype(DTYPES[a["dtype"]])
        count = int(np.prod(a["shape"], dtype=np.int64))
        arrays[a["name"]] = np.frombuffer(blob, dtype, count, start + a["offset"]).reshape(a["shape"])
    return header, arrays


def wrap_script(key: str, blob: bytes) -> str:
    """The script that hands ``blob`` to the page under ``key``."""
    return f'{SCRIPT_PREFIX}{json.dumps(key)},"{base64.b64encode(blob).decode("ascii")}");\n'


def read_script(path: str | Path) -> tuple[str, dict, dict[str, np.ndarray]]:
    """The key, header and arrays of an explorer script file."""
    text = Path(path).read_text()
    if not text.startswith(SCRIPT_PREFIX):
        raise InputError("not an explorer data script", path)
    key, payload = json.loads("[" + text[len(SCRIPT_PREFIX) :].rstrip().rstrip(";").rstrip(")") + "]")
    return (key, *decode(base64.b64decode(payload)))


def sample_rows(count: int, budget: int) -> np.ndarray:
    """The rows of a cloud of ``count`` points the explorer draws: all of them when ``budget``
    is 0 or not below ``count``, else ``budget`` rows chosen with a fixed seed, ascending."""
    if budget <= 0 or count <= budget:
        return np.arange(count, dtype=np.int64)
    return np.sort(np.random.default_rng(SAMPLE_SEED).choice(count, size=budget, replace=False))


def draw_order(count: int, budget: int) -> np.ndarray:
    """A cloud's rows in the page's order: the sample (``points.js``), then the rest, ascending."""
    sample = sample_rows(count, budget)
    if len(sample) == count:
        return sample
    left = np.ones(count, bool)
    left[sample] = False
    return np.concatenate([sample, np.flatnonzero(left)])


def _cloud_counts(cloud: np.ndarray) -> tuple[int, int]:
    return int(np.count_nonzero(cloud == 1)), int(np.count_nonzero(cloud == 2))


def registered_counts(registered: str | Path) -> tuple[int, int]:
    """The point counts of both clouds of a registered pair file."""
    columns, _ = read_table(registered, columns=("cloud",))
    return _cloud_counts(np.asarray(columns["cloud"]))


def points_blobs(registered: str | Path, budget: int) -> tuple[bytes, bytes]:
    """The sampled points of both clouds (float32 xyz, in frame 1) and the sensor origins' pose,
    and the rest of the points (the same, in draw order after the sample)."""
    columns, meta = read_table(registered, required=("cloud", "x", "y", "z"))
    cloud = np.asarray(columns["cloud"])
    xyz = np.column_stack([columns[a] for a in "xyz"])
    sampled, rest, clouds = {}, {}, []
    for c in (1, 2):
        mine = xyz[cloud == c]
        order = draw_order(len(mine), budget)
        drawn = len(sample_rows(len(mine), budget))
        sampled[f"xyz{c}"] = mine[order[:drawn]].astype(np.float32)
        rest[f"xyz{c}"] = mine[order[drawn:]].astype(np.float32)
        clouds.append({"total": len(mine), "drawn": drawn})
    header = {"budget": budget, "clouds": clouds, "T_1_2": meta.get("T_1_2")}
    return encode({"kind": POINTS, **header}, sampled), encode({"kind": REST, **header}, rest)


def change_arrays(changes: dict[str, np.ndarray], orders: tuple[np.ndarray, np.ndarray], drawn: tuple[int, int]):
    """The stage's removed and moved points (their positions in each cloud's draw order; a
    moved one's new coordinates) and the counts, in the sample (``drawn``) and in all, per cloud."""
    arrays, counts = {}, []
    cloud, rows = np.asarray(changes["cloud"]), np.asarray(changes["row"], dtype=np.int64)
    removed = np.asarray(changes["removed"], dtype=bool)
    xyz = np.column_stack([changes[a] for a in "xyz"])
    for c, order, sampled in zip((1, 2), orders, drawn):
        position = np.empty(len(order), np.uint32)
        position[order] = np.arange(len(order), dtype=np.uint32)
        count = {}
        for what, mine in (("removed", removed), ("moved", ~removed)):
            chosen = (cloud == c) & mine
            at = position[rows[chosen]]
            arrays[f"{what}{c}"] = at
            if what == "moved":
                arrays[f"moved{c}_xyz"] = xyz[chosen].astype(np.float32)
            count[what] = {"total": len(at), "drawn": int(np.count_nonzero(at < sampled))}
        counts.append(count)
    return arrays, {"clouds": counts}


def field_arrays(field_path: str | Path) -> tuple[dict, dict]:
    """The valid vectors of a field file: voxel id, bins, counts, tail (mean1), vector, |d|,
    se, z and the tags as bits (bit i: TAGS[i])."""
    f = read_vector_field(field_path)
    c = f.columns
    bins = [b for b in ("az_bin", "el_bin", "r_bin") if b in c] or [b for b in ("ix", "iy", "iz") if b in c]
    arrays = {
        "voxel": np.asarray(c["voxel"], dtype=np.float64),  # exact to 2^53, what a page's number holds
        "bins": np.column_stack([np.asarray(c[b]) for b in bins]).astype(np.int32),
        "n": np.column_stack([c["n1"], c["n2"]]).astype(np.int32),
        "tail": f.tails.astype(np.float32),
        "vector": f.vectors.astype(np.float32),
        "magnitude": f.magnitude,
    }
    for name in ("se", "z"):
        if name in c:
            arrays[name] = np.asarray(c[name], dtype=np.float64)
    tags = np.zeros(len(f.magnitude), np.uint32)
    for bit, tag in enumerate(TAGS):
        if f"tag_{tag}" in c:
            tags |= np.asarray(c[f"tag_{tag}"], dtype=bool).astype(np.uint32) << bit
    arrays["tags"] = tags
    statistics = f.meta.get("statistics") or {}
    header = {
        "bins": bins,
        "tags": list(TAGS),
        "z_min": f.z_min,
        "voxels": int(statistics.get("voxels", len(f.magnitude))),
        "max_magnitude": f.max_magnitude,
    }
    return arrays, header


def stage_blob(
    stage_id: str,
    level: int,
    hypothesis: str,
    field_path: str | Path,
    changes_path: str | Path | None,
    counts: tuple[int, int],
    budget: int,
    T_1_2,
) -> bytes:
    """A stage's blob: its field's vectors and, after stage 0, what it did to the sampled points."""
    arrays, header = field_arrays(field_path)
    orders = tuple(draw_order(n, budget) for n in counts)
    if changes_path is not None:
        columns, meta = read_table(changes_path, required=("cloud", "row", "removed", "x", "y", "z"))
        drawn = tuple(len(sample_rows(n, budget)) for n in counts)
        moves, change_header = change_arrays(columns, orders, drawn)
        arrays |= moves
        header |= change_header
        T_1_2 = meta.get("T_1_2", T_1_2)
    header |= {"kind": "stage", "stage": stage_id, "level": level, "hypothesis": hypothesis, "T_1_2": T_1_2}
    return encode(header, arrays)


def write_points_scripts(registered: str | Path, budget: int, out: str | Path, rest: str | Path) -> list[Path]:
    """The pair's sampled points at ``out`` and the rest at ``rest``."""
    for path, key, blob in zip((out, rest), (POINTS, REST), points_blobs(registered, budget)):
        write_text(path, wrap_script(key, blob))
    return [Path(out), Path(rest)]


def write_stage_script(
    registered: str | Path, field_path: str | Path, changes_path: str | Path | None, budget: int, out: str | Path
) -> Path:
    """A stage's script; the stage's id, level and hypothesis come from its field file's and
    changes file's metadata (stage 0 has no changes file: the registered pair's pose)."""
    field_meta = read_metadata(field_path)
    stage_id = str(field_meta.get("stage") or Path(field_path).parent.name)
    changes_meta = read_metadata(changes_path) if changes_path is not None else {}
    level = int(changes_meta.get("level", level_of(stage_id) or 0))
    hypothesis = str(changes_meta.get("hypothesis") or (NO_MITIGATION if level == 0 else stage_id.split("-")[1]))
    blob = stage_blob(
        stage_id,
        level,
        hypothesis,
        field_path,
        changes_path,
        registered_counts(registered),
        budget,
        read_metadata(registered).get("T_1_2"),
    )
    write_text(out, wrap_script(stage_id, blob))
    return Path(out)
