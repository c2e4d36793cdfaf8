"""Stages stored as what they change: a stage's points read back from the registered pair and
the changes of stages 0..k equal the survivors computed directly, stage by stage."""

from __future__ import annotations

import numpy as np
import pytest

from lidarfield.commands.jobs import write_stage
from lidarfield.errors import InputError
from lidarfield.io.parquet_table import read_table
from lidarfield.pair import read_pair, write_pair
from lidarfield.poses import pose_from_xyzrpy
from lidarfield.registration import register_pair
from lidarfield.sensors.models import PRESETS
from lidarfield.simulation.raycast import simulate_scan
from lidarfield.simulation.scene import load_scene
from lidarfield.storage.stage_points import CHANGES, read_stage_points, stage_files
from lidarfield.study.stack import apply_stack

GRID = {"kind": "spherical", "azimuth_bins": 36, "elevation_deg": [-22.5, 15.0], "elevation_bins": 5, "min_points": 30}
# Two built-ins that correct, realign (sensor 2 registered 0.3 m and 1 deg off) and
# range_calibration (cloud 2's ranges 1% long), then every built-in that removes.
STACK = [
    {"realign": {}},
    {"range_calibration": {}},
    {"ego_vehicle": {"radius_m": 6.5}},
    {"field_of_view": {}},
    {"shadow": {}},
    {"crop": {"max_range_m": 12.0}},
    {"outliers": {}},
]
CORRECTING_LEVELS = (1, 2)


@pytest.fixture(scope="module")
def stages(tmp_path_factory):
    """The stack's stages computed directly (the reference), and the pair folder they were
    written to as changes."""
    scene, sensor = load_scene("paper-intersection"), PRESETS["vlp16"]
    scan1 = simulate_scan(scene, sensor, pose_from_xyzrpy([0, 0, 3, 0, 0, 0]), seed=1, range_noise_m=0.01)
    scan2 = simulate_scan(
        scene, sensor, pose_from_xyzrpy([1, 1, 3, 0, 0, 0.05]), seed=2, range_noise_m=0.01, range_scale=1.01
    )
    pair = register_pair(scan1, scan2, "truth")
    offset = pose_from_xyzrpy([0.3, -0.1, 0, 0, 0, np.radians(1.0)])
    pair.xyz2, pair.T_1_2 = pair.xyz2 @ offset[:3, :3].T + offset[:3, 3], offset @ pair.T_1_2
    folder = tmp_path_factory.mktemp("pair")
    write_pair(folder / "registered.parquet", pair)
    pair, _ = read_pair(folder / "registered.parquet")  # as the jobs read it
    computed = list(apply_stack(pair, STACK, ".", GRID))
    ids = [f"{stage.level:02d}-{stage.name}-{stage.level:08x}" for stage in computed]
    for stage in computed:
        previous = ids[stage.level - 1] if stage.level else None
        stage_dir = folder / "stages" / ids[stage.level]
        write_stage(stage, ids[stage.level], previous, stage_dir / CHANGES, stage_dir / "removed.parquet")
    return computed, folder, ids


def test_every_stage_reads_back_as_its_survivors(stages):
    computed, folder, ids = stages
    changes = [folder / "stages" / stage_id / CHANGES for stage_id in ids]
    assert all(stage.removed1 + stage.removed2 > 0 for stage in computed[3:]), "each removal removes"
    for stage in computed:
        pair, meta = read_stage_points(folder / "registered.parquet", changes[: stage.level + 1])
        direct = stage.pair
        np.testing.assert_array_equal(pair.xyz1, direct.xyz1)
        np.testing.assert_array_equal(pair.xyz2, direct.xyz2)
        np.testing.assert_array_equal(pair.T_1_2, direct.T_1_2)
        for mine, theirs in ((pair.attributes1, direct.attributes1), (pair.attributes2, direct.attributes2)):
            assert set(mine) == set(theirs)
            for name in theirs:
                np.testing.assert_array_equal(mine[name], theirs[name])
                assert mine[name].dtype == theirs[name].dtype
        assert meta["stage"] == ids[stage.level] and meta["hypothesis"] == stage.name
        assert meta.get("correction") == stage.correction
        assert meta["sensor1"] == direct.sensor1.to_dict() and meta["registration"] == direct.registration


def test_a_stage_stores_only_what_it_changed(stages):
    computed, folder, ids = stages
    for stage in computed:
        columns, meta = read_table(folder / "stages" / ids[stage.level] / CHANGES)
        removed = columns["removed"]
        assert np.count_nonzero(removed) == stage.removed1 + stage.removed2
        assert np.isnan(columns["x"][removed]).all()
        moved = np.count_nonzero(~removed)
        if stage.level in CORRECTING_LEVELS:
            # realign moves the survivors of cloud 2, range_calibration those it corrected: never
            # more than a cloud's survivors, and never cloud 1 (registered to, not moved)
            assert stage.moved2 and 0 < moved <= len(stage.pair.xyz2)
            assert set(columns["cloud"][~removed]) == {2}
        else:
            assert moved == 0 and stage.correction is None
        assert meta["previous"] == (ids[stage.level - 1] if stage.level else None)


def test_the_stage_files_of_a_stage_folder_follow_its_previous_stages(stages):
    _, folder, ids = stages
    registered, changes = stage_files(folder / "stages" / ids[3])
    assert registered == folder / "registered.parquet"
    assert changes == [folder / "stages" / stage_id / CHANGES for stage_id in ids[:4]]


def test_a_change_file_that_does_not_fit_is_an_error_naming_it(stages):
    _, folder, ids = stages
    changes = [folder / "stages" / stage_id / CHANGES for stage_id in ids]
    # a removing stage applied twice: the rows it removes are gone the second time
    with pytest.raises(InputError, match=f"{ids[3]}.*cloud [12]: removes row"):
        read_stage_points(folder / "registered.parquet", changes[:4] + changes[3:4])
