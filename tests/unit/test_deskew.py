"""``deskew``: a rolling-shutter scan of the simulated intersection moved to its sweep start."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from lidarfield.analysis.field_stats import analyse_field
from lidarfield.errors import HypothesisError
from lidarfield.field.grid import field_settings_from_config
from lidarfield.hypotheses import BUILTINS, CORRECTING, apply_step, validate_step
from lidarfield.pair import RegisteredPair
from lidarfield.poses import pose_from_xyzrpy
from lidarfield.registration import register_pair
from lidarfield.sensors.models import PRESETS
from lidarfield.simulation.raycast import simulate_scan
from lidarfield.simulation.scene import load_scene
from lidarfield.study.stack import apply_stack

V = [10.0, 0.0, 0.0]  # scan 1's vehicle, m/s (its pose is level, heading +x: world = sensor frame)


def scan(x: float, yaw: float, seed: int, moving: bool, noise: float = 0.02):
    scene, sensor = load_scene("paper-intersection"), PRESETS["vlp16"]
    return simulate_scan(
        scene,
        sensor,
        pose_from_xyzrpy([x, 0, 3, 0, 0, yaw]),
        seed=seed,
        range_noise_m=noise,
        rolling_shutter=moving,
        linear_velocity_mps=V if moving else [0, 0, 0],
    )


@pytest.fixture(scope="module")
def skewed():
    """Scan 1 at 10 m/s with rolling shutter, scan 2 of the same place with the vehicle stopped
    (yawed 0.21 deg so that its rays interleave), 2 cm noise, registered by the truth."""
    return register_pair(scan(0, 0, 1, True), scan(0, 0.0037, 2, False), "truth")


def _rms(pair: RegisteredPair) -> float:
    return analyse_field(pair, field_settings_from_config({}))[1]["rms_magnitude"]


def test_registered_as_a_correcting_builtin():
    assert "deskew" in BUILTINS and "deskew" in CORRECTING
    assert validate_step({"deskew": {"cloud": 1}})["deskew"]["cloud"] == 1
    assert validate_step({"deskew": {}})["deskew"]["cloud"] == "both"


def test_moves_the_points_to_where_they_were_at_the_sweep_start():
    """Without noise, the de-skewed points are the world's points in the start pose's frame, exactly."""
    s = scan(0, 0, 1, True, noise=0.0)
    pair = RegisteredPair(s.xyz, s.xyz, np.eye(4), s.sensor, s.sensor, dict(s.attributes), dict(s.attributes))
    truth = s.xyz + np.outer(s.attributes["time"], V)
    outcome = apply_step(pair, {"deskew": {"cloud": 1, "velocity_mps": V}})
    assert outcome.xyz2 is None and np.abs(outcome.xyz1 - truth).max() < 1e-9
    # timed by azimuth instead (counter-clockwise from +x, 10 Hz): the same times, the same points
    by_azimuth = apply_step(pair, {"deskew": {"cloud": 1, "velocity_mps": V, "time_attribute": "none"}})
    assert np.abs(by_azimuth.xyz1 - truth).max() < 1e-9
    assert by_azimuth.fitted["cloud1"]["time_source"].startswith("azimuth")
    # the same in sensor 2's frame: cloud 2 put 5 m away and yawed 30 deg by T_1_2
    T = pose_from_xyzrpy([5, -2, 0, 0, 0, np.radians(30)])
    moved = RegisteredPair(s.xyz, s.xyz @ T[:3, :3].T + T[:3, 3], T, s.sensor, s.sensor, {}, dict(s.attributes))
    outcome = apply_step(moved, {"deskew": {"cloud": 2, "velocity_mps": V}})
    assert np.abs(outcome.xyz2 - (truth @ T[:3, :3].T + T[:3, 3])).max() < 1e-9


def test_reference_and_time_conventions_agree():
    """The same sweep timed from its end (negative seconds), in nanoseconds or absolute: the same points;
    referred to its end, the points move by -v x (sweep length) from where the start puts them."""
    s = scan(0, 0, 1, True, noise=0.0)
    t = s.attributes["time"]
    attrs = {"time": t, "t_end": t - 0.1, "t_ns": t * 1e9, "t_abs": 1.7e9 + t}
    pair = RegisteredPair(s.xyz, s.xyz[:0], np.eye(4), s.sensor, s.sensor, attrs, {})
    start = apply_step(pair, {"deskew": {"cloud": 1, "velocity_mps": V}}).xyz1
    for name, unit, zero in (("t_end", "s", "end"), ("t_ns", "ns", "start")):
        step = {"deskew": {"cloud": 1, "velocity_mps": V, "time_attribute": name, "time_unit": unit, "time_zero": zero}}
        assert np.abs(apply_step(pair, step).xyz1 - start).max() < 1e-6
    # absolute: the sweep starts at the earliest point (fired at 0 s here); seconds since the epoch
    # in float64 resolve 0.24 us, 2.4 um at 10 m/s
    step = {"deskew": {"cloud": 1, "velocity_mps": V, "time_attribute": "t_abs", "time_zero": "absolute"}}
    assert np.abs(apply_step(pair, step).xyz1 - start).max() < 1e-5
    end = apply_step(pair, {"deskew": {"cloud": 1, "velocity_mps": V, "reference": "end"}})
    assert np.allclose(end.xyz1, start - np.array(V) * 0.1)
    assert end.fitted["reference"] == "end" and end.fitted["cloud1"]["time_max_s"] <= 0


def test_the_field_after_deskew(skewed):
    """Measured: RMS magnitude 0.5604 m skewed, 0.1456 m de-skewed; the pair without rolling
    shutter 0.0050 m, scan 1 taken still from mid-sweep (0.5 m on) 0.1393 m. The de-skewed scan
    is exact (above), but its points were fired from along the 1 m its sensor drove: the field
    compares samplings from different viewpoints, which the still scan from mid-sweep shares."""
    stage0, stage = apply_stack(skewed, [{"deskew": {"cloud": 1}}])
    c = stage.correction
    assert c["reference"] == "start" and "cloud2" not in c
    one = c["cloud1"]
    assert one["velocity_mps"] == V and one["motion_source"] == "record"  # the simulated scan's own
    assert one["time_source"] == "attribute time (s, from start)"
    assert 0.99 < one["max_displacement_m"] <= 1.0 and one["time_min_s"] == 0 and 0.099 < one["time_max_s"] <= 0.1
    assert stage.moved1 and not stage.moved2 and stage.removed1 == stage.removed2 == 0
    assert np.array_equal(stage.pair.xyz2, skewed.xyz2)  # the still scan, untouched
    mid = register_pair(scan(0.5, 0, 1, False), scan(0, 0.0037, 2, False), "truth")
    before, after, reference = _rms(skewed), _rms(stage.pair), _rms(mid)
    assert abs(after - reference) < 0.2 * reference and after < 0.3 * before, (before, after, reference)


def test_a_still_scan_is_unchanged():
    still = register_pair(scan(0, 0, 1, False), scan(0, 0.0037, 2, False), "truth")
    for step in ({}, {"velocity_mps": [1, 0, 0]}):  # the scans' records (still) come before settings
        outcome = apply_step(still, {"deskew": step})
        assert outcome.xyz1 is None and outcome.xyz2 is None  # nothing moved, not even by rounding
        assert (
            outcome.fitted["cloud2"]["max_displacement_m"] == 0
            and outcome.fitted["cloud1"]["motion_source"] == "record"
        )
    bare = RegisteredPair(
        still.xyz1, still.xyz2, still.T_1_2, still.sensor1, still.sensor2, still.attributes1, still.attributes2
    )
    outcome = apply_step(bare, {"deskew": {"velocity_mps": [0, 0, 0], "angular_velocity_rps": [0, 0, 0]}})
    assert outcome.xyz1 is None and outcome.fitted["cloud1"]["motion_source"] == "settings"


def test_names_what_is_missing(skewed):
    unrecorded = RegisteredPair(skewed.xyz1, skewed.xyz2, skewed.T_1_2, skewed.sensor1, skewed.sensor2)
    with pytest.raises(
        HypothesisError,
        match=r"deskew: no motion for cloud 1 \(motion_source auto\): its scan recorded none, no velocity_mps nor "
        r"angular_velocity_rps is given, and the pair's "
        r"scans do not both record a stamp to derive it from T_1_2",
    ):
        apply_step(unrecorded, {"deskew": {}})
    same_time = RegisteredPair(
        skewed.xyz1,
        skewed.xyz2,
        skewed.T_1_2,
        skewed.sensor1,
        skewed.sensor2,
        sweeps={"1": {"stamp_s": 0.0}, "2": {"stamp_s": 0.0}},
    )
    with pytest.raises(HypothesisError, match=r"the pair's scans have one stamp"):
        apply_step(same_time, {"deskew": {}})
    with pytest.raises(
        HypothesisError, match=r"no motion for cloud 1 \(motion_source record\): its scan recorded none$"
    ):
        apply_step(same_time, {"deskew": {"motion_source": "record", "velocity_mps": V}})
    with pytest.raises(HypothesisError, match=r"need motion_source auto or record or settings or pair, got 'odometry'"):
        apply_step(skewed, {"deskew": {"motion_source": "odometry"}})
    bare = RegisteredPair(skewed.xyz1, skewed.xyz2, skewed.T_1_2)
    with pytest.raises(
        HypothesisError, match=r"deskew: cloud 1 has no 'time' attribute and no sensor model's rotation_hz"
    ):
        apply_step(bare, {"deskew": {"cloud": 1, "velocity_mps": V}})
    with pytest.raises(HypothesisError, match=r"need cloud 1, 2 or both, got 3"):
        apply_step(skewed, {"deskew": {"cloud": 3, "velocity_mps": V}})
    with pytest.raises(HypothesisError, match=r"need reference start or mid or end, got 'middle'"):
        apply_step(skewed, {"deskew": {"reference": "middle", "velocity_mps": V}})


def test_turning_while_driving_is_undone_exactly():
    """Yawing at 0.5 rad/s while driving 10 m/s (the simulator's linear velocity is in the world,
    = the start frame here): the de-skewed points are the world's points in the sweep-start frame."""
    from lidarfield.simulation.trajectory import moved_pose

    w = [0.0, 0.0, 0.5]
    scene, sensor = load_scene("paper-intersection"), PRESETS["vlp16"]
    pose = pose_from_xyzrpy([0, 0, 3, 0, 0, 0])
    s = simulate_scan(scene, sensor, pose, rolling_shutter=True, linear_velocity_mps=V, angular_velocity_rps=w)
    firing = moved_pose(pose, s.attributes["time"], V, w)  # world-from-sensor at each point's firing
    world = np.einsum("nij,nj->ni", firing[:, :3, :3], s.xyz) + firing[:, :3, 3]
    truth = (world - pose[:3, 3]) @ pose[:3, :3]
    pair = RegisteredPair(s.xyz, s.xyz[:0], np.eye(4), sensor, sensor, dict(s.attributes), {})
    outcome = apply_step(pair, {"deskew": {"cloud": 1, "velocity_mps": V, "angular_velocity_rps": w}})
    assert np.abs(outcome.xyz1 - truth).max() < 1e-9
    assert outcome.fitted["cloud1"]["angular_velocity_rps"] == w and outcome.xyz2 is None


# --- where the motion comes from (issue 24) ----------------------------------------------------


def test_a_simulated_scan_records_its_stamp_and_the_motion_its_points_carry(tmp_path):
    """The record is in the sensor frame at the sweep start (the world velocity turned by the
    pose's yaw), zero without rolling shutter; it survives the scan file and the pair file."""
    from lidarfield.io import read_scan, write_scan
    from lidarfield.pair import read_pair, write_pair

    scene, sensor = load_scene("paper-intersection"), PRESETS["vlp16"]
    pose = pose_from_xyzrpy([0, 0, 3, 0, 0, np.pi / 2])  # heading +y
    moving = simulate_scan(
        scene,
        sensor,
        pose,
        time_s=2.5,
        rolling_shutter=True,
        linear_velocity_mps=[0, 10, 0],
        angular_velocity_rps=[0, 0, 0.3],
    )
    assert moving.stamp_s == 2.5
    assert np.allclose(moving.sweep_motion["velocity_mps"], [10, 0, 0]) and moving.sweep_motion[
        "angular_velocity_rps"
    ] == [0, 0, 0.3]
    instantaneous = simulate_scan(scene, sensor, pose, linear_velocity_mps=[0, 10, 0])
    assert instantaneous.sweep_motion == {"velocity_mps": [0.0, 0.0, 0.0], "angular_velocity_rps": [0.0, 0.0, 0.0]}
    write_scan(moving, tmp_path / "moving.parquet")
    back = read_scan(tmp_path / "moving.parquet")
    assert back.stamp_s == 2.5 and back.sweep_motion == moving.sweep_motion
    pair = register_pair(back, instantaneous, "truth")
    write_pair(tmp_path / "pair.parquet", pair)
    read, _ = read_pair(tmp_path / "pair.parquet")
    assert read.sweeps == pair.sweeps and read.stamp(1) == 2.5 and read.stamp(2) == 0.0
    assert (
        read.sweep_motion(1) == moving.sweep_motion
        and read.subset(np.ones(len(read.xyz1), bool), np.ones(len(read.xyz2), bool)).sweeps == read.sweeps
    )


def test_deskew_is_the_first_suggestion_for_a_moving_scan_against_a_still_one(skewed):
    from lidarfield.analysis.suggest import candidate_steps, suggestions

    table = suggestions(
        skewed, field_settings_from_config({}), candidate_steps(None, [], ".", {}), ".", {}, defaults=True
    )
    assert table["hypothesis"][0] == "deskew" and table["corrects"][0] and table["energy_reduction"][0] > 0.9


def test_the_constant_velocity_between_the_pairs_stamps_when_no_scan_recorded_its_motion():
    """Two consecutive sweeps of one drive at 10 m/s (0.1 s apart, both with rolling shutter):
    without their records, the motion is T_1_2 over the stamps' difference, in each scan's frame,
    and de-skews both clouds as their records do."""
    drive = register_pair(
        simulate_scan(
            load_scene("paper-intersection"),
            PRESETS["vlp16"],
            pose_from_xyzrpy([0, 0, 3, 0, 0, 0.2]),
            seed=1,
            rolling_shutter=True,
            linear_velocity_mps=[10 * np.cos(0.2), 10 * np.sin(0.2), 0],
        ),
        simulate_scan(
            load_scene("paper-intersection"),
            PRESETS["vlp16"],
            pose_from_xyzrpy([np.cos(0.2), np.sin(0.2), 3, 0, 0, 0.2]),
            time_s=0.1,
            seed=2,
            rolling_shutter=True,
            linear_velocity_mps=[10 * np.cos(0.2), 10 * np.sin(0.2), 0],
        ),
        "truth",
    )
    by_record = apply_step(drive, {"deskew": {}})
    stamps_only = {k: {"stamp_s": record["stamp_s"]} for k, record in drive.sweeps.items()}
    unrecorded = RegisteredPair(
        drive.xyz1,
        drive.xyz2,
        drive.T_1_2,
        drive.sensor1,
        drive.sensor2,
        drive.attributes1,
        drive.attributes2,
        sweeps=stamps_only,
    )
    by_pair = apply_step(unrecorded, {"deskew": {}})
    for cloud in ("cloud1", "cloud2"):
        assert by_pair.fitted[cloud]["motion_source"] == "pair" and by_record.fitted[cloud]["motion_source"] == "record"
        assert np.allclose(by_pair.fitted[cloud]["velocity_mps"], [10, 0, 0], atol=1e-9)
        assert np.allclose(by_pair.fitted[cloud]["angular_velocity_rps"], 0, atol=1e-9)
    assert np.abs(by_pair.xyz1 - by_record.xyz1).max() < 1e-9 and np.abs(by_pair.xyz2 - by_record.xyz2).max() < 1e-9
    # settings come after a record: a scan's own record wins, unless they are asked for
    assert apply_step(drive, {"deskew": {"velocity_mps": [1, 0, 0]}}).fitted["cloud1"]["motion_source"] == "record"
    asked = apply_step(drive, {"deskew": {"velocity_mps": [1, 0, 0], "motion_source": "settings"}}).fitted["cloud1"]
    assert asked["motion_source"] == "settings" and asked["velocity_mps"] == [1, 0, 0]
    assert (
        apply_step(unrecorded, {"deskew": {"velocity_mps": [1, 0, 0]}}).fitted["cloud1"]["motion_source"] == "settings"
    )


def test_with_the_pose_it_undoes_the_shift_a_pose_fitted_on_the_skewed_scan_took():
    """Scan 2 taken at 10 m/s (1 m over its sweep), its pose fitted on the skewed scan
    (``realign``: measured 0.42 m and 0.66 deg off the truth). De-skewed alone it lands that far
    off (RMS magnitude 0.435 m; 0.587 m skewed); with its pose refitted it is the pair de-skewed
    at the true pose (0.132 m both) and the pose is the truth's to a millimetre. A still scan
    moves nothing, and no pose is fitted."""
    pair = register_pair(scan(0, 0.0037, 2, False), scan(0, 0, 1, True), "truth")
    realigned = apply_step(pair, {"realign": {}})
    fitted = replace(pair, xyz2=realigned.xyz2, T_1_2=realigned.T_1_2)
    assert np.abs(fitted.T_1_2[:3, 3] - pair.T_1_2[:3, 3]).max() > 0.3
    at_truth = apply_step(pair, {"deskew": {}})
    alone = apply_step(fitted, {"deskew": {}})
    joint = apply_step(fitted, {"deskew": {"with_pose": True}})
    assert np.abs(joint.T_1_2 - pair.T_1_2).max() < 0.002 and joint.fitted["parameters"] == 6
    assert abs(joint.fitted["pose"]["angle_deg"] - realigned.fitted["angle_deg"]) < 0.02
    truth_rms = _rms(replace(pair, xyz2=at_truth.xyz2))
    assert abs(_rms(replace(fitted, xyz2=joint.xyz2, T_1_2=joint.T_1_2)) - truth_rms) < 0.05 * truth_rms
    assert _rms(replace(fitted, xyz2=alone.xyz2)) > 2 * truth_rms
    still = register_pair(scan(0, 0, 1, False), scan(0, 0.0037, 2, False), "truth")
    outcome = apply_step(still, {"deskew": {"with_pose": True}})
    assert outcome.xyz1 is None and outcome.xyz2 is None and outcome.T_1_2 is None and "pose" not in outcome.fitted
