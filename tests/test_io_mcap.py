"""MCAP reading (ROS 2 CDR, foxglove JSON and protobuf, occtool's own channel) and writing.

Fixtures are written here with the real writers (mcap_ros2, mcap, mcap_protobuf).
"""

from __future__ import annotations

import base64
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from mcap.writer import Writer as McapWriter
from mcap_ros2.writer import Writer as Ros2Writer

from occtool.errors import InputError
from occtool.features import Features, Pose, Position, RangeLog
from occtool.io import describe_log, detect_format, read_log, write_csv, write_mcap

SEP = "=" * 80 + "\n"
HEADER_DEFS = (
    SEP + "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
    + SEP + "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
)
GEOMETRY_DEFS = (
    SEP + "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
    + SEP + "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
)
POINTCLOUD2_DEF = (
    "std_msgs/Header header\nuint32 height\nuint32 width\nsensor_msgs/PointField[] fields\n"
    "bool is_bigendian\nuint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n"
    + HEADER_DEFS
    + SEP + "MSG: sensor_msgs/PointField\nuint8 INT8=1\nuint8 UINT8=2\nuint8 INT16=3\nuint8 UINT16=4\n"
    "uint8 INT32=5\nuint8 UINT32=6\nuint8 FLOAT32=7\nuint8 FLOAT64=8\n"
    "string name\nuint32 offset\nuint8 datatype\nuint32 count\n"
)
LASERSCAN_DEF = (
    "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n"
    "float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n"
    "float32[] ranges\nfloat32[] intensities\n" + HEADER_DEFS
)
TF_DEF = (
    "geometry_msgs/TransformStamped[] transforms\n"
    + SEP + "MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\n"
    "geometry_msgs/Transform transform\n"
    + SEP + "MSG: geometry_msgs/Transform\ngeometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n"
    + GEOMETRY_DEFS + HEADER_DEFS
)
ODOMETRY_DEF = (
    "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n"
    "geometry_msgs/TwistWithCovariance twist\n"
    + SEP + "MSG: geometry_msgs/PoseWithCovariance\ngeometry_msgs/Pose pose\nfloat64[36] covariance\n"
    + SEP + "MSG: geometry_msgs/Pose\ngeometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n"
    + SEP + "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n"
    + SEP + "MSG: geometry_msgs/TwistWithCovariance\ngeometry_msgs/Twist twist\nfloat64[36] covariance\n"
    + SEP + "MSG: geometry_msgs/Twist\ngeometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n"
    + GEOMETRY_DEFS + HEADER_DEFS
)


def header(t: float, frame: str) -> dict:
    return {"stamp": {"sec": int(t), "nanosec": int(round((t - int(t)) * 1e9))}, "frame_id": frame}


def quaternion(yaw: float) -> dict:
    return {"x": 0.0, "y": 0.0, "z": float(np.sin(yaw / 2)), "w": float(np.cos(yaw / 2))}


def transform(t: float, parent: str, child: str, xyz=(0.0, 0.0, 0.0), yaw: float = 0.0) -> dict:
    return {
        "header": header(t, parent),
        "child_frame_id": child,
        "transform": {"translation": dict(zip("xyz", map(float, xyz))), "rotation": quaternion(yaw)},
    }


def pointcloud2(t: float, frame: str, columns: dict[str, np.ndarray], dtypes: dict[str, str], pad: int = 0) -> dict:
    """A PointCloud2 message with the given fields packed in the given order, plus padding."""
    codes = {"f4": 7, "f8": 8, "u1": 2, "i4": 5}
    fields, offset = [], 0
    for name in columns:
        fields.append({"name": name, "offset": offset, "datatype": codes[dtypes[name]], "count": 1})
        offset += np.dtype(dtypes[name]).itemsize
    step = offset + pad
    dtype = np.dtype({"names": list(columns), "formats": ["<" + dtypes[n] for n in columns],
                      "offsets": [f["offset"] for f in fields], "itemsize": step})
    n = len(next(iter(columns.values())))
    records = np.zeros(n, dtype=dtype)
    for name, values in columns.items():
        records[name] = values
    return {
        "header": header(t, frame), "height": 1, "width": n, "fields": fields, "is_bigendian": False,
        "point_step": step, "row_step": step * n, "data": records.tobytes(), "is_dense": False,
    }


def laserscan(t: float, frame: str, ranges, *, angle_min=-1.0, increment=0.5, range_min=0.1, range_max=10.0,
              intensities=()) -> dict:
    return {
        "header": header(t, frame), "angle_min": angle_min, "angle_max": angle_min + increment * (len(ranges) - 1),
        "angle_increment": increment, "time_increment": 0.0, "scan_time": 0.1, "range_min": range_min,
        "range_max": range_max, "ranges": [float(r) for r in ranges], "intensities": [float(i) for i in intensities],
    }


def write_ros2(path: Path, messages: list[tuple[str, str, dict, float]]) -> Path:
    """Write (topic, type, message, time) tuples with the real ROS 2 writer."""
    definitions = {
        "sensor_msgs/msg/PointCloud2": POINTCLOUD2_DEF, "sensor_msgs/msg/LaserScan": LASERSCAN_DEF,
        "tf2_msgs/msg/TFMessage": TF_DEF, "nav_msgs/msg/Odometry": ODOMETRY_DEF,
    }
    with open(path, "wb") as handle:
        writer = Ros2Writer(handle)
        schemas = {}
        for k, (topic, kind, message, t) in enumerate(messages):
            if kind not in schemas:
                schemas[kind] = writer.register_msgdef(kind, definitions[kind])
            writer.write_message(topic, schemas[kind], message, log_time=int(t * 1e9), publish_time=int(t * 1e9), sequence=k)
        writer.finish()
    return path


def test_pointcloud2_fields_are_read_from_the_message_layout(tmp_path):
    # Evidence first, an extra intensity field, float64 z and 3 padding bytes: no fixed offsets.
    columns = {
        "evidence": np.array([0.2, 0.4, 0.6, 0.8]),
        "x": np.array([1.0, np.nan, 2.0, 0.5]),
        "intensity": np.array([5, 6, 7, 8]),
        "y": np.array([0.0, 1.0, -1.0, 0.25]),
        "z": np.array([-0.5, 0.0, 0.125, 3.0]),
    }
    dtypes = {"evidence": "f4", "x": "f4", "intensity": "u1", "y": "f4", "z": "f8"}
    path = write_ros2(tmp_path / "cloud.mcap", [("/points", "sensor_msgs/msg/PointCloud2",
                                                  pointcloud2(1.0, "base_link", columns, dtypes, pad=3), 1.0)])
    assert detect_format(path) == "mcap"
    log = read_log(path)
    features = log.single().features
    # The NaN point is dropped as no return.
    np.testing.assert_allclose(features.points, [[1.0, 0.0, -0.5], [2.0, -1.0, 0.125], [0.5, 0.25, 3.0]])
    np.testing.assert_allclose(features.evidence, np.float32([0.2, 0.6, 0.8]))
    assert any("NaN" in note for note in log.notes)
    # Without an evidence field by that name, a constant is used.
    constant = read_log(path, evidence_field="quality", evidence=0.3).single().features
    np.testing.assert_array_equal(constant.evidence, [0.3, 0.3, 0.3])
    # Raw intensities 5..8 are no evidence values: an error, or nothing left when skipped.
    with pytest.raises(InputError, match="evidence value 5"):
        read_log(path, evidence_field="intensity")
    with pytest.raises(InputError, match="hold no valid points"):
        read_log(path, evidence_field="intensity", skip_invalid=True)


def test_pointcloud2_evidence_outside_the_unit_interval_is_an_error_unless_skipped(tmp_path):
    columns = {"x": np.array([1.0, 2.0]), "y": np.array([0.0, 0.0]), "z": np.array([0.0, 0.0]),
               "evidence": np.array([0.5, 1.5])}
    path = write_ros2(tmp_path / "cloud.mcap", [("/points", "sensor_msgs/msg/PointCloud2",
                                                  pointcloud2(1.0, "base_link", columns, dict.fromkeys(columns, "f4")), 1.0)])
    with pytest.raises(InputError, match=r"topic /points.*evidence value 1\.5"):
        read_log(path)
    log = read_log(path, skip_invalid=True)
    np.testing.assert_array_equal(log.single().features.points, [[1.0, 0.0, 0.0]])
    assert any("skipped 1 point" in note for note in log.notes)


def test_laserscan_keeps_valid_beams_in_the_scan_plane(tmp_path):
    ranges = [1.0, 0.05, np.inf, 2.0, 11.0, np.nan, 3.0]
    path = write_ros2(tmp_path / "scan.mcap", [("/scan", "sensor_msgs/msg/LaserScan", laserscan(2.0, "base_link", ranges), 2.0)])
    log = read_log(path)
    features = log.single().features
    angles = -1.0 + 0.5 * np.array([0, 3, 6])
    r = np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(features.points, np.column_stack([r * np.cos(angles), r * np.sin(angles), np.zeros(3)]), atol=1e-6)
    np.testing.assert_array_equal(features.evidence, [0.9, 0.9, 0.9])
    assert log.single().stamp == pytest.approx(2.0)


def test_laserscan_evidence_from_intensities_when_asked(tmp_path):
    path = write_ros2(tmp_path / "scan.mcap", [("/scan", "sensor_msgs/msg/LaserScan",
                                                 laserscan(0.5, "base_link", [1.0, 2.0, 3.0], intensities=[50, 100, 200]), 0.5)])
    np.testing.assert_allclose(read_log(path, use_intensities=True).single().features.evidence, [0.25, 0.5, 1.0])
    with pytest.raises(InputError, match="intensities"):
        read_log(write_ros2(tmp_path / "plain.mcap", [("/scan", "sensor_msgs/msg/LaserScan",
                                                         laserscan(0.5, "base_link", [1.0]), 0.5)]), use_intensities=True)


def test_static_mounting_and_odometry_poses_make_positions(tmp_path):
    # The laser is mounted 0.2 m ahead of base_link, turned 90 degrees to the left. The robot
    # takes two scans at the origin, then one 2 m ahead facing +y.
    tf_static = {"transforms": [transform(0.0, "base_link", "laser", (0.2, 0.0, 0.3), np.pi / 2)]}
    messages = [("/tf_static", "tf2_msgs/msg/TFMessage", tf_static, 0.0)]
    for t, (x, yaw) in zip([1.0, 2.0, 3.0], [(0.0, 0.0), (0.05, 0.0), (2.0, np.pi / 2)]):
        messages.append(("/tf", "tf2_msgs/msg/TFMessage", {"transforms": [transform(t, "odom", "base_link", (x, 0, 0), yaw)]}, t))
        messages.append(("/scan", "sensor_msgs/msg/LaserScan", laserscan(t + 0.01, "laser", [1.0], angle_min=0.0), t + 0.01))
    path = write_ros2(tmp_path / "robot.mcap", messages)
    log = read_log(path)
    assert len(log.positions) == 2
    first, second = log.positions
    # Beam at angle 0 of the laser points along base_link's +y: one point per scan.
    assert len(first.features) == 2
    np.testing.assert_allclose(first.features.points[0], [0.0, 1.0, 0.0], atol=1e-9)
    # The second scan was taken 0.05 m further ahead: seen from the first, its point is 0.05 m ahead.
    np.testing.assert_allclose(first.features.points[1], [0.05, 1.0, 0.0], atol=1e-9)
    # The position's pose is the sensor's: base pose moved by the mounting offset.
    assert first.pose == pytest.approx(Pose(0.2, 0.0, 0.3, 0.0)) or (
        (first.pose.x, first.pose.y, first.pose.z, first.pose.yaw) == pytest.approx((0.2, 0.0, 0.3, 0.0))
    )
    assert (second.pose.x, second.pose.y, second.pose.yaw) == pytest.approx((2.0, 0.2, np.pi / 2))
    # Overriding the frames: with the base frame as sensor frame nothing is rotated.
    plain = read_log(path, sensor_frame="base_link")
    np.testing.assert_allclose(plain.positions[0].features.points[0], [1.0, 0.0, 0.0], atol=1e-9)
    assert len(read_log(path, group_by="message").positions) == 3
    assert len(read_log(path, position_tolerance=(0.01, 0.26)).positions) == 3


def test_odometry_gives_poses_when_there_is_no_tf(tmp_path):
    messages = []
    for t, x in [(1.0, 0.0), (2.0, 3.0)]:
        odom = {
            "header": header(t, "odom"), "child_frame_id": "base_link",
            "pose": {"pose": {"position": {"x": x, "y": 1.0, "z": 0.0}, "orientation": quaternion(0.5)}, "covariance": [0.0] * 36},
            "twist": {"twist": {"linear": {"x": 0, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": 0}}, "covariance": [0.0] * 36},
        }
        messages.append(("/odom", "nav_msgs/msg/Odometry", odom, t))
        messages.append(("/scan", "sensor_msgs/msg/LaserScan", laserscan(t, "base_link", [1.0, 2.0]), t + 0.001))
    log = read_log(write_ros2(tmp_path / "odom.mcap", messages))
    assert [(p.pose.x, p.pose.y) for p in log.positions] == [(0.0, 1.0), (3.0, 1.0)]
    assert log.positions[0].pose.yaw == pytest.approx(0.5)


def test_channel_choice_errors_name_topics_and_schemas(tmp_path):
    scan = laserscan(1.0, "base_link", [1.0])
    path = write_ros2(tmp_path / "two.mcap", [
        ("/front", "sensor_msgs/msg/LaserScan", scan, 1.0),
        ("/rear", "sensor_msgs/msg/LaserScan", scan, 1.1),
        ("/tf", "tf2_msgs/msg/TFMessage", {"transforms": []}, 1.2),
    ])
    with pytest.raises(InputError, match=r"several range channels.*/front \(sensor_msgs/msg/LaserScan, 1 messages\).*/rear"):
        read_log(path)
    assert len(read_log(path, topics=["/rear"]).single().features) == 1
    assert len(read_log(path, topics=["/front", "/rear"]).single().features) == 2
    with pytest.raises(InputError, match="no topic '/missing'"):
        read_log(path, topics=["/missing"])
    with pytest.raises(InputError, match="tf2_msgs/msg/TFMessage.*cannot read"):
        read_log(path, topics=["/tf"])
    only_tf = write_ros2(tmp_path / "tf.mcap", [("/tf", "tf2_msgs/msg/TFMessage", {"transforms": []}, 1.0)])
    with pytest.raises(InputError, match="no range data"):
        read_log(only_tf)


def test_truncated_and_corrupt_files_are_clear_errors(tmp_path):
    scans = [("/scan", "sensor_msgs/msg/LaserScan", laserscan(t, "base_link", [1.0] * 50), t) for t in np.arange(1.0, 3.0, 0.1)]
    good = write_ros2(tmp_path / "good.mcap", scans).read_bytes()
    for name, data in [
        ("truncated.mcap", good[: len(good) // 2]),
        ("tail.mcap", good[:-20]),
        ("garbled.mcap", good[:200] + bytes(len(good) - 400) + good[-200:]),
    ]:
        path = tmp_path / name
        path.write_bytes(data)
        with pytest.raises(InputError, match=f"{name} is not a readable MCAP file"):
            read_log(path)
    # Bad magic but an .mcap name: no other format matches either.
    fake = tmp_path / "fake.mcap"
    fake.write_bytes(b"\x00\x01 not an mcap")
    with pytest.raises(InputError):
        read_log(fake)


def write_json_channel(path: Path, topic: str, schema: str, messages: list[dict]) -> Path:
    with open(path, "wb") as handle:
        writer = McapWriter(handle)
        writer.start()
        schema_id = writer.register_schema(name=schema, encoding="jsonschema", data=b"{}")
        channel_id = writer.register_channel(topic=topic, message_encoding="json", schema_id=schema_id)
        for k, message in enumerate(messages):
            writer.add_message(channel_id, log_time=k, publish_time=k, data=json.dumps(message).encode(), sequence=k)
        writer.finish()
    return path


def test_foxglove_json_pointcloud_and_laserscan(tmp_path):
    xyz_e = np.array([[1.0, 2.0, 3.0, 0.5], [-1.0, 0.5, 0.0, 1.0]], dtype="<f4")
    cloud = {
        "timestamp": {"sec": 3, "nsec": 500000000}, "frame_id": "base_link",
        "pose": {"position": {"x": 0, "y": 0, "z": 0}, "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}},
        "point_stride": 16,
        "fields": [{"name": n, "offset": 4 * i, "type": 7} for i, n in enumerate(["x", "y", "z", "evidence"])],
        "data": base64.b64encode(xyz_e.tobytes()).decode(),
    }
    log = read_log(write_json_channel(tmp_path / "cloud.mcap", "/cloud", "foxglove.PointCloud", [cloud]))
    np.testing.assert_allclose(log.single().features.points, xyz_e[:, :3])
    np.testing.assert_allclose(log.single().features.evidence, xyz_e[:, 3])
    assert log.single().stamp == pytest.approx(3.5)
    scan = {"timestamp": {"sec": 1, "nsec": 0}, "frame_id": "base_link", "start_angle": 0.0,
            "end_angle": float(np.pi / 2), "ranges": [1.0, 0.0, 2.0], "intensities": []}
    features = read_log(write_json_channel(tmp_path / "scan.mcap", "/scan", "foxglove.LaserScan", [scan])).single().features
    np.testing.assert_allclose(features.points, [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0]], atol=1e-12)


def test_foxglove_protobuf_pointcloud(tmp_path):
    pytest.importorskip("mcap_protobuf")
    from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
    from mcap_protobuf.writer import Writer as ProtobufWriter

    xyz = np.array([[1.0, 0.0, 0.5], [0.0, -3.0, 1.5]], dtype="<f8")
    message = PointCloud(
        frame_id="base_link", point_stride=24,
        fields=[PackedElementField(name=n, offset=8 * i, type=PackedElementField.FLOAT64) for i, n in enumerate("xyz")],
        data=xyz.tobytes(),
    )
    message.timestamp.FromNanoseconds(7_000_000_000)
    path = tmp_path / "proto.mcap"
    with open(path, "wb") as handle, ProtobufWriter(handle) as writer:
        writer.write_message("/cloud", message, log_time=1, publish_time=1)
    log = read_log(path, evidence=0.4)
    np.testing.assert_array_equal(log.single().features.points, xyz)
    np.testing.assert_array_equal(log.single().features.evidence, [0.4, 0.4])
    assert log.single().stamp == pytest.approx(7.0)


def test_csv_to_mcap_to_features_is_identical(tmp_path):
    rng = np.random.default_rng(3)
    log = RangeLog(positions=[
        Position(0, Features(rng.normal(size=(500, 3)), rng.uniform(size=500)), Pose(1.0, 2.0, 0.0, 0.3), 10.0),
        Position(1, Features(rng.normal(size=(20, 3)), rng.uniform(size=20)), Pose(1.1, 2.0, 0.0, 0.3), 5.0),
    ])
    csv_path = tmp_path / "features.csv"
    write_csv(log, csv_path)
    from_csv = read_log(csv_path)
    mcap_path = tmp_path / "features.mcap"
    write_mcap(from_csv, mcap_path)
    from_mcap = read_log(mcap_path)
    assert len(from_mcap.positions) == len(from_csv.positions) == 2
    for a, b in zip(from_csv.positions, from_mcap.positions):
        np.testing.assert_array_equal(a.features.points, b.features.points)
        np.testing.assert_array_equal(a.features.evidence, b.features.evidence)
        assert a.pose == b.pose
    # Another reader sees occtool's channel with its JSON schema.
    rows, _ = __import__("occtool.io.mcap", fromlist=["describe_channels"]).describe_channels(mcap_path)
    assert [(r.topic, r.schema, r.encoding, r.messages) for r in rows] == [
        ("/occtool/features", "occtool.RangeFeatures", "json", 2)
    ]


@given(
    counts=st.lists(st.integers(min_value=1, max_value=40), min_size=1, max_size=4),
    seed=st.integers(min_value=0, max_value=2**16),
    with_pose=st.booleans(),
)
def test_any_log_round_trips_through_mcap(tmp_path_factory, counts, seed, with_pose):
    rng = np.random.default_rng(seed)
    positions = [
        Position(k, Features(rng.normal(scale=10, size=(n, 3)), rng.uniform(size=n)),
                 Pose(*rng.normal(size=4)) if with_pose else None, None)
        for k, n in enumerate(counts)
    ]
    path = tmp_path_factory.mktemp("mcap") / "log.mcap"
    write_mcap(RangeLog(positions), path)
    back = read_log(path)
    assert len(back.positions) == len(positions)
    for a, b in zip(positions, back.positions):
        np.testing.assert_array_equal(a.features.points, b.features.points)
        np.testing.assert_array_equal(a.features.evidence, b.features.evidence)
        assert a.pose == b.pose


def test_describe_log_lists_channels_and_support(tmp_path):
    from rich.console import Console

    path = write_ros2(tmp_path / "mixed.mcap", [
        ("/scan", "sensor_msgs/msg/LaserScan", laserscan(1.0, "base_link", [1.0]), 1.0),
        ("/tf", "tf2_msgs/msg/TFMessage", {"transforms": []}, 1.0),
    ])
    console = Console(width=200, record=True)
    console.print(describe_log(path))
    text = console.export_text()
    assert "/scan" in text and "sensor_msgs/msg/LaserScan" in text and "yes: range data" in text
    assert "/tf" in text and "yes: poses" in text


def test_real_ccny_laserscan_recording(shared_data):
    path = shared_data / "ccny_hokuyo_bag" / "demo_ros2_converted.mcap"
    log = read_log(path)
    assert len(log.positions) == 1
    assert any("no poses" in note for note in log.notes)
    features = log.single().features
    alpha, h, r = features.polar()
    np.testing.assert_array_equal(h, 0.0)
    assert r.min() >= 0.02 - 1e-6 and r.max() <= 5.6 + 1e-6
    assert np.abs(alpha).max() <= 2.0862138 + 1e-6
    # 360 scans of 681 beams, less the 13,342 readings below range_min (no return).
    assert len(features) == 360 * 681 - 13342
    per_message = read_log(path, group_by="message")
    assert len(per_message.positions) == 360
    assert sum(len(p.features) for p in per_message.positions) == len(features)


# --- no-return beams kept as free rays (--no-return-range) -----------------------------------


def _beams(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.arctan2(points[:, 1], points[:, 0]), np.hypot(points[:, 0], points[:, 1])


# REP 117: +inf is no return, -inf too close, NaN erroneous; 12 > range_max (10) is no return,
# 0.05 < range_min (0.1) invalid; 10 (= range_max) is a return.
REP117_RANGES = [1.0, np.inf, -np.inf, np.nan, 12.0, 0.05, 2.0, 10.0]


@pytest.mark.parametrize("reach, expected", [(5.0, 5.0), (50.0, 10.0)])
def test_laserscan_keeps_exactly_the_inf_and_above_range_max_beams_as_free_rays(tmp_path, reach, expected):
    path = write_ros2(tmp_path / "scan.mcap", [("/scan", "sensor_msgs/msg/LaserScan",
                                                 laserscan(2.0, "base_link", REP117_RANGES), 2.0)])
    angles = -1.0 + 0.5 * np.arange(len(REP117_RANGES))
    plain = read_log(path)
    np.testing.assert_allclose(plain.single().features.range, [1.0, 2.0, 10.0], rtol=1e-6)
    assert any("dropped 2 of 8 laser beam(s) with no return (+inf or above range_max)" in n for n in plain.notes)
    assert any("dropped 3 of 8 invalid laser beam(s)" in n for n in plain.notes)

    log = read_log(path, no_return_range=reach)
    features = log.single().features
    alpha, r = _beams(features.points)
    # Beam order: 1.0, +inf, 12.0 (> range_max), 2.0, 10.0.
    np.testing.assert_allclose(alpha, angles[[0, 1, 4, 6, 7]], atol=1e-6)
    np.testing.assert_allclose(r, [1.0, expected, expected, 2.0, 10.0], rtol=1e-6)
    np.testing.assert_array_equal(features.evidence, [0.9, 0.0, 0.0, 0.9, 0.9])
    assert (features.points[:, 2] == 0.0).all()
    assert any(f"kept 2 of 8 laser beam(s) with no return (+inf or above range_max) as free rays at {expected:g} m "
               "with evidence 0" in n for n in log.notes)
    assert any("dropped 3 of 8 invalid laser beam(s)" in n for n in log.notes)


def test_laserscan_free_rays_with_intensities_and_a_mounting(tmp_path):
    # The laser is turned 90 degrees left on base_link: free rays turn with the returns.
    tf_static = {"transforms": [transform(0.0, "base_link", "laser", (0.2, 0.0, 0.3), np.pi / 2)]}
    scan = laserscan(1.0, "laser", [1.0, np.inf, 3.0], angle_min=0.0, increment=0.5, intensities=[50, 7, 200])
    path = write_ros2(tmp_path / "scan.mcap", [("/tf_static", "tf2_msgs/msg/TFMessage", tf_static, 0.0),
                                                ("/scan", "sensor_msgs/msg/LaserScan", scan, 1.0)])
    features = read_log(path, use_intensities=True, no_return_range=4.0).single().features
    # Intensities are scaled by the returns' largest; the free ray has evidence 0 whatever its intensity.
    np.testing.assert_allclose(features.evidence, [0.25, 0.0, 1.0])
    alpha, r = _beams(features.points)
    np.testing.assert_allclose(alpha, np.pi / 2 + np.array([0.0, 0.5, 1.0]), atol=1e-6)
    np.testing.assert_allclose(r, [1.0, 4.0, 3.0], rtol=1e-6)


def test_foxglove_laserscan_inf_beams_are_free_rays(tmp_path):
    scan = {"timestamp": {"sec": 1, "nsec": 0}, "frame_id": "base_link", "start_angle": 0.0,
            "end_angle": float(np.pi / 2), "ranges": [1.0, float("inf"), float("nan"), 2.0], "intensities": []}
    # Python's json writes +inf as Infinity, which the JSON decoder reads back.
    path = write_json_channel(tmp_path / "scan.mcap", "/scan", "foxglove.LaserScan", [scan])
    assert len(read_log(path).single().features) == 2
    features = read_log(path, no_return_range=3.0).single().features
    np.testing.assert_allclose(features.points, [[1.0, 0.0, 0.0], [3.0 * np.cos(np.pi / 6), 1.5, 0.0], [0.0, 2.0, 0.0]],
                               atol=1e-12)
    np.testing.assert_array_equal(features.evidence, [0.9, 0.0, 0.9])


def test_point_clouds_and_occtools_channel_ignore_the_no_return_range(tmp_path):
    columns = {"x": np.array([1.0, np.nan]), "y": np.array([0.0, 0.0]), "z": np.array([0.0, 0.0])}
    path = write_ros2(tmp_path / "cloud.mcap", [("/points", "sensor_msgs/msg/PointCloud2",
                                                  pointcloud2(1.0, "base_link", columns, dict.fromkeys(columns, "f4")), 1.0)])
    for source in (path, tmp_path / "own.mcap"):
        if source.name == "own.mcap":
            write_mcap(read_log(path), source)
        plain, option = read_log(source).single().features, read_log(source, no_return_range=5.0).single().features
        np.testing.assert_array_equal(option.points, plain.points)
        np.testing.assert_array_equal(option.evidence, plain.evidence)


def test_free_rays_round_trip_through_occtools_channel(tmp_path):
    path = write_ros2(tmp_path / "scan.mcap", [("/scan", "sensor_msgs/msg/LaserScan",
                                                 laserscan(2.0, "base_link", REP117_RANGES), 2.0)])
    log = read_log(path, no_return_range=5.0)
    write_mcap(log, tmp_path / "own.mcap")
    back = read_log(tmp_path / "own.mcap").single().features
    np.testing.assert_array_equal(back.points, log.single().features.points)
    np.testing.assert_array_equal(back.evidence, [0.9, 0.0, 0.0, 0.9, 0.9])


@pytest.mark.parametrize("bad", [0.0, -2.0, float("nan"), float("-inf")])
def test_a_bad_no_return_range_is_an_error_for_mcap(tmp_path, bad):
    path = write_ros2(tmp_path / "scan.mcap", [("/scan", "sensor_msgs/msg/LaserScan",
                                                 laserscan(2.0, "base_link", [1.0]), 2.0)])
    with pytest.raises(InputError, match="no-return range"):
        read_log(path, no_return_range=bad)
