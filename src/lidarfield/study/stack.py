"""Applying a hypothesis stack: stage k applies entry k to the survivors of stage k-1.

Every stage keeps its survivors and the points it removed (with their attributes), so that a
figure can draw the removed points of a stage over the kept ones, and the field of every stage
can be compared with the one before.

A correcting stage (a hypothesis returning corrected coordinates, see
:mod:`lidarfield.hypotheses.outcome`) keeps its survivors *as corrected*, and sensor 2's
corrected pose; its removed points are as they were. Every stage's survivors carry ``row``
(an attribute of both clouds): the point's row among its cloud's points in the registered
pair. Stage 0 numbers them 0..N-1; every later stage keeps the rows of its survivors, whatever
it moved. A stage is stored as what it changed (its ``changes``, by these rows): see
:mod:`lidarfield.storage.stage_points`.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..hypotheses import parse_stack, parse_step, run_step, step_spec
from ..hypotheses.outcome import Outcome, displacement, reasons_of_removed
from ..hypotheses.outliers import carry_neighbours
from ..hypotheses.range_calibration import carry_planes
from ..hypotheses.steps import step_name
from ..pair import RegisteredPair
from ..storage.stage_ids import canonical_json
from ..storage.stage_points import NO_MITIGATION, ROW, change_columns, with_rows


@dataclass
class Stage:
    level: int  # 0 = no mitigation; k = after entry k of the stack
    name: str  # hypothesis name ('none' for stage 0)
    spec: dict | None  # the normalised stack entry {name: params}; None for stage 0
    pair: RegisteredPair  # the survivors
    removed: RegisteredPair  # the points this stage removed: xyz1 of cloud 1, xyz2 of cloud 2
    keep1: np.ndarray  # over the previous stage's cloud 1 (stage 0: the registered pair's)
    keep2: np.ndarray
    correction: dict | None = None  # what a correcting stage fitted and applied; None: it only removed
    moved1: bool = False  # whether the stage moved cloud 1's survivors
    moved2: bool = False
    # (median, max) distance the survivors of each cloud moved, metres
    displacement1: tuple[float, float] = (0.0, 0.0)
    displacement2: tuple[float, float] = (0.0, 0.0)
    reasons: np.ndarray | None = None  # why each removed point went (cloud 1's, then 2's); None: not said
    # the stage's changes.parquet rows: what it removed and moved (see lidarfield.storage.stage_points)
    changes: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def removed1(self) -> int:
        return len(self.removed.xyz1)

    @property
    def removed2(self) -> int:
        return len(self.removed.xyz2)

    def removed_columns(self) -> dict[str, np.ndarray]:
        """The removed-points table: points-table columns plus ``hypothesis``, ``row`` (the
        point's row among its cloud's points in the previous stage) and, when the hypothesis
        says why it removed each point, ``reason``."""
        columns = self.removed.to_columns()
        columns.pop(ROW, None)  # here: the row in the previous stage, below
        columns["hypothesis"] = np.full(len(columns["cloud"]), self.name, dtype=object).astype(str)
        columns["row"] = np.concatenate([np.flatnonzero(~self.keep1), np.flatnonzero(~self.keep2)]).astype(np.int64)
        if self.reasons is not None:
            columns["reason"] = self.reasons
        return columns

    def metadata(self, stage_id: str) -> dict:
        """The stage's keys in its points and removed files' metadata (a correcting stage's also
        ``correction``, ``moved`` and ``displacement``)."""
        meta = {"stage": stage_id, "level": self.level, "hypothesis": self.name, "spec": self.spec}
        if self.correction is None:  # a removing stage: its files as before corrections existed
            return meta
        return {
            **meta,
            "correction": self.correction,
            "moved": [cloud for cloud, moved in ((1, self.moved1), (2, self.moved2)) if moved],
            "displacement": {
                "1": dict(zip(("median_m", "max_m"), self.displacement1)),
                "2": dict(zip(("median_m", "max_m"), self.displacement2)),
            },
        }

    def correction_json(self) -> str:
        """The canonical JSON of what the stage fitted and applied; '' for a removing stage."""
        return "" if self.correction is None else canonical_json(self.correction)


def initial_stage(pair: RegisteredPair) -> Stage:
    """Stage 0: the registered pair itself (numbered by ``row``), nothing removed."""
    pair = with_rows(pair)
    keep1, keep2 = np.ones(len(pair.xyz1), dtype=bool), np.ones(len(pair.xyz2), dtype=bool)
    stage = Stage(0, NO_MITIGATION, None, pair, pair.subset(~keep1, ~keep2), keep1, keep2)
    stage.changes = change_columns(pair, keep1, keep2, pair)
    return stage


def next_stage(
    pair: RegisteredPair, step: dict, level: int, base_dir: str | Path = ".", study_grid: dict | None = None
) -> Stage:
    """Stage ``level``: hypothesis ``step`` applied to ``pair`` (the previous stage's survivors).
    The entry is parsed here, once: planning validated it already."""
    return parsed_stage(pair, *parse_step(step, base_dir, study_grid, level), level, base_dir)


def parsed_stage(
    pair: RegisteredPair, name: str, params, level: int, base_dir: str | Path = ".", outcome: Outcome | None = None
) -> Stage:
    """Stage ``level``: the parsed entry (``parse_step``'s name and parameters) applied to
    ``pair``; ``outcome``: the entry's outcome on ``pair`` when it is known already (a
    suggestion's), not run again."""
    spec = step_spec(name, params)
    if outcome is None:
        outcome = run_step(pair, name, params, base_dir, level)
    keep1, keep2 = outcome
    survivors = pair.subset(keep1, keep2)
    stage = Stage(level, step_name(spec), spec, survivors, pair.subset(~keep1, ~keep2), keep1, keep2)
    stage.reasons = reasons_of_removed(outcome)
    if outcome.corrects:
        correct(stage, pair, outcome)
    stage.changes = change_columns(pair, keep1, keep2, stage.pair)
    return stage


def correct(stage: Stage, pair: RegisteredPair, outcome) -> None:
    """Move ``stage``'s survivors (of ``pair``) and sensor 2 as ``outcome`` corrected them."""
    keep1, keep2, survivors = stage.keep1, stage.keep2, stage.pair
    stage.correction = outcome.fitted
    if outcome.xyz1 is not None:
        survivors.xyz1 = np.ascontiguousarray(outcome.xyz1[keep1])
        stage.moved1, stage.displacement1 = True, displacement(pair.xyz1[keep1], survivors.xyz1)
    if outcome.xyz2 is not None:
        survivors.xyz2 = np.ascontiguousarray(outcome.xyz2[keep2])
        stage.moved2, stage.displacement2 = True, displacement(pair.xyz2[keep2], survivors.xyz2)
    if outcome.T_1_2 is not None:
        survivors.T_1_2 = outcome.T_1_2


def apply_stack(
    pair: RegisteredPair, stack: list[dict], base_dir: str | Path = ".", study_grid: dict | None = None
) -> Iterator[Stage]:
    """Stage 0 (no mitigation), then one stage per entry of ``stack``, lazily.

    The whole stack is parsed first, once (a HypothesisError before any stage is produced).
    ``base_dir`` is where plugin files are found; ``study_grid`` is the study's ``grid``
    section (``shadow``'s default grid).
    """
    return _stages(pair, parse_stack(stack, base_dir, study_grid), base_dir)


def _stages(pair: RegisteredPair, parsed: list[tuple], base_dir) -> Iterator[Stage]:
    stage = initial_stage(pair)
    yield stage
    for level, (name, params) in enumerate(parsed, start=1):
        stage = following_stage(stage, name, params, level, base_dir)
        yield stage


def following_stage(
    previous: Stage, name: str, params, level: int, base_dir: str | Path = ".", outcome: Outcome | None = None
) -> Stage:
    """Stage ``level`` after ``previous`` (``parsed_stage`` on its survivors), with what was
    derived from ``previous``'s points carried over."""
    stage = parsed_stage(previous.pair, name, params, level, base_dir, outcome)
    # what the caller derived from the previous stage's points (its suggestions' outlier
    # scores and the calibrations' normals), carried over exactly for less than a new search
    # costs; outlier scores of a cloud the stage moved as a whole too, others are searched anew
    # when needed
    carry_neighbours(previous.pair, stage.keep1, stage.keep2, stage.pair, moved=moved_clouds(stage))
    carry_planes(previous.pair, stage.keep1, stage.keep2, stage.pair)
    return stage


def moved_clouds(stage: Stage) -> tuple[int, ...]:
    """The clouds (1, 2) whose survivors the stage moved."""
    return tuple(cloud for cloud, moved in ((1, stage.moved1), (2, stage.moved2)) if moved)
