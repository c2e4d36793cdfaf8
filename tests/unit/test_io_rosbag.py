"""ROS bags written with rosbags' own writers from the real scans, read back point for point."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from lidarfield.errors import InputError
from lidarfield.io import read_scan, scan_count
from lidarfield.io.rosbag.pointcloud2 import PointField, decode_cloud
from lidarfield.io.rosbag.writer import CloudMessage, write_bag
from lidarfield.poses import pose_from_xyzrpy
from lidarfield.scan import Scan

pytest.importorskip("rosbags")

RINGS = 16  # the ExpD text files: ring-major 16 x ~1810 firings, NaN = no return


def organised_expd(path) -> Scan:
    """An ExpD scan with its no-return rows kept (NaN) and the ring of each row."""
    xyz = np.loadtxt(path)
    return Scan(xyz, {"ring": np.repeat(np.arange(RINGS, dtype=np.uint16), len(xyz) // RINGS)})


def as_float32(xyz: np.ndarray) -> np.ndarray:
    return xyz.astype(np.float32).astype(np.float64)


@pytest.fixture(scope="module")
def organised_expd_scans(expd):
    """ExpD's Cloud1 and Cloud10 with their no-return rows kept (NaN) and the ring of each row."""
    return [organised_expd(expd / name) for name in ("Cloud1_ExpD.txt", "Cloud10_ExpD.txt")]


def bag_path(tmp_path, storage):
    return tmp_path / ("drive.bag" if storage == "ros1" else f"drive_{storage}")


@pytest.mark.parametrize("storage", ["ros1", "sqlite3", "mcap"])
def test_velodyne_layout_round_trip_in_every_storage(tmp_path, organised_expd_scans, storage):
    clouds = [CloudMessage(scan, 1000.0 + 0.9 * k) for k, scan in enumerate(organised_expd_scans)]
    path = write_bag(bag_path(tmp_path, storage), clouds, storage=storage, layout="velodyne")
    references = [path] + ([path / f"{path.name}.mcap"] if storage == "mcap" else [])  # folder and bare .mcap
    for reference in references:
        assert scan_count(reference) == 2
        for k, original in enumerate(organised_expd_scans):
            scan = read_scan(f"{reference}#{k}")
            valid = np.isfinite(original.xyz).all(axis=1)
            np.testing.assert_array_equal(scan.xyz, as_float32(original.xyz[valid]))
            np.testing.assert_array_equal(scan.attributes["ring"], original.attributes["ring"][valid])
            assert scan.dropped_invalid == int((~valid).sum())
            assert scan.stamp_s == pytest.approx(1000.0 + 0.9 * k, abs=1e-9)
            assert scan.source == f"{reference}#/points#{k}"


def test_ouster_48_byte_layout_of_a_real_ouster_scan(tmp_path, shared_data):
    decoded = np.fromfile(shared_data / "ouster-os1-128" / "lb_n3_scan0_xyz_refl_float32.bin", dtype="<f4").reshape(
        -1, 4
    )
    time = np.linspace(0.0, 0.099, len(decoded))  # seconds since the scan began
    scan = Scan(decoded[:, :3], {"intensity": decoded[:, 3], "time": time})
    path = write_bag(tmp_path / "os.bag", [CloudMessage(scan, 5.0)], layout="ouster")
    back = read_scan(path)
    np.testing.assert_array_equal(back.xyz, decoded[:, :3].astype(np.float64))
    np.testing.assert_array_equal(back.attributes["intensity"], decoded[:, 3])
    np.testing.assert_allclose(back.attributes["time"], time, atol=0.6e-9)  # t: integer ns
    assert {"reflectivity", "ring", "ambient", "range"} <= set(back.attributes)


def test_organised_cloud_keeps_row_order_and_drops_nan_rows(tmp_path, expd, organised_expd_scans):
    cloud = CloudMessage(organised_expd_scans[0], 3.0, shape=(RINGS, 1810))
    back = read_scan(write_bag(tmp_path / "org.bag", [cloud]))
    plain = read_scan(expd / "Cloud1_ExpD.txt")  # the text reader: same rows, same order
    np.testing.assert_array_equal(back.xyz, as_float32(plain.xyz))
    assert back.dropped_invalid == plain.dropped_invalid == 16054


def test_big_endian_cloud_reads_as_the_little_endian_one(tmp_path, organised_expd_scans):
    clouds = [CloudMessage(organised_expd_scans[1], 2.0)]
    little = read_scan(write_bag(tmp_path / "le.bag", clouds))
    big = read_scan(write_bag(tmp_path / "be.bag", clouds, big_endian=True))
    np.testing.assert_array_equal(big.xyz, little.xyz)
    for name in ("intensity", "ring", "time"):
        np.testing.assert_array_equal(big.attributes[name], little.attributes[name])
        assert big.attributes[name].dtype.isnative


def reference_decode(fields, height, width, point_step, row_step, big_endian, data):
    """Point by point with struct: the plain reference of decode_cloud."""
    codes = {1: "b", 2: "B", 3: "h", 4: "H", 5: "i", 6: "I", 7: "f", 8: "d"}
    order = ">" if big_endian else "<"
    rows = []
    for r in range(height):
        for c in range(width):
            start = r * row_step + c * point_step
            rows.append(
                {
                    f.name: struct.unpack_from(order + codes[f.datatype], data, start + f.offset)[0]
                    for f in fields
                    if f.count == 1
                }
            )
    return rows


@pytest.mark.parametrize("big_endian", [False, True])
def test_decoder_matches_a_struct_reference_for_every_datatype(big_endian):
    rng = np.random.default_rng(3)
    fields = [
        PointField("x", 0, 7),
        PointField("y", 4, 7),
        PointField("z", 8, 8),
        PointField("i8", 16, 1),
        PointField("u8", 17, 2),
        PointField("i16", 18, 3),
        PointField("u16", 20, 4),
        PointField("i32", 24, 5),
        PointField("rgb3", 28, 2, 3),
        PointField("u32", 32, 6),
        PointField("f64", 40, 8),
    ]
    height, width, point_step = 3, 5, 52  # 4 bytes of padding after each point
    row_step = width * point_step + 7  # and 7 at the end of each row
    data = rng.integers(0, 256, height * row_step, dtype=np.uint8).tobytes()
    xyz, attributes = decode_cloud(fields, height, width, point_step, row_step, big_endian, data)
    expected = reference_decode(fields, height, width, point_step, row_step, big_endian, data)
    assert "rgb3" not in attributes  # an array field is not a scalar attribute
    for axis, column in zip("xyz", xyz.T):
        np.testing.assert_array_equal(column, [p[axis] for p in expected])
    for name, values in attributes.items():
        np.testing.assert_array_equal(values, [p[name] for p in expected])


def drive(t):
    """The sensor's pose at time t: 2 m/s along x, 0.5 rad/s yaw, climbing 0.1 m/s."""
    return pose_from_xyzrpy([2.0 * t, 0.0, 0.1 * t, 0.0, 0.0, 0.5 * t])


@pytest.mark.parametrize(
    "storage, pose_type",
    [
        ("ros1", "nav_msgs/msg/Odometry"),
        ("sqlite3", "geometry_msgs/msg/PoseStamped"),
        ("mcap", "geometry_msgs/msg/PoseWithCovarianceStamped"),
        ("ros1", "tf2_msgs/msg/TFMessage"),
    ],
)
def test_poses_from_a_topic_at_another_rate_are_interpolated(tmp_path, organised_expd_scans, storage, pose_type):
    # Scans at 10 Hz from t = 0.05 s, poses at 7 Hz: no scan stamp falls on a pose stamp.
    stamps = [0.05 + 0.1 * k for k in range(2)]
    clouds = [CloudMessage(scan, 100.0 + t) for scan, t in zip(organised_expd_scans, stamps)]
    poses = [(100.0 + k / 7, drive(k / 7)) for k in range(4)]
    topic = "/tf" if pose_type.startswith("tf2") else "/odom"
    path = write_bag(
        bag_path(tmp_path, storage), clouds, storage=storage, poses=poses, pose_topic=topic, pose_type=pose_type
    )
    source = {"topic": topic, **({"frame": "lidar"} if topic == "/tf" else {})}
    for k, t in enumerate(stamps):
        pose = read_scan(f"{path}#{k}", poses=source).pose
        # Linear in translation is exact for this drive; slerp about z is exact for a constant yaw rate.
        np.testing.assert_allclose(pose, drive(t), atol=1e-9)


def test_scan_outside_the_pose_messages_span_is_an_error(tmp_path, organised_expd_scans):
    poses = [(10.0 + 0.1 * k, drive(0.1 * k)) for k in range(5)]
    path = write_bag(
        tmp_path / "late.bag",
        [CloudMessage(organised_expd_scans[0], 10.2), CloudMessage(organised_expd_scans[1], 11.0)],
        poses=poses,
    )
    assert read_scan(f"{path}#0", poses={"topic": "/odom"}).pose is not None
    with pytest.raises(
        InputError, match=r"late.bag: scan stamp 11.000000 s lies outside .* /odom \(10.000000 .. 10.400000 s\)"
    ):
        read_scan(f"{path}#1", poses={"topic": "/odom"})


def test_tf_needs_an_existing_child_frame(tmp_path, organised_expd_scans):
    poses = [(0.1 * k, drive(0.1 * k)) for k in range(3)]
    path = write_bag(
        tmp_path / "tf.bag",
        [CloudMessage(organised_expd_scans[0], 0.1)],
        poses=poses,
        pose_topic="/tf",
        pose_type="tf2_msgs/msg/TFMessage",
    )
    with pytest.raises(InputError, match="child frame"):
        read_scan(path, poses={"topic": "/tf"})
    with pytest.raises(InputError, match=r"no transform on /tf has child frame 'velodyne'; child frames: lidar"):
        read_scan(path, poses={"topic": "/tf", "frame": "velodyne"})


def test_several_cloud_topics_need_the_topic(tmp_path, organised_expd_scans):
    clouds = [
        CloudMessage(organised_expd_scans[0], 1.0, topic="/front"),
        CloudMessage(organised_expd_scans[1], 1.05, topic="/rear"),
    ]
    path = write_bag(tmp_path / "two.bag", clouds)
    with pytest.raises(
        InputError,
        match=r"two.bag: the bag holds 2 PointCloud2 topics: name one \(.*two.bag#/TOPIC#k, or topic: in a "
        r"sequence\); topics: /front .*, /rear",
    ):
        read_scan(f"{path}#0")
    assert scan_count(f"{path}#/rear") == 1
    np.testing.assert_array_equal(read_scan(f"{path}#/rear#0").xyz, read_scan(f"{path}#/rear").xyz)
    assert len(read_scan(f"{path}#/rear")) == int(np.isfinite(organised_expd_scans[1].xyz).all(axis=1).sum())
    with pytest.raises(
        InputError, match=r"topic /side is not in the bag; its topics: /front \(sensor_msgs/PointCloud2, 1\), /rear"
    ):
        read_scan(f"{path}#/side#0")


def test_bag_without_pointcloud2(tmp_path):
    path = write_bag(tmp_path / "odom.bag", [], poses=[(1.0, np.eye(4))])
    with pytest.raises(
        InputError,
        match=r"odom.bag: the bag holds no sensor_msgs/PointCloud2 topic; its topics: /odom \(nav_msgs/Odometry, 1\)",
    ):
        scan_count(path)


@pytest.mark.parametrize("storage", ["ros1", "mcap"])
def test_truncated_bag_is_one_error_naming_it(tmp_path, organised_expd_scans, storage):
    path = write_bag(
        bag_path(tmp_path, storage),
        [CloudMessage(s, 1.0 + k) for k, s in enumerate(organised_expd_scans)],
        storage=storage,
    )
    file = path if storage == "ros1" else path / f"{path.name}.mcap"
    data = file.read_bytes()
    file.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match=str(path.name)) as error:
        read_scan(f"{path}#1")
    assert "\n" not in str(error.value)


# A drive whose sensor frame is rolled and yawed against the world: 8 m/s along world x and y,
# turning 0.3 rad/s about its own z. Odometry's twist is in that (child) frame.
START = pose_from_xyzrpy([5.0, -3.0, 2.0, 0.4, 0.0, 1.2])
WORLD_VELOCITY = np.array([6.0, 5.0, 0.3])
ANGULAR_VELOCITY = np.array([0.0, 0.05, 0.3])


def turning(t):
    from lidarfield.simulation.trajectory import moved_pose

    return moved_pose(START, t, WORLD_VELOCITY, ANGULAR_VELOCITY)


def twist_at(t):
    """The drive's (linear, angular) velocity at t in its sensor frame, as Odometry publishes it."""
    return turning(t)[:3, :3].T @ WORLD_VELOCITY, ANGULAR_VELOCITY


def turning_bag(path, scans, pose_type="nav_msgs/msg/Odometry", zero_twist=False):
    """Scans at 100.07 and 100.17 s (timed by azimuth over a 0.1 s sweep), odometry at 20 Hz."""
    clouds = []
    for scan, stamp in zip(scans, (100.07, 100.17)):
        valid = np.isfinite(scan.xyz).all(axis=1)
        azimuth = np.mod(np.arctan2(scan.xyz[valid, 1], scan.xyz[valid, 0]), 2 * np.pi)
        clouds.append(CloudMessage(Scan(scan.xyz[valid], {"time": azimuth / (2 * np.pi) * 0.1}), stamp))
    stamps = 100.0 + 0.05 * np.arange(6)
    twists = [((0, 0, 0), (0, 0, 0)) if zero_twist else twist_at(t - 100.0) for t in stamps]
    topic = "/tf" if pose_type.startswith("tf2") else "/odom"
    poses = [(t, turning(t - 100.0)) for t in stamps]
    path = write_bag(path, clouds, poses=poses, twists=twists, pose_topic=topic, pose_type=pose_type)
    return path, {"topic": topic, **({"frame": "lidar"} if topic == "/tf" else {})}


def test_a_scan_posed_by_odometry_records_the_twist_nearest_its_stamp(tmp_path, organised_expd_scans):
    path, source = turning_bag(tmp_path / "turn.bag", organised_expd_scans)
    for k, nearest in enumerate((100.05, 100.15)):
        scan = read_scan(f"{path}#{k}", poses=source)
        linear, angular = twist_at(nearest - 100.0)
        np.testing.assert_allclose(scan.sweep_motion["velocity_mps"], linear, rtol=0, atol=1e-12)
        np.testing.assert_allclose(scan.sweep_motion["angular_velocity_rps"], angular, rtol=0, atol=1e-12)
        assert scan.sweep_motion["source"] == "odometry"
        # in the sensor's frame, not the world's: turned by the scan's pose it is the drive's velocity
        rotation = turning(nearest - 100.0)[:3, :3]
        assert np.abs(linear - WORLD_VELOCITY).max() > 1.0
        np.testing.assert_allclose(rotation @ scan.sweep_motion["velocity_mps"], WORLD_VELOCITY, atol=1e-9)


@pytest.mark.parametrize("pose_type", ["geometry_msgs/msg/PoseStamped", "tf2_msgs/msg/TFMessage", "zero twist"])
def test_no_twist_no_record(tmp_path, organised_expd_scans, pose_type):
    zero = pose_type == "zero twist"
    kind = "nav_msgs/msg/Odometry" if zero else pose_type
    path, source = turning_bag(tmp_path / "still.bag", organised_expd_scans, kind, zero_twist=zero)
    scan = read_scan(f"{path}#0", poses=source)
    assert scan.pose is not None and scan.sweep_motion is None


def test_deskew_takes_the_odometry_twist_as_the_same_motion_given_in_settings(tmp_path, organised_expd_scans):
    from lidarfield.hypotheses import apply_step
    from lidarfield.registration import register_pair

    path, source = turning_bag(tmp_path / "turn.bag", organised_expd_scans)
    pair = register_pair(*(read_scan(f"{path}#{k}", poses=source) for k in range(2)), "truth")
    for cloud, nearest in ((1, 100.05), (2, 100.15)):
        linear, angular = twist_at(nearest - 100.0)
        recorded = apply_step(pair, {"deskew": {"cloud": cloud}})
        given = apply_step(
            pair,
            {
                "deskew": {
                    "cloud": cloud,
                    "motion_source": "settings",
                    "velocity_mps": linear.tolist(),
                    "angular_velocity_rps": angular.tolist(),
                }
            },
        )
        assert recorded.fitted[f"cloud{cloud}"]["motion_source"] == "odometry"
        moved, expected = getattr(recorded, f"xyz{cloud}"), getattr(given, f"xyz{cloud}")
        assert np.abs(moved - expected).max() < 1e-9
        original = pair.xyz1 if cloud == 1 else pair.xyz2
        assert np.linalg.norm(moved - original, axis=1).max() > 0.5  # 0.1 s at 8 m/s, turning
