"""What to try next: every candidate hypothesis applied on its own to a stage's survivors.

For each candidate the field it would leave is computed from the same voxel ids (the pair is
binned once) and compared with the stage's field:

- ``energy_reduction``: 1 - energy after / energy before, both summed over the voxels valid
  before *and* after (energy = min(n1, n2) |v|^2, as in ``tags``). A rule that only empties
  voxels below ``min_points`` makes their vectors vanish without explaining them: those voxels
  are counted in ``voxels_invalidated`` (and their share of the energy before in
  ``energy_invalidated``), not in the reduction.
- ``removed1``, ``removed2`` and ``removed_share`` (of both clouds' points): what it costs. A
  rule that removes half the scan to shrink the field is not an explanation.
- ``corrects``: whether the candidate moved points (a *correcting* hypothesis such as
  ``realign``: it removes nothing, its reduction is over the moved points' field), with
  ``displacement_median_m`` and ``displacement_max_m`` (how far the moved cloud's points moved;
  the larger over both clouds; 0 for a removal) and ``fitted`` (canonical JSON of what it
  fitted, e.g. realign's ``translation_m`` and ``rotation_deg``; ``{}`` for a removal).
- ``suggested_by`` and ``tag_share``: the tag that points to the candidate (``TAG_CORRECTIONS``:
  ``rigid`` -> ``realign``, ``radial`` -> ``range_calibration``) and that tag's share of the
  stage's field energy (``tags``); ``""`` and NaN for a candidate no tag points to.
- ``whitened_reduction``: the same over the field in units of its noise: 1 - whitened energy
  after / before (``tags.whitened_energy``: |C^-1/2 d|^2 per voxel, C each vector's sampling
  covariance with the scan patterns, as the verdict reads it), over the same voxels. Raw energy
  is dominated by the few voxels of edges and clutter, where a point more or less moves a mean
  by decimetres: removing a few per cent of the points there (``outliers``) lowers it more than
  the right correction, which moves every voxel's vector by millimetres to centimetres. In
  units of its noise every voxel counts by how far its vector is from what sampling explains,
  so a correction that explains a pattern across the field lowers the whitened energy most,
  and a removal lowers it only where what it removes was the pattern. Removing a share s of
  the points at random lowers it by about s (each voxel's whitened energy beyond noise grows
  with its count).
- ``removal_null``: the whitened reduction a removal of as many points at random would give,
  voxel by voxel: sum of s E / sum of E over those voxels, E a voxel's whitened energy before
  and s the share of its points the candidate removed (0 for a correction that removes
  nothing; a voxel's energy beyond its noise grows with its count, so a random share s of its
  points takes about s of it). ``stopping_rule`` asks a removal to explain more than that:
  a removal concentrated where the pattern is (a moving object, the own body) beats it, one
  that thins the whole field (statistical outliers of every surface's edges) does not.
- ``fitted_null``: the whitened reduction fitting the correction's free parameters to noise
  alone would give: its ``parameters`` (``fitted``: realign's rigid motion 6, a range
  calibration 2, or 1 + one offset per ring with ``per_ring``, an elevation calibration one
  per laser it found off; 0 for what fits nothing, as ``deskew`` with the scan's recorded
  motion or an elevation calibration that found no laser off, and for a removal) over the whitened energy
  before. A least-squares fit of p parameters takes about p from a chi^2 of noise, so a
  correction with more parameters always explains more of a field; ranked and stopped on its
  reduction beyond this, a per-laser calibration (33 parameters on an HDL-32E, 129 on an
  OS1-128) competes with a rigid motion fairly. (Measured 2026-11-27 on the real OS1-128 frames,
  20,000 points: the per-ring fit took 9.8% of the whitened energy, its 129 parameters' null
  5.4%; realign 75%, its null 0.3%.)
- ``max_after``, ``p95_after`` (m) and ``energy_after``: the field it leaves, all valid voxels.
- ``seen_through_removed`` and ``seen_through_null``: what a removal explains of the points
  the field cannot show, those of one cloud that lie where the other scan's rays passed through
  (``moving_objects.seen_through``, with its defaults): the share of them it removes, and the
  share removing as many points of each voxel at random would (sum of s c over sum of c, c a
  voxel's points seen through). A static scene gives none, so they are the evidence of an
  object that moved; removing a moved object removes them all, where its vectors are small in
  units of their noise (its voxels hold its own spread) and the voxels it empties are no
  longer in the reduction. NaN for a correction (it moves points: what they are then is not
  measured) and where they cannot be told (no sensor model, no origin of sensor 2, or none seen
  through); 0 for a candidate that removes nothing. ``stopping_rule.explains_seen_through``
  reads them.
- ``calibration_seen``: False for a range calibration fitted with the pose whose scale and
  offset are both within ``range_calibration.MIN_CALIBRATION_SIGNIFICANCE`` standard errors of
  none (its record's ``calibration_seen``: that fit is the pose alone); True for every other
  candidate.

``rank`` 1 is the largest whitened reduction beyond ``fitted_null`` (ties: fewer points removed,
then the larger share of the energy in the tag that points to it; undefined reductions last,
and with them a row whose ``calibration_seen`` is False).
Candidates are the config's ``suggest`` list, or by default every built-in hypothesis the stack
has not applied up to that stage, with its defaults: the removing ones and every correcting one
(``CORRECTING``: a correction joins by being registered there). The per-laser calibration
(``range_calibration`` with ``per_ring``) is not among them: on the zoo's real pairs it named no
fault more and doubled explain's time (docs/diagnosis.md); a config's ``suggest`` can list it.
``elevation_calibration`` is: it fits only the lasers its screen finds off, so it costs one
pairing where none is, and its null counts the lasers it fitted. A
default candidate that cannot apply to the pair (``NotApplicableError``:
``field_of_view`` without sensor models; for a correcting one any ``HypothesisError``, e.g.
``realign`` with too few points) is skipped with a logged line; a configured one is an error
naming it.

A candidate's row depends only on its parameters, the stage's points (with their attributes and
the pair's metadata), the grid and the code that computes it: ``points_digest`` digests the last
three (the code as ``code_digest``: the package version and the source of every module of the
package), and a row computed for the same digest (another stage of the pair whose points its
hypothesis left unchanged, as a no-op ``crop`` appended to a stack does) is reused as it is
(``known``) instead of running the candidate again; after an edit of the code no row written
before it is reused. Plugin candidates are always run: their source can change under the same
parameters.

The candidates a stage runs are independent: they are evaluated by a pool of threads
(``threads.usable_threads``: the usable cores, one in a workflow job), each row then completed and
ranked in the candidates' order, so the table is the serial one bit for bit. The pool starts
the correcting candidates first (they fit: the costliest), so that a stage does not wait at its
end for one long fit started last.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import logging
import math
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import __version__
from ..errors import HypothesisError, InputError, NotApplicableError
from ..field.channels import pair_binning
from ..field.grid import FieldSettings
from ..field.kernel import field_from_voxel_ids
from ..field.pair_field import scan_patterns
from ..hypotheses import BUILTINS, CORRECTING, apply_step, validate_step
from ..hypotheses.outcome import Outcome, displacement
from ..hypotheses.steps import step_name
from ..io.parquet_table import read_metadata, read_table, write_table
from ..pair import RegisteredPair
from ..storage.stage_ids import canonical_json
from ..threads import usable_threads
from .tags import vector_tags, voxel_energy, whitened_energy

log = logging.getLogger(__name__)

SUGGESTION_COLUMNS = (
    "rank",
    "hypothesis",
    "params",
    "removed1",
    "removed2",
    "removed_share",
    "corrects",
    "displacement_median_m",
    "displacement_max_m",
    "fitted",
    "suggested_by",
    "tag_share",
    "voxels_invalidated",
    "energy_invalidated",
    "max_after",
    "p95_after",
    "energy_after",
    "energy_reduction",
    "whitened_reduction",
    "removal_null",
    "seen_through_removed",
    "seen_through_null",
    "fitted_null",
    "calibration_seen",
)

# The tag whose voxels each correcting built-in would explain: a field whose energy sits in
# ``rigid`` voxels is a registration offset (``realign``), in ``radial`` ones a range error
# (``range_calibration``). Used to break ties and to annotate the tables.
TAG_CORRECTIONS = {"rigid": "realign", "radial": "range_calibration"}


# The parameters of a default candidate where they are not its hypothesis' defaults. ``shadow``
# by occlusion: the question a candidate asks is whether the field's pattern is content one
# sensor could not see from its place, and the z-buffer test answers it point by point, where
# the first radial cluster keeps what lies behind a corner continuous in range with the facade
# (the street canyon's gaps between buildings, docs/diagnosis.md); a stack keeps the DESIGN's rule.
# (``auto``: the first radial cluster where a scan has no sensor model to test occlusion with.)
# ``range_calibration`` and ``deskew`` each both alone and with sensor 2's pose fitted with it:
# a range error is partly a pose error on real scenes (a scale moves the ground as a vertical
# shift), and a skew's mean over the sweep is a shift, so where the pose was fitted on the
# faulty scan (scan matching), or by a ``realign`` before, it took that part and the correction
# alone fits the wrong thing (docs/diagnosis.md); where it was measured apart from the scan (the
# truth, odometry, GNSS) it did not, and the pose's 6 parameters only fit noise. The pair cannot
# say which: both are candidates, ranked beyond their parameters (``fitted_null``); except where
# the pose is the simulation's truth (``RegisteredPair.pose_exact``), exact: there the pose's part
# of a joint fit is noise alone, and only the correction alone is tried (``exact_pose_candidates``).
DEFAULT_CANDIDATE_PARAMS = {
    "shadow": [{"rule": "auto"}],
    "range_calibration": [{}, {"with_pose": True}],
    "deskew": [{}, {"with_pose": True}],
}


def candidate_steps(
    suggest: list[dict] | None, applied: list[dict], base_dir: str | Path = ".", study_grid: dict | None = None
) -> list[dict]:
    """The normalised candidates of a stage whose stack so far is ``applied``: ``suggest``
    validated, or every built-in not in ``applied`` with its defaults (each entry of
    ``DEFAULT_CANDIDATE_PARAMS`` where given): the removing ones, then
    the correcting ones (``CORRECTING``, in ``BUILTINS`` order)."""
    if suggest is None:
        done = {step_name(step) for step in applied}
        fresh = [name for name in BUILTINS if name not in done]
        ordered = [name for name in fresh if name not in CORRECTING] + [name for name in fresh if name in CORRECTING]
        suggest = [{name: params} for name in ordered for params in DEFAULT_CANDIDATE_PARAMS.get(name, [{}])]
    if not isinstance(suggest, list):
        raise HypothesisError(f"suggest: a list of {{name: {{parameters}}}} entries, got {suggest!r}")
    candidates = []
    for k, step in enumerate(suggest, start=1):
        try:
            candidates.append(validate_step(step, base_dir, study_grid))
        except HypothesisError as e:
            raise HypothesisError(f"suggest entry {k}: {e}") from None
    return candidates


def suggestions(
    pair: RegisteredPair,
    settings: FieldSettings,
    candidates: list[dict],
    base_dir: str | Path = ".",
    study_grid: dict | None = None,
    defaults: bool = False,
    known: dict[tuple[str, str], dict] | None = None,
    outcomes: dict[tuple[str, str], Outcome] | None = None,
    workers: int | None = None,
) -> dict[str, np.ndarray]:
    """The suggestion table (``SUGGESTION_COLUMNS``, one row per candidate, sorted by rank).

    ``defaults``: the candidates are the default ones, so one that cannot apply to this pair is
    skipped (and logged) rather than an error. ``known``: rows already computed for the same
    ``points_digest`` (``rows_by_candidate``), reused for the built-in candidates they hold.
    ``outcomes``: filled with each built-in candidate's outcome run here, by ``candidate_key``
    (``explain`` applies the chosen one's as it is instead of running it again).
    """
    known = known or {}
    if defaults:
        candidates = exact_pose_candidates(pair, candidates)
    reused = [known.get(candidate_key(spec)) for spec in candidates]
    if all(row is not None for row in reused):  # nothing to run: not even the field before
        log.info("all %d candidates reused: the same points and grid as a stage already suggested for", len(reused))
        return rank_table(reused)
    settings = pair_binning(settings, pair).settings  # the grid of the stage's own field
    ids1, ids2 = settings.grid.assign(pair.xyz1), settings.grid.assign(pair.xyz2)
    patterns = scan_patterns(pair)
    before = field_from_voxel_ids(ids1, pair.xyz1, ids2, pair.xyz2, settings, patterns=patterns)
    shares = tag_energy_shares(before)
    todo = [(k, spec) for k, (spec, row) in enumerate(zip(candidates, reused), start=1) if row is None]
    stage = StagePoints(pair, settings, ids1, ids2, patterns, before, shares)

    def evaluate(task: tuple[int, dict]) -> tuple[dict | None, Outcome | None]:
        return candidate_row(stage, *task, base_dir, study_grid, defaults)

    threads = min(len(todo), usable_threads() if workers is None else workers)
    if threads > 1:  # the candidates are independent; numpy, scipy and Open3D release the GIL
        # the fits first (the costliest: ICP, the calibrations' iterations), so that no thread
        # is left with one at the end while the others wait; the rows are kept by their k
        started = sorted(todo, key=lambda task: step_name(task[1]) not in CORRECTING)
        with ThreadPoolExecutor(threads) as pool:
            running = {task[0]: pool.submit(evaluate, task) for task in started}
            evaluated = {k: running[k].result() for k, _ in todo}  # an error: the first in the serial order
    else:
        evaluated = {k: evaluate((k, spec)) for k, spec in todo}
    seen = None  # the points seen through, found once, for the first candidate that removes any
    rows = []
    for k, (spec, row) in enumerate(zip(candidates, reused), start=1):
        if row is not None:
            log.info("candidate %s %s reused: the same points and grid", row["hypothesis"], row["params"])
            rows.append(row)
            continue
        row, outcome = evaluated[k]
        if row is None:
            continue
        if outcomes is not None and candidate_key(spec)[0]:
            outcomes[candidate_key(spec)] = outcome
        if row["seen_through_removed"] is None:  # a removal of some points
            seen = seen_through_points(pair, ids1, ids2) if seen is None else seen
            row |= seen.columns(*outcome)
        rows.append(row)
    return rank_table(rows)


def exact_pose_candidates(pair: RegisteredPair, candidates: list[dict]) -> list[dict]:
    """``candidates`` without those fitted with sensor 2's pose (``with_pose``) where that pose
    is exact (``pair.pose_exact``): the simulation's truth, not fitted on the scans."""
    if not pair.pose_exact:
        return candidates
    kept = [spec for spec in candidates if not spec[step_name(spec)].get("with_pose")]
    if len(kept) < len(candidates):
        log.info(
            "%d candidates fitted with the pose not run: the pose is the simulation's truth",
            len(candidates) - len(kept),
        )
    return kept


@dataclass(frozen=True)
class StagePoints:
    """What every candidate of a stage is compared with: the pair binned once (voxel ids of
    each cloud on the stage's own grid), its scan patterns, its field and the tags' shares."""

    pair: RegisteredPair
    settings: FieldSettings
    ids1: np.ndarray
    ids2: np.ndarray
    patterns: object
    before: dict[str, np.ndarray]
    shares: dict[str, float]


def candidate_row(
    stage: StagePoints,
    k: int,
    spec: dict,
    base_dir: str | Path,
    study_grid: dict | None,
    defaults: bool,
) -> tuple[dict | None, Outcome | None]:
    """Suggest entry ``k`` (``spec``) applied to the stage: its row (all ``SUGGESTION_COLUMNS``
    but ``rank``; ``seen_through_*`` None for a removal of some points, which needs the points
    seen through) and its outcome; (None, None) for a default candidate that cannot apply."""
    pair, settings, ids1, ids2 = stage.pair, stage.settings, stage.ids1, stage.ids2
    start = time.perf_counter()
    try:
        outcome = apply_step(pair, spec, base_dir, study_grid)
    except HypothesisError as e:
        cannot_apply = isinstance(e, NotApplicableError) or step_name(spec) in CORRECTING
        if not (defaults and cannot_apply):
            raise HypothesisError(f"suggest entry {k}: {e}") from None
        log.info("candidate %s skipped: it does not apply to this pair (%s)", step_name(spec), e)
        return None, None
    keep1, keep2 = outcome
    removed1, removed2 = int(np.count_nonzero(~keep1)), int(np.count_nonzero(~keep2))
    moved = [displacement(pair.xyz1, outcome.xyz1), displacement(pair.xyz2, outcome.xyz2)]
    tag = next((t for t, name in TAG_CORRECTIONS.items() if name == step_name(spec)), "")
    if outcome.xyz1 is not None or outcome.xyz2 is not None:  # a correction: the moved points' field
        xyz1 = pair.xyz1 if outcome.xyz1 is None else outcome.xyz1
        xyz2 = pair.xyz2 if outcome.xyz2 is None else outcome.xyz2
        xyz1, xyz2 = xyz1[keep1], xyz2[keep2]
        corrected = pair if outcome.T_1_2 is None else dataclasses.replace(pair, T_1_2=outcome.T_1_2)
        after = field_from_voxel_ids(
            settings.grid.assign(xyz1),
            xyz1,
            settings.grid.assign(xyz2),
            xyz2,
            settings,
            patterns=scan_patterns(corrected),
        )
    elif removed1 or removed2:
        after = field_from_voxel_ids(
            ids1[keep1], pair.xyz1[keep1], ids2[keep2], pair.xyz2[keep2], settings, patterns=stage.patterns
        )
    else:  # the same points: the same field (as a no-op ego_vehicle or crop often is)
        after = stage.before
    total = len(pair.xyz1) + len(pair.xyz2)
    row = {
        "hypothesis": step_name(spec),
        "params": canonical_json(spec[step_name(spec)]),
        "removed1": removed1,
        "removed2": removed2,
        "removed_share": (removed1 + removed2) / total if total else math.nan,
        "corrects": outcome.corrects,
        "displacement_median_m": max(m[0] for m in moved),
        "displacement_max_m": max(m[1] for m in moved),
        "fitted": canonical_json(outcome.fitted),
        # False only for a calibration fitted with the pose that found none (range_calibration)
        "calibration_seen": bool(outcome.fitted.get("calibration_seen", True)),
        "suggested_by": tag,
        "tag_share": stage.shares.get(tag, math.nan),
        **compare_fields(stage.before, after, fitted_parameters(outcome.fitted)),
    }
    if not (removed1 or removed2):  # a correction moves points between voxels, it removes none
        row["removal_null"] = 0.0
    if outcome.corrects:
        row |= {"seen_through_removed": math.nan, "seen_through_null": math.nan}
    elif removed1 or removed2:
        row |= {"seen_through_removed": None, "seen_through_null": None}
    else:
        row |= {"seen_through_removed": 0.0, "seen_through_null": 0.0}
    log.info(
        "candidate %s %s: energy reduction %.3f (whitened %.3f), %d + %d points removed, moved up to %.3f m (%.2f s)",
        row["hypothesis"],
        row["params"],
        row["energy_reduction"],
        row["whitened_reduction"],
        removed1,
        removed2,
        row["displacement_max_m"],
        time.perf_counter() - start,
    )
    return row, outcome


def rank_table(rows: list[dict]) -> dict[str, np.ndarray]:
    """The suggestion table of candidate ``rows`` (``SUGGESTION_COLUMNS`` but ``rank``), ranked."""
    order = sorted(range(len(rows)), key=lambda i: _rank_key(rows[i]))
    columns = {name: [] for name in SUGGESTION_COLUMNS}
    for rank, i in enumerate(order, start=1):
        columns["rank"].append(rank)
        for name in SUGGESTION_COLUMNS[1:]:
            columns[name].append(rows[i][name])
    types = {
        "rank": np.int64,
        "removed1": np.int64,
        "removed2": np.int64,
        "voxels_invalidated": np.int64,
        "corrects": bool,
        "calibration_seen": bool,
        "hypothesis": str,
        "params": str,
        "fitted": str,
        "suggested_by": str,
    }
    return {name: np.asarray(values, dtype=types.get(name, np.float64)) for name, values in columns.items()}


def compare_fields(before: dict[str, np.ndarray], after: dict[str, np.ndarray], parameters: int = 0) -> dict:
    """The field ``after`` a candidate, against ``before``. A removal's voxels are a subset of
    ``before``'s; a correction can move points into voxels that held none before: those count
    in ``energy_after`` but not in the reductions, which are over the voxels valid before and after.
    ``parameters``: how many the candidate fitted (``fitted_null``)."""
    valid_before = np.asarray(before["valid"], dtype=bool)
    rows = np.searchsorted(before["voxel"], after["voxel"])
    found = rows < len(valid_before)
    found[found] = before["voxel"][rows[found]] == after["voxel"][found]
    valid_after = np.zeros(len(valid_before), dtype=bool)
    valid_after[rows[found]] = np.asarray(after["valid"], dtype=bool)[found]
    common = valid_before & valid_after
    invalidated = valid_before & ~valid_after

    def reduction(energy) -> float:
        """1 - ``energy`` after / before over the common voxels (NaN without energy before)."""
        after_common = np.zeros(len(valid_before))
        after_common[rows[found]] = energy(after)[found]
        common_before = float(energy(before)[common].sum())
        return 1.0 - float(after_common[common].sum()) / common_before if common_before > 0 else math.nan

    counts_after = np.zeros(len(valid_before))
    counts_after[rows[found]] = (after["n1"] + after["n2"])[found]
    with np.errstate(invalid="ignore", divide="ignore"):
        removed = np.clip(1.0 - counts_after / (before["n1"] + before["n2"]), 0.0, 1.0)
    whitened_before = whitened_energy(before)[common]
    energy_before = voxel_energy(before)
    magnitude = np.asarray(after["magnitude"], dtype=np.float64)[np.asarray(after["valid"], dtype=bool)]
    total_before = float(energy_before.sum())
    return {
        "voxels_invalidated": int(np.count_nonzero(invalidated)),
        "energy_invalidated": float(energy_before[invalidated].sum()) / total_before if total_before > 0 else math.nan,
        "max_after": float(magnitude.max()) if magnitude.size else math.nan,
        "p95_after": float(np.percentile(magnitude, 95)) if magnitude.size else math.nan,
        "energy_after": float(voxel_energy(after).sum()),
        "energy_reduction": reduction(voxel_energy),
        "whitened_reduction": reduction(whitened_energy),
        "removal_null": float(removed[common] @ whitened_before) / whitened_before.sum()
        if whitened_before.sum() > 0
        else math.nan,
        "fitted_null": fitted_null(parameters, float(whitened_before.sum())),
    }


def seen_through_points(pair: RegisteredPair, ids1: np.ndarray, ids2: np.ndarray) -> SeenThrough:
    """The stage's points seen through by the other scan (``moving_objects.seen_through`` with
    its defaults), for the points of voxel ids ``ids1``, ``ids2``; none where that cannot be
    told (no sensor model, or no origin of sensor 2)."""
    from ..hypotheses.moving_objects import Params, seen_through

    try:
        seen = seen_through(pair, Params())
    except NotApplicableError:
        seen = None
    return SeenThrough(seen, ids1, ids2)


class SeenThrough:
    """A stage's points seen through (``seen``: per cloud, or None where unknown), by voxel
    (``ids1``, ``ids2``): ``columns`` of each removal, the voxels numbered once per stage."""

    def __init__(self, seen: tuple[np.ndarray, np.ndarray] | None, ids1: np.ndarray, ids2: np.ndarray):
        self.count = 0 if seen is None else int(np.count_nonzero(seen[0]) + np.count_nonzero(seen[1]))
        if self.count:
            self.seen = np.concatenate(seen)
            _, self.voxel = np.unique(np.concatenate([ids1, ids2]), return_inverse=True)
            self.in_voxel = np.bincount(self.voxel, weights=self.seen)
            self.points = np.bincount(self.voxel)

    def columns(self, keep1: np.ndarray, keep2: np.ndarray) -> dict[str, float]:
        """``seen_through_removed`` and ``seen_through_null`` of a removal (keep-masks; NaN
        without any point seen through)."""
        if not self.count:
            return {"seen_through_removed": math.nan, "seen_through_null": math.nan}
        kept = np.concatenate([keep1, keep2])
        removed_share = np.bincount(self.voxel, weights=~kept, minlength=len(self.points)) / self.points
        return {
            "seen_through_removed": np.count_nonzero(self.seen & ~kept) / self.count,
            "seen_through_null": float(removed_share @ self.in_voxel) / self.count,
        }


def fitted_parameters(fitted: dict) -> int:
    """How many free parameters a correction fitted (its record's ``parameters``; 0 without)."""
    return int(fitted.get("parameters", 0)) if isinstance(fitted, dict) else 0


def fitted_null(parameters: int, whitened_before: float) -> float:
    """The share of a whitened energy ``whitened_before`` that fitting ``parameters`` free
    parameters to noise alone would explain: about one unit of chi^2 each."""
    if parameters <= 0:
        return 0.0
    return parameters / whitened_before if whitened_before > 0 else math.inf


def tag_energy_shares(columns: dict[str, np.ndarray]) -> dict[str, float]:
    """The share of the field's energy in the voxels of each tag of ``TAG_CORRECTIONS`` (NaN
    for a field without energy)."""
    energy = voxel_energy(columns)
    total = float(energy.sum())
    return {
        tag: float(energy[flags].sum()) / total if total > 0 else math.nan
        for tag, flags in vector_tags(columns).items()
        if tag in TAG_CORRECTIONS
    }


def _rank_key(row: dict) -> tuple:
    reduction = row["whitened_reduction"] - row["fitted_null"]
    # a calibration fitted with the pose that found none is the pose alone: last, as undefined
    defined = math.isfinite(reduction) and row["calibration_seen"]
    share = row["tag_share"] if math.isfinite(row["tag_share"]) else 0.0
    return (not defined, -reduction if defined else 0.0, row["removed1"] + row["removed2"], -share)


def candidate_key(spec: dict) -> tuple[str, str]:
    """What names a candidate's row among the rows of one ``points_digest``: its hypothesis and
    parameters (canonical JSON); a plugin's never matches (its source is not in it)."""
    name = step_name(spec)
    return (name, canonical_json(spec[name])) if name in BUILTINS else ("", "")


# The package's own source: what computes a suggestion row (the candidates, the field, the tags).
PACKAGE = Path(__file__).resolve().parents[1]


def source_digest(root: Path, version: str) -> str:
    """A digest of ``version`` and every module (``*.py``, by its path) under ``root``."""
    digest = hashlib.blake2b(version.encode(), digest_size=16)
    for path in sorted(root.rglob("*.py")):
        digest.update(f"{path.relative_to(root).as_posix()}:{path.stat().st_size}:".encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


@functools.cache
def code_digest() -> str:
    """``source_digest`` of this package: Snakemake reruns a rule when its own code changes, not
    when the package's does, and the version alone does not change with every edit. The whole
    package rather than the modules a row uses: an edit anywhere costs one rerun of the
    candidates, a missed module would reuse stale rows."""
    return source_digest(PACKAGE, __version__)


def points_digest(pair: RegisteredPair, grid_section: dict, code: str | None = None) -> str:
    """A digest of all a candidate's row depends on but its parameters: both clouds' points with
    their attributes, the pair's metadata (pose, sensors, sweeps, rigs), the grid and the code
    (``code``, default ``code_digest()``)."""
    digest = hashlib.blake2b((code or code_digest()).encode(), digest_size=16)
    for xyz, attributes in ((pair.xyz1, pair.attributes1), (pair.xyz2, pair.attributes2)):
        digest.update(np.ascontiguousarray(xyz).data)
        for name in sorted(attributes):
            values = np.ascontiguousarray(attributes[name])
            digest.update(f"{name}:{values.dtype.str}:".encode())
            digest.update(values.data)
    digest.update(json.dumps([pair.metadata(), grid_section], sort_keys=True, default=repr).encode())
    return digest.hexdigest()


def rows_by_candidate(table: dict[str, np.ndarray]) -> dict[tuple[str, str], dict]:
    """A suggestion table's rows (without ``rank``) by ``candidate_key``, to reuse them."""
    names = SUGGESTION_COLUMNS[1:]
    return {
        (str(table["hypothesis"][i]), str(table["params"][i])): {name: _scalar(table[name][i]) for name in names}
        for i in range(len(table["rank"]))
    }


def _scalar(value):
    """A table cell as the Python value a computed row holds (strings are read as objects)."""
    return value.item() if isinstance(value, np.generic) else value


def stored_rows(paths: list[Path], digest: str) -> dict[tuple[str, str], dict]:
    """The rows of the first of the ``suggestions.parquet`` files ``paths`` computed for the same
    ``points_digest`` (a stage of the pair with the same points, by the same code); {} when none was."""
    for path in paths:
        try:
            if read_metadata(path).get("points") != digest:
                continue
            table, _ = read_table(path, required=SUGGESTION_COLUMNS)
        except (InputError, OSError):  # one being replaced, or of another version: not reused
            continue
        log.info("reusing the rows of %s: the same points, grid and code", path)
        return rows_by_candidate(table)
    return {}


def write_suggestions(
    out: str | Path,
    table: dict[str, np.ndarray],
    stage_id: str | None,
    candidates: list[dict],
    grid_section: dict,
    points: str | None = None,
) -> None:
    """Write a suggestion table (atomically) with the stage, candidates, grid and ``points``
    (its ``points_digest``, by which a stage with the same points reuses its rows) as metadata."""
    write_table(out, table, {"stage": stage_id, "candidates": candidates, "grid": grid_section, "points": points})
