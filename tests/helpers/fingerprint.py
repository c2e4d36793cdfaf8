"""A study's results as digests: every column of its summary and of each stage's field.

Two runs of the same study give the same fingerprint only if every value of the summary and
every value of every field is the same, bit for bit. ``tests/data/default_study.json`` is the
default study's, written by the code before stages were stored as their changes (main at
e16a60a, the survivor copies, with the day's other work merged) with

    snakemake --cores 2 results/summary.parquet   # in a checkout of that commit
    python tests/helpers/fingerprint.py results tests/data/default_study.json

and tests/workflow/test_stage_changes.py checks the code of today against it. Regenerated on
branch covis (2026-11-25) the same way, when the vectors' covariance gained the change of
viewpoint on what both sensors saw: every field's se, z, wu, wv and ww changed, and the
summary's voxels_significant, share_significant, p_direction, p_coherence and verdict (the
paper-sim pair's stages 1 and 2 went from patterned to random); nothing else did.
Regenerated on branch binning (2026-11-27) the same way (in a copy of the workdir, with
``--snakefile`` of the branch), for channel-aware binning (lidarfield.field.channels): the
field's band edges moved between paper-sim-80's channels (-7.5 -> -7.4, 0 -> -0.2, 7.5 ->
7.4 deg; 0 deg is a channel) and its azimuth columns between firings (offset 0 -> 0.1 deg).
Every field column changed (bins, counts, means, vectors and what follows from them); in the
summary the field's statistics (magnitudes, energy shares, rigid part, p_direction,
p_coherence, share_significant, voxels, voxels_valid) and four new columns
(elevation_edges_deg, azimuth_edges_deg, binning, binning_warning). Unchanged: n1, n2,
removed1, removed2 (and every removed.parquet, compared file by file), the verdicts and
voxels_significant. The code before the change, run here, also differed from the stored
digests in nx, ny, nz, planarity, se, z, wu, wv, ww and four summary statistics (last-digit
differences of this machine's linear algebra), so those are not all this change's.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq


def column_digest(values: np.ndarray) -> str:
    values = np.asarray(values)
    if values.dtype.kind in "biuf":
        return hashlib.sha256(np.ascontiguousarray(values).tobytes()).hexdigest()[:16]
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


if __name__ == "__main__":
    results, out = map(Path, sys.argv[1:3])
    out.write_text(json.dumps(fingerprint(results), indent=1, sort_keys=True) + "\n")
