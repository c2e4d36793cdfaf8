"""A stage's candidates evaluated by a pool of threads (``suggestions``' ``workers``, issue 38):
the same table, bit for bit, and the same outcomes as one at a time, on the default study's
pair registered 0.3 m off with every default candidate (realign's fit, range_calibration's
pairing, the removals and their seen-through columns); a configured candidate that cannot apply
is the same error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from helpers.ego_car import registered_off
from lidarfield.analysis.suggest import candidate_steps, suggestions
from lidarfield.commands.jobs import simulated_scan
from lidarfield.errors import HypothesisError
from lidarfield.registration import register_pair
from lidarfield.study.config import load_config

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def study_pair():
    study = load_config(ROOT / "config" / "config.yaml", ROOT)
    spec = study.pairs["paper-sim"]
    pair = register_pair(simulated_scan(spec.scan1.spec), simulated_scan(spec.scan2.spec), "truth")
    return study, registered_off(pair)


def run(study, pair, candidates, workers: int, defaults: bool = True):
    outcomes = {}
    table = suggestions(
        pair, study.grid, candidates, ".", study.grid_section, defaults, outcomes=outcomes, workers=workers
    )
    return table, outcomes


def test_threads_give_the_serial_table_and_outcomes(study_pair):
    study, pair = study_pair
    candidates = candidate_steps(None, [], ".", study.grid_section)
    serial, serial_outcomes = run(study, pair, candidates, workers=1)
    threaded, threaded_outcomes = run(study, pair, candidates, workers=2)
    assert list(serial["hypothesis"])[0] == "realign"  # the 0.3 m offset found first
    assert serial["seen_through_removed"][serial["removed1"] + serial["removed2"] > 0].size  # removals ranked too
    assert serial.keys() == threaded.keys()
    for name, values in serial.items():
        np.testing.assert_array_equal(threaded[name], values, err_msg=name)
    assert serial_outcomes.keys() == threaded_outcomes.keys()
    for key, outcome in serial_outcomes.items():
        for name in ("keep1", "keep2", "xyz1", "xyz2", "T_1_2"):
            np.testing.assert_array_equal(getattr(threaded_outcomes[key], name), getattr(outcome, name), str(key))


def test_threads_raise_the_serial_error_of_a_configured_candidate(study_pair):
    study, pair = study_pair
    # realign on 2 points of each cloud cannot fit; configured (not a default), it is an error
    tiny = pair.subset(np.arange(2), np.arange(2))
    candidates = candidate_steps([{"crop": {}}, {"realign": {}}], [], ".", study.grid_section)
    errors = []
    for workers in (1, 2):
        with pytest.raises(HypothesisError) as e:
            run(study, tiny, candidates, workers, defaults=False)
        errors.append(str(e.value))
    assert errors[0] == errors[1]
    assert errors[0].startswith("suggest entry 2: ")
