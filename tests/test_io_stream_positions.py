"""Streaming a log's positions (occtool.io.iter_positions): the same positions as read_log,
byte for byte, for every format, chunk boundaries and the fallbacks included."""

from __future__ import annotations

import gzip
import shutil

import numpy as np
import pytest
from test_io_mcap import header, laserscan, quaternion, transform, write_ros2

import occtool.io.csv_stream as csv_module
from occtool.errors import InputError
from occtool.features import Features, Pose, Position, RangeLog
from occtool.io import iter_positions, read_log, write_csv, write_mcap


def assert_same_positions(path, **options):
    whole = read_log(path, **options)
    stream = iter_positions(path, **options)
    for _ in range(2):  # a stream reads its file again on every iteration
        streamed = list(stream)
        assert len(streamed) == len(whole.positions)
        for mine, theirs in zip(streamed, whole.positions):
            assert (mine.index, mine.pose, mine.stamp, mine.source) == (
                theirs.index, theirs.pose, theirs.stamp, theirs.source)
            assert mine.features.points.tobytes() == theirs.features.points.tobytes()
            assert mine.features.evidence.tobytes() == theirs.features.evidence.tobytes()
        assert stream.notes == whole.notes
    return whole


def _posed_log(count=7, seed=3):
    rng = np.random.default_rng(seed)
    positions = []
    for k in range(count):
        points = rng.uniform(-3, 3, size=(40 + 5 * k, 3))
        positions.append(Position(k, Features(points, rng.uniform(0, 1, len(points))),
                                  Pose(float(k), 0.5 * k, 0.0, 0.1 * k), stamp=10.0 + k))
    return RangeLog(positions=positions, source="synthetic")


@pytest.mark.parametrize("name", ["logs/tiny.carmen.log", "logs/tiny.xyz", "logs/tiny_ascii.pcd",
                                  "logs/tiny_ascii.ply", "logs/nodes.dat", "office/features.csv",
                                  "corridor/features.csv"])
def test_every_fixture_streams_the_positions_read_log_gives(fixtures_dir, name):
    assert_same_positions(fixtures_dir / name)


@pytest.mark.parametrize("options", [{}, {"no_return_range": 5.0}, {"group_by": "message"},
                                     {"evidence": 0.4}, {"position_tolerance": (1.0, 3.0)}])
def test_a_gzip_carmen_log_streams_line_by_line_the_same_positions(fixtures_dir, tmp_path, options):
    path = tmp_path / "tiny.log.gz"
    with open(fixtures_dir / "logs" / "tiny.carmen.log", "rb") as source, gzip.open(path, "wb") as target:
        shutil.copyfileobj(source, target)
    assert_same_positions(path, **options)


def test_occtools_own_mcap_channel_is_read_whole_with_the_same_positions(tmp_path):
    path = tmp_path / "log.mcap"
    write_mcap(_posed_log(), path)
    assert_same_positions(path)


def _ros2_messages(pose_topic):
    # A laser mounted 0.2 m ahead, turned left; scans before the first pose, then a drive.
    tf_static = {"transforms": [transform(0.0, "base_link", "laser", (0.2, 0.0, 0.3), np.pi / 2)]}
    messages = [("/tf_static", "tf2_msgs/msg/TFMessage", tf_static, 0.0),
                ("/scan", "sensor_msgs/msg/LaserScan", laserscan(0.5, "laser", [1.0, 20.0], angle_min=0.0), 0.5)]
    for k in range(6):
        t, x, yaw = 1.0 + k, 0.3 * k, 0.2 * k
        if pose_topic == "/tf":
            messages.append(("/tf", "tf2_msgs/msg/TFMessage",
                             {"transforms": [transform(t, "odom", "base_link", (x, 0, 0), yaw)]}, t))
        elif pose_topic == "/odom":
            messages.append(("/odom", "nav_msgs/msg/Odometry", {
                "header": header(t, "odom"), "child_frame_id": "base_link",
                "pose": {"pose": {"position": {"x": x, "y": 1.0, "z": 0.0}, "orientation": quaternion(yaw)},
                         "covariance": [0.0] * 36},
                "twist": {"twist": {"linear": {"x": 0, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": 0}},
                          "covariance": [0.0] * 36}}, t))
        ranges = [1.0 + 0.1 * k, float("inf"), 2.0, float("nan")]
        messages.append(("/scan", "sensor_msgs/msg/LaserScan", laserscan(t + 0.01, "laser", ranges), t + 0.01))
    return messages


@pytest.mark.parametrize("pose_topic", ["/tf", "/odom", None])
@pytest.mark.parametrize("options", [{}, {"no_return_range": 4.0}, {"group_by": "message"},
                                     {"sensor_frame": "base_link"}])
def test_mcap_laser_scans_stream_message_by_message_the_same_positions(tmp_path, pose_topic, options):
    path = write_ros2(tmp_path / "robot.mcap", _ros2_messages(pose_topic))
    whole = assert_same_positions(path, **options)
    assert len(whole.positions) >= 1


def test_an_mcap_error_is_raised_before_the_first_position(tmp_path):
    messages = _ros2_messages("/tf")
    messages.append(("/cloud", "sensor_msgs/msg/LaserScan", laserscan(9.0, "laser", [1.0]), 9.0))
    path = write_ros2(tmp_path / "two.mcap", messages)
    with pytest.raises(InputError, match="several range channels"):
        iter_positions(path).__iter__().__next__()
    assert_same_positions(path, topics=["/scan", "/cloud"])


@pytest.mark.slow
def test_the_ccny_ros1_bag_and_its_mcap_twin_stream_the_same_positions(shared_data):
    pytest.importorskip("rosbags")
    assert_same_positions(shared_data / "ccny_hokuyo_bag" / "demo.bag")
    assert_same_positions(shared_data / "ccny_hokuyo_bag" / "demo_ros2_converted.mcap")


@pytest.mark.parametrize("chunk", [64, 1000, 1 << 22])
@pytest.mark.parametrize("columns", ["position", "pose", "both", "neither"])
def test_csv_streams_in_chunks_the_same_positions(tmp_path, monkeypatch, chunk, columns):
    # Chunks of 64 bytes cut every position (and pose run) across chunks.
    monkeypatch.setattr(csv_module, "CHUNK_BYTES", chunk)
    log = _posed_log()
    path = tmp_path / "log.csv"
    write_csv(log, path)
    if columns != "both":
        keep = {"position": ["x", "y", "z", "m", "position"], "pose": None,
                "neither": ["x", "y", "z", "m"]}[columns]
        lines = path.read_text().splitlines()
        header = lines[0].split(",")
        wanted = [header.index(c) for c in keep if c != "position" or "position" in header] if keep else \
            [i for i, c in enumerate(header) if c != "position"]
        path.write_text("\n".join(",".join(line.split(",")[i] for i in wanted) for line in lines) + "\n")
    for group_by in ("position", "message"):
        whole = assert_same_positions(path, group_by=group_by)
    assert len(whole.positions) == (1 if columns == "neither" else 7)


def test_csv_poses_within_tolerance_join_one_position_across_chunks(tmp_path, monkeypatch):
    monkeypatch.setattr(csv_module, "CHUNK_BYTES", 50)
    rows = ["x,y,z,m,pose_x,pose_y,pose_yaw"]
    for scan, pose in enumerate([(0, 0, 0), (0.1, 0, 0.05), (0.2, 0, 0), (3, 0, 0), (3, 0.1, 0.1)]):
        rows += [f"{1 + k * 0.1},{scan * 0.01 + 0.5},0.2,0.7,{pose[0]},{pose[1]},{pose[2]}" for k in range(4)]
    path = tmp_path / "scans.csv"
    path.write_text("\n".join(rows) + "\n")
    whole = assert_same_positions(path)
    assert [len(p.features) for p in whole.positions] == [12, 8]


def test_interleaved_position_ids_fall_back_to_reading_whole(tmp_path, monkeypatch):
    monkeypatch.setattr(csv_module, "CHUNK_BYTES", 30)
    path = tmp_path / "interleaved.csv"
    path.write_text("x,y,z,m,position\n1,0,0,0.5,4\n2,0,0,0.5,9\n3,0,0,0.5,4\n1,1,0,0.5,9\n")
    whole = assert_same_positions(path)
    assert [len(p.features) for p in whole.positions] == [2, 2]


@pytest.mark.parametrize("bad", ["1,0,0,1.5,0", "1,0,0,oops,0", "0,0,0,0.5,0", "1,0,0,0.5,0.5"])
def test_a_bad_csv_row_in_a_later_chunk_is_the_same_error_or_skipped_the_same(tmp_path, monkeypatch, bad):
    monkeypatch.setattr(csv_module, "CHUNK_BYTES", 40)
    lines = ["x,y,z,m,position"] + [f"{1 + k},0,0,0.5,{k // 3}" for k in range(12)]
    lines.insert(9, bad)
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError) as whole_error:
        read_log(path)
    with pytest.raises(InputError) as stream_error:
        list(iter_positions(path))
    assert str(stream_error.value) == str(whole_error.value)
    if "whole numbers" not in str(whole_error.value):
        assert_same_positions(path, skip_invalid=True)


def test_a_bad_carmen_line_anywhere_is_an_error_before_the_first_position(fixtures_dir, tmp_path):
    lines = (fixtures_dir / "logs" / "tiny.carmen.log").read_text().splitlines()
    lines.append("FLASER 4 1.0 2.0 oops 0.5 0.0 0.0 0.0 0.0 0.0 0.0 1.5 nohost 1.5")
    path = tmp_path / "late.log"
    path.write_text("\n".join(lines) + "\n")
    stream = iter(iter_positions(path))
    with pytest.raises(InputError, match=r"late.log, line \d+: FLASER record has a field that is not a number"):
        next(stream)
    assert_same_positions(path, skip_invalid=True)


def test_options_are_checked_when_the_stream_is_made(fixtures_dir, tmp_path):
    with pytest.raises(InputError, match="group-by"):
        iter_positions(fixtures_dir / "logs" / "tiny.carmen.log", group_by="scan")
    with pytest.raises(FileNotFoundError):
        iter_positions(tmp_path / "absent.log")
