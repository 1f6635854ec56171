"""Reachable region and navigation scores against geometric answers worked out by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import example, given, settings
from hypothesis import strategies as st

from occtool.errors import InputError
from occtool.robot import Robot
from occtool.scoring import (
    as_polygon,
    blocking_obstacles,
    configuration_obstacles,
    evaluate_navigation,
    reachable_region,
    robot_frame_points,
    robot_frame_polygon,
    true_reach,
)
from occtool.simulate import SCENES, Scene, box, build_scene

ROBOT = Robot(radius=0.25, sensor_height=1.0, body_height=1.0, ground_clearance=0.05)


def segment_area(radius: float, d: float) -> float:
    """Area of the part of a disk of ``radius`` beyond the chord at distance ``d`` from its centre."""
    return radius**2 * math.acos(d / radius) - d * math.sqrt(radius**2 - d**2)


def room(half: float, *extra) -> Scene:
    """A square room of inner half-width ``half`` around the robot, plus extra obstacles."""
    t = 0.1
    walls = [
        box("n", -half - t, half, half + t, half + t, 0.0, 2.5),
        box("s", -half - t, -half - t, half + t, -half, 0.0, 2.5),
        box("e", half, -half, half + t, half, 0.0, 2.5),
        box("w", -half - t, -half, -half, half, 0.0, 2.5),
    ]
    return Scene(tuple(walls) + tuple(extra), ROBOT, "room")


def wall_ahead(distance: float, z_min: float = 0.0, z_max: float = 2.5) -> Scene:
    return Scene((box("wall", distance, -5.0, distance + 0.1, 5.0, z_min, z_max),), ROBOT, "wall")


def test_far_walls_leave_the_whole_disk() -> None:
    region = reachable_region(room(5.0), max_range=2.0)
    assert region.area == pytest.approx(math.pi * 4.0, rel=1e-4)


def test_close_walls_leave_the_room_shrunk_by_the_radius() -> None:
    # Inner half-width 0.9 shrunk by 0.25: a 1.3 m square, its corners (0.92 m) inside the 1 m disk.
    region = reachable_region(room(0.9), max_range=1.0)
    assert region.area == pytest.approx(1.3**2, rel=1e-4)
    assert region.bounds == pytest.approx((-0.65, -0.65, 0.65, 0.65), abs=1e-3)


def test_wall_one_metre_ahead_cuts_the_disk_at_one_minus_radius() -> None:
    region = reachable_region(wall_ahead(1.0), max_range=1.5)
    expected = math.pi * 1.5**2 - segment_area(1.5, 0.75)
    assert region.area == pytest.approx(expected, rel=1e-4)
    assert region.bounds[2] == pytest.approx(0.75, abs=1e-6)


@pytest.mark.parametrize("height", [0.03, 0.05])
def test_obstacle_under_the_clearance_does_not_cut(height: float) -> None:
    region = reachable_region(wall_ahead(1.0, 0.0, height), max_range=1.5)
    assert region.area == pytest.approx(math.pi * 1.5**2, rel=1e-4)


def test_pallet_above_the_clearance_cuts() -> None:
    region = reachable_region(wall_ahead(1.0, 0.0, 0.15), max_range=1.5)
    assert region.bounds[2] == pytest.approx(0.75, abs=1e-6)


def test_table_top_in_the_body_band_cuts_and_above_the_body_does_not() -> None:
    table = wall_ahead(1.0, 0.70, 0.75)
    cut = reachable_region(table, max_range=1.5)
    assert cut.bounds[2] == pytest.approx(0.75, abs=1e-6)
    short_robot = table.with_robot(Robot(radius=0.25, sensor_height=0.6, body_height=0.65))
    assert reachable_region(short_robot, max_range=1.5).area == pytest.approx(math.pi * 1.5**2, rel=1e-4)


def test_region_behind_a_box_is_shadowed_and_star_shaped() -> None:
    scene = Scene((box("box", 0.8, -0.2, 1.2, 0.2, 0.0, 0.5),), ROBOT)
    region = reachable_region(scene, max_range=2.0)
    assert not region.contains(shapely.Point(1.8, 0.0))  # behind the box: not reachable straight
    assert region.contains(shapely.Point(1.0, 1.5))  # beside it
    rng = np.random.default_rng(3)
    points = rng.uniform(-2, 2, (400, 2))
    inside = points[shapely.contains_xy(region, points[:, 0], points[:, 1])]
    segments = shapely.linestrings(np.stack([np.zeros_like(inside), inside * 0.999], axis=1))
    assert shapely.covered_by(segments, region.buffer(1e-6)).all()


def test_robot_touching_an_obstacle_has_an_empty_region() -> None:
    assert reachable_region(wall_ahead(0.2), max_range=1.0).is_empty


@pytest.mark.parametrize("name", sorted(SCENES))
@pytest.mark.parametrize("max_range", [1.0, 2.5])
def test_truth_scores_perfectly_against_itself(name: str, max_range: float) -> None:
    scene = build_scene(name)
    truth = reachable_region(scene, max_range=max_range)
    result = evaluate_navigation(truth, scene, max_range=max_range)
    assert result.iou == pytest.approx(1.0, abs=1e-9)
    assert result.violation == pytest.approx(0.0, abs=1e-9)
    assert result.coverage == pytest.approx(1.0, abs=1e-9)
    assert 0 < result.area <= math.pi * max_range**2


def test_whole_disk_against_a_wall_scores_the_known_violation() -> None:
    scene = wall_ahead(1.0)
    disk = shapely.Point(0, 0).buffer(1.5, quad_segs=256)
    result = evaluate_navigation(disk, scene, max_range=1.5)
    beyond_cut = segment_area(1.5, 0.75)
    # The grown wall spans x in [0.75, 1.35]; past it lies shadow, unreachable but not a collision.
    in_wall = beyond_cut - segment_area(1.5, 1.35)
    assert result.violation == pytest.approx(in_wall / disk.area, rel=2e-3)
    assert result.excess == pytest.approx(beyond_cut / disk.area, rel=2e-3)
    assert result.iou == pytest.approx((disk.area - beyond_cut) / disk.area, rel=2e-3)


def test_shrunken_truth_is_safe_with_lower_iou() -> None:
    scene = build_scene("office")
    truth = reachable_region(scene, max_range=2.0)
    inner = truth.buffer(-0.1)
    result = evaluate_navigation(inner, scene, max_range=2.0)
    assert result.violation == 0.0
    assert result.iou == pytest.approx(inner.area / truth.area, rel=1e-6)
    assert result.iou < 0.95


def test_vertex_array_and_empty_polygon_are_accepted() -> None:
    scene = room(3.0)
    square = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    result = evaluate_navigation(square, scene, max_range=1.0)
    assert result.area == pytest.approx(1.0)
    assert result.iou == pytest.approx(1.0 / result.truth_area, rel=1e-6)
    empty = evaluate_navigation(shapely.Polygon(), scene, max_range=1.0)
    assert empty.area == 0.0 and empty.iou == 0.0 and empty.violation == 0.0
    with pytest.raises(InputError):
        evaluate_navigation(np.array([[0.0, 0.0], [1.0, np.nan], [1.0, 1.0]]), scene, max_range=1.0)


def test_as_polygon_makes_vertices_valid_and_refuses_what_is_not_an_area() -> None:
    # A bow tie is invalid: made valid it is its two triangles, 0.25 m2 each.
    bow_tie = as_polygon(np.array([[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]]))
    assert bow_tie.is_valid and bow_tie.area == pytest.approx(0.5)
    assert as_polygon(np.zeros((0, 2))).is_empty
    for bad in (np.zeros((2, 2)), np.zeros((4, 3)), shapely.LineString([(0, 0), (1, 1)])):
        with pytest.raises(InputError):
            as_polygon(bad)


def test_blocking_obstacles_are_those_overlapping_the_body_band() -> None:
    # ROBOT: ground clearance 0.05 m, body height 1 m.
    kerb = box("kerb", 1, 0, 2, 1, 0.0, 0.05)  # at the clearance: driven over
    pallet = box("pallet", 1, 0, 2, 1, 0.0, 0.06)
    table = box("table", 1, 0, 2, 1, 0.7, 0.75)
    shelf = box("shelf", 1, 0, 2, 1, 1.0, 1.2)  # at the body's top: passes over
    scene = Scene((kerb, pallet, table, shelf), ROBOT)
    assert [o.name for o in blocking_obstacles(scene)] == ["pallet", "table"]


def test_robot_frame_points_know_answers() -> None:
    from occtool.features import Pose

    # A robot at (1, 2) facing +y: a point 1 m north of it is 1 m ahead, one east of it 1 m to the right.
    points = robot_frame_points([[1.0, 3.0], [2.0, 2.0], [1.0, 2.0]], Pose(x=1.0, y=2.0, yaw=math.pi / 2))
    np.testing.assert_allclose(points, [[1.0, 0.0], [0.0, -1.0], [0.0, 0.0]], atol=1e-12)


@given(
    x=st.floats(0.5, 2.0), y=st.floats(-2.0, 2.0), w=st.floats(0.05, 1.0),
    radius=st.floats(0.0, 0.4), max_range=st.floats(0.5, 3.0),
)
def test_region_never_overlaps_grown_obstacles_and_stays_in_the_disk(
    x: float, y: float, w: float, radius: float, max_range: float
) -> None:
    scene = Scene((box("b", x, y, x + w, y + w, 0.0, 1.0),), ROBOT)
    if configuration_obstacles(scene, robot_radius=radius).contains(shapely.Point(0, 0)):
        return
    region = reachable_region(scene, robot_radius=radius, max_range=max_range, n_rays=720)
    grown = configuration_obstacles(scene, robot_radius=radius)
    assert shapely.intersection(region, grown).area < 1e-9
    assert region.area <= math.pi * max_range**2 + 1e-9


def test_robot_frame_polygon_undoes_the_pose() -> None:
    from occtool.features import Pose

    pose = Pose(x=3.0, y=-1.0, yaw=0.8)
    square = shapely.Polygon([(0.2, 0.0), (1.0, 0.0), (1.0, 0.5), (0.2, 0.5)])
    world = shapely.transform(square, pose.to_world)
    back = robot_frame_polygon(world, pose)
    assert shapely.symmetric_difference(back, square).area < 1e-12


@settings(max_examples=30)
@given(seed=st.integers(0, 2**16), radius=st.floats(0.0, 0.4), max_range=st.floats(0.5, 2.5))
def test_region_agrees_with_a_direct_segment_check(seed: int, radius: float, max_range: float) -> None:
    # A point is reachable when it lies in the disk and the segment to it misses every grown
    # obstacle; check that for random points away from the region's boundary.
    rng = np.random.default_rng(seed)
    boxes = []
    for i in range(4):
        x, y = rng.uniform(-2.5, 2.5, 2)
        w, d = rng.uniform(0.05, 0.8, 2)
        z_min = rng.choice([0.0, 0.0, 0.7, 1.2])
        boxes.append(box(f"b{i}", x, y, x + w, y + d, z_min, z_min + rng.uniform(0.02, 0.6)))
    scene = Scene(tuple(boxes), ROBOT)
    grown = configuration_obstacles(scene, robot_radius=radius)
    if grown.intersects(shapely.Point(0, 0)):
        return
    region = reachable_region(scene, robot_radius=radius, max_range=max_range)
    points = rng.uniform(-max_range, max_range, (300, 2))
    clear = shapely.distance(region.boundary, shapely.points(points)) > 0.01
    points = points[clear]
    segments = shapely.linestrings(np.stack([np.zeros_like(points), points], axis=1))
    direct = (np.hypot(points[:, 0], points[:, 1]) <= max_range) & ~shapely.intersects(segments, grown)
    np.testing.assert_array_equal(shapely.contains_xy(region, points[:, 0], points[:, 1]), direct)


@settings(max_examples=20)
@given(yaw=st.floats(-math.pi, math.pi), name=st.sampled_from(sorted(SCENES)))
@example(yaw=3.048988447567546, name="aisle")  # a ray slips past the beam's tip in one sweep only
@example(yaw=1.1959773690841713, name="aisle")  # the grown shelves by the 0.5 m gap: an overlay went wrong
def test_region_turns_with_the_scene(yaw: float, name: str) -> None:
    scene = build_scene(name)
    max_range, n_rays = 1.5, 1440
    region = reachable_region(scene, max_range=max_range, n_rays=n_rays)
    turned = reachable_region(scene.rotated(yaw), max_range=max_range, n_rays=n_rays)
    expected = shapely.affinity.rotate(region, yaw, origin=(0, 0), use_radians=True)
    # Rays sample the turned scene at other angles: the two differ by slivers along the
    # boundary, and by the wedge of a ray that passes a thin obstacle's tip in one sweep
    # and not in the other (a few, each at most half the max range squared times the step).
    wedge = 0.5 * max_range**2 * 2 * math.pi / n_rays
    assert shapely.symmetric_difference(expected, turned).area < 5e-3 * region.area + 4 * wedge


def test_touching_footprints_grow_into_their_union() -> None:
    # Two shelves a robot's diameter apart grow into footprints sharing an edge; turned, its
    # two copies end an ulp apart, and GEOS's floating-precision overlay then went wrong
    # without a word (their intersection came out 3.3 m^2, the aisle's obstacles lost 8.7 m^2
    # and the robot saw through the shelves). The overlays snap-round to a grid instead.
    yaw = 1.1959773690841713
    left = [o for o in build_scene("aisle").obstacles if o.name.startswith("shelf left")]
    straight, turned = Scene(tuple(left), ROBOT), Scene(tuple(left), ROBOT).rotated(yaw)
    grown = [shapely.buffer(o.polygon, ROBOT.radius, quad_segs=16) for o in turned.obstacles]
    assert sum(g.area for g in grown) == pytest.approx(configuration_obstacles(turned).area, rel=1e-9)
    assert configuration_obstacles(turned).area == pytest.approx(configuration_obstacles(straight).area, rel=1e-9)
    # The scores of the truth itself stay exact in the turned aisle.
    scene = build_scene("aisle").rotated(yaw)
    result = evaluate_navigation(reachable_region(scene, max_range=1.5, n_rays=1440), scene, max_range=1.5,
                                 n_rays=1440)
    assert result.iou == pytest.approx(1.0, abs=1e-9) and result.violation < 1e-9


def test_office_truth_passes_the_doorway_and_stops_at_the_table() -> None:
    # The 1 m doorway at y = 1.2 leaves a 0.5 m channel (x in [-0.05, 0.45]) for a 0.25 m robot.
    region = reachable_region(build_scene("office"), max_range=1.5)
    assert region.contains(shapely.Point(0.2, 1.45))
    assert not region.contains(shapely.Point(-0.2, 1.1)) and not region.contains(shapely.Point(0.6, 1.1))
    # The table top (0.70-0.75 m, x from 0.9) blocks though nothing of it is at the sensor height.
    assert not region.contains(shapely.Point(0.7, 0.2)) and region.contains(shapely.Point(0.6, 0.2))
    # The 3 cm cable cover at y = -0.7 is driven over; the 15 cm pallet behind is not.
    assert region.contains(shapely.Point(0.8, -0.75))
    assert not region.contains(shapely.Point(-0.5, -0.7))


def test_true_reach_along_known_directions() -> None:
    scene = wall_ahead(1.0)
    angles = np.array([0.0, math.pi / 4, math.pi / 2, math.pi])
    reach = true_reach(scene, angles, max_range=1.5)
    assert reach == pytest.approx([0.75, 0.75 * math.sqrt(2.0), 1.5, 1.5], abs=1e-9)
    assert (true_reach(wall_ahead(0.2), angles, max_range=1.5) == 0).all()


def test_true_reach_in_a_square_room_of_side_two() -> None:
    # Inner half-width 1 + radius: the walls grown by the radius leave the square |x|, |y| <= 1
    # (its corners sharp: the inner corners of the grown walls), so the reach along a is
    # min(1/|cos a|, 1/|sin a|), sqrt(2) at the corners. Angles past +-pi turn the same way.
    scene = room(1.0 + ROBOT.radius)
    angles = np.concatenate([np.linspace(-math.pi, math.pi, 721), [k * math.pi / 4 for k in range(-12, 13)],
                             np.linspace(-4 * math.pi, 4 * math.pi, 333)])
    with np.errstate(divide="ignore"):
        expected = np.minimum(1.0 / np.abs(np.cos(angles)), 1.0 / np.abs(np.sin(angles)))
    np.testing.assert_allclose(true_reach(scene, angles, max_range=5.0), expected, rtol=0, atol=1e-9)
    # Capped at the max range: the disk of radius 1.2 pokes out of the square only by its corners.
    np.testing.assert_allclose(true_reach(scene, angles, max_range=1.2), np.minimum(expected, 1.2), rtol=0, atol=1e-9)


def test_true_reach_grazes_vertices_and_follows_edges() -> None:
    # Robot radius 0: the C-space obstacle is the footprint, the square [1, 2] x [0, 1].
    scene = Scene((box("b", 1.0, 0.0, 2.0, 1.0, 0.0, 2.0),), ROBOT)
    angles = np.array([
        0.0,                      # along the bottom edge: touches it at (1, 0)
        math.atan2(1.0, 1.0),     # through the corner (1, 1) only, grazing it
        math.atan2(1.0, 2.0),     # into the left edge at (1, 0.5), out through the corner (2, 1)
        math.atan2(1.0, 2.0) + 2 * math.pi,  # the same, a turn on (a turn on from 0 is not: sin 2pi < 0)
        math.atan2(1.0, 2.0) - 4 * math.pi,  # and two turns back
        -1e-6,                    # just below the box: misses
        math.atan2(1.0, 1.0) + 1e-6,  # just above the corner: misses
        math.pi,                  # away from it
    ])
    reach = true_reach(scene, angles, robot_radius=0.0, max_range=3.0)
    np.testing.assert_allclose(reach, [1.0, math.sqrt(2.0)] + [math.hypot(1.0, 0.5)] * 3 + [3.0] * 3,
                               rtol=0, atol=1e-9)


def test_true_reach_is_zero_with_the_origin_on_an_obstacles_boundary() -> None:
    # The wall's grown face runs through the robot's centre: it already touches the wall.
    on, off = wall_ahead(ROBOT.radius), wall_ahead(ROBOT.radius + 1e-6)
    angles = np.linspace(-math.pi, math.pi, 16, endpoint=False)
    assert (true_reach(on, angles, max_range=1.0) == 0).all() and reachable_region(on, max_range=1.0).is_empty
    assert true_reach(off, np.array([0.0, math.pi]), max_range=1.0) == pytest.approx([1e-6, 1.0], abs=1e-9)


@pytest.mark.parametrize("name", ["clutter", "aisle"])
def test_the_truths_ray_filter_and_blocks_change_nothing(monkeypatch, name: str) -> None:
    # The edges are filtered by the wedge of each block of rays; every edge against every
    # ray, a few rays at a time, gives the very same reaches.
    from occtool.scoring import _rays

    scene = build_scene(name, yaw=0.7)
    angles = np.concatenate([np.linspace(-math.pi, math.pi, 1440, endpoint=False),
                             np.random.default_rng(0).uniform(-10, 10, 200)])
    reach = true_reach(scene, angles, max_range=3.0)
    assert (reach < 3.0).any()
    monkeypatch.setattr(_rays, "_edges_in_wedge", lambda c, s, x1, *rest: np.ones(len(x1), dtype=bool))
    monkeypatch.setattr(_rays, "PAIRS_PER_BLOCK", 2000)
    np.testing.assert_array_equal(true_reach(scene, angles, max_range=3.0), reach)


def test_the_truth_casts_its_own_rays() -> None:
    # The judge shares no code with the maps it judges: a bug in the navigation maps' ray
    # caster must not turn up in the truth too.
    import ast
    import inspect
    import subprocess
    import sys

    from occtool.scoring import _polygon, _rays

    for module in (_polygon, _rays):
        tree = ast.parse(inspect.getsource(module))
        imported = [node.module or "" for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)]
        imported += [alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names]
        assert imported and not [name for name in imported if name.startswith("occtool.navigation")]
        assert not [name for name, value in vars(module).items()
                    if getattr(value, "__module__", "").startswith("occtool.navigation")]
    loaded = subprocess.run([sys.executable, "-c", "import sys, occtool.scoring as s; s.true_reach; "
                             "print(sorted(m for m in sys.modules if m.startswith('occtool.navigation')))"],
                            capture_output=True, text=True, check=True).stdout
    assert loaded.strip() == "[]"


def test_points_are_judged_by_their_direction() -> None:
    scene = wall_ahead(1.0)
    obstacle = np.array([[0.75, 0.0], [0.5, 0.5], [0.0, 1.5], [-1.5, 0.0]])  # the last two face open space
    exploration = np.array([[0.0, 1.5], [0.0, -1.5], [1.5, 0.0]])  # the last faces the wall
    result = evaluate_navigation(reachable_region(scene, max_range=1.5), scene, max_range=1.5,
                                 obstacle_points=obstacle, exploration_points=exploration)
    assert result.obstacle_accuracy == pytest.approx(0.5)
    assert result.exploration_accuracy == pytest.approx(2 / 3)
    plain = evaluate_navigation(shapely.Polygon(), scene, max_range=1.5)
    assert plain.obstacle_accuracy is None and "obstacle_accuracy" not in plain.to_dict()


def test_the_blind_radius_is_where_the_lowest_ray_meets_the_obstacles_top():
    from occtool.scoring import blind_radius

    robot = Robot()  # sensor 1 m up, body 0.05-1.0 m
    down, up = math.radians(-50.0), math.radians(30.0)
    pallet = box("pallet", 0.5, -0.2, 1.0, 0.2, 0.0, 0.15)
    assert blind_radius(pallet, robot, tilt_range=(down, up)) == pytest.approx(0.85 / math.tan(math.radians(50.0)))
    # Taller than the sensor: the horizontal ray sees it at any distance, beyond the minimum range.
    wall = box("wall", 0.5, -1.0, 0.6, 1.0, 0.0, 2.5)
    assert blind_radius(wall, robot, tilt_range=(down, up)) == 0.0
    assert blind_radius(wall, robot, tilt_range=(down, up), min_range=0.2) == 0.0
    # Hanging above the sensor, it is seen by rays tilted up only.
    lamp = box("lamp", 0.5, -0.1, 0.7, 0.1, 1.2, 1.5)
    tall = Robot(body_height=1.6)
    assert blind_radius(lamp, tall, tilt_range=(down, up)) == pytest.approx(0.2 / math.tan(up))
    assert blind_radius(lamp, tall, tilt_range=(down, 0.0)) == math.inf


def test_the_violation_splits_into_what_the_sensor_could_see_and_its_blind_zone():
    from occtool.scoring import observable_footprints, violation_by_observability

    # A pallet 0.15 m high from 0.55 to 1.0 m ahead: a camera tilting down to -50 degrees
    # from 1 m sees its top from 0.713 m on; the 0.16 m in front of that are blind.
    robot = Robot()
    scene = Scene((box("pallet", 0.55, -0.1, 1.0, 0.1, 0.0, 0.15),), robot, "pallet", "")
    field = {"tilt_range": (math.radians(-50.0), math.radians(30.0)), "min_range": 0.2}
    (_, seen), = observable_footprints(scene, **field)
    reach = 0.85 / math.tan(math.radians(50.0))  # 0.713 m
    # The disk's edge meets the pallet's sides (y = +-0.1) nearest.
    assert seen.bounds[0] == pytest.approx(math.sqrt(reach**2 - 0.1**2), abs=1e-4) and seen.bounds[2] == 1.0
    # Within the radius of the blind front only, more than the radius from the seen part.
    blind = shapely.box(0.31, -0.05, 0.41, 0.05)
    assert violation_by_observability(blind, scene, **field) == pytest.approx(
        {"violation": 1.0, "observable": 0.0, "unobservable": 1.0})
    # Beside the seen part, 2-12 cm from it.
    beside = shapely.box(0.75, 0.12, 0.85, 0.22)
    assert violation_by_observability(beside, scene, **field) == pytest.approx(
        {"violation": 1.0, "observable": 1.0, "unobservable": 0.0})
    # A third of each and a third clear; the full violation is evaluate_navigation's.
    both = shapely.union_all([blind, beside, shapely.box(-0.5, -0.05, -0.4, 0.05)])
    split = violation_by_observability(both, scene, **field)
    assert split["observable"] == pytest.approx(1 / 3) and split["unobservable"] == pytest.approx(1 / 3)
    assert split["violation"] == pytest.approx(evaluate_navigation(both, scene, max_range=1.5).violation)
