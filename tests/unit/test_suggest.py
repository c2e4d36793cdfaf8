"""What to try next: each candidate alone on a stage's survivors, ranked by energy reduction."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from helpers.clouds import targets
from lidarfield.analysis.suggest import SUGGESTION_COLUMNS, SeenThrough, candidate_steps, suggestions
from lidarfield.errors import HypothesisError
from lidarfield.field.grid import FieldSettings, SphericalGrid
from lidarfield.pair import RegisteredPair
from lidarfield.study.config import load_config

SETTINGS = FieldSettings(SphericalGrid())
GRID = SETTINGS.to_config()


def with_vehicle(n: int = 40, voxels: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Points 1.5 m out at the centre of the first ``voxels`` azimuth bins of band 2 (scan 2's own
    vehicle), ``n`` per voxel."""
    az = np.radians(np.repeat(np.arange(voxels) * 10.0 + 5.0, n))
    return np.column_stack([1.5 * np.cos(az), 1.5 * np.sin(az), np.zeros_like(az)]), az


def test_the_candidate_that_removes_the_cause_ranks_first():
    vehicle, _ = with_vehicle()
    pair = RegisteredPair(targets(60, 1), np.vstack([targets(60, 2), vehicle]))
    candidates = candidate_steps([{"crop": {}}, {"ego_vehicle": {}}, {"crop": {"max_range_m": 9.0}}], [])
    table = suggestions(pair, SETTINGS, candidates)
    assert list(table) == list(SUGGESTION_COLUMNS)
    assert list(table["rank"]) == [1, 2, 3]
    best = {name: table[name][0] for name in table}
    assert best["hypothesis"] == "ego_vehicle" and best["params"] == '{"box_m":null,"radius_m":3.0}'
    assert best["removed1"] == 0 and best["removed2"] == len(vehicle)
    assert best["voxels_invalidated"] == 0
    assert best["energy_reduction"] > 0.95
    assert best["removed_share"] == pytest.approx(len(vehicle) / (2 * 180 * 60 + len(vehicle)))
    # crop with defaults removes nothing: no reduction, nothing invalidated.
    noop = int(np.flatnonzero(table["params"] == '{"box_m":null,"max_range_m":null,"min_range_m":0.0}')[0])
    assert table["energy_reduction"][noop] == pytest.approx(0.0, abs=1e-12) and table["removed1"][noop] == 0


def test_emptying_voxels_is_counted_apart_not_as_a_reduction():
    vehicle, _ = with_vehicle()
    pair = RegisteredPair(targets(60, 1), np.vstack([targets(60, 2), vehicle]))
    # Every target is 10 m out: max_range_m 9 empties every voxel of scan 2's targets.
    table = suggestions(pair, SETTINGS, candidate_steps([{"crop": {"max_range_m": 9.0}}], []))
    assert table["voxels_invalidated"][0] == 180
    assert table["energy_invalidated"][0] == pytest.approx(1.0)
    assert math.isnan(table["energy_reduction"][0])  # no voxel is valid both before and after
    # Cropping away the targets of one azimuth half keeps the others unchanged: reduction 0
    # over the voxels still valid, the emptied ones counted apart.
    half = candidate_steps([{"crop": {"box_m": [-100, 100, 0, 100, -100, 100]}}], [])
    table = suggestions(RegisteredPair(targets(60, 1), targets(60, 2)), SETTINGS, half)
    assert table["voxels_invalidated"][0] == 90
    assert table["energy_reduction"][0] == pytest.approx(0.0, abs=1e-12)


def test_default_candidates_are_the_builtins_not_yet_applied():
    grid = {"kind": "spherical", "azimuth_bins": 12, "elevation_deg": [-30.0, 10.0], "elevation_bins": 4}
    names = [next(iter(step)) for step in candidate_steps(None, [{"field_of_view": {}}], ".", grid)]
    assert names == [
        "ego_vehicle",
        "shadow",
        "crop",
        "outliers",
        "moving_objects",
        "realign",
        "range_calibration",
        "range_calibration",
        "deskew",
        "deskew",
        "elevation_calibration",
    ]  # corrections last; range_calibration and deskew alone and with the pose (suggest.DEFAULT_CANDIDATE_PARAMS)
    steps = candidate_steps(None, [], ".", grid)
    assert [s["deskew"]["with_pose"] for s in steps if "deskew" in s] == [False, True]
    assert [s["range_calibration"]["with_pose"] for s in steps if "range_calibration" in s] == [False, True]
    shadow = candidate_steps(None, [], ".", grid)[2]["shadow"]
    assert shadow["grid"]["azimuth_bins"] == 12 and shadow["origins"] == [1, 2]  # the study's grid, defaults
    with pytest.raises(HypothesisError, match="suggest entry 2"):
        candidate_steps([{"crop": {}}, {"shadow": {"jump_m": -1}}], [])


def test_study_candidates_per_stage(tmp_path):
    study = load_config("config/config.yaml")  # stack: field_of_view, shadow
    assert [next(iter(s)) for s in study.candidates(0)] == [
        "ego_vehicle",
        "field_of_view",
        "shadow",
        "crop",
        "outliers",
        "moving_objects",
        "realign",
        "range_calibration",
        "range_calibration",
        "deskew",
        "deskew",
        "elevation_calibration",
    ]
    assert [next(iter(s)) for s in study.candidates(2)] == [
        "ego_vehicle",
        "crop",
        "outliers",
        "moving_objects",
        "realign",
        "range_calibration",
        "range_calibration",
        "deskew",
        "deskew",
        "elevation_calibration",
    ]
    config = tmp_path / "study.yaml"
    config.write_text(
        "hypotheses: [{ego_vehicle: {}}]\nsuggest: [{ego_vehicle: {radius_m: 5}}, {shadow: {origins: [1]}}]\n"
    )
    study = load_config(config, require_pairs=False)
    assert study.candidates(1) == study.candidates(0)  # an explicit list is used as given
    assert study.candidates(0)[0] == {"ego_vehicle": {"radius_m": 5.0, "box_m": None}}
    config.write_text("suggest: [{no_such_rule: {}}]\n")
    with pytest.raises(HypothesisError, match="suggest entry 1.*unknown hypothesis"):
        load_config(config, require_pairs=False)


def test_a_plugin_candidate_runs_from_its_file(tmp_path):
    (tmp_path / "near.py").write_text(
        "import numpy as np\n\n"
        "def remove(pair, params):\n"
        "    far = lambda xyz: np.linalg.norm(xyz, axis=1) >= params['radius_m']\n"
        "    return far(pair.xyz1), far(pair.xyz2)\n"
    )
    vehicle, _ = with_vehicle()
    pair = RegisteredPair(targets(60, 1), np.vstack([targets(60, 2), vehicle]))
    spec = {"plugin": {"file": "near.py", "function": "remove", "params": {"radius_m": 3.0}}}
    (candidate,) = candidate_steps([spec], [], tmp_path)
    table = suggestions(pair, SETTINGS, [candidate], tmp_path)
    # The same points as ego_vehicle's 3 m radius: the same reduction.
    ego = suggestions(pair, SETTINGS, candidate_steps([{"ego_vehicle": {}}], []))
    assert table["hypothesis"][0] == "plugin" and table["removed2"][0] == len(vehicle)
    assert table["energy_reduction"][0] == pytest.approx(ego["energy_reduction"][0], rel=1e-12)
    with pytest.raises(HypothesisError, match="suggest entry 1"):
        candidate_steps([{"plugin": {"file": "missing.py", "function": "remove"}}], [], tmp_path)


def test_the_suggest_job_skips_default_candidates_that_cannot_apply(tmp_path, capsys):
    """The workflow's job: with --default-candidates, field_of_view on a pair without sensor
    models is skipped; without it (a configured list), it is an error naming the entry."""
    from lidarfield.cli import run_in_process
    from lidarfield.io.parquet_table import read_table
    from lidarfield.pair import write_pair

    vehicle, _ = with_vehicle()
    write_pair(tmp_path / "registered.parquet", RegisteredPair(targets(60, 1), np.vstack([targets(60, 2), vehicle])))
    candidates = candidate_steps(None, [], ".", GRID)
    argv = [
        "job",
        "suggest",
        "--registered",
        str(tmp_path / "registered.parquet"),
        "--stage",
        "00-none-00000000",
        "--candidates",
        json.dumps(candidates),
        "--grid",
        json.dumps(GRID),
        "--out",
        str(tmp_path / "suggestions.parquet"),
    ]
    assert run_in_process([*argv, "--default-candidates"]) == 0
    table, _ = read_table(tmp_path / "suggestions.parquet")
    # range_calibration cannot apply: its fit would throw the vehicle kilometres away; deskew has
    # no motion (no velocity given, no scan stamps); field_of_view needs the sensor models the pair
    # has not; shadow by occlusion (the default candidate's rule) too, but from one place (this
    # pair's scans) it removes nothing whatever the models
    assert set(table["hypothesis"]) == {"ego_vehicle", "shadow", "crop", "outliers", "realign"}
    assert table["hypothesis"][0] == "ego_vehicle" and table["energy_reduction"][0] > 0.95
    (tmp_path / "suggestions.parquet").unlink()
    assert run_in_process(argv) == 2
    assert "suggest entry 2: field_of_view: sensor 1 has no sensor model" in capsys.readouterr().err
    assert not (tmp_path / "suggestions.parquet").exists()


def test_a_candidate_that_removes_nothing_gets_the_row_of_a_recomputed_field():
    """The job reuses the field before for such a candidate: the row must be what recomputing
    the field from the same points gives, to the bit."""
    from lidarfield.analysis.suggest import compare_fields
    from lidarfield.field.kernel import field_from_voxel_ids

    vehicle, _ = with_vehicle()
    pair = RegisteredPair(targets(60, 1), np.vstack([targets(60, 2), vehicle]))
    table = suggestions(pair, SETTINGS, candidate_steps([{"crop": {}}], []))
    ids1, ids2 = SETTINGS.grid.assign(pair.xyz1), SETTINGS.grid.assign(pair.xyz2)
    before = field_from_voxel_ids(ids1, pair.xyz1, ids2, pair.xyz2, SETTINGS)
    recomputed = compare_fields(before, field_from_voxel_ids(ids1, pair.xyz1, ids2, pair.xyz2, SETTINGS))
    assert table["removed1"][0] == table["removed2"][0] == 0
    for name, value in recomputed.items():
        assert table[name][0] == value or (math.isnan(table[name][0]) and math.isnan(value)), name


def test_a_correction_that_moves_points_into_new_voxels_is_compared_over_the_common_ones():
    """A correction (unlike a removal) can move points into voxels that held none before (deskew
    did, on the default study's drive): the reduction is over the voxels valid before and after,
    as a plain dictionary by voxel id computes it, and the new voxels count in energy_after."""
    from lidarfield.analysis.suggest import compare_fields
    from lidarfield.analysis.tags import voxel_energy
    from lidarfield.field.kernel import field_from_voxel_ids
    from lidarfield.poses import pose_from_xyzrpy

    def field(xyz1, xyz2):
        return field_from_voxel_ids(SETTINGS.grid.assign(xyz1), xyz1, SETTINGS.grid.assign(xyz2), xyz2, SETTINGS)

    xyz1, xyz2 = targets(60, 1), targets(60, 2)
    xyz1, xyz2 = xyz1[np.arctan2(xyz1[:, 1], xyz1[:, 0]) > 0], xyz2[np.arctan2(xyz2[:, 1], xyz2[:, 0]) > 0]
    turn = pose_from_xyzrpy([0, 0, 0, 0, 0, math.pi])[:3, :3]
    # cloud 2's points shifted a little, and a copy of both clouds half a turn away (where the
    # clouds had no point)
    after_xyz1, after_xyz2 = np.vstack([xyz1, xyz1 @ turn.T]), np.vstack([xyz2 + 0.05, xyz2 @ turn.T])
    before, after = field(xyz1, xyz2), field(after_xyz1, after_xyz2)
    assert set(after["voxel"][after["valid"]]) - set(before["voxel"])  # valid voxels that are new

    def energies(columns):
        return {v: e for v, e, ok in zip(columns["voxel"], voxel_energy(columns), columns["valid"]) if ok}

    by_voxel_before, by_voxel_after = energies(before), energies(after)
    common = set(by_voxel_before) & set(by_voxel_after)
    expected = 1 - sum(by_voxel_after[v] for v in common) / sum(by_voxel_before[v] for v in common)
    compared = compare_fields(before, after)
    assert compared["energy_reduction"] == pytest.approx(expected, rel=1e-12)
    assert compared["energy_after"] == pytest.approx(sum(by_voxel_after.values()), rel=1e-12)
    assert compared["voxels_invalidated"] == len(set(by_voxel_before) - set(by_voxel_after))


def test_a_default_correction_that_cannot_apply_is_skipped():
    """realign on a cloud 2 of 5 points: a HypothesisError of a correcting candidate is 'cannot
    apply' among the default candidates (skipped), an error naming the entry when configured."""
    pair = RegisteredPair(targets(60, 1), targets(60, 2)[:5])
    candidates = candidate_steps([{"crop": {}}, {"realign": {}}], [])
    table = suggestions(pair, SETTINGS, candidates, defaults=True)
    assert list(table["hypothesis"]) == ["crop"] and not table["corrects"][0]
    assert table["fitted"][0] == "{}" and table["displacement_max_m"][0] == 0.0
    with pytest.raises(HypothesisError, match="suggest entry 2: realign: too few points"):
        suggestions(pair, SETTINGS, candidates)


def test_a_suggested_correction_shows_its_displacement_and_fit(tmp_path):
    """The report's table and `lidarfield run`'s line: a correction's row says how far it moved
    the points and what it fitted, and which tag points to it."""
    from lidarfield.analysis.suggest import write_suggestions
    from lidarfield.cli.run import format_next_steps
    from lidarfield.report.suggestions import describe_fitted, stage_suggestions

    fitted = {"translation_m": [-0.3, 0.0002, 0.0], "rotation_deg": [0, 0, 0.01], "angle_deg": 0.01}
    row = {
        "rank": 1,
        "hypothesis": "realign",
        "params": "{}",
        "removed1": 0,
        "removed2": 0,
        "removed_share": 0.0,
        "corrects": True,
        "displacement_median_m": 0.3,
        "displacement_max_m": 0.31,
        "fitted": json.dumps(fitted),
        "suggested_by": "rigid",
        "tag_share": 0.63,
        "voxels_invalidated": 0,
        "energy_invalidated": 0.0,
        "max_after": 0.05,
        "p95_after": 0.02,
        "energy_after": 1.0,
        "energy_reduction": 0.95,
        "whitened_reduction": 0.97,
        "removal_null": 0.0,
        "seen_through_removed": np.nan,
        "seen_through_null": np.nan,
        "fitted_null": 0.02,
        "calibration_seen": True,
    }
    table = {name: np.asarray([row[name]]) for name in SUGGESTION_COLUMNS}
    stage = tmp_path / "stages" / "00-none"
    stage.mkdir(parents=True)
    write_suggestions(stage / "suggestions.parquet", table, "00-none", [], GRID)
    assert describe_fitted(fitted) == "t = (-0.300, 0.000, 0.000) m, rotation 0.010°"
    assert describe_fitted("{}") == "" and describe_fitted({"scale": 1.0012}) == "scale = 1.001"
    html = stage_suggestions(stage)
    assert "moves 0.300 / 0.310 m" in html and "t = (-0.300, 0.000, 0.000) m" in html
    assert "suggested by the rigid tag (63% of the energy)" in html
    line = format_next_steps([{"stage": "00-none", "verdict": "patterned"}], tmp_path)
    assert (
        "realign reduces the energy by 97.0% in units of its noise (95.0% raw) (fitted t = (-0.300, 0.000, 0.000) m"
        in line
    )


def test_seen_through_columns_weigh_a_removal_against_thinning_the_same_voxels():
    """Voxel 0 holds 6 points (two of cloud 1 seen through), voxel 1 holds 4 (one of cloud 2
    seen through). Removing the two seen through in voxel 0 takes 2 of the 3; removing as many
    points of each voxel at random takes a third of voxel 0's two and none of voxel 1's: 2/9."""
    ids1, ids2 = np.array([0, 0, 0, 0, 1, 1]), np.array([0, 0, 1, 1])
    seen = (np.array([1, 1, 0, 0, 0, 0], bool), np.array([0, 0, 1, 0], bool))
    keep1, keep2 = np.array([0, 0, 1, 1, 1, 1], bool), np.ones(4, bool)
    got = SeenThrough(seen, ids1, ids2).columns(keep1, keep2)
    assert got["seen_through_removed"] == pytest.approx(2 / 3) and got["seen_through_null"] == pytest.approx(2 / 9)
    # the same number of points, one of each voxel's ordinary ones: none seen through, the same null
    other = SeenThrough(seen, ids1, ids2).columns(np.array([1, 1, 0, 0, 1, 1], bool), keep2)
    assert other["seen_through_removed"] == 0 and other["seen_through_null"] == pytest.approx(2 / 9)
    # a voxel emptied of what was seen through: all of them, against the voxel's share
    whole = SeenThrough(seen, ids1, ids2).columns(~seen[0], ~seen[1])
    assert whole["seen_through_removed"] == 1 and whole["seen_through_null"] == pytest.approx((2 / 6 * 2 + 1 / 4) / 3)
    assert math.isnan(SeenThrough(None, ids1, ids2).columns(keep1, keep2)["seen_through_removed"])
    nothing = (np.zeros(6, bool), np.zeros(4, bool))
    assert math.isnan(SeenThrough(nothing, ids1, ids2).columns(keep1, keep2)["seen_through_null"])


def test_a_correction_is_ranked_by_what_it_explains_beyond_its_free_parameters():
    """Two corrections explaining the same share of the whitened energy: the one fitting fewer
    parameters ranks first; one with many parameters ranks first only for what it explains
    beyond them (``fitted_null``: parameters over the whitened energy)."""
    from lidarfield.analysis.suggest import compare_fields, fitted_null, rank_table
    from lidarfield.analysis.tags import whitened_energy
    from lidarfield.field.kernel import field_from_voxel_ids

    assert fitted_null(6, 600.0) == pytest.approx(0.01) and fitted_null(0, 600.0) == 0.0
    vehicle, _ = with_vehicle()
    pair = RegisteredPair(targets(60, 1), np.vstack([targets(60, 2), vehicle]))
    ids1, ids2 = SETTINGS.grid.assign(pair.xyz1), SETTINGS.grid.assign(pair.xyz2)
    before = field_from_voxel_ids(ids1, pair.xyz1, ids2, pair.xyz2, SETTINGS)
    same = compare_fields(before, before, parameters=33)
    assert same["fitted_null"] == pytest.approx(33 / whitened_energy(before).sum())

    def row(name, reduction, null, seen=True):
        given = {
            "hypothesis": name,
            "whitened_reduction": reduction,
            "fitted_null": null,
            "tag_share": math.nan,
            "calibration_seen": seen,
        }
        return {column: given.get(column, 0) for column in SUGGESTION_COLUMNS[1:]}

    table = rank_table([row("per_ring", 0.30, 0.05), row("common", 0.27, 0.001), row("rigid", 0.26, 0.006)])
    assert list(table["hypothesis"]) == ["common", "rigid", "per_ring"]
    table = rank_table([row("per_ring", 0.40, 0.05), row("common", 0.27, 0.001)])
    assert list(table["hypothesis"]) == ["per_ring", "common"]
    # a calibration fitted with the pose that found none (``calibration_seen`` False) is the pose alone: last
    table = rank_table([row("pose_alone", 0.50, 0.001, seen=False), row("rigid", 0.26, 0.006)])
    assert list(table["hypothesis"]) == ["rigid", "pose_alone"]
