"""Applying a hypothesis stack: stage k applies entry k to the survivors of stage k-1.

Every stage keeps its survivors and the points it removed (with their attributes), so that a
figure can draw the removed points of a stage over the kept ones, and the field of every stage
can be compared with the one before.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..hypotheses import apply_step, validate_stack, validate_step
from ..hypotheses.outliers import carry_neighbours
from ..hypotheses.steps import step_name
from ..pair import RegisteredPair

NO_MITIGATION = "none"  # the hypothesis name of stage 0


@dataclass
class Stage:
    level: int  # 0 = no mitigation; k = after entry k of the stack
    name: str  # hypothesis name ('none' for stage 0)
    spec: dict | None  # the normalised stack entry {name: params}; None for stage 0
    pair: RegisteredPair  # the survivors
    removed: RegisteredPair  # the points this stage removed: xyz1 of cloud 1, xyz2 of cloud 2
    keep1: np.ndarray  # over the previous stage's cloud 1 (stage 0: the registered pair's)
    keep2: np.ndarray

    @property
    def removed1(self) -> int:
        return len(self.removed.xyz1)

    @property
    def removed2(self) -> int:
        return len(self.removed.xyz2)

    def removed_columns(self) -> dict[str, np.ndarray]:
        """The removed-points table: points-table columns plus ``hypothesis`` and ``row`` (the
        point's row among its cloud's points in the previous stage)."""
        columns = self.removed.to_columns()
        columns["hypothesis"] = np.full(len(columns["cloud"]), self.name, dtype=object).astype(str)
        columns["row"] = np.concatenate([np.flatnonzero(~self.keep1), np.flatnonzero(~self.keep2)]).astype(np.int64)
        return columns

    def metadata(self, stage_id: str) -> dict:
        """The stage's keys in its points and removed files' metadata."""
        return {"stage": stage_id, "level": self.level, "hypothesis": self.name, "spec": self.spec}


def initial_stage(pair: RegisteredPair) -> Stage:
    """Stage 0: the registered pair itself, nothing removed."""
    keep1, keep2 = np.ones(len(pair.xyz1), dtype=bool), np.ones(len(pair.xyz2), dtype=bool)
    return Stage(0, NO_MITIGATION, None, pair, pair.subset(~keep1, ~keep2), keep1, keep2)


def next_stage(
    pair: RegisteredPair, step: dict, level: int, base_dir: str | Path = ".", study_grid: dict | None = None
) -> Stage:
    """Stage ``level``: hypothesis ``step`` applied to ``pair`` (the previous stage's survivors)."""
    spec = validate_step(step, base_dir, study_grid, level)
    keep1, keep2 = apply_step(pair, spec, base_dir, study_grid, level)
    return Stage(level, step_name(spec), spec, pair.subset(keep1, keep2), pair.subset(~keep1, ~keep2), keep1, keep2)


def apply_stack(
    pair: RegisteredPair, stack: list[dict], base_dir: str | Path = ".", study_grid: dict | None = None
) -> Iterator[Stage]:
    """Stage 0 (no mitigation), then one stage per entry of ``stack``, lazily.

    The whole stack is validated first (a HypothesisError before any stage is produced).
    ``base_dir`` is where plugin files are found; ``study_grid`` is the study's ``grid``
    section (``shadow``'s default grid).
    """
    steps = validate_stack(stack, base_dir, study_grid)
    return _stages(pair, steps, base_dir, study_grid)


def _stages(pair: RegisteredPair, steps: list[dict], base_dir, study_grid) -> Iterator[Stage]:
    stage = initial_stage(pair)
    yield stage
    for level, step in enumerate(steps, start=1):
        previous, stage = stage, next_stage(stage.pair, step, level, base_dir, study_grid)
        # what the caller derived from the previous stage's points (its suggestions' outlier
        # scores), carried over exactly for less than a new search costs
        carry_neighbours(previous.pair, stage.keep1, stage.keep2, stage.pair)
        yield stage
