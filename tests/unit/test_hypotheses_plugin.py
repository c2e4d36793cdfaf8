"""Plugin hypotheses: the analyst's own file and function, and one clear error for each way it
can go wrong."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import ROOT
from lidarfield.errors import HypothesisError
from lidarfield.hypotheses import apply_step, validate_step
from lidarfield.pair import RegisteredPair
from lidarfield.storage.stage_ids import stage_ids

PLUGINS = {
    "good.py": "import numpy as np\ndef remove(pair, params):\n    return pair.xyz1[:, 0] < params['x_max'], "
    "np.ones(len(pair.xyz2), bool)\n",
    "raises.py": "def remove(pair, params):\n    raise ValueError('no cars here')\n",
    "short.py": "import numpy as np\ndef remove(pair, params):\n    return np.ones(len(pair.xyz1) - 1, bool), "
    "np.ones(len(pair.xyz2), bool)\n",
    "ints.py": "import numpy as np\ndef remove(pair, params):\n    return np.ones(len(pair.xyz1), int), "
    "np.ones(len(pair.xyz2), bool)\n",
    "single.py": "import numpy as np\ndef remove(pair, params):\n    return np.ones(len(pair.xyz1), bool)\n",
    "broken.py": "def remove(pair, params)\n    return None\n",
    "mutates.py": "def remove(pair, params):\n    pair.xyz1[:] = 0\n",
}


@pytest.fixture
def plugin_dir(tmp_path):
    for name, source in PLUGINS.items():
        (tmp_path / name).write_text(source)
    return tmp_path


@pytest.fixture
def pair():
    rng = np.random.default_rng(0)
    return RegisteredPair(rng.normal(size=(50, 3)), rng.normal(size=(40, 3)))


def test_plugin_masks_are_used(plugin_dir, pair):
    keep1, keep2 = apply_step(pair, {"plugin": {"file": "good.py", "params": {"x_max": 0.0}}}, plugin_dir)
    assert np.array_equal(keep1, pair.xyz1[:, 0] < 0.0) and keep2.all()
    assert validate_step({"plugin": {"file": "good.py"}}, plugin_dir) == {
        "plugin": {"file": "good.py", "function": "remove", "params": {}}
    }


@pytest.mark.parametrize(
    "file, function, problem",
    [
        ("missing.py", "remove", "plugin file not found"),
        ("raises.py", "remove", "raised ValueError: no cars here"),
        ("short.py", "remove", "keep1 must be a boolean array of length 50 (cloud 1), got dtype bool and shape (49,)"),
        ("ints.py", "remove", "keep1 must be a boolean array of length 50 (cloud 1), got dtype int64"),
        ("single.py", "remove", "must return (keep1, keep2)"),
        ("broken.py", "remove", "importing the file raised SyntaxError"),
        ("good.py", "filter", "the file has no function 'filter' (functions: remove)"),
        ("mutates.py", "remove", "raised ValueError: assignment destination is read-only"),
    ],
)
def test_plugin_failures_are_one_error_naming_file_and_hypothesis(plugin_dir, pair, file, function, problem):
    step = {"plugin": {"file": file, "function": function}}
    with pytest.raises(HypothesisError) as error:
        apply_step(pair, step, plugin_dir, level=3)
    message = str(error.value)
    assert message.startswith(f"{plugin_dir / file}: plugin hypothesis {function!r} (stack entry 3): ")
    assert problem in message


def test_editing_a_plugin_changes_its_stage_id_and_the_later_ones(plugin_dir):
    stack = [{"crop": {}}, {"plugin": {"file": "good.py"}}, {"outliers": {}}]
    before = stage_ids({"pair": 1}, stack, plugin_dir)
    (plugin_dir / "good.py").write_text(PLUGINS["good.py"] + "# tuned\n")
    after = stage_ids({"pair": 1}, stack, plugin_dir)
    assert before[:2] == after[:2] and before[2] != after[2] and before[3] != after[3]


def test_example_plugin_removes_what_moved():
    # Ground 3 m below the sensor (below the car band) and a wall; a car at x = 0 in scan 1
    # and at x = 5 in scan 2, nowhere near any point of the other scan.
    rng = np.random.default_rng(1)
    ground = np.column_stack([rng.uniform(-10, 10, (2, 4000)).T, np.full(4000, -3.0)])
    wall = np.column_stack([rng.uniform(-10, 10, 1000), np.full(1000, 15.0), rng.uniform(-3, 2, 1000)])
    static = np.vstack([ground, wall])
    car1, car2 = ([x, 5.0, -1.0] + rng.normal(scale=0.2, size=(60, 3)) for x in (0.0, 5.0))
    moved = RegisteredPair(np.vstack([static, car1]), np.vstack([static + 0.05, car2]))
    step = {"plugin": {"file": "hypotheses/moving_cars.py", "params": {"min_gap_m": 1.0}}}
    keep1, keep2 = apply_step(moved, step, ROOT)
    for keep in (keep1, keep2):
        assert keep[: len(static)].all() and not keep[len(static) :].any()
