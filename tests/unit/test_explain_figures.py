"""``lidarfield explain``'s figures drawn by a second process while the loop goes on (issue 38):
the folder is the one drawn after the loop, file for file and byte for byte; a child's error
is raised by the command."""

from __future__ import annotations

from pathlib import Path

import pytest

from helpers.ego_car import ego_car_pair, registered_off
from lidarfield.analysis.stopping_rule import ExplainSettings
from lidarfield.report import explanation as report
from lidarfield.report.explanation import StageFigures, can_fork, write_explanation
from lidarfield.study.config import validate_config
from lidarfield.study.explain_loop import explain_pair

pytestmark = pytest.mark.skipif(not can_fork(), reason="no fork start method here")

GRID = {"kind": "spherical", "azimuth_bins": 36, "elevation_deg": [-22.0, 16.0], "elevation_bins": 5}


@pytest.fixture(scope="module")
def ego_car():
    """The ego-car drive seen by a VLP-16, registered 0.3 m off (steps that correct and remove)."""
    return registered_off(ego_car_pair("vlp16")), validate_config({"grid": GRID}, require_pairs=False)


def explained(pair, study, out: Path, background: bool):
    plots = study.config["plots"]
    with StageFigures("pair", study.grid, out, plots, background) as figures:
        explanation = explain_pair(
            pair, study.grid, study.grid_section, ExplainSettings(max_steps=2), None, ".", "pair", figures
        )
        write_explanation(explanation, study.grid, study.grid_section, out, plots, figures.paths)
    return explanation


def folder(out: Path) -> dict[str, bytes]:
    return {str(path.relative_to(out)): path.read_bytes() for path in sorted(out.rglob("*")) if path.is_file()}


def test_figures_drawn_while_the_loop_goes_on_are_the_serial_folder(ego_car, tmp_path):
    pair, study = ego_car
    background = explained(pair, study, tmp_path / "background", background=True)
    serial = explained(pair, study, tmp_path / "serial", background=False)
    assert background.steps == serial.steps and len(serial.steps) == 2
    files = folder(tmp_path / "serial")
    # stage 0's field, and per step before / after and what a removal removed (+ page copies)
    assert sum(name.endswith(".png") and "figures" in name for name in files) >= 2 * (1 + 2)
    drawn = folder(tmp_path / "background")
    assert drawn.keys() == files.keys()
    assert [name for name in files if drawn[name] != files[name]] == []


def test_an_error_drawing_in_the_child_is_raised(ego_car, tmp_path, monkeypatch):
    pair, study = ego_car

    def broken(*args, **kwargs):
        raise ValueError("no room for the figure")

    monkeypatch.setattr(report, "draw_stage", broken)  # the child is a copy: broken there too
    with pytest.raises(ValueError, match="no room for the figure"):
        explained(pair, study, tmp_path, background=True)
