"""``lidarfield explain``'s figures drawn by a second process while the loop goes on (issue 38):
the folder is the one drawn after the loop, file for file and byte for byte, with no fork of
the (threaded) process; the drawing process's error, or its death, is raised by the command."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from helpers.ego_car import ego_car_pair, registered_off
from lidarfield.analysis.stopping_rule import ExplainSettings
from lidarfield.report.explanation import FIGURES_DIR, StageFigures, write_explanation
from lidarfield.study.config import validate_config
from lidarfield.study.explain_loop import explain_pair

GRID = {"kind": "spherical", "azimuth_bins": 36, "elevation_deg": [-22.0, 16.0], "elevation_bins": 5}


@pytest.fixture(scope="module")
def ego_car():
    """The ego-car drive seen by a VLP-16, registered 0.3 m off (steps that correct and remove)."""
    return registered_off(ego_car_pair("vlp16")), validate_config({"grid": GRID}, require_pairs=False)


def explained(pair, study, out: Path, background: bool, on_start=None, max_steps: int = 2):
    plots = study.config["plots"]
    with StageFigures("pair", study.grid, out, plots, background) as figures:
        if on_start is not None:
            on_start(figures)
        explanation = explain_pair(
            pair, study.grid, study.grid_section, ExplainSettings(max_steps=max_steps), None, ".", "pair", figures
        )
        write_explanation(explanation, study.grid, study.grid_section, out, plots, figures.paths)
    return explanation


def folder(out: Path) -> dict[str, bytes]:
    return {str(path.relative_to(out)): path.read_bytes() for path in sorted(out.rglob("*")) if path.is_file()}


def test_figures_drawn_while_the_loop_goes_on_are_the_serial_folder(ego_car, tmp_path, monkeypatch):
    pair, study = ego_car

    def fork():
        raise AssertionError("a threaded process forked")

    with monkeypatch.context() as patched:
        patched.setattr(os, "fork", fork)
        background = explained(pair, study, tmp_path / "background", background=True)
    serial = explained(pair, study, tmp_path / "serial", background=False)
    assert background.steps == serial.steps and len(serial.steps) == 2
    files = folder(tmp_path / "serial")
    # stage 0's field, and per step before / after and what a removal removed (+ page copies)
    assert sum(name.endswith(".png") and "figures" in name for name in files) >= 2 * (1 + 2)
    drawn = folder(tmp_path / "background")
    assert drawn.keys() == files.keys()
    assert [name for name in files if drawn[name] != files[name]] == []


def test_an_error_drawing_is_raised(ego_car, tmp_path):
    pair, study = ego_car

    def block_figures(figures):  # a file where the figures' folder goes: the drawing process cannot write
        (tmp_path / FIGURES_DIR).write_text("not a folder")

    with pytest.raises(OSError, match="figures"):
        explained(pair, study, tmp_path, background=True, on_start=block_figures, max_steps=0)


def test_the_drawing_process_killed_is_raised(ego_car, tmp_path):
    pair, study = ego_car

    def kill(figures):
        os.kill(figures.drawing.process.pid, signal.SIGKILL)

    with pytest.raises(RuntimeError, match="drawing the figures ended with exit code -9"):
        explained(pair, study, tmp_path, background=True, on_start=kill, max_steps=0)
