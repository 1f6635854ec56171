"""`occtool.formats.foxglove`: the MCAP of a run's map, read back with the `mcap` reader."""

from __future__ import annotations

import io
import math

import numpy as np
import pytest

pytest.importorskip("mcap")
pytest.importorskip("mcap_protobuf")
pytest.importorskip("foxglove_schemas_protobuf")

from foxglove_schemas_protobuf import LinePrimitive_pb2, PackedElementField_pb2  # noqa: E402
from mcap.reader import make_reader  # noqa: E402
from mcap_protobuf.decoder import DecoderFactory  # noqa: E402

from occtool.features import Pose  # noqa: E402
from occtool.formats.foxglove import BASE_FRAME, FRAME, GRID_TOPIC, SCENE_TOPIC, TF_TOPIC, run_map_mcap_bytes  # noqa: E402
from occtool.fuse import FREE, OCCUPIED, UNKNOWN, PlacedMap, Raster, RunMap  # noqa: E402  # noqa: E402
from occtool.navigation import navigation_map  # noqa: E402
from occtool.robot import Robot  # noqa: E402

# Three rows (row 0 the bottom, at the origin's y) of four columns.
CELLS = np.array([[FREE, FREE, OCCUPIED, UNKNOWN],
                  [UNKNOWN, FREE, FREE, OCCUPIED],
                  [OCCUPIED, OCCUPIED, UNKNOWN, FREE]], dtype=np.uint8)
OCCUPANCY = np.array([[0, 0, 100, -1], [-1, 0, 0, 100], [100, 100, -1, 0]], dtype=np.int8)
RESOLUTION = 0.25
ORIGIN = (-1.5, 2.0)
POSES = [Pose(1.0, 2.0, 0.0, 0.0), Pose(-0.5, 3.0, 0.0, math.pi / 2)]
STAMPS = [12.5, 13.25]


def room(alpha, h, level):
    """A round room of radius 1 m with a doorway ahead: a polygon and points of both kinds."""
    alpha, h = np.broadcast_arrays(alpha, h)
    return np.where(np.abs(alpha) < math.asin(0.4), np.inf, np.sqrt(1.0 + np.square(h)))


def run_map(trajectory=()):
    nav = navigation_map(room, robot=Robot(radius=0.25), heights=[-0.5], max_range=1.5)
    placed = [PlacedMap(position, pose, stamp, nav.in_world(pose))
              for position, pose, stamp in zip((3, 7), POSES, STAMPS)]
    raster = Raster(CELLS, RESOLUTION, ORIGIN, np.full(CELLS.shape, 0.5, np.float32), np.zeros(CELLS.shape, bool))
    return RunMap(fused=None, world=None, raster=raster, placed=placed, navigation=None,
                  obstacles=np.zeros((0, 2)), frontiers=np.zeros((0, 2)), trajectory=list(trajectory))


def read(data):
    """``{topic: [(schema name, log time, decoded message), ...]}`` in the order written."""
    reader = make_reader(io.BytesIO(data), decoder_factories=[DecoderFactory()])
    topics = {}
    for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
        assert channel.message_encoding == "protobuf"
        topics.setdefault(channel.topic, []).append((schema.name, message.log_time, decoded))
    return topics


@pytest.fixture(scope="module")
def plain():
    run = run_map()
    return run, read(run_map_mcap_bytes(run))


def test_the_topics_and_their_schemas(plain):
    _, topics = plain
    assert sorted(topics) == sorted([GRID_TOPIC, SCENE_TOPIC]) == ["/map", "/positions"]
    assert {name for name, _, _ in topics[GRID_TOPIC]} == {"foxglove.Grid"}
    assert {name for name, _, _ in topics[SCENE_TOPIC]} == {"foxglove.SceneUpdate"}
    assert len(topics[GRID_TOPIC]) == 1 and len(topics[SCENE_TOPIC]) == 2


def test_the_grid_is_the_raster_in_occupancy_grid_values(plain):
    _, topics = plain
    _, log_time, grid = topics[GRID_TOPIC][0]
    assert grid.frame_id == FRAME == "map"
    assert (grid.pose.position.x, grid.pose.position.y, grid.pose.position.z) == (*ORIGIN, 0.0)
    assert (grid.pose.orientation.x, grid.pose.orientation.y, grid.pose.orientation.z,
            grid.pose.orientation.w) == (0.0, 0.0, 0.0, 1.0)
    assert (grid.cell_size.x, grid.cell_size.y) == (RESOLUTION, RESOLUTION)
    assert grid.column_count == 4 and grid.row_stride == 4 and grid.cell_stride == 1
    int8 = PackedElementField_pb2.PackedElementField.INT8
    assert [(f.name, f.offset, f.type) for f in grid.fields] == [("occupancy", 0, int8)]
    rows = len(grid.data) // grid.row_stride
    assert rows == 3 and len(grid.data) == CELLS.size
    np.testing.assert_array_equal(np.frombuffer(grid.data, dtype=np.int8).reshape(rows, 4), OCCUPANCY)
    # Stamped when the last position was seen.
    assert log_time == grid.timestamp.ToNanoseconds() == round(STAMPS[-1] * 1e9)


def test_each_position_is_a_scene_entity_on_its_stamp(plain):
    run, topics = plain
    for (_, log_time, update), item in zip(topics[SCENE_TOPIC], run.placed):
        assert log_time == round(item.stamp * 1e9)
        (entity,) = update.entities
        assert entity.id == f"position-{item.position}" and entity.frame_id == "map"
        assert entity.timestamp.ToNanoseconds() == log_time
        rings = [item.nav.polygon.exterior, *item.nav.polygon.interiors]
        assert len(entity.lines) == len(rings) > 0
        for line, ring in zip(entity.lines, rings):
            # A loop: the ring without its closing point.
            assert line.type == LinePrimitive_pb2.LinePrimitive.LINE_LOOP
            np.testing.assert_array_equal([(p.x, p.y, p.z) for p in line.points],
                                          np.c_[np.asarray(ring.coords)[:-1], np.zeros(len(ring.coords) - 1)])
        obstacles, exploration = item.nav.obstacle_points, item.nav.exploration_points
        assert len(obstacles) > 0 and len(exploration) > 0
        assert len(entity.spheres) == len(obstacles) + len(exploration)
        centres = np.array([(s.pose.position.x, s.pose.position.y) for s in entity.spheres])
        np.testing.assert_allclose(centres, np.concatenate([obstacles, exploration]))
        reds = [s.color.r > 0.5 and s.color.g < 0.5 for s in entity.spheres]
        assert reds == [True] * len(obstacles) + [False] * len(exploration)
    # The same room seen from two poses, each in the world where its pose put it: the
    # second outline is the first's moved from (1, 2) to (-0.5, 3) and turned a quarter.
    first, second = (np.array([(p.x, p.y) for p in update.entities[0].lines[0].points])
                     for _, _, update in topics[SCENE_TOPIC])
    quarter = np.array([[0.0, -1.0], [1.0, 0.0]])
    np.testing.assert_allclose(second - [-0.5, 3.0], (first - [1.0, 2.0]) @ quarter.T, atol=1e-9)


def test_registered_poses_go_on_tf():
    trajectory = [(20.0, Pose(1.0, 2.0, 0.0, math.pi / 2)), (None, Pose(-1.0, 0.5, 0.1, -math.pi))]
    topics = read(run_map_mcap_bytes(run_map(trajectory)))
    assert sorted(topics) == ["/map", "/positions", "/tf"] and TF_TOPIC == "/tf"
    transforms = topics[TF_TOPIC]
    assert [name for name, _, _ in transforms] == ["foxglove.FrameTransform"] * 2
    # A pose without a stamp is placed 0.1 s per scan from the start.
    assert [log_time for _, log_time, _ in transforms] == [20_000_000_000, 100_000_000]
    for (_, _, message), (_, pose) in zip(transforms, trajectory):
        assert (message.parent_frame_id, message.child_frame_id) == ("map", BASE_FRAME)
        assert (message.translation.x, message.translation.y, message.translation.z) == (pose.x, pose.y, pose.z)
        q = message.rotation
        assert (q.x, q.y) == (0.0, 0.0)
        assert 2.0 * math.atan2(q.z, q.w) == pytest.approx(pose.yaw)
        assert q.z**2 + q.w**2 == pytest.approx(1.0)


@pytest.mark.parametrize("stamp", [math.nan, -1.0, 1e300, math.inf])
def test_a_stamp_that_is_no_time_keeps_the_messages_order(stamp):
    # A library caller's stamps are not read from an index: they must not overflow the writer.
    run = run_map()
    run.placed[0].stamp = stamp
    times = [log_time for _, log_time, _ in read(run_map_mcap_bytes(run))[SCENE_TOPIC]]
    assert times[1] == round(STAMPS[1] * 1e9) and 0 <= times[0] <= times[1]
