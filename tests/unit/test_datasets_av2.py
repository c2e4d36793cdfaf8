"""Argoverse 2 sensor logs as sequences: sweeps in the vehicle frame, written in a lidar's frame
with the calibration, posed by the vehicle's interpolated city poses."""

from __future__ import annotations

import shutil
from fractions import Fraction

import numpy as np
import pyarrow as pa
import pyarrow.feather as feather
import pytest

from helpers.av2_layout import (
    DOWN_IN_VEHICLE,
    UP_IN_VEHICLE,
    intensity_of,
    write_av2_log,
    write_calibration,
)
from lidarfield import ConfigError, InputError, read_scan, write_scan
from lidarfield.commands.jobs import recorded_scan
from lidarfield.datasets import describe_dataset, read_dataset
from lidarfield.poses import invert_pose
from lidarfield.study.config import validate_config


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    return write_av2_log(tmp_path_factory.mktemp("av2") / "log-0001")


def dataset(log, **settings) -> dict:
    return {"format": "av2", "path": str(log.folder), **settings}


def study(log, register="truth", hypotheses=(), **settings):
    entry = {"dataset": dataset(log, **settings), "register": register}
    return validate_config({"sequences": {"a": entry}, "hypotheses": list(hypotheses)})


def test_the_scans_are_the_sweeps_with_the_lidar_poses_and_times(log):
    sequence = read_dataset(dataset(log))
    assert [scan.path for scan in sequence.scans] == [str(path) for path in log.sweeps]  # notes.txt ignored
    assert [scan.format for scan in sequence.scans] == ["av2"] * 4
    # correctly rounded: the stamps (about 3e17 ns) exceed 2**53, so ``stamp * 1e-9`` rounds twice
    assert [scan.stamp_s for scan in sequence.scans] == [float(Fraction(int(stamp), 10**9)) for stamp in log.stamps_ns]
    # sweep 0's pose is listed; sweeps 1-3 are interpolated between poses 30 ms before and 20 ms after
    assert np.abs(np.array([scan.pose for scan in sequence.scans]) - log.up_poses).max() < 1e-9
    options = sequence.scans[0].options
    assert options["frame"] == "up_lidar" and options["lidars"] == ["up_lidar", "down_lidar"]
    assert np.abs(np.array(options["T_frame_vehicle"]) - invert_pose(UP_IN_VEHICLE)).max() < 1e-12
    assert sequence.sensor is None  # both lidars: no one model describes them (docs/datasets-av2.md)
    down = read_dataset(dataset(log, frame="down_lidar", lidars=["down_lidar", "up_lidar"])).scans[0].options
    assert down["lidars"] == ["up_lidar", "down_lidar"]  # one order, one stage id
    assert np.abs(np.array(down["T_frame_vehicle"]) - invert_pose(DOWN_IN_VEHICLE)).max() < 1e-12


@pytest.mark.parametrize(
    ("frame", "lidars", "sensor"),
    [
        ("up_lidar", ["up_lidar"], "vlp32c"),
        ("down_lidar", ["down_lidar"], "vlp32c"),
        ("up_lidar", ["down_lidar"], None),
        ("down_lidar", None, None),
        ("egovehicle", ["up_lidar"], None),
    ],
)
def test_the_default_sensor_is_vlp32c_only_for_one_lidar_in_its_own_frame(log, frame, lidars, sensor):
    settings = {"frame": frame} if lidars is None else {"frame": frame, "lidars": lidars}
    assert read_dataset(dataset(log, **settings)).sensor == sensor


def test_register_truth_recovers_the_simulated_relative_poses_within_1e_9(log):
    planned = study(log, frame="up_lidar", lidars=["up_lidar"])
    assert sorted(planned.pairs) == ["a-000", "a-001", "a-002"]
    from lidarfield.registration import register_pair

    for k, name in enumerate(sorted(planned.pairs)):
        pair = planned.pairs[name]
        assert pair.scan1.spec["sensor"] == "vlp32c" and pair.scan1.spec["format"] == "av2"
        registered = register_pair(recorded_scan(pair.scan1.spec), recorded_scan(pair.scan2.spec), pair.register)
        expected = invert_pose(log.up_poses[k]) @ log.up_poses[k + 1]
        assert np.abs(registered.T_1_2 - expected).max() < 1e-9


@pytest.mark.parametrize("frame", ["up_lidar", "down_lidar"])
def test_one_lidar_in_its_own_frame_is_its_simulated_scan_within_1e_9(log, frame):
    """x, y, z stored as float64 (the dataset's float32: the next test)."""
    simulated = log.up if frame == "up_lidar" else log.down
    sequence = read_dataset(dataset(log, frame=frame, lidars=[frame]))
    for k in (0, 2):
        scan = recorded_scan(study_spec(sequence.scans[k], sequence.sensor))
        truth = simulated[k]
        assert len(scan) == len(truth) > 10_000
        assert np.abs(scan.xyz - truth.xyz).max() < 1e-9
        ring = truth.attributes["ring"] + (32 if frame == "down_lidar" else 0)
        assert np.array_equal(scan.attributes["ring"], ring)
        # offset_ns is the firing time rounded to the nanosecond
        assert np.array_equal(scan.attributes["time"], np.round(truth.attributes["time"] * 1e9) / 1e9)
        assert np.abs(scan.attributes["time"] - truth.attributes["time"]).max() <= 0.5e-9
        assert np.array_equal(scan.attributes["intensity"], intensity_of(truth, 0 if frame == "up_lidar" else 3))
        assert scan.stamp_s == log.stamps_ns[k] / 10**9 and scan.sensor.name == "vlp32c"
        pose = log.up_poses[k] if frame == "up_lidar" else log.down_poses[k]
        assert np.abs(scan.pose - pose).max() < 1e-9


def study_spec(scan, sensor) -> dict:
    from lidarfield.study.pairs import recorded_scan_spec

    return recorded_scan_spec(scan.path, scan.format, sensor, scan.pose, None, scan.options, scan.stamp_s)


def test_both_lidars_in_the_vehicle_frame_put_each_point_where_the_world_has_it(log):
    """The vehicle frame and both lidars: every point, mapped by the scan's pose, lands where the
    simulation's own lidar pose puts it (both lidars at once, 1e-9)."""
    sequence = read_dataset(dataset(log, frame="egovehicle"))
    scan = recorded_scan(study_spec(sequence.scans[1], sequence.sensor))
    world = scan.xyz @ scan.pose[:3, :3].T + scan.pose[:3, 3]
    up, down = scan.attributes["ring"] < 32, scan.attributes["ring"] >= 32
    for mask, simulated, pose in ((up, log.up[1], log.up_poses[1]), (down, log.down[1], log.down_poses[1])):
        expected = simulated.xyz @ pose[:3, :3].T + pose[:3, 3]
        assert mask.sum() == len(simulated)
        assert np.abs(np.sort(world[mask], axis=0) - np.sort(expected, axis=0)).max() < 1e-9
    assert np.abs(scan.pose - log.vehicle_poses[1]).max() < 1e-9


def test_float32_sweeps_as_in_the_dataset_hold_to_float32_precision(tmp_path):
    """The dataset stores x, y, z as float32: 2^-24 of the coordinates (6e-8 x 100 m), 1e-5 here."""
    log32 = write_av2_log(tmp_path / "log", xyz_dtype=np.float32)
    sequence = read_dataset(dataset(log32, lidars=["up_lidar"]))
    scan = recorded_scan(study_spec(sequence.scans[3], sequence.sensor))
    assert np.abs(scan.xyz - log32.up[3].xyz).max() < 1e-5


def test_a_study_of_the_log_is_the_study_of_the_same_scans_as_files_with_lidar_poses(log, tmp_path):
    """Specs planned alike and every stage's summary statistics equal (within 1e-9) to those of the
    simulated scans written as files with a poses file of the lidar's poses. The grid's edges lie
    between the simulated beams (0.2 deg azimuth steps from 0, a beam at -4 deg): on an edge, a
    point's 1e-15 of frame-change rounding would pick its voxel."""
    from helpers.datasets import assert_same_stage_statistics, stage_statistics
    from lidarfield.io.pose_files import write_kitti_poses

    for k, scan in enumerate(log.up):
        write_scan(scan, tmp_path / f"{k:03d}.parquet")
    write_kitti_poses(tmp_path / "poses.txt", log.up_poses)
    stack = [{"ego_vehicle": {"radius_m": 3.0}}, {"field_of_view": {}}, {"shadow": {"origins": [1, 2]}}]
    grid = {"azimuth_offset_deg": 0.1, "elevation_deg": [-25.5, 15.5], "elevation_bins": 5}
    log_entry = {"dataset": dataset(log, lidars=["up_lidar"])}
    as_log = validate_config({"sequences": {"a": log_entry}, "hypotheses": stack, "grid": grid})
    entry = {"scans": str(tmp_path / "*.parquet"), "poses": str(tmp_path / "poses.txt"), "sensor": "vlp32c"}
    as_files = validate_config({"sequences": {"a": entry}, "hypotheses": stack, "grid": grid})
    assert sorted(as_log.pairs) == sorted(as_files.pairs)
    for name in as_files.pairs:
        a, b = as_log.pairs[name], as_files.pairs[name]
        assert a.scan1.spec["sensor"] == b.scan1.spec["sensor"] == "vlp32c"
        assert np.abs(np.array(a.scan2.spec["pose"]) - np.array(b.scan2.spec["pose"])).max() < 1e-9
    for name in ("a-000", "a-002"):
        stages = stage_statistics(as_log, name)
        assert len(stages) == 4 and sum(s[0] + s[1] for s in stages) > 1000
        assert_same_stage_statistics(stages, stage_statistics(as_files, name))


def test_planning_reads_the_tables_never_a_sweep(log, tmp_path, monkeypatch):
    """A sweep replaced by garbage still plans (its ingest job, reading it, fails with its name),
    and no sweep file is opened while the study is planned."""
    copy = tmp_path / "log"
    shutil.copytree(log.folder, copy)
    broken = copy / "sensors" / "lidar" / log.sweeps[2].name
    broken.write_bytes(b"\x00garbage" * 10)
    opened = []
    real = feather.read_table
    monkeypatch.setattr(
        feather, "read_table", lambda source, *a, **k: opened.append(str(source)) or real(source, *a, **k)
    )
    planned = validate_config({"sequences": {"a": {"dataset": {"format": "av2", "path": str(copy)}}}})
    assert len(planned.pairs) == 3
    assert sorted(opened) == sorted(
        str(copy / p) for p in ("calibration/egovehicle_SE3_sensor.feather", "city_SE3_egovehicle.feather")
    )
    with pytest.raises(InputError, match=f"{broken}: an Argoverse 2 lidar sweep: not a readable Feather file"):
        recorded_scan(planned.pairs["a-002"].scan1.spec)


def test_a_sweep_read_on_its_own_is_both_lidars_in_the_vehicle_frame(log):
    scan = read_scan(log.sweeps[0])
    assert len(scan) == len(log.up[0]) + len(log.down[0]) and scan.sensor is None
    assert set(np.unique(scan.attributes["ring"] // 32)) == {0, 1}
    with pytest.raises(InputError, match="frame 'up_lidar' needs T_frame_vehicle"):
        read_scan(log.sweeps[0], options={"frame": "up_lidar"})


def _rewrite(path, **changes):
    table = feather.read_table(path)
    columns = {name: table.column(name) for name in table.column_names}
    for name, value in changes.items():
        if value is None:
            columns.pop(name)
        else:
            columns[name] = value(columns[name]) if callable(value) else value
    feather.write_feather(pa.table(columns), path)


POSES, CALIBRATION = "city_SE3_egovehicle.feather", "calibration/egovehicle_SE3_sensor.feather"


def _drop_poses_around_sweep(folder, stamps, k, keep=()):
    path = folder / POSES
    table = feather.read_table(path)
    times = table.column("timestamp_ns").to_numpy()
    drop = (np.abs(times - stamps[k]) <= 60_000_000) & ~np.isin(times, keep)
    feather.write_feather(table.filter(pa.array(~drop)), path)


@pytest.mark.parametrize(
    ("change", "file", "message"),
    [
        (lambda f, s: (f / CALIBRATION).unlink(), CALIBRATION, "the calibration .* file not found"),
        (
            lambda f, s: write_calibration(f / CALIBRATION, {"up_lidar": UP_IN_VEHICLE}),
            CALIBRATION,
            "has no sensor 'down_lidar'; its sensors: up_lidar",
        ),
        (lambda f, s: _rewrite(f / CALIBRATION, qw=None), CALIBRATION, r"missing column\(s\) \['qw'\]"),
        (
            lambda f, s: _rewrite(f / CALIBRATION, qx=lambda c: pa.array(np.full(len(c), 2.0))),
            CALIBRATION,
            "row 0 is no pose",
        ),
        (lambda f, s: (f / POSES).unlink(), POSES, "the vehicle's poses .* file not found"),
        (lambda f, s: (f / POSES).write_bytes(b"ARROW1\x00\x00trunc"), POSES, "not a readable Feather file"),
        (lambda f, s: _rewrite(f / POSES, timestamp_ns=None), POSES, r"missing column\(s\) \['timestamp_ns'\]"),
        (
            lambda f, s: _rewrite(f / POSES, timestamp_ns=lambda c: pa.array(c.to_numpy() * 1e-9)),
            POSES,
            "timestamp_ns is float64, not integer nanoseconds",
        ),
        (
            lambda f, s: [p.unlink() for p in (f / "sensors" / "lidar").glob("*.feather")],
            "sensors/lidar",
            "no Argoverse 2 sweep",
        ),
        (lambda f, s: shutil.rmtree(f / "sensors"), "", r"not an Argoverse 2 log \(no sensors/lidar/"),
        (
            lambda f, s: _drop_poses_around_sweep(f, s, 2),
            "sensors/lidar/{2}.feather",
            r"no pose of the vehicle within 50 ms of this sweep \(the nearest in .*egovehicle.feather is 70.0 ms",
        ),
        (
            lambda f, s: _drop_poses_around_sweep(f, s, 3, keep=[s[3] - 30_000_000]),
            "sensors/lidar/{3}.feather",
            "taken 30.0 ms after the last pose .* outside the poses' time span",
        ),
    ],
)
def test_a_broken_log_names_the_file_and_the_problem(log, tmp_path, change, file, message):
    folder = tmp_path / "log"
    shutil.copytree(log.folder, folder)
    change(folder, log.stamps_ns)
    named = str(folder / file.format(*log.stamps_ns)).rstrip("/")
    with pytest.raises(ConfigError, match=message) as error:
        validate_config(
            {"sequences": {"a": {"dataset": {"format": "av2", "path": str(folder), "frame": "down_lidar"}}}}
        )
    assert named in str(error.value) and "\n" not in str(error.value)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda p: p.unlink(), "file not found"),
        (lambda p: p.write_bytes(p.read_bytes()[:200]), "not a readable Feather file"),
        (lambda p: _rewrite(p, offset_ns=None), r"missing column\(s\) \['offset_ns'\]"),
        (lambda p: _rewrite(p, x=lambda c: pa.array(["a"] * len(c))), "column.* not numeric .*x is string"),
        (lambda p: _rewrite(p, laser_number=lambda c: pa.array(np.full(len(c), 70, np.uint8))), "outside 0..63"),
    ],
)
def test_a_broken_sweep_names_its_file(log, tmp_path, change, message):
    sweep = tmp_path / log.sweeps[0].name
    shutil.copy(log.sweeps[0], sweep)
    spec = study_spec(read_dataset(dataset(log)).scans[0], None)
    change(sweep)
    with pytest.raises(InputError, match=message) as error:
        recorded_scan({**spec, "path": str(sweep)})
    assert str(error.value).startswith(str(sweep))


def test_info_describes_the_log(log):
    assert describe_dataset(log.folder) == (
        f"{log.folder}: Argoverse 2 sensor log\n  4 lidar sweeps, 0.3 s\n  9 vehicle poses over 0.4 s\n"
        "  calibrated lidars: up_lidar, down_lidar"
    )
