"""nuScenes v1.0 folders as sequences: a scene's LIDAR_TOP sweeps, posed by ego_pose @ calibrated_sensor."""

from __future__ import annotations

import json
import shutil
from fractions import Fraction

import numpy as np
import pytest

from helpers.nuscenes_layout import SCENES, VERSION, write_nuscenes_layout
from lidarfield import ConfigError
from lidarfield.datasets import read_dataset
from lidarfield.datasets.nuscenes import describe
from lidarfield.errors import InputError
from lidarfield.io import read_scan
from lidarfield.poses import invert_pose, pose_error
from lidarfield.study.config import validate_config


@pytest.fixture(scope="module")
def nuscenes_folder(tmp_path_factory):
    root = tmp_path_factory.mktemp("nuscenes") / "nuscenes"
    return root, write_nuscenes_layout(root)


def _dataset(root, scene="scene-0061", **more) -> dict:
    return {"format": "nuscenes", "path": str(root), "version": VERSION, "scene": scene, **more}


def _study(root, scene="scene-0061", **more):
    return validate_config({"sequences": {"n": {"dataset": _dataset(root, scene, **more)}}})


def test_a_scene_is_its_lidar_top_sweeps_in_time_order(nuscenes_folder):
    """Sweeps included: the ones before the scene's first key frame and after its last are its
    own (tied to its nearest sample); the other scene's and RADAR_FRONT's are not."""
    root, sweeps = nuscenes_folder
    for scene in SCENES:
        sequence = read_dataset(_dataset(root, scene))
        expected = [s for s in sweeps if s.scene == scene]
        assert [scan.path for scan in sequence.scans] == [str(root / s.filename) for s in expected]
        assert [scan.stamp_s for scan in sequence.scans] == pytest.approx([s.timestamp_us * 1e-6 for s in expected])
        assert all(scan.format == "nuscenes" for scan in sequence.scans) and sequence.sensor == "hdl32"
    scans = read_dataset(_dataset(root)).scans
    assert [scan.path.split("/")[-3] for scan in scans] == [
        "sweeps",
        "samples",
        "sweeps",
        "sweeps",
        "samples",
        "sweeps",
    ]
    assert all("LIDAR_TOP" in scan.path for scan in scans)
    assert np.all(np.diff([scan.stamp_s for scan in scans]) > 0)


def test_sweeps_false_keeps_the_key_frames(nuscenes_folder):
    root, sweeps = nuscenes_folder
    for scene in SCENES:
        sequence = read_dataset(_dataset(root, scene, sweeps=False))
        expected = [str(root / s.filename) for s in sweeps if s.scene == scene and s.key_frame]
        assert [scan.path for scan in sequence.scans] == expected and len(expected) == 2
        assert "key frames" in sequence.what


def test_the_poses_are_the_simulated_lidar_poses(nuscenes_folder):
    root, sweeps = nuscenes_folder
    for scene in SCENES:
        poses = np.array([scan.pose for scan in read_dataset(_dataset(root, scene)).scans])
        assert np.abs(poses - np.array([s.lidar_pose for s in sweeps if s.scene == scene])).max() < 1e-9


def test_ego_poses_taken_as_lidar_poses_would_turn_the_motion_sideways(nuscenes_folder):
    """The trap: the vehicle's poses used as the lidar's own (rotated -90 deg about z, 1.84 m
    up) put the forward motion on the lidar's y and register every pair wrongly."""
    _, sweeps = nuscenes_folder
    first, last = sweeps[0], sweeps[5]
    lidar = invert_pose(first.lidar_pose) @ last.lidar_pose
    ego = invert_pose(first.ego_pose) @ last.ego_pose
    assert abs(lidar[1, 3]) > 1.2 and abs(lidar[0, 3]) < 0.3  # 1.5 m forward: lidar y, ego x
    translation_error, _ = pose_error(ego, lidar)
    assert translation_error > 1.5


def test_a_study_registers_the_scene_by_truth_within_1e_9(nuscenes_folder):
    from lidarfield.commands.jobs import recorded_scan
    from lidarfield.registration import register_pair

    root, sweeps = nuscenes_folder
    study = _study(root)
    assert sorted(study.pairs) == [f"n-{k:03d}" for k in range(5)]
    lidar = [s.lidar_pose for s in sweeps if s.scene == "scene-0061"]
    for k in (0, 3):
        pair = study.pairs[f"n-{k:03d}"]
        registered = register_pair(recorded_scan(pair.scan1.spec), recorded_scan(pair.scan2.spec), pair.register)
        assert np.abs(registered.T_1_2 - invert_pose(lidar[k]) @ lidar[k + 1]).max() < 1e-9
    spec = study.pairs["n-000"].scan1.spec
    assert spec["sensor"] == "hdl32" and spec["format"] == "nuscenes"
    assert spec["stamp_s"] == pytest.approx(sweeps[0].timestamp_us * 1e-6)


def test_the_ingested_points_are_the_simulated_ones(nuscenes_folder):
    from lidarfield.commands.jobs import recorded_scan

    root, sweeps = nuscenes_folder
    study = _study(root, "scene-0103", sweeps=False)
    scan = recorded_scan(study.pairs["n-000"].scan2.spec)
    simulated = [s for s in sweeps if s.scene == "scene-0103" and s.key_frame][1]
    assert len(scan) == len(simulated.scan) > 10_000
    assert np.array_equal(scan.xyz, simulated.scan.xyz.astype(np.float32).astype(np.float64))
    assert np.abs(scan.xyz - simulated.scan.xyz).max() < 1e-5  # float32 of coordinates within 30 m
    assert scan.attributes["ring"].dtype == np.uint16
    assert np.array_equal(scan.attributes["ring"], simulated.scan.attributes["ring"])
    assert scan.attributes["ring"].max() == 31  # HDL-32E: rings 0..31
    assert np.array_equal(scan.attributes["intensity"], simulated.intensity)
    assert scan.sensor.name == "hdl32" and np.abs(scan.pose - simulated.lidar_pose).max() < 1e-9


def test_the_same_scans_as_files_with_lidar_poses_plan_the_same_jobs(nuscenes_folder, tmp_path):
    """A dataset sequence is the files-and-poses sequence it stands for (same specs, same ids)."""
    from lidarfield.io.pose_files import write_kitti_poses

    root, _ = nuscenes_folder
    dataset = read_dataset(_dataset(root))
    poses_file = tmp_path / "lidar_poses.txt"
    write_kitti_poses(poses_file, np.array([scan.pose for scan in dataset.scans]))
    files = [scan.path for scan in dataset.scans]
    as_dataset = _study(root)
    as_files = validate_config(
        {"sequences": {"n": {"scans": files, "poses": str(poses_file), "format": "nuscenes", "sensor": "hdl32"}}}
    )
    assert sorted(as_files.pairs) == sorted(as_dataset.pairs)
    for name in as_files.pairs:
        for k in ("scan1", "scan2"):
            a, b = getattr(as_dataset.pairs[name], k).spec, getattr(as_files.pairs[name], k).spec
            # beyond the files: the stamps, and each sweep's motion from its neighbours' poses
            assert a["sweep_motion"]["source"] == "neighbours" and "sweep_motion" not in b
            assert {**a, "stamp_s": None, "pose": None, "sweep_motion": None} == {
                **b,
                "stamp_s": None,
                "pose": None,
                "sweep_motion": None,
            }
            assert np.abs(np.array(a["pose"]) - np.array(b["pose"])).max() < 1e-12


def test_a_scans_time_is_its_microseconds_correctly_rounded(nuscenes_folder):
    """``us * 1e-6`` rounds twice (1e-6 is not a binary fraction): 1531883530150000 us gave
    1531883530.1499999 s, one unit in the last place (0.24 us) early."""
    root, sweeps = nuscenes_folder
    for scene in SCENES:
        stamps = [scan.stamp_s for scan in read_dataset(_dataset(root, scene)).scans]
        assert stamps == [float(Fraction(s.timestamp_us, 10**6)) for s in sweeps if s.scene == scene]


CITY = (1823.37, 2617.91, 12.6)  # where nuScenes' Boston and Singapore maps put their scenes


def test_at_city_coordinates_the_study_is_that_of_its_files_with_poses_converted_by_hand(tmp_path):
    """Every stage's statistics of a scene thousands of metres from the global origin equal
    (within 1e-9) those of its lidar files given with poses converted by hand from the tables
    (SciPy's quaternions, ego_pose @ calibrated_sensor): no precision lost in the poses, the
    times or the points, which the map's offset would magnify (float32 at 3 km: 0.24 mm)."""
    from helpers.datasets import assert_same_stage_statistics, stage_statistics
    from helpers.nuscenes_layout import pose
    from lidarfield.io.pose_files import write_kitti_poses

    root = tmp_path / "nuscenes"
    sweeps = [s for s in write_nuscenes_layout(root, CITY) if s.scene == "scene-0103"]
    tables = {name: json.loads((root / VERSION / f"{name}.json").read_text()) for name in ("sample_data", "ego_pose")}
    calibration = json.loads((root / VERSION / "calibrated_sensor.json").read_text())
    by_file = {r["filename"]: r for r in tables["sample_data"]}
    ego = {r["token"]: r for r in tables["ego_pose"]}
    lidar = {r["token"]: r for r in calibration}
    by_hand = []
    for sweep in sweeps:
        record = by_file[sweep.filename]
        e, c = ego[record["ego_pose_token"]], lidar[record["calibrated_sensor_token"]]
        by_hand.append(pose(e["translation"], e["rotation"]) @ pose(c["translation"], c["rotation"]))
    assert min(np.linalg.norm(T[:2, 3]) for T in by_hand) > 3000
    write_kitti_poses(tmp_path / "lidar_poses.txt", np.array(by_hand))
    stack = [{"ego_vehicle": {"radius_m": 3.0}}, {"field_of_view": {}}, {"shadow": {"origins": [1, 2]}}]
    files = {"scans": [str(root / s.filename) for s in sweeps], "poses": str(tmp_path / "lidar_poses.txt")}
    as_dataset = validate_config({"sequences": {"n": {"dataset": _dataset(root, "scene-0103")}}, "hypotheses": stack})
    as_files = validate_config(
        {"sequences": {"n": {**files, "format": "nuscenes", "sensor": "hdl32"}}, "hypotheses": stack}
    )
    for name in ("n-000", "n-002"):
        stages = stage_statistics(as_dataset, name)
        assert len(stages) == 4 and sum(s[0] + s[1] for s in stages) > 1000
        assert all(s[2]["field_energy"] > 0 for s in stages)
        assert_same_stage_statistics(stages, stage_statistics(as_files, name))


def test_a_relative_path_is_relative_to_the_study_folder(nuscenes_folder):
    root, sweeps = nuscenes_folder
    dataset = {"format": "nuscenes", "path": root.name, "version": VERSION, "scene": "scene-0061"}
    study = validate_config({"sequences": {"n": {"dataset": dataset}}}, base_dir=root.parent)
    assert study.pairs["n-000"].scan1.spec["path"] == f"{root.name}/{sweeps[0].filename}"


def test_without_a_version_the_only_version_folder_is_taken(nuscenes_folder):
    root, _ = nuscenes_folder
    dataset = {"format": "nuscenes", "path": str(root), "scene": "scene-0061"}
    assert len(read_dataset(dataset).scans) == 6


def test_an_unknown_scene_lists_the_scenes_there(nuscenes_folder):
    root, _ = nuscenes_folder
    with pytest.raises(ConfigError, match=r"no scene 'scene-61'.*scene\.json; its scenes: scene-0061, scene-0103"):
        _study(root, "scene-61")


def _edit(table: str, change):
    def edit(folder):
        path = folder / VERSION / f"{table}.json"
        rows = json.loads(path.read_text())
        change(rows)
        path.write_text(json.dumps(rows))

    return edit


def _lidar_record(rows, key_frame=True) -> dict:
    return next(r for r in rows if "LIDAR_TOP" in r["filename"] and r["is_key_frame"] == key_frame)


def _drop(rows, where):
    rows[:] = [r for r in rows if not where(r)]


@pytest.mark.parametrize(
    ("change", "file", "message"),
    [
        (lambda f: shutil.rmtree(f / VERSION), "nuscenes", "no version folder 'v1.0-mini'; its versions: none"),
        (lambda f: (f / VERSION / "ego_pose.json").unlink(), "ego_pose.json", "nuScenes table not found"),
        (lambda f: (f / VERSION / "sample_data.json").write_text("[{"), "sample_data.json", "not a JSON table"),
        (lambda f: (f / VERSION / "scene.json").write_text("{}"), "scene.json", "a JSON list of records"),
        (_edit("sample_data", lambda rows: _lidar_record(rows).pop("timestamp")), "sample_data.json", "'timestamp'"),
        (
            _edit("sample_data", lambda rows: _lidar_record(rows).update(timestamp="1531883530100000")),
            "sample_data.json",
            "a timestamp (integer, us) and a filename expected",
        ),
        (
            _edit("sensor", lambda rows: _drop(rows, lambda r: r["channel"] == "LIDAR_TOP")),
            "sensor.json",
            "no sensor of channel LIDAR_TOP",
        ),
        (
            _edit("calibrated_sensor", lambda rows: rows[0].update(rotation=[0.0, 0.0, 0.0, 0.0])),
            "calibrated_sensor.json",
            "not a unit quaternion",
        ),
        (
            _edit("ego_pose", lambda rows: _drop(rows, lambda r: r["timestamp"] % 100_000 == 50_000)),
            "ego_pose.json",
            "ego pose(s) the lidar sample_data refer to are missing",
        ),
        (
            _edit("ego_pose", lambda rows: [r.update(translation=[1.0, 2.0]) for r in rows]),
            "ego_pose.json",
            "translation [x, y, z] and rotation [w, x, y, z] expected",
        ),
        (
            _edit("sample", lambda rows: _drop(rows, lambda r: r["timestamp"] % 1_000_000 == 600_000)),
            "sample_data.json",
            "not in sample.json",
        ),
        (lambda f: shutil.rmtree(f / "sweeps"), "sweeps/LIDAR_TOP", "4 of the 6 lidar files of scene-0061 not found"),
        (lambda f: shutil.rmtree(f / "samples" / "LIDAR_TOP"), "samples/LIDAR_TOP", "2 of the 6 lidar files"),
    ],
)
def test_a_broken_layout_names_the_file_and_the_problem(nuscenes_folder, tmp_path, change, file, message):
    root = tmp_path / "nuscenes"
    shutil.copytree(nuscenes_folder[0], root)
    change(root)
    with pytest.raises(ConfigError) as caught:
        _study(root)
    text = str(caught.value)
    assert str(root) in text and file in text and message in text, text
    assert "\n" not in text


def test_missing_sweeps_say_that_the_key_frames_read_alone(nuscenes_folder, tmp_path):
    root = tmp_path / "nuscenes"
    shutil.copytree(nuscenes_folder[0], root)
    shutil.rmtree(root / "sweeps")
    with pytest.raises(ConfigError, match="use sweeps: false for the key frames only"):
        _study(root)
    assert len(_study(root, sweeps=False).pairs) == 1


def test_planning_reads_no_lidar_file(nuscenes_folder, tmp_path):
    """The index is the tables: lidar files that would not read still plan (their jobs fail)."""
    root = tmp_path / "nuscenes"
    shutil.copytree(nuscenes_folder[0], root)
    for path in (root / "sweeps" / "LIDAR_TOP").iterdir():
        path.write_bytes(b"not a scan")
    assert len(_study(root).pairs) == 5


@pytest.mark.parametrize(
    ("content", "words"),
    [
        (np.zeros(7, dtype="<f4").tobytes(), ["size 28 bytes", "20-byte rows"]),
        (b"", ["empty scan"]),
        (np.full((3, 5), np.nan, dtype="<f4").tobytes(), ["empty scan", "all 3 rows"]),
        (np.array([[1, 2, 3, 4, -1.0]], dtype="<f4").tobytes(), ["ring", "not a nuScenes lidar file"]),
    ],
)
def test_a_bad_lidar_file_names_itself(tmp_path, content, words):
    path = tmp_path / "n015__LIDAR_TOP__1531883530050000.pcd.bin"
    path.write_bytes(content)
    with pytest.raises(InputError) as caught:
        read_scan(path, format="nuscenes")
    assert str(path) in str(caught.value) and all(word in str(caught.value) for word in words), str(caught.value)


def test_rows_with_nan_coordinates_are_dropped_and_counted(tmp_path):
    path = tmp_path / "sweep.pcd.bin"
    rows = np.array([[1, 2, 3, 10, 5], [np.nan, 0, 0, 0, np.nan], [4, 5, 6, 20, 7]], dtype="<f4")
    rows.tofile(path)
    scan = read_scan(path, format="nuscenes")
    assert scan.xyz.tolist() == [[1, 2, 3], [4, 5, 6]] and scan.dropped_invalid == 1
    assert scan.attributes["ring"].tolist() == [5, 7] and scan.attributes["intensity"].tolist() == [10, 20]


def test_info_describes_the_folder(nuscenes_folder):
    root, _ = nuscenes_folder
    assert describe(root) == f"{root}: nuScenes dataset\n  {VERSION}: 2 scenes, 4 key frames: scene-0061, scene-0103"
    assert describe(root / VERSION) is None and describe(root / "samples") is None


def test_big_tables_decoded_in_pieces_give_the_same_scans(nuscenes_folder, monkeypatch):
    from lidarfield.datasets import nuscenes

    root, sweeps = nuscenes_folder
    whole = read_dataset(_dataset(root, "scene-0103"))
    monkeypatch.setattr(nuscenes, "_PIECE", 300)  # every table but sensor.json is 'big'
    decoded, load_in_pieces = [], nuscenes._load_in_pieces
    monkeypatch.setattr(nuscenes, "_load_in_pieces", lambda *a: decoded.append(load_in_pieces(*a)) or decoded[-1])
    nuscenes._cached_index.cache_clear()
    pieces = read_dataset(_dataset(root, "scene-0103"))
    nuscenes._cached_index.cache_clear()
    assert len(decoded) == 2 and all(rows for rows in decoded)  # sample_data and ego_pose, in pieces
    assert pieces == whole and len(pieces.scans) == 4


@pytest.mark.parametrize(
    "rows",
    [
        [{"token": f"t{k}", "name": "}{" * k, "n": [k, k + 1]} for k in range(40)],  # braces in strings
        [{"token": f"t{k}", "nested": {"k": {"deeper": k}}} for k in range(40)],  # nested objects
    ],
)
def test_pieces_that_do_not_decode_fall_back_to_the_whole_table(tmp_path, monkeypatch, rows):
    from lidarfield.datasets import nuscenes

    monkeypatch.setattr(nuscenes, "_PIECE", 64)
    path = tmp_path / "table.json"
    path.write_text(json.dumps(rows, indent=1))
    kept = nuscenes._load(path, lambda r: None if "token" in r and not r["token"].endswith("7") else r)
    assert kept == [r for r in rows if r["token"].endswith("7")]
    path.write_text(json.dumps(rows)[:-40])
    with pytest.raises(ConfigError, match="table.json: dataset: not a JSON table"):
        nuscenes._load(path, lambda r: r)
