"""``lidarfield explain`` reuses what a step's suggestions computed (issue 38): the chosen
candidate's outcome makes the next stage as it is, and the outlier scores' neighbour distances
are carried to the next stage. Against the plain way (the stack found applied anew by
``apply_stack``, every hypothesis run again, and each stage's suggestions on its points with
nothing carried): the same stages and the same ranked candidates with the same numbers, on the
default study's pair and the real shared pairs."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from helpers.ego_car import registered_off
from helpers.real_pairs import real_pair
from lidarfield.analysis.stopping_rule import ExplainSettings
from lidarfield.analysis.suggest import candidate_steps, suggestions
from lidarfield.commands.jobs import simulated_scan
from lidarfield.field.grid import field_settings_from_config
from lidarfield.hypotheses import parse_step
from lidarfield.pair import RegisteredPair
from lidarfield.registration import register_pair
from lidarfield.sensors.models import PRESETS
from lidarfield.study import explain_loop
from lidarfield.study.config import load_config
from lidarfield.study.stack import apply_stack, following_stage, initial_stage, next_stage

ROOT = Path(__file__).resolve().parents[2]
TEXT_COLUMNS = ("hypothesis", "params", "suggested_by")


def assert_same_numbers(fast, plain, what: str) -> None:
    """Equal, numbers within 1e-9 (realign's fit, rounded to 1e-9, run again)."""
    if isinstance(plain, dict):
        assert fast.keys() == plain.keys(), what
        for key in plain:
            assert_same_numbers(fast[key], plain[key], f"{what}.{key}")
    elif isinstance(plain, list):
        assert len(fast) == len(plain), what
        for k, (a, b) in enumerate(zip(fast, plain)):
            assert_same_numbers(a, b, f"{what}[{k}]")
    elif isinstance(plain, float):
        np.testing.assert_allclose(fast, plain, rtol=1e-6, atol=1e-9, err_msg=what)
    else:
        assert fast == plain, what


def explained_against_plain(
    pair: RegisteredPair, study, monkeypatch, max_steps: int, suggest: list[dict] | None = None
) -> list[str]:
    """Explain ``pair`` (at most ``max_steps`` steps, any reduction worth it; ``suggest``: the
    candidates, None the default ones), recording the suggestion tables the loop computed, and
    compare every stage and each table after the first with the plain way's (the first stage's
    is computed the plain way by the loop too); the steps."""
    computed = []

    def recorded(stage_pair, *args, **kwargs):
        table = suggestions(stage_pair, *args, **kwargs)
        computed.append((stage_pair, args[1], table))
        return table

    monkeypatch.setattr(explain_loop, "suggestions", recorded)
    settings = ExplainSettings(max_steps=max_steps, min_energy_reduction=0.0, min_reduction_per_removed=0.0)
    explanation = explain_loop.explain_pair(pair, study.grid, study.grid_section, settings, suggest, ".", "pair")
    stages = list(apply_stack(pair, explanation.stack, ".", study.grid_section))
    assert len(stages) == len(explanation.stages)
    for explained, plain in zip(explanation.stages, stages):
        for name in ("xyz1", "xyz2", "T_1_2"):
            np.testing.assert_allclose(getattr(explained.stage.pair, name), getattr(plain.pair, name), atol=1e-9)
    levels = [s.stage.pair for s in explanation.stages]
    for stage_pair, candidates, fast in computed:
        level = next(k for k, p in enumerate(levels) if p is stage_pair)
        if level == 0:
            continue
        nothing_carried = dataclasses.replace(stages[level].pair, neighbours={})
        plain = suggestions(nothing_carried, study.grid, candidates, ".", study.grid_section, suggest is None)
        assert_same_table(fast, plain, f"level {level}")
    return [row["hypothesis"] for row in explanation.steps]


def assert_same_table(fast: dict, plain: dict, what: str = "") -> None:
    """The same ranked candidates with the same numbers (``assert_same_numbers``)."""
    assert list(fast["hypothesis"]) == list(plain["hypothesis"]), what  # the ranking
    for name, values in plain.items():
        if name in TEXT_COLUMNS:
            assert list(fast[name]) == list(values), f"{what} {name}"
        elif name == "fitted":
            for a, b in zip(fast[name], values):
                assert_same_numbers(json.loads(a), json.loads(b), f"{what} fitted")
        else:
            np.testing.assert_allclose(fast[name], values, rtol=1e-6, atol=1e-9, err_msg=f"{what} {name}")


def test_the_default_study_pair_registered_off_is_explained_as_the_plain_way(monkeypatch):
    """Registered 0.3 m off, the loop realigns (a correction: its outcome reused) and the field
    is random after it; every default candidate."""
    study = load_config(ROOT / "config" / "config.yaml", ROOT)
    spec = study.pairs["paper-sim"]
    pair = register_pair(simulated_scan(spec.scan1.spec), simulated_scan(spec.scan2.spec), "truth")
    assert explained_against_plain(registered_off(pair), study, monkeypatch, max_steps=2) == ["realign"]


# Removals only, and outliers (whose scores are what is carried), cheap on large scans.
CANDIDATES = [{"field_of_view": {}}, {"ego_vehicle": {}}, {"outliers": {}}]


@pytest.mark.parametrize("name", ["expd", "hdl32", "os1 0->1"])
def test_the_real_pairs_next_stage_and_its_suggestions_are_the_plain_ways(shared_data, name):
    """At their reference poses, one step of the loop's: the first removal that removes points
    applied with the outcome its suggestion computed (``following_stage``, which also carries
    the outlier scores), against the stage made anew from a pair that carries nothing; then the
    next stage's suggestions on each."""
    real = real_pair(shared_data, name)
    model = PRESETS[real.sensor]
    xyz2 = real.scan2.xyz @ real.reference[:3, :3].T + real.reference[:3, 3]
    pair = RegisteredPair(real.scan1.xyz, xyz2, real.reference, model, model, registration={"method": "transform"})
    grid_section = load_config(ROOT / "config" / "config.yaml", ROOT).grid_section
    settings = field_settings_from_config(grid_section)
    candidates = candidate_steps(CANDIDATES, [], ".", grid_section)
    first = initial_stage(pair)
    outcomes = {}
    table = suggestions(first.pair, settings, candidates, ".", grid_section, outcomes=outcomes)
    chosen = next(k for k in range(len(table["rank"])) if table["removed1"][k] + table["removed2"][k] > 0)
    key = (str(table["hypothesis"][chosen]), str(table["params"][chosen]))
    name, params = parse_step({key[0]: json.loads(key[1])}, ".", grid_section, 1)
    fast = following_stage(first, name, params, 1, ".", outcomes[key])
    assert fast.pair.neighbours  # the outlier scores carried
    plain = next_stage(initial_stage(dataclasses.replace(pair, neighbours={})).pair, {name: json.loads(key[1])}, 1)
    for column in ("xyz1", "xyz2", "T_1_2"):
        np.testing.assert_array_equal(getattr(fast.pair, column), getattr(plain.pair, column))
    assert_same_table(
        suggestions(fast.pair, settings, candidates, ".", grid_section),
        suggestions(plain.pair, settings, candidates, ".", grid_section),
    )
