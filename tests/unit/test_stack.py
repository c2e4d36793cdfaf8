"""apply_stack: stage k applies hypothesis k to the survivors of stage k-1 and records what it
removed; on the paper's simulated pair the field shrinks stage by stage."""

from __future__ import annotations

import numpy as np
import pytest

from lidarfield.analysis.field_stats import field_statistics
from lidarfield.errors import HypothesisError
from lidarfield.field.grid import field_settings_from_config
from lidarfield.field.kernel import discrepancy_field
from lidarfield.pair import RegisteredPair
from lidarfield.poses import pose_from_xyzrpy
from lidarfield.registration import register_pair
from lidarfield.sensors.models import PRESETS
from lidarfield.simulation.raycast import simulate_scan
from lidarfield.simulation.scene import load_scene
from lidarfield.study.stack import apply_stack


def _rows(xyz: np.ndarray) -> set[tuple[float, ...]]:
    return set(map(tuple, xyz))


def test_each_stage_removes_from_the_previous_survivors_and_records_it():
    rng = np.random.default_rng(0)
    xyz1, xyz2 = rng.normal(scale=8, size=(3000, 3)), rng.normal(scale=8, size=(2500, 3))
    pair = RegisteredPair(
        xyz1, xyz2, pose_from_xyzrpy([1, 0, 0, 0, 0, 0.1]), attributes1={"intensity": np.arange(3000.0)}
    )
    stack = [
        {"ego_vehicle": {"radius_m": 4}},
        {"crop": {"max_range_m": 15}},
        {"field_of_view": {"elevation_deg": [-30, 30]}},
    ]
    stages = list(apply_stack(pair, stack))
    assert [(s.level, s.name) for s in stages] == [(0, "none"), (1, "ego_vehicle"), (2, "crop"), (3, "field_of_view")]
    # stage 0: the registered pair's own arrays, numbered by their row in it
    assert np.shares_memory(stages[0].pair.xyz1, pair.xyz1) and np.shares_memory(stages[0].pair.xyz2, pair.xyz2)
    assert stages[0].removed1 == stages[0].removed2 == 0 and stages[0].spec is None
    for stage in stages:  # every stage's survivors know their row in the registered pair
        assert np.array_equal(xyz1[stage.pair.attributes1["row"]], stage.pair.xyz1)
        assert np.array_equal(xyz2[stage.pair.attributes2["row"]], stage.pair.xyz2)
    assert stages[1].spec == {"ego_vehicle": {"radius_m": 4.0, "box_m": None}}
    for before, after in zip(stages, stages[1:]):
        assert after.removed1 > 0 and after.removed2 > 0
        for cloud in ("xyz1", "xyz2"):
            kept, gone = getattr(after.pair, cloud), getattr(after.removed, cloud)
            assert len(kept) + len(gone) == len(getattr(before.pair, cloud))
            assert _rows(kept) | _rows(gone) == _rows(getattr(before.pair, cloud))
        # Attributes travel with their points, kept or removed.
        for part in (after.pair, after.removed):
            assert np.array_equal(xyz1[part.attributes1["intensity"].astype(int)], part.xyz1)
    columns = stages[2].removed_columns()
    assert set(columns["hypothesis"]) == {"crop"}
    assert np.count_nonzero(columns["cloud"] == 1) == stages[2].removed1
    assert len(stages[0].removed_columns()["hypothesis"]) == 0


def test_the_whole_stack_is_validated_before_any_stage():
    pair = RegisteredPair(np.ones((4, 3)), np.ones((4, 3)))
    with pytest.raises(HypothesisError, match="hypothesis 2 \\(shadow\\)"):
        apply_stack(pair, [{"crop": {}}, {"shadow": {"jump_m": -1}}])


def test_a_step_is_parsed_once_in_the_job_and_once_by_the_stack(monkeypatch, tmp_path):
    """Planning validated the entries: the mitigate job parses its entry once (not also in a
    validation and again in ``apply_step``), ``apply_stack`` each entry once."""
    import lidarfield.hypotheses as hypotheses
    from lidarfield.commands.jobs import mitigate_stage
    from lidarfield.pair import write_pair

    parsed = []
    parse_params = hypotheses.parse_params
    monkeypatch.setattr(hypotheses, "parse_params", lambda *a: parsed.append(a[2]) or parse_params(*a))
    rng = np.random.default_rng(1)
    pair = RegisteredPair(rng.normal(scale=8, size=(500, 3)), rng.normal(scale=8, size=(400, 3)))
    write_pair(tmp_path / "registered.parquet", pair)
    step = {"crop": {"max_range_m": 12.0}}
    out = tmp_path / "changes.parquet", tmp_path / "removed.parquet"
    mitigate_stage(tmp_path / "registered.parquet", [], step, "01-crop-00000000", 1, *out)
    assert parsed == ["hypothesis 1 (crop)"] and out[0].is_file()
    parsed.clear()
    stages = list(apply_stack(pair, [{"ego_vehicle": {"radius_m": 4}}, step]))
    assert parsed == ["hypothesis 1 (ego_vehicle)", "hypothesis 2 (crop)"]
    assert stages[2].spec == {"crop": {**stages[2].spec["crop"], "max_range_m": 12.0}} and stages[2].removed1 > 0


# --- the paper's simulated pair ------------------------------------------------------------

# 36 azimuth bins and 5 elevation bands of 7.5 deg (the 37.5 deg the paper states), the lowest
# edge just below the sensor's lowest channel (-22 deg); top band 7.5..15 deg holds its +9.6.
GRID = {"kind": "spherical", "azimuth_bins": 36, "elevation_deg": [-22.5, 15.0], "elevation_bins": 5, "min_points": 30}


@pytest.fixture(scope="module")
def paper_fields():
    scene, sensor = load_scene("paper-intersection"), PRESETS["paper-sim-80"]
    poses = [pose_from_xyzrpy([0, 0, 3, 0, 0, 0]), pose_from_xyzrpy([1, 1, 3, 0, 0, 0.05])]
    pair = register_pair(*(simulate_scan(scene, sensor, pose) for pose in poses), "truth")
    settings = field_settings_from_config(GRID)
    stack = [{"field_of_view": {}}, {"shadow": {"jump_m": 1.0, "min_points": 30, "origins": [1, 2]}}]
    return [discrepancy_field(s.pair.xyz1, s.pair.xyz2, settings) for s in apply_stack(pair, stack, ".", GRID)]


def _band_max(field: dict, band: int) -> float:
    in_band = field["valid"] & (field["el_bin"] == band)
    return float(field["magnitude"][in_band].max())


def test_largest_discrepancies_fall_stage_by_stage(paper_fields):
    maxima = [field_statistics(f)["max_magnitude"] for f in paper_fields]
    rms = [field_statistics(f)["rms_magnitude"] for f in paper_fields]
    assert maxima[0] > maxima[1] > maxima[2]
    assert rms[0] > rms[1] > rms[2]
    assert maxima[2] < 0.25 * maxima[0]


def test_field_of_view_boundary_bands_lose_their_large_vectors(paper_fields):
    none, fov, _ = paper_fields
    top, bottom = 4, 0  # the bands holding the sensor's +9.6 and -22 deg limits
    assert _band_max(none, top) > 0.25 and _band_max(fov, top) < 0.6 * _band_max(none, top)
    assert _band_max(none, bottom) > 0.6 and _band_max(fov, bottom) < 0.25 * _band_max(none, bottom)
    # The bands in between are not field_of_view's business: unchanged.
    for band in (1, 2, 3):
        assert _band_max(fov, band) == pytest.approx(_band_max(none, band))
