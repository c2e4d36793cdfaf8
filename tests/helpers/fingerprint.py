"""A study's results as a fingerprint: every column of its summary and of each stage's field.

Each numeric column is kept as its row count, its count of non-finite values and three sums
of its finite values (plain, absolute and weighted by row position, so a reordering shows);
every other column as a digest. Two fingerprints agree (:func:`differences`) when the other
columns are equal and every sum agrees within ``RTOL``: a changed count, vector or verdict
anywhere is a difference; a last-bit difference in a normal or a standard error is not.
Exact digests were not portable: numpy's SIMD kernels and LAPACK's differ by a few ulps from
one processor to another (2026-11-27: on this project's AVX-512 machine main's own code gave
other last bits of nx, ny, nz, planarity, se, wu, wv, ww and z than the digests written on the
machine before, with counts, means and vectors identical).

``tests/data/default_study.json`` is the default study's, written with

    snakemake --cores 2 results/summary.parquet
    python tests/helpers/fingerprint.py results tests/data/default_study.json

and tests/workflow/test_stage_changes.py checks the code of today against it. History: first
written by the code that stored every stage's survivors (e16a60a); regenerated on branch covis
(2026-11-25) when the vectors' covariance gained the change of viewpoint (se, z, wu, wv, ww and
the summary's significance columns changed); rewritten in this form on 2026-11-27 from main's
outputs (bit-identical to those of 93528e2 on this machine). Regenerated the same day for
channel-aware binning (lidarfield.field.channels): the field's band edges moved between
paper-sim-80's channels (-7.5 -> -7.4, 0 -> -0.2, 7.5 -> 7.4 deg; 0 deg is a channel) and its
azimuth columns between firings (offset 0 -> 0.1 deg). Every field column changed (bins,
counts, means, vectors and what follows from them); in the summary the field's statistics
(magnitudes, energy shares, rigid part, p_direction, p_coherence, share_significant, voxels,
voxels_valid) and four new columns (elevation_edges_deg, azimuth_edges_deg, binning,
binning_warning). Unchanged: n1, n2, removed1, removed2 (and every removed.parquet, compared
file by file), the verdicts and voxels_significant. Regenerated on branch verdict (2026-11-27)
when the randomness tests began to read a surface voxel of a pair from two places by its normal
part alone (``field.significance``; every pair of the default study is from two places): the
field's wu, wv, ww changed and it gained se_normal and read_normal; in the summary
p_direction, p_coherence and the verdict (paper-sim's three stages now ``random``: p 0.586 /
0.506 at stage 0, patterned before). Unchanged: every other column, n1, n2, removed1, removed2,
voxels_significant, the vectors and their se and z. Regenerated on branch surface (2026-11-28)
when a surface voxel began to be read by its normal part only where the line of sight from
sensor 1 crosses its surface (``significance.read_by_normal_part``): on the drive's pairs
drive-000 (stages 0-2), drive-001 and drive-004 (stages 1-2) one or two voxels a stage that hold
a plane along the rays are read whole, so the field's read_normal, wu, wv and ww changed there.
Unchanged: every summary column (the p-values and verdicts among them), every other field
column and every removal (n1, n2, removed1, removed2). Regenerated on branch randomafter
(2026-11-28) when the randomness tests' null draws began to correlate between neighbouring
voxels (``randomness.NULL_NEIGHBOUR_CORRELATION``): in the summary p_direction and p_coherence
changed (their sums over the 27 stages 2.576 -> 2.664 and 1.422 -> 2.792). Unchanged: every
verdict, every field column and every removal.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

# How closely two fingerprints' sums must agree, relative to the column's sum of |x|: far above a
# few ulps in each of a few hundred values, far below one point more in a voxel (about 1e-5 of
# a field's counts) or a vector moved by a micrometre.
RTOL = 1e-7


def column_digest(values: np.ndarray) -> str | list[float]:
    """A numeric column's [rows, non-finite, sum, sum of |x|, position-weighted sum]; any other
    column's digest."""
    values = np.asarray(values)
    if values.dtype.kind in "biuf":
        x = values.astype(np.float64)
        finite = np.isfinite(x)
        weights = (np.arange(len(x)) % 97 + 1) / 97.0
        x = np.where(finite, x, 0.0)
        return [len(x), int(np.count_nonzero(~finite)), float(x.sum()), float(np.abs(x).sum()), float(x @ weights)]
    return hashlib.sha256(json.dumps([None if v is None else str(v) for v in values]).encode()).hexdigest()[:16]


def table_digests(path: Path, order: tuple[str, ...] = ()) -> dict[str, str]:
    """Each column's digest (rows sorted by ``order``, the columns that name them)."""
    table = pq.read_table(path)
    if order:
        table = table.sort_by([(name, "ascending") for name in order])
    return {name: column_digest(table.column(name).to_numpy(zero_copy_only=False)) for name in table.column_names}


def fingerprint(results: Path) -> dict:
    """The digests of ``results/summary.parquet`` (rows by pair and stage) and of every
    ``results/{pair}/stages/{stage}/field.parquet``, keyed ``pair/stage``."""
    fields = {
        f"{path.parents[2].name}/{path.parent.name}": table_digests(path)
        for path in sorted(results.glob("*/stages/*/field.parquet"))
    }
    return {"summary": table_digests(results / "summary.parquet", ("pair", "stage")), "fields": fields}


def differences(got: dict, expected: dict, rtol: float = RTOL) -> list[str]:
    """Where two fingerprints disagree: ``table: column`` for each column that differs, and
    the tables that only one of them has."""
    tables = {"summary": (got["summary"], expected["summary"])}
    tables |= {key: (got["fields"].get(key), columns) for key, columns in expected["fields"].items()}
    found = [f"{key}: only in the results" for key in sorted(set(got["fields"]) - set(expected["fields"]))]
    for key, (mine, theirs) in tables.items():
        if mine is None:
            found.append(f"{key}: missing")
            continue
        for name in sorted(set(mine) | set(theirs)):
            a, b = mine.get(name), theirs.get(name)
            same = a == b
            if isinstance(a, list) and isinstance(b, list):
                scale = rtol * max(a[3], b[3])
                same = a[:2] == b[:2] and all(abs(x - y) <= scale for x, y in zip(a[2:], b[2:], strict=True))
            if not same:
                found.append(f"{key}: {name} {a} != {b}")
    return found


if __name__ == "__main__":
    results, out = map(Path, sys.argv[1:3])
    out.write_text(json.dumps(fingerprint(results), indent=1, sort_keys=True) + "\n")
