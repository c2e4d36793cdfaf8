"""The loop closed (``lidarfield explain``): from a registered pair, apply the best suggestion
worth it, recompute the field, and repeat until the verdict is not ``patterned`` or nothing helps.

Everything stays in memory: each step is a :class:`~.stack.Stage` (the same ``parsed_stage`` as a
study's mitigate job) with its field and statistics (``analyse_field``, as the field job), and
the candidates of each step are the suggestions of that stage (``analysis.suggest``: the
config's ``suggest`` list, or every built-in the stack has not applied); the chosen one's
outcome, computed for its suggestion, makes the next stage as it is (not run again), and what
the stage did not change of the points' neighbour distances is carried to it
(``stack.following_stage``). The stopping rule is
:mod:`lidarfield.analysis.stopping_rule`. Before it stops, it looks at what the field cannot
show: a scan that returned nothing in a sector the other fills (``analysis.coverage``) is a
finding, and a step of ``field_of_view`` when that removes the sector's points (whatever the
verdict: the cut sector has no vector); then objects that moved (points of one cloud where
the other scan's rays passed through) are a finding, and a step of ``moving_objects`` when it
removes them (``stopping_rule.explains_seen_through``, whatever the verdict: the free space is
not in the field); then the vehicle's own body (most of what ``ego_vehicle`` removes stays put
in both sensors' frames while they moved: ``analysis.carried``) is a finding and a step of
``ego_vehicle``, also in place of a correction the ranking chose (a correction would fit the
carried body, not the pose). What it found is a stack (normalised entries, as a config's
``hypotheses:``), one row per step with the numbers behind the choice, and every stage's field.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from ..analysis.carried import carried_body
from ..analysis.coverage import blind_sectors
from ..analysis.field_stats import analyse_field
from ..analysis.stopping_rule import (
    STOP_MAX_STEPS,
    STOP_NO_CANDIDATES,
    STOP_NOTHING_HELPS,
    STOP_VERDICT,
    ExplainSettings,
    best_worth_it,
    explains_seen_through,
    repeats,
    worth_it,
)
from ..analysis.suggest import candidate_key, candidate_steps, suggestions
from ..field.grid import FieldSettings
from ..hypotheses import apply_step, parse_step
from ..hypotheses.steps import step_name
from ..pair import RegisteredPair
from ..storage.stage_ids import canonical_json
from .stack import Stage, following_stage, initial_stage
from .summary import summary_row

log = logging.getLogger(__name__)

# One row per step: the choice and what it did to the field. The first ``PRINTED`` columns are
# what ``lidarfield explain`` prints; the page shows all but the last two (the JSON ones).
STEP_COLUMNS = (
    "step",
    "hypothesis",
    "whitened_reduction",
    "energy_reduction",
    "removed1",
    "removed2",
    "removed_share",
    "displacement_max_m",
    "verdict_before",
    "verdict_after",
    "field_energy_before",
    "field_energy_after",
    "runner_up",
    "max_magnitude_before",
    "max_magnitude_after",
    "worth_it",
    "candidates",
    "params",
    "fitted",
)
PRINTED_COLUMNS = STEP_COLUMNS[:13]
TABLE_COLUMNS = STEP_COLUMNS[:-2]


@dataclass
class ExplainedStage:
    """One stage of the loop: the stage, its field's columns and its statistics."""

    stage: Stage
    columns: dict[str, np.ndarray]
    statistics: dict

    @property
    def label(self) -> str:
        return f"{self.stage.level:02d}-{self.stage.name}"


@dataclass
class Explanation:
    """What the loop found: the stages (0 = the registered pair), one row per applied step, the
    stack that applies them, and why it stopped."""

    pair_name: str
    stages: list[ExplainedStage]
    steps: list[dict] = field(default_factory=list)
    stop: str = ""
    findings: list[str] = field(default_factory=list)  # what the loop saw beside the field (``coverage``)

    @property
    def stack(self) -> list[dict]:
        return [explained.stage.spec for explained in self.stages[1:]]

    @property
    def verdict(self) -> str:
        return self.stages[-1].statistics["verdict"]

    def summary_rows(self) -> list[dict]:
        """One summary row per stage (``study.summary``'s contract), for the pair figures."""
        return [stage_summary_row(self.pair_name, explained) for explained in self.stages]

    def record(self) -> dict:
        """The explanation as JSON-able data (``explain.json``)."""
        return {
            "pair": self.pair_name,
            "stack": self.stack,
            "stop": self.stop,
            "findings": self.findings,
            "verdict": self.verdict,
            "steps": self.steps,
        }


def stage_summary_row(pair_name: str, explained: ExplainedStage) -> dict:
    stage = explained.stage
    meta = {**stage.metadata(explained.label), **stage.pair.metadata()}
    cloud = np.repeat(np.array([1, 2], dtype=np.uint8), [stage.removed1, stage.removed2])
    return summary_row(pair_name, stage.pair, meta, cloud, explained.statistics)


def explained_stage(stage: Stage, settings: FieldSettings) -> ExplainedStage:
    columns, statistics = analyse_field(stage.pair, settings)
    return ExplainedStage(stage, columns, statistics)


def explain_pair(
    pair: RegisteredPair,
    settings: FieldSettings,
    grid_section: dict,
    explain: ExplainSettings,
    suggest: list[dict] | None = None,
    base_dir: str | Path = ".",
    pair_name: str = "pair",
    on_stage: Callable[[list[ExplainedStage]], None] | None = None,
) -> Explanation:
    """Apply the best suggestion worth it, recompute, repeat (see the module docstring).

    ``suggest``: the config's normalised candidates (None: the default ones, which skip what
    cannot apply to the pair); a candidate whose hypothesis the stack already has is never
    tried again. ``on_stage``: called with the stages so far each time one is decided (stage 0
    first), e.g. to draw its figures while the loop goes on.
    """
    current = explained_stage(initial_stage(pair), settings)
    result = Explanation(pair_name, [current])
    if on_stage is not None:
        on_stage(result.stages)

    def take(table: dict[str, np.ndarray], chosen: int, outcomes: dict) -> None:
        """Apply row ``chosen`` of ``table``: the outcome its suggestion computed (``outcomes``)
        as it is, not run again."""
        nonlocal current
        key = (str(table["hypothesis"][chosen]), str(table["params"][chosen]))
        level = len(result.steps) + 1
        name, params = parse_step({key[0]: json.loads(key[1])}, base_dir, grid_section, level)
        stage = following_stage(current.stage, name, params, level, base_dir, outcomes.get(key))
        following = explained_stage(stage, settings)
        result.steps.append(step_row(level, table, chosen, current, following, explain))
        result.stages.append(following)
        log.info("step %d: %s", level, format_step(result.steps[-1]))
        current.stage.pair.derived.clear()  # its images and trees: its suggestions are made
        current = following
        if on_stage is not None:
            on_stage(result.stages)

    def before_stopping(candidates: list[dict], outcomes: dict, table: dict[str, np.ndarray] | None = None):
        """What the field cannot show, before the loop stops: (table, row) of a step, or None;
        the suggestions' outcomes in ``outcomes``."""
        pair = current.stage.pair
        sector = blind_sector_step(pair, settings, candidates, base_dir, grid_section, suggest, result, outcomes)
        if sector is not None:
            return sector, 0
        table_of = stage_table_of(outcomes)
        moved = moved_objects_step(candidates, table_of, explain, result, table)
        return moved or carried_body_step(pair, candidates, table_of, explain, result, outcomes, table)

    def stage_table_of(outcomes: dict) -> Callable[[list[dict]], dict[str, np.ndarray]]:
        """The suggestion table of some candidates of the current stage (their outcomes in ``outcomes``)."""

        def table_of(steps: list[dict]) -> dict[str, np.ndarray]:
            pair = current.stage.pair
            return suggestions(pair, settings, steps, base_dir, grid_section, suggest is None, outcomes=outcomes)

        return table_of

    while True:
        verdict = current.statistics["verdict"]
        room = len(result.steps) < explain.max_steps
        applied = result.stack
        candidates = [
            step for step in candidate_steps(suggest, applied, base_dir, grid_section) if not repeats(step, applied)
        ]
        if verdict != "patterned":
            result.stop = STOP_VERDICT.format(verdict=verdict)
            if not room:
                break
            outcomes = {}
            found = before_stopping(candidates, outcomes)
            if found is None:
                break
            take(*found, outcomes)
            continue
        if not room:
            result.stop = STOP_MAX_STEPS
            break
        if not candidates:
            result.stop = STOP_NO_CANDIDATES
            break
        outcomes = {}
        table = suggestions(
            current.stage.pair, settings, candidates, base_dir, grid_section, suggest is None, outcomes=outcomes
        )
        chosen = best_worth_it(table, explain)
        if chosen is not None and table["corrects"][chosen]:
            body = carried_body_step(
                current.stage.pair, candidates, stage_table_of(outcomes), explain, result, outcomes, table
            )
            table, chosen = body or (table, chosen)
        if chosen is None:
            result.stop = STOP_NOTHING_HELPS
            found = before_stopping(candidates, outcomes, table)
            if found is None:
                break
            table, chosen = found
        take(table, chosen, outcomes)
    log.info("explain %s: %d step(s), stopped: %s", pair_name, len(result.steps), result.stop)
    return result


def blind_sector_step(
    pair: RegisteredPair,
    settings: FieldSettings,
    candidates: list[dict],
    base_dir: str | Path,
    grid_section: dict,
    suggest: list[dict] | None,
    result: Explanation,
    outcomes: dict,
) -> dict[str, np.ndarray] | None:
    """When the loop would stop: a scan that returned nothing in a sector the other fills
    (``coverage.blind_sectors``) is a field of view the field cannot show (it has no vector
    there). Each is a finding of ``result``; the suggestion table of ``field_of_view`` alone
    when it is a candidate and removes most of the other cloud's points in the sector (the
    blind scan's model says so), else None (the finding says the model does not); its outcome
    in ``outcomes`` (``suggestions``')."""
    sectors = blind_sectors(pair)
    for sector in sectors:
        if sector.statement() not in result.findings:
            result.findings.append(sector.statement())
    view = [step for step in candidates if step_name(step) == "field_of_view"]
    if not sectors or not view:
        return None
    table = suggestions(pair, settings, view, base_dir, grid_section, suggest is None, outcomes=outcomes)
    if not len(table["rank"]):
        return None
    keep1, keep2 = outcomes[candidate_key(view[0])]
    for sector in sectors:
        kept = keep2 if sector.blind == 1 else keep1
        if np.count_nonzero(sector.points & ~kept) >= 0.5 * np.count_nonzero(sector.points):
            return table
    return None


def carried_body_step(
    pair: RegisteredPair,
    candidates: list[dict],
    table_of: Callable[[list[dict]], dict[str, np.ndarray]],
    explain: ExplainSettings,
    result: Explanation,
    outcomes: dict,
    table: dict[str, np.ndarray] | None = None,
) -> tuple[dict[str, np.ndarray], int] | None:
    """When the loop would stop, or apply a correction: most of what the ``ego_vehicle``
    candidate removes stays put in both sensors' frames while they moved
    (``carried.carried_body``) is the vehicle's own body. The field may not show it (a car's
    roof under the sensor moves within its own plane), and a correction would fit it, not the
    pose (a rigid ``realign`` aligning a truck's cargo body moves scan 2 by the pose change
    itself). (table, row) of ``ego_vehicle``, from the stage's ``table`` when it has one, else
    from ``table_of`` of that candidate alone, when it removes at most ``max_removed_share`` of the points;
    a finding of ``result``. None when it is no candidate or does not remove the body."""
    body = [step for step in candidates if step_name(step) == "ego_vehicle"]
    if not body:
        return None
    key = candidate_key(body[0])
    keep1, keep2 = outcomes[key] if key in outcomes else apply_step(pair, body[0])
    carried = carried_body(pair, keep1, keep2)
    if not carried.is_vehicle:
        return None
    if table is None or "ego_vehicle" not in table["hypothesis"]:
        table = table_of(body)
    rows = np.flatnonzero(table["hypothesis"] == "ego_vehicle")
    if not len(rows) or float(table["removed_share"][rows[0]]) > explain.max_removed_share:
        return None
    result.findings.append(carried.statement())
    return table, int(rows[0])


def moved_objects_step(
    candidates: list[dict],
    table_of: Callable[[list[dict]], dict[str, np.ndarray]],
    explain: ExplainSettings,
    result: Explanation,
    table: dict[str, np.ndarray] | None = None,
) -> tuple[dict[str, np.ndarray], int] | None:
    """When the loop would stop: points of one cloud where the other scan's rays passed through
    are objects that moved, which the field cannot show in units of its noise. (table, row) of
    the ``moving_objects`` candidate that explains them (``explains_seen_through``), from the
    stage's ``table`` when it has one, else from ``table_of(candidates)`` (the stage's
    suggestions); a finding of ``result``. None when none does."""
    moving = [step for step in candidates if step_name(step) == "moving_objects"]
    if not moving:
        return None
    if table is None or "moving_objects" not in table["hypothesis"]:
        table = table_of(moving)
    for i in np.flatnonzero(table["hypothesis"] == "moving_objects"):
        row = {name: column[i] for name, column in table.items()}
        if explains_seen_through(row, explain):
            result.findings.append(
                f"{row['removed1']} + {row['removed2']} points of objects that moved: they hold "
                f"{row['seen_through_removed']:.0%} of the points one scan saw through where the other has returns "
                f"(removing as many points of each voxel at random: {row['seen_through_null']:.0%})"
            )
            return table, int(i)
    return None


def step_row(
    level: int,
    table: dict[str, np.ndarray],
    chosen: int,
    before: ExplainedStage,
    after: ExplainedStage,
    explain: ExplainSettings,
) -> dict:
    """The numbers behind step ``level``'s choice (``STEP_COLUMNS``)."""
    rows = [{name: column[i] for name, column in table.items()} for i in range(len(table["rank"]))]
    others = [r for i, r in enumerate(rows) if i != chosen]
    runner_up = f"{others[0]['hypothesis']} {float(others[0]['whitened_reduction']):.3f}" if others else ""
    row = rows[chosen]
    values = {
        "step": level,
        "hypothesis": str(row["hypothesis"]),
        "whitened_reduction": float(row["whitened_reduction"]),
        "energy_reduction": float(row["energy_reduction"]),
        "removed1": int(row["removed1"]),
        "removed2": int(row["removed2"]),
        "removed_share": float(row["removed_share"]),
        "displacement_max_m": float(row["displacement_max_m"]),
        "verdict_before": before.statistics["verdict"],
        "verdict_after": after.statistics["verdict"],
        "field_energy_before": float(before.statistics["field_energy"]),
        "field_energy_after": float(after.statistics["field_energy"]),
        "max_magnitude_before": float(before.statistics["max_magnitude"]),
        "max_magnitude_after": float(after.statistics["max_magnitude"]),
        "candidates": len(rows),
        "worth_it": sum(worth_it(r, explain) for r in rows),
        "runner_up": runner_up,
        "params": str(row["params"]),
        "fitted": str(row["fitted"]),
    }
    return {name: values[name] for name in STEP_COLUMNS}


def format_step(row: dict) -> str:
    """One step as a line: the choice and the numbers behind it."""
    cost = (
        f"moved up to {row['displacement_max_m']:.3f} m"
        if row["fitted"] not in ("", "{}")
        else f"removed {row['removed1']} + {row['removed2']} points ({100 * row['removed_share']:.1f}%)"
    )
    return (
        f"{row['hypothesis']}: energy reduction {100 * row['whitened_reduction']:.1f}% in noise units "
        f"({100 * row['energy_reduction']:.1f}% raw), {cost}, "
        f"verdict {row['verdict_before']} -> {row['verdict_after']}, "
        f"field energy {row['field_energy_before']:.4g} -> {row['field_energy_after']:.4g}"
        + (f" (runner-up {row['runner_up']})" if row["runner_up"] else "")
    )


def stack_config(explanation: Explanation, grid_section: dict) -> str:
    """The stack found as a ready study config (YAML): the grid it was found on and
    ``hypotheses:`` with every parameter as used, each step's numbers and what it fitted as a
    comment. ``lidarfield run --config`` and a study's config take it as it is."""
    lines = [
        f"# found by lidarfield explain for {explanation.pair_name}: {len(explanation.steps)} step(s), "
        f"stopped: {explanation.stop}",
        "grid: " + _flow(grid_section),
        "hypotheses:" + ("" if explanation.steps else " []"),
    ]
    for spec, row in zip(explanation.stack, explanation.steps):
        fitted = json.loads(row["fitted"] or "{}")
        note = (
            f"energy reduction {row['whitened_reduction']:.3f} in noise units ({row['energy_reduction']:.3f} raw), "
            f"removed {row['removed1']} + {row['removed2']}"
        )
        note += f", fitted {canonical_json(fitted)}" if fitted else ""
        lines.append(f"  - {_flow(spec)}  # step {row['step']}: {note}")
    return "\n".join(lines) + "\n"


def _flow(value) -> str:
    """One line of YAML flow style."""
    return yaml.safe_dump(value, default_flow_style=True, sort_keys=True, width=float("inf")).strip()
