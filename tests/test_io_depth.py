"""Issue 23: depth images to features (back-projection, frames, noise, budget) and the
TUM RGB-D and 3DMatch / 7-Scenes folders, checked against known answers and the truth."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from occtool.errors import InputError
from occtool.io import detect_format, read_log
from occtool.io.depth import (
    OPTICAL_TO_BODY,
    DepthCounts,
    PinholeCamera,
    back_project,
    camera_scan,
    noise_evidence,
)
from occtool.simulate._depth import DEFAULT_CAMERA, camera_rotation, render_depth_frames, write_depth_folder

FIXTURES = Path(__file__).resolve().parent.parent / "fixtures"
CAMERA = PinholeCamera(64, 48, 50.0, 50.0, 31.5, 23.5)


def test_the_cli_defaults_are_the_readers() -> None:
    from occtool.cli.fit import fit
    from occtool.io import read_options

    defaults = {p.name: p.default for p in fit.params}
    for name in ("depth_features", "depth_noise", "depth_max_range"):
        assert defaults[name] == getattr(read_options, f"DEFAULT_{name.upper()}")


def test_a_wall_at_known_depth_back_projects_into_rep103() -> None:
    depth = np.full((48, 64), 2000, dtype=np.uint16)  # 2 m, millimetres
    points, evidence = back_project(depth, CAMERA, scale=1e-3, budget=None)
    assert points.shape == (48 * 64, 3)
    np.testing.assert_allclose(points[:, 0], 2.0)  # forward = optical z
    # Pixel (u=0, v=0) is left of and above the centre: y > 0 (left), z > 0 (up).
    first = points[0]
    np.testing.assert_allclose(first, [2.0, 31.5 / 50.0 * 2.0, 23.5 / 50.0 * 2.0])
    last = points[-1]  # bottom right
    np.testing.assert_allclose(last, [2.0, -31.5 / 50.0 * 2.0, -23.5 / 50.0 * 2.0])
    np.testing.assert_allclose(evidence, noise_evidence(2.0))
    assert np.allclose(OPTICAL_TO_BODY @ [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    assert np.allclose(OPTICAL_TO_BODY @ [1.0, 0.0, 0.0], [0.0, -1.0, 0.0])
    assert np.allclose(OPTICAL_TO_BODY @ [0.0, 1.0, 0.0], [0.0, 0.0, -1.0])


def test_invalid_and_no_return_depths() -> None:
    depth = np.full((48, 64), 3.0, dtype=np.float32)
    depth[0, :10] = 0.0          # no measurement
    depth[1, :10] = np.nan       # no measurement
    depth[2, :10] = np.inf       # too far: no return
    depth[3, :10] = 20.0         # beyond the max range: no return
    depth[4, :10] = 0.05         # nearer than the minimum range
    counts = DepthCounts()
    points, evidence = back_project(depth, CAMERA, budget=None, max_range=8.0, counts=counts)
    assert counts.invalid == 30 and counts.no_return == 20 and counts.returns == 48 * 64 - 50
    assert len(points) == 48 * 64 - 50 and (evidence > 0).all()
    points, evidence = back_project(depth, CAMERA, budget=None, max_range=8.0, no_return_range=5.0)
    free = evidence == 0.0
    assert free.sum() == 20
    np.testing.assert_allclose(points[free, 0], 5.0)  # free rays end at depth min(R, max range)
    points, evidence = back_project(depth, CAMERA, budget=None, max_range=4.0, no_return_range=5.0)
    np.testing.assert_allclose(points[evidence == 0.0, 0], 4.0)


def test_the_noise_evidence_is_quadratic_in_depth() -> None:
    z = np.array([0.5, 1.0, 2.0, 4.0, 8.0])
    m = noise_evidence(z, noise=0.01)
    assert (np.diff(m) < 0).all() and m[0] > 0.99 and m[-1] >= 0.05
    # m depends on k z only: doubling the noise is halving the range.
    np.testing.assert_allclose(noise_evidence(z, noise=0.02), noise_evidence(2 * z, noise=0.01))
    assert (noise_evidence(z, noise=0.0) == 1.0).all()


def test_the_budget_keeps_the_geometry() -> None:
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.5, 5.0, (480, 640))
    depth[:, :320] = 1.0  # left half a wall at 1 m
    points, _ = back_project(depth, PinholeCamera(640, 480, 525, 525, 319.5, 239.5), budget=5000)
    assert 2500 < len(points) <= 5000
    # The wall keeps its share of the view (half the pixels) within a few percent.
    share = np.mean(np.isclose(points[:, 0], 1.0))
    assert abs(share - 0.5) < 0.03


def test_640x480_frames_back_project_at_30_per_second() -> None:
    import time

    rng = np.random.default_rng(1)
    frame = (rng.uniform(0.4, 6.0, (480, 640)) * 1000).astype(np.uint16)
    frame[rng.random((480, 640)) < 0.1] = 0
    camera = PinholeCamera(640, 480, 525, 525, 319.5, 239.5)
    back_project(frame, camera, scale=1e-3)
    start = time.process_time()
    for i in range(30):
        back_project(frame, camera, scale=1e-3, phase=i)
    assert time.process_time() - start < 1.0


def test_shapes_and_intrinsics_are_checked() -> None:
    with pytest.raises(InputError, match="does not match the camera's 48x64"):
        back_project(np.zeros((10, 10)), CAMERA)
    with pytest.raises(InputError, match="fx must be finite and > 0"):
        PinholeCamera(64, 48, 0.0, 50.0, 31.5, 23.5)
    with pytest.raises(InputError, match="not a pinhole matrix"):
        PinholeCamera.from_matrix(64, 48, [[50, 0, 31.5], [0, 50, 23.5], [0, 1, 1]])
    with pytest.raises(InputError, match="width"):
        PinholeCamera(0, 48, 50.0, 50.0, 31.5, 23.5)


def test_a_tilted_camera_pose_levels_its_points() -> None:
    tilt, yaw = math.radians(-30.0), math.radians(40.0)
    pose = np.eye(4)
    pose[:3, :3] = camera_rotation(yaw, tilt)
    pose[:3, 3] = (1.0, 2.0, 1.2)
    # A point 2 m straight ahead of the camera, in the camera's body frame.
    levelled, found = camera_scan(np.array([[2.0, 0.0, 0.0]]), pose)
    assert math.isclose(found.yaw, yaw) and (found.x, found.y, found.z) == (1.0, 2.0, 1.2)
    np.testing.assert_allclose(levelled[0], [2.0 * math.cos(tilt), 0.0, 2.0 * math.sin(tilt)], atol=1e-12)


@pytest.fixture(scope="module")
def office_frames():
    return render_depth_frames("office")


def _score(features, scene):
    from occtool.fit import OccupancyRegressor
    from occtool.navigation import NavigationWarning
    from occtool.scoring import evaluate_navigation

    model = OccupancyRegressor(seed=0).fit(features)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NavigationWarning)
        nav = model.navigation_map(max_range=1.5)
    return evaluate_navigation(nav.polygon, scene, robot_radius=nav.robot_radius, max_range=nav.max_range)


@pytest.mark.parametrize("layout", ["tum", "3dmatch"])
def test_a_rendered_folder_maps_the_office_as_well_as_its_point_cloud(tmp_path, office_frames, layout) -> None:
    frames, scene = office_frames
    # 3DMatch's world is its first camera's (not level): the reader must find the floor.
    world = np.linalg.inv(frames[0].camera_to_world) if layout == "3dmatch" else None
    folder = write_depth_folder(frames, tmp_path / layout, layout=layout, world=world)
    path = folder / ("depth.txt" if layout == "tum" else "camera-intrinsics.txt")
    assert detect_format(path) == detect_format(folder) == layout
    log = read_log(path, position_tolerance=(0.25, 3.2), depth_features=1250)
    assert len(log.positions) == 1
    position = log.positions[0]
    assert abs(position.pose.z - scene.robot.sensor_height) < 0.02  # the camera's height above the floor
    assert any("floor plane" in note for note in log.notes)
    result = _score(position.features, scene)
    from occtool.simulate import simulate_scene

    points, _ = simulate_scene("office", n_features=len(position.features), seed=0)
    reference = _score(points, scene)
    assert result.iou >= reference.iou - 0.02
    assert result.violation <= 0.005


def test_the_fixture_reads_with_its_readme_command() -> None:
    log = read_log(FIXTURES / "depth-office" / "depth.txt", position_tolerance=(0.25, 3.2))
    assert len(log.positions) == 1 and len(log.positions[0].features) > 5000
    assert detect_format(FIXTURES / "depth-office") == "tum"


def test_frames_turning_in_place_split_by_heading_by_default(tmp_path, office_frames) -> None:
    frames, _ = office_frames
    folder = write_depth_folder(frames, tmp_path / "tum", layout="tum")
    log = read_log(folder, depth_features=500)
    assert len(log.positions) == 8  # 45 degrees apart, more than the default 0.26 rad
    assert [round(math.degrees(p.pose.yaw)) % 360 for p in log.positions] == [0, 45, 90, 135, 180, 225, 270, 315]


def test_bad_folders_are_one_line_errors(tmp_path, office_frames) -> None:
    frames, _ = office_frames
    folder = write_depth_folder(frames[:2], tmp_path / "tum", layout="tum")
    png = sorted((folder / "depth").iterdir())[0]
    data = png.read_bytes()
    png.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="not a readable depth image"):
        read_log(folder)
    log = read_log(folder, skip_invalid=True)
    assert any("skipped 1 depth frame" in note for note in log.notes)
    png.write_bytes(data)
    (folder / "camera-intrinsics.txt").write_text("525 0 319.5\n0 525\n")
    with pytest.raises(InputError, match="camera intrinsics"):
        read_log(folder)
    match = write_depth_folder(frames[:2], tmp_path / "m", layout="3dmatch")
    (match / "seq-01" / "frame-000001.pose.txt").write_text("1 0 0\n")
    with pytest.raises(InputError, match="4x4"):
        read_log(match)
    (match / "seq-01" / "frame-000001.pose.txt").unlink()
    with pytest.raises(InputError, match="pose file frame-000001.pose.txt is missing"):
        read_log(match)
    small = write_depth_folder(frames[:1], tmp_path / "small", layout="3dmatch")
    from PIL import Image

    Image.fromarray(np.zeros((10, 10), dtype=np.uint16)).save(small / "seq-01" / "frame-000001.depth.png")
    np.savetxt(small / "seq-01" / "frame-000001.pose.txt", np.eye(4))
    with pytest.raises(InputError, match="where the folder's first is 160x120"):
        read_log(small)


def test_the_cli_maps_a_depth_folder(tmp_path, office_frames) -> None:
    from click.testing import CliRunner

    from occtool.cli.main import cli

    frames, _ = office_frames
    folder = write_depth_folder(frames, tmp_path / "tum", layout="tum")
    result = CliRunner().invoke(cli, ["info", str(folder / "depth.txt")])
    assert result.exit_code == 0, result.output
    assert "tum" in result.output
    out = tmp_path / "model.json"
    result = CliRunner().invoke(cli, ["fit", str(folder / "depth.txt"), "-o", str(out), "--depth-features", "500",
                                      "--position-tolerance", "0.25,3.2", "--depth-noise", "0.005"])
    assert result.exit_code == 0, result.output
    assert out.is_file() and DEFAULT_CAMERA.width == 160


@pytest.mark.parametrize("layout", ["tum", "3dmatch"])
def test_occtool_map_takes_the_depth_folder_itself(tmp_path, office_frames, layout) -> None:
    # The folder a user has (not only its depth.txt) is a log, not a model set without an index.
    from click.testing import CliRunner

    from occtool.cli.main import cli
    from occtool.fuse import WorldMap, load_map

    frames, _ = office_frames
    world = np.linalg.inv(frames[0].camera_to_world) if layout == "3dmatch" else None
    folder = write_depth_folder(frames, tmp_path / layout, layout=layout, world=world)
    out = tmp_path / "map"
    result = CliRunner().invoke(cli, ["-q", "map", str(folder), "-o", str(out), "--depth-features", "500",
                                      "--sensor-height", "1.0", "--world", "2d"])
    assert result.exit_code == 0, result.output
    assert isinstance(load_map(out / "world.occmap"), WorldMap)
    plain = tmp_path / "plain"
    plain.mkdir()
    result = CliRunner().invoke(cli, ["-q", "map", str(plain), "-o", str(tmp_path / "none")])
    assert result.exit_code == 1 and "not a model set" in result.output


# --- depth images in MCAP and ROS bags ------------------------------------------------------


def _same(first, second) -> None:
    assert len(first.positions) == len(second.positions)
    for a, b in zip(first.positions, second.positions):
        np.testing.assert_allclose(a.features.points, b.features.points, atol=1e-9)
        np.testing.assert_allclose(a.features.evidence, b.features.evidence, atol=1e-9)


@pytest.fixture(scope="module")
def depth_mcap(tmp_path_factory, office_frames):
    from occtool.simulate._depth import write_depth_mcap

    frames, _ = office_frames
    return write_depth_mcap(frames, tmp_path_factory.mktemp("mcap") / "office.mcap")


def test_a_depth_mcap_maps_the_office_as_well_as_its_point_cloud(depth_mcap, office_frames) -> None:
    _, scene = office_frames
    log = read_log(depth_mcap, depth_features=1250)
    position = log.single()
    assert position.pose.z == pytest.approx(scene.robot.sensor_height)  # the cameras' mounting height, from tf
    result = _score(position.features, scene)
    from occtool.simulate import simulate_scene

    points, _ = simulate_scene("office", n_features=len(position.features), seed=0)
    assert result.iou >= _score(points, scene).iou - 0.02
    assert result.violation <= 0.005


@pytest.mark.parametrize("encoding", ["32FC1", "compressedDepth", "bag"])
def test_encodings_and_containers_give_the_same_features(tmp_path, depth_mcap, office_frames, encoding) -> None:
    from occtool.simulate._depth import write_depth_bag, write_depth_mcap

    frames, _ = office_frames
    if encoding == "bag":
        pytest.importorskip("rosbags")
        other = write_depth_bag(frames, tmp_path / "office.bag")
    else:
        other = write_depth_mcap(frames, tmp_path / "office.mcap", encoding=encoding)
    reference = read_log(depth_mcap, depth_features=800)
    found = read_log(other, depth_features=800)
    if encoding == "32FC1":  # metres, not rounded to millimetres: the same pixels within 0.5 mm
        assert len(found.single().features) == len(reference.single().features)
        np.testing.assert_allclose(found.single().features.points, reference.single().features.points, atol=1e-3)
    else:
        _same(found, reference)


def test_the_mcap_and_the_folder_of_the_same_frames_agree(tmp_path, depth_mcap, office_frames) -> None:
    frames, _ = office_frames
    folder = write_depth_folder(frames, tmp_path / "tum", layout="3dmatch")  # millimetres, as 16UC1
    from_folder = read_log(folder, position_tolerance=(0.25, 3.2), depth_features=800).single().features
    from_mcap = read_log(depth_mcap, depth_features=800).single().features
    assert len(from_folder) == len(from_mcap)
    # The folder's frames are placed by the floor found in them: within a few mm of the truth.
    np.testing.assert_allclose(from_folder.points, from_mcap.points, atol=0.01)


def _raw_image(depth_mm: np.ndarray, frame: str, encoding: str = "16UC1") -> dict:
    import base64

    return {"timestamp": {"sec": 1, "nsec": 0}, "frame_id": frame, "width": depth_mm.shape[1],
            "height": depth_mm.shape[0], "encoding": encoding, "step": depth_mm.shape[1] * 2,
            "data": base64.b64encode(depth_mm.astype("<u2").tobytes()).decode()}


def _write_json(path: Path, channels: dict[str, tuple[str, list[dict]]]) -> Path:
    import json

    from mcap.writer import Writer

    with open(path, "wb") as handle:
        writer = Writer(handle)
        writer.start()
        k = 0
        for topic, (schema, messages) in channels.items():
            schema_id = writer.register_schema(name=schema, encoding="jsonschema", data=b"{}")
            channel_id = writer.register_channel(topic=topic, message_encoding="json", schema_id=schema_id)
            for message in messages:
                writer.add_message(channel_id, log_time=k, publish_time=k, data=json.dumps(message).encode(),
                                   sequence=k)
                k += 1
        writer.finish()
    return path


def test_a_foxglove_raw_image_without_a_mounting_is_a_level_camera(tmp_path) -> None:
    calibration = {"timestamp": {"sec": 0, "nsec": 0}, "frame_id": "cam", "width": 64, "height": 48,
                   "distortion_model": "plumb_bob", "D": [0.1, 0, 0, 0, 0], "K": CAMERA.matrix.reshape(-1).tolist()}
    depth = np.full((48, 64), 2500, dtype=np.uint16)
    path = _write_json(tmp_path / "raw.mcap", {
        "/cam/calibration": ("foxglove.CameraCalibration", [calibration]),
        "/cam/depth": ("foxglove.RawImage", [_raw_image(depth, "cam")]),
        "/cam/color": ("foxglove.RawImage", [_raw_image(depth, "cam", "rgb8")]),
    })
    log = read_log(path, depth_features=100_000)
    np.testing.assert_allclose(log.single().features.points[:, 0], 2.5)  # ahead, in REP-103
    assert any("taken as level" in note for note in log.notes)
    assert any("distortion coefficients of cam ignored" in note for note in log.notes)
    with pytest.raises(InputError, match="'rgb8', not depth"):
        read_log(path, topics=["/cam/color"])
    no_info = _write_json(tmp_path / "noinfo.mcap", {"/cam/depth": ("foxglove.RawImage", [_raw_image(depth, "cam")])})
    with pytest.raises(InputError, match="no sensor_msgs/msg/CameraInfo"):
        read_log(no_info)
    other = _write_json(tmp_path / "other.mcap", {
        "/cam/calibration": ("foxglove.CameraCalibration", [{**calibration, "frame_id": "elsewhere"}]),
        "/cam/depth": ("foxglove.RawImage", [_raw_image(depth, "cam")])})
    with pytest.raises(InputError, match="no camera info for the image's frame 'cam'"):
        read_log(other)
    wrong = _write_json(tmp_path / "wrong.mcap", {
        "/cam/calibration": ("foxglove.CameraCalibration", [calibration]),
        "/cam/depth": ("foxglove.RawImage", [_raw_image(np.zeros((10, 10), np.uint16), "cam")])})
    with pytest.raises(InputError, match="a 10x10 depth image where the camera info of 'cam' says 64x48"):
        read_log(wrong)


@pytest.mark.slow
def test_a_hand_held_walk_maps_and_is_scored_on_frames_held_out_in_blocks(tmp_path) -> None:
    import json

    from click.testing import CliRunner

    from occtool.cli.main import cli
    from occtool.simulate._depth import walk

    small = PinholeCamera(80, 60, 69.28, 69.28, 39.5, 29.5)
    yaws, positions = walk(16)
    frames, _ = render_depth_frames("office", camera=small, yaws=yaws, positions=positions)
    folder = write_depth_folder(frames, tmp_path / "walk", layout="tum", camera=small)
    log = read_log(folder, depth_features=500)
    assert len(log.positions) > 4 and all(p.pose is not None for p in log.positions)
    first = log.positions[0].pose
    assert (first.x, first.y) == pytest.approx(positions[0], abs=1e-6)
    assert first.yaw == pytest.approx(yaws[0], abs=1e-6)
    runner = CliRunner()
    result = runner.invoke(cli, ["map", str(folder / "depth.txt"), "-o", str(tmp_path / "map"),
                                 "--depth-features", "500"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "map" / "map.pgm").is_file()
    result = runner.invoke(cli, ["evaluate-log", str(folder / "depth.txt"), "--block", "4", "--holdout", "0.25",
                                 "--depth-features", "300", "--json"])
    assert result.exit_code == 0, result.output
    figures = json.loads(result.output[result.output.index("{"):])
    assert figures["scans"] == 16 and figures["held_out_scans"] == 4
    assert 0.5 < figures["auc"]["fused_log_odds"] <= 1.0


def test_a_camera_without_a_mounting_gets_its_tilt_and_height_from_the_floor(tmp_path, office_frames) -> None:
    from mcap_ros2.writer import Writer

    import occtool.simulate._depth as rendering

    frames, _ = office_frames
    definitions = {"sensor_msgs/msg/Image": rendering._IMAGE_DEF, "sensor_msgs/msg/CameraInfo":
                   rendering._CAMERA_INFO_DEF, "tf2_msgs/msg/TFMessage": rendering._TF_DEF}
    path = tmp_path / "unmounted.mcap"
    with open(path, "wb") as handle:
        writer, schemas = Writer(handle), {}
        for topic, kind, message, t in rendering.depth_log_messages(frames[:1]):
            if topic == "/tf_static":
                continue
            if kind not in schemas:
                schemas[kind] = writer.register_msgdef(kind, definitions[kind])
            writer.write_message(topic, schemas[kind], message, log_time=int(t * 1e9), publish_time=int(t * 1e9))
        writer.finish()
    log = read_log(path, depth_features=100_000)
    assert any("tilt (-25.0 degrees) and height (1.00 m) estimated from the floor plane" in n for n in log.notes)
    mounted = read_log(rendering.write_depth_mcap(frames[:1], tmp_path / "mounted.mcap"), depth_features=100_000)
    np.testing.assert_allclose(log.single().features.points, mounted.single().features.points, atol=0.01)
    assert log.single().pose.z == pytest.approx(1.0, abs=0.01)


def test_frames_without_poses_get_the_cameras_tilt_from_the_floor(tmp_path, office_frames) -> None:
    frames, _ = office_frames
    folder = write_depth_folder(frames[:1], tmp_path / "tum", layout="tum")
    (folder / "groundtruth.txt").unlink()
    log = read_log(folder, depth_features=100_000)
    assert log.single().pose is None
    assert any("tilt (-25.0 degrees) and height (1.00 m) estimated from the floor plane" in n for n in log.notes)
    posed = read_log(write_depth_folder(frames[:1], tmp_path / "posed", layout="tum"), depth_features=100_000)
    np.testing.assert_allclose(log.single().features.points, posed.single().features.points, atol=0.01)


def test_a_folder_streams_the_positions_read_log_returns(tmp_path, office_frames) -> None:
    from occtool.io import iter_positions

    frames, _ = office_frames
    world = np.linalg.inv(frames[0].camera_to_world)
    folder = write_depth_folder(frames, tmp_path / "m", layout="3dmatch", world=world)
    whole = read_log(folder, depth_features=300)
    stream = iter_positions(folder, depth_features=300)
    for _ in range(2):  # each iteration reads the folder again
        streamed = list(stream)
        assert len(streamed) == len(whole.positions) == 8
        for a, b in zip(streamed, whole.positions):
            np.testing.assert_array_equal(a.features.points, b.features.points)
            assert a.pose == b.pose
    assert stream.notes == whole.notes


def test_the_fixture_is_what_its_readme_command_makes(tmp_path) -> None:
    from click.testing import CliRunner

    from occtool.cli.main import cli

    result = CliRunner().invoke(cli, ["simulate", "office", "-o", str(tmp_path), "--depth-frames", "tum"])
    assert result.exit_code == 0, result.output
    made = sorted(p.relative_to(tmp_path / "depth-tum") for p in (tmp_path / "depth-tum").rglob("*") if p.is_file())
    kept = sorted(p.relative_to(FIXTURES / "depth-office") for p in (FIXTURES / "depth-office").rglob("*")
                  if p.is_file())
    assert made == kept
    from occtool.io.depth_folders import read_depth_png

    for name in made:
        mine, theirs = tmp_path / "depth-tum" / name, FIXTURES / "depth-office" / name
        if name.suffix == ".png":  # the pixels, not the bytes (zlib's output may differ between builds)
            np.testing.assert_array_equal(read_depth_png(mine), read_depth_png(theirs))
        else:
            assert mine.read_text() == theirs.read_text(), name


@pytest.mark.parametrize("camera, distorted", [("freiburg1", True), ("freiburg2", True), ("freiburg3", False)])
def test_tum_distortion_is_ignored_with_one_warning(tmp_path, camera, distorted) -> None:
    """freiburg1's and freiburg2's published distortion is not applied (no OpenCV): one warning says so."""
    import shutil

    pytest.importorskip("PIL")
    real = FIXTURES / "tum-fr3-cabinet"
    folder = tmp_path / f"rgbd_dataset_{camera}_test"
    (folder / "depth").mkdir(parents=True)
    listed = [line for line in (real / "depth.txt").read_text().splitlines() if not line.startswith("#")][:2]
    for line in listed:
        shutil.copy(real / line.split()[1], folder / line.split()[1])
    (folder / "depth.txt").write_text("\n".join(listed) + "\n")
    shutil.copy(real / "groundtruth.txt", folder / "groundtruth.txt")  # no camera-intrinsics.txt: TUM's by name
    log = read_log(folder, group_by="message", depth_features=500)
    assert any(f"TUM's {camera} camera (" in note for note in log.notes)
    warned = [note for note in log.notes if "distortion" in note]
    assert len(warned) == (1 if distorted else 0)
    if distorted:
        assert warned[0].startswith("warning:") and "ignored" in warned[0]
