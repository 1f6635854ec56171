"""Issue 37, item 2: every reader's poses are checked once, by one function.

:func:`occtool.io.positions.check_pose` refuses a pose that is not finite, lies past
:data:`occtool.limits.MAX_WORLD_COORDINATE`, or whose rotation is none (a quaternion far
from unit length, a matrix that is not orthonormal). CARMEN lines, TUM ground truth, MCAP
``/tf`` and odometry, and 3DMatch pose files all call it, so a NaN or 1e300 pose is one
:class:`InputError` naming the line or message, in every reader alike, never a traceback
or a RuntimeWarning with exit 0.
"""

from __future__ import annotations

import math
import shutil
import traceback
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from test_io_mcap import header, laserscan, quaternion, transform, write_ros2

from occtool.cli.main import cli
from occtool.errors import InputError
from occtool.io import read_log
from occtool.io.positions import check_pose
from occtool.limits import MAX_WORLD_COORDINATE

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures"
FUZZ = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
#: Crafted values: finite, at and past the bound, overflowing, not finite.
VALUES = st.sampled_from([0.0, 0.5, -2.0, 1e7, MAX_WORLD_COORDINATE, 2 * MAX_WORLD_COORDINATE, 1e300, -1e300,
                          math.nan, math.inf, -math.inf])


def _bad(*values: float) -> bool:
    return not all(math.isfinite(v) and abs(v) <= MAX_WORLD_COORDINATE for v in values)


def _read(path: Path, **keywords):
    """read_log with RuntimeWarnings as errors: an overflow is a refusal, not a warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        return read_log(path, **keywords)


def assert_one_line_error(result, *fragments: str) -> None:
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise AssertionError("uncaught exception:\n" + "".join(traceback.format_exception(*result.exc_info)))
    errors = [line for line in result.output.splitlines() if line.startswith("Error:")]
    assert result.exit_code != 0 and len(errors) == 1 and "Traceback" not in result.output, result.output
    for fragment in fragments:
        assert fragment in errors[0], (fragment, result.output)


# --- the function ---------------------------------------------------------------------------


@pytest.mark.parametrize(("keywords", "message"), [
    (dict(translation=(math.nan, 0, 0), yaw=0.0), "translation .* NaN or infinity"),
    (dict(translation=(1e300, 0, 0), yaw=0.0), "reaches past"),
    (dict(translation=(0, 0, 0), yaw=math.inf), "yaw .* NaN or infinity"),
    (dict(translation=(0, 0, 0), quaternion=(0, 0, 0, 2)), "length 2, not 1"),
    (dict(translation=(0, 0, 0), quaternion=(0, 0, 0.6, 0.6)), "not 1"),
    (dict(translation=(0, 0, 0), rotation=np.diag([1.0, 1.0, -1.0])), "not a rotation"),
    (dict(translation=(0, 0, 0), rotation=2 * np.eye(3)), "not a rotation"),
])
def test_check_pose_refuses_what_is_no_pose(keywords, message):
    with pytest.raises(InputError, match=f"^line 9: .*{message}"):
        check_pose("line 9", **keywords)


def test_check_pose_takes_rotations_within_their_tolerance():
    check_pose("x", (1e7, -1e7, 0.0), quaternion=(0.0, 0.0, np.sin(0.3), np.cos(0.3) * (1 + 1e-7)))
    yaw = 0.7
    r = np.array([[np.cos(yaw), -np.sin(yaw), 0.0], [np.sin(yaw), np.cos(yaw), 0.0], [0.0, 0.0, 1.0]])
    check_pose("x", (0.0, 0.0, 0.0), rotation=r.astype(np.float32))


# --- CARMEN -----------------------------------------------------------------------------------


def _flaser(x: float, y: float, theta: float, stamp: float) -> str:
    ranges = "1.1 1.3 1.2 1.6 1.4"
    return f"FLASER 5 {ranges} {x!r} {y!r} {theta!r} 0 0 0 {stamp} host {stamp}\n"


@FUZZ
@given(x=VALUES, y=VALUES, theta=VALUES)
@example(x=math.nan, y=0.0, theta=0.0)
@example(x=1e300, y=0.0, theta=0.0)
def test_a_carmen_pose_is_read_or_refused_naming_its_line(tmp_path_factory, x, y, theta):
    path = tmp_path_factory.mktemp("carmen") / "run.log"
    path.write_text(_flaser(0.0, 0.0, 0.0, 1.0) + _flaser(x, y, theta, 2.0))
    if _bad(x, y, theta):
        with pytest.raises(InputError, match=r"run.log, line 2: FLASER: the pose's"):
            _read(path)
        log = _read(path, skip_invalid=True)  # dropped as a line that does not parse, counted
        assert len(log.positions) == 1 and any("1 laser line" in note for note in log.notes)
    else:
        log = _read(path)
        assert all(math.isfinite(p.pose.x) for p in log.positions if p.pose is not None)


@pytest.mark.parametrize("start", ["nan", "inf", "1e300", "40"])
def test_a_robotlaser1_line_with_a_nan_start_angle_is_an_error_naming_the_line(tmp_path, start):
    line = f"ROBOTLASER1 0 {start} 1.0 0.5 80.0 0.01 0 3 1.0 2.0 3.0 0 0 0 0 1.0 2.0 0.0 0 0 0 0 0 7.0 host 7.0\n"
    path = tmp_path / "robot.log"
    path.write_text(line)
    with pytest.raises(InputError, match=r"robot.log, line 1: ROBOTLASER1 start angle"):
        _read(path)
    assert_one_line_error(CliRunner().invoke(cli, ["fit", str(path), "-o", str(tmp_path / "m.json")]),
                          "line 1", "start angle")


def test_a_1e300_pose_is_one_line_on_the_command_line(tmp_path):
    path = tmp_path / "run.log"
    path.write_text(_flaser(0.0, 0.0, 0.0, 1.0) + _flaser(1e300, 0.0, 0.0, 2.0))
    result = CliRunner().invoke(cli, ["map", str(path), "-o", str(tmp_path / "out")])
    assert_one_line_error(result, "line 2", "reaches past")
    assert not (tmp_path / "out").exists()


# --- TUM ground truth -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tum(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("tum") / "rgbd_dataset_freiburg3_poses"
    shutil.copytree(FIXTURES / "depth-office", folder)
    lines = (folder / "groundtruth.txt").read_text().splitlines()
    (folder / "groundtruth.txt").write_text("\n".join(lines[:4]) + "\n")  # two comments, two poses
    listed = [line for line in (folder / "depth.txt").read_text().splitlines() if not line.startswith("#")]
    (folder / "depth.txt").write_text("\n".join(listed[:2]) + "\n")
    return folder


@FUZZ
@given(t=VALUES, q=st.sampled_from([(0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0, 2.0), (0.5, 0.5, 0.5, 0.5),
                                     (0.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.005), (0.0, 0.0, math.nan, 1.0),
                                     (0.0, 0.0, 1e300, 1.0)]))
def test_a_tum_ground_truth_pose_is_read_or_refused_naming_its_line(tum, tmp_path_factory, t, q):
    folder = tmp_path_factory.mktemp("copy") / tum.name
    shutil.copytree(tum, folder)
    lines = (folder / "groundtruth.txt").read_text().splitlines()
    stamp = lines[3].split()[0]
    lines[3] = " ".join([stamp, repr(t), "0.0", "1.0", *map(repr, q)])
    (folder / "groundtruth.txt").write_text("\n".join(lines) + "\n")
    norm = math.sqrt(sum(v * v for v in q)) if all(math.isfinite(v) for v in q) else math.nan
    if _bad(t, *q) or not abs(norm - 1.0) <= 1e-2:
        with pytest.raises(InputError, match=r"groundtruth.txt, line 4: "):
            _read(folder)
    else:
        assert _read(folder).positions


# --- MCAP /tf and odometry --------------------------------------------------------------------


def _tf_log(path: Path, translation, rotation) -> Path:
    moving = transform(1.0, "odom", "base_link", (0.0, 0.0, 0.0))
    moving["transform"]["translation"] = dict(zip("xyz", translation))
    moving["transform"]["rotation"] = rotation
    return write_ros2(path, [
        ("/tf", "tf2_msgs/msg/TFMessage", {"transforms": [moving]}, 1.0),
        ("/scan", "sensor_msgs/msg/LaserScan", laserscan(1.0, "base_link", [1.0, 2.0]), 1.001),
    ])


@FUZZ
@given(x=VALUES, w=st.sampled_from([1.0, 1.0 + 1e-6, 2.0, 0.5, 1e300]))
def test_a_tf_pose_is_read_or_refused_naming_its_message(tmp_path_factory, x, w):
    path = _tf_log(tmp_path_factory.mktemp("tf") / "tf.mcap", (x, 0.0, 0.0), {"x": 0.0, "y": 0.0, "z": 0.0, "w": w})
    if _bad(x) or abs(w - 1.0) > 1e-2:
        with pytest.raises(InputError, match=r"tf.mcap, /tf: the transform odom -> base_link"):
            _read(path)
    else:
        assert _read(path).positions


def test_a_tf_quaternion_of_length_two_names_the_message_by_its_stamp(tmp_path):
    path = _tf_log(tmp_path / "tf.mcap", (0.0, 0.0, 0.0), {"x": 0.0, "y": 0.0, "z": 0.0, "w": 2.0})
    with pytest.raises(InputError, match=r"/tf: the transform odom -> base_link \(message at 1 s\): .*length 2"):
        _read(path)


@pytest.mark.parametrize("x", [1e300, -2 * MAX_WORLD_COORDINATE])
def test_an_odometry_pose_past_the_world_is_refused_naming_the_message(tmp_path, x):
    odometry = {
        "header": header(1.0, "odom"), "child_frame_id": "base_link",
        "pose": {"pose": {"position": {"x": x, "y": 1.0, "z": 0.0}, "orientation": quaternion(0.0)},
                 "covariance": [0.0] * 36},
        "twist": {"twist": {"linear": {"x": 0, "y": 0, "z": 0}, "angular": {"x": 0, "y": 0, "z": 0}},
                  "covariance": [0.0] * 36},
    }
    path = write_ros2(tmp_path / "odom.mcap", [
        ("/odom", "nav_msgs/msg/Odometry", odometry, 1.0),
        ("/scan", "sensor_msgs/msg/LaserScan", laserscan(1.0, "base_link", [1.0, 2.0]), 1.001)])
    with pytest.raises(InputError, match=r"odom.mcap, /odom, message \d+: the odometry pose.*reaches past"):
        _read(path)
    assert_one_line_error(CliRunner().invoke(cli, ["fit", str(path), "-o", str(tmp_path / "m.json")]),
                          "odometry pose")


# --- 3DMatch ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def frames(tmp_path_factory) -> Path:
    from PIL import Image

    folder = tmp_path_factory.mktemp("match") / "frames"
    folder.mkdir()
    image = np.full((48, 64), 1500, dtype=np.uint16)
    for i in range(2):
        Image.fromarray(image).save(folder / f"frame-{i:06d}.depth.png")
        np.savetxt(folder / f"frame-{i:06d}.pose.txt", np.eye(4))
    (folder / "camera-intrinsics.txt").write_text("60 0 32\n0 60 24\n0 0 1\n")
    return folder


@pytest.mark.parametrize(("change", "message"), [
    ({(0, 3): 1e300}, "reaches past"),
    ({(0, 0): 2.0}, "not a rotation"),
    ({(2, 2): -1.0}, "not a rotation"),
    ({(3, 0): 1.0}, "last row"),
])
def test_a_3dmatch_pose_file_that_is_no_pose_is_refused_naming_the_file(frames, tmp_path, change, message):
    pytest.importorskip("PIL")
    folder = tmp_path / "frames"
    shutil.copytree(frames, folder)
    pose = np.eye(4)
    for index, value in change.items():
        pose[index] = value
    np.savetxt(folder / "frame-000001.pose.txt", pose)
    with pytest.raises(InputError, match=f"frame-000001.pose.txt: .*{message}"):
        _read(folder)


def test_a_3dmatch_pose_lost_by_tracking_is_still_dropped_with_a_note(frames, tmp_path):
    pytest.importorskip("PIL")
    folder = tmp_path / "frames"
    shutil.copytree(frames, folder)
    np.savetxt(folder / "frame-000001.pose.txt", np.full((4, 4), -np.inf))
    log = _read(folder)
    assert any("tracking lost" in note for note in log.notes)
