"""Scenes, the simulated stereo camera and the truth file."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import shapely
from hypothesis import assume, given
from hypothesis import strategies as st

from occtool.errors import InputError
from occtool.robot import Robot
from occtool.scoring import reachable_region
from occtool.simulate import (
    FLOOR,
    NOTHING,
    SCENES,
    TILT_RANGE,
    Obstacle,
    Scene,
    box,
    build_scene,
    cast_rays,
    load_truth,
    simulate_scene,
)


def true_ranges(features, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Range to the first surface along each feature's ray, and the surface hit."""
    return cast_rays(scene, features.points)


def test_contract_scenes_exist() -> None:
    assert {"office", "corridor"} <= set(SCENES)
    assert len(SCENES) >= 3
    for name in SCENES:
        scene = build_scene(name)
        assert scene.name == name and scene.description == SCENES[name] and scene.obstacles


def test_unknown_scene_names_the_choices() -> None:
    with pytest.raises(InputError, match="office"):
        build_scene("garage")


def test_office_has_its_parts() -> None:
    scene = build_scene("office")
    by_name = {o.name: o for o in scene.obstacles}
    top = by_name["table top"]
    assert top.z_max - top.z_min == pytest.approx(0.05)
    assert 0.6 <= top.z_min <= 0.8
    assert top.z_max < scene.robot.sensor_height  # no part of the top at the sensor height
    assert by_name["pallet"].z_max == pytest.approx(0.15)
    assert sum("leg" in name for name in by_name) == 4
    # A doorway within 1.5 m: rays through it reach no wall.
    ranges, surface = cast_rays(scene, [[0.0, 1.0, 0.0], [0.4, 1.0, 0.0]])
    assert (surface == NOTHING).all()


def test_cast_rays_known_hits() -> None:
    scene = Scene((box("wall", 1.0, -5.0, 1.1, 5.0, 0.0, 2.5), box("top", -2.0, -0.5, -1.0, 0.5, 0.7, 0.75)),
                  Robot(sensor_height=1.0))
    directions = [
        [1.0, 0.0, 0.0],      # straight at the wall
        [1.0, 1.0, 0.0],      # at 45 degrees: sqrt(2)
        [0.0, 0.0, -1.0],     # down to the floor
        [0.0, 1.0, 0.0],      # along the wall: nothing
        [-1.5, 0.0, -0.25],   # onto the table top (0.25 m below the sensor) at x = -1.5
        [1.0, 0.0, 2.0],      # over the wall (top at 1.5 m above the sensor, x = 1 reached at z = 2)
    ]
    ranges, surface = cast_rays(scene, directions)
    assert ranges[:3] == pytest.approx([1.0, math.sqrt(2.0), 1.0])
    assert surface[:3].tolist() == [0, 0, FLOOR]
    assert surface[3] == NOTHING and np.isinf(ranges[3])
    assert surface[4] == 1 and ranges[4] == pytest.approx(math.hypot(1.5, 0.25))
    assert surface[5] == NOTHING


def test_noise_free_features_lie_on_surfaces_with_the_floor_among_them() -> None:
    features, scene = simulate_scene("office", n_features=3000, seed=2, range_noise=0.0, outlier_rate=0.0)
    ranges, surface = true_ranges(features, scene)
    assert features.range == pytest.approx(ranges, abs=1e-9)
    assert (features.points[:, 2] >= scene.robot.floor_h - 1e-9).all()
    on_floor = surface == FLOOR
    assert 0.2 < on_floor.mean() < 0.9
    assert features.points[on_floor, 2] == pytest.approx(np.full(on_floor.sum(), -1.0))
    names = {scene.obstacles[i].name for i in np.unique(surface[~on_floor])}
    assert {"table top", "pallet", "box large"} <= names
    # Tilt stays within the pan-tilt unit's range.
    tilt = np.arcsin(features.points[:, 2] / features.range)
    assert tilt.min() >= TILT_RANGE[0] - 1e-9 and tilt.max() <= TILT_RANGE[1] + 1e-9


def test_outlier_share_and_noise_level() -> None:
    rate, noise = 0.05, 0.003
    features, scene = simulate_scene("office", n_features=10000, seed=5, range_noise=noise, outlier_rate=rate)
    ranges, _ = true_ranges(features, scene)
    residual = features.range - ranges
    sigma = noise * ranges**2
    wrong = np.abs(residual) > 5 * sigma + 1e-6
    # Outliers landing within 5 sigma of the true range cannot be told apart: a little under the rate.
    assert 0.8 * rate < wrong.mean() < 1.2 * rate
    good = residual[~wrong] / sigma[~wrong]
    assert np.std(good) == pytest.approx(1.0, abs=0.05)


def test_evidence_is_mostly_high() -> None:
    features, _ = simulate_scene("corridor", n_features=4000, seed=1)
    m = features.evidence
    assert ((m >= 0) & (m <= 1)).all()
    assert ((m >= 0.7) & (m <= 1.0)).mean() > 0.8
    assert m.std() > 0.02  # a spread, not a constant


def test_deterministic_for_a_seed() -> None:
    a, _ = simulate_scene("clutter", n_features=1000, seed=7)
    b, _ = simulate_scene("clutter", n_features=1000, seed=7)
    c, _ = simulate_scene("clutter", n_features=1000, seed=8)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.evidence, b.evidence)
    assert not np.array_equal(a.points, c.points)


def test_untextured_wall_registers_nothing_but_blocks() -> None:
    features, scene = simulate_scene("open", n_features=3000, seed=0, range_noise=0.0, outlier_rate=0.0)
    white = next(i for i, o in enumerate(scene.obstacles) if not o.textured)
    _, surface = true_ranges(features, scene)
    assert not (surface == white).any()
    region = reachable_region(scene, max_range=3.0)
    assert region.bounds[2] < 1.4 - scene.robot.radius + 1e-6


@pytest.mark.parametrize("yaw", [0.7, -2.0])
def test_yaw_turns_features_and_truth_together(yaw: float) -> None:
    plain, scene = simulate_scene("office", n_features=800, seed=3)
    turned, turned_scene = simulate_scene("office", n_features=800, seed=3, yaw=yaw)
    np.testing.assert_allclose(turned.points, plain.rotated(yaw).points, atol=1e-12)
    np.testing.assert_array_equal(turned.evidence, plain.evidence)
    # The turned features lie on the turned scene's surfaces as the plain ones on the plain scene.
    np.testing.assert_allclose(true_ranges(turned, turned_scene)[0], true_ranges(plain, scene)[0], atol=1e-9)
    truth = reachable_region(scene, max_range=2.0)
    turned_truth = reachable_region(turned_scene, max_range=2.0)
    rotated = shapely.affinity.rotate(truth, yaw, origin=(0, 0), use_radians=True)
    assert shapely.symmetric_difference(rotated, turned_truth).area < 2e-3 * truth.area


def test_robot_sets_the_camera_height() -> None:
    features, scene = simulate_scene("office", n_features=2000, seed=0, range_noise=0.0, outlier_rate=0.0,
                                     robot=Robot(sensor_height=1.4, body_height=1.5))
    assert scene.robot.sensor_height == 1.4
    assert features.points[:, 2].min() == pytest.approx(-1.4)


@pytest.mark.parametrize(
    "kwargs",
    [{"n_features": -1}, {"outlier_rate": 1.5}, {"range_noise": -0.1}, {"range_noise": float("nan")},
     {"sensor_range": 0.1}],
)
def test_bad_parameters_are_input_errors(kwargs: dict) -> None:
    with pytest.raises(InputError):
        simulate_scene("office", **kwargs)


@pytest.mark.parametrize(
    "footprint, z_min, z_max",
    [([(0, 0), (1, 0)], 0.0, 1.0), ([(0, 0), (1, 0), (1, 1)], 1.0, 0.5),
     ([(0, 0), (1, 1), (1, 0), (0, 1)], 0.0, 1.0), ([(0, 0), (1, 0), (1, float("inf"))], 0.0, 1.0)],
)
def test_bad_obstacles_are_refused(footprint, z_min: float, z_max: float) -> None:
    with pytest.raises(InputError):
        Obstacle("bad", footprint, z_min, z_max)


coordinate = st.floats(-5.0, 5.0, allow_nan=False)


@st.composite
def scenes(draw) -> Scene:
    obstacles = []
    for i in range(draw(st.integers(0, 5))):
        x, y = draw(coordinate), draw(coordinate)
        w, d = draw(st.floats(0.01, 2.0)), draw(st.floats(0.01, 2.0))
        z_min = draw(st.floats(0.0, 2.0))
        obstacles.append(box(f"box {i}", x, y, x + w, y + d, z_min, z_min + draw(st.floats(0.01, 1.0)),
                             textured=draw(st.booleans())))
    robot = Robot(radius=draw(st.floats(0.0, 1.0)), sensor_height=draw(st.floats(0.1, 2.0)),
                  body_height=draw(st.floats(0.5, 2.0)), ground_clearance=draw(st.floats(0.0, 0.4)))
    return Scene(tuple(obstacles), robot, draw(st.text(max_size=10)), draw(st.text(max_size=30)))


@given(scenes())
def test_truth_dict_round_trip(scene: Scene) -> None:
    assert Scene.from_dict(json.loads(json.dumps(scene.to_dict()))) == scene


def test_truth_file_round_trip(tmp_path) -> None:
    scene = build_scene("clutter", yaw=0.3)
    path = tmp_path / "truth.json"
    scene.save_truth(path)
    data = json.loads(path.read_text())
    assert data["format"] == "occtool-scene-truth" and data["version"] == 1
    assert data["frame_id"] == "base_link" and data["units"] == "m"
    assert load_truth(path) == scene


def test_binary_truth_file_is_an_input_error(tmp_path) -> None:
    path = tmp_path / "truth.json"
    path.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(InputError, match="UTF-8"):
        load_truth(path)


@pytest.mark.parametrize(
    "content, message",
    [
        ("[1, 2", "not valid JSON"),
        (json.dumps({"format": "something else"}), "not a scene truth"),
        (json.dumps({"format": "occtool-scene-truth", "version": 99, "obstacles": []}), "version"),
        (json.dumps({"format": "occtool-scene-truth", "version": 1}), "obstacles"),
        (json.dumps({"format": "occtool-scene-truth", "version": 1,
                     "obstacles": [{"name": "b", "footprint": [[0, 0]], "z_min": 0, "z_max": 1}]}), "3 vertices"),
        (json.dumps({"format": "occtool-scene-truth", "version": 1,
                     "obstacles": [{"name": "b", "z_min": 0}]}), "lacks footprint"),
        (json.dumps({"format": "occtool-scene-truth", "version": 1, "robot": {"radius": -1},
                     "obstacles": []}), "radius"),
    ],
)
def test_malformed_truth_is_a_one_line_input_error(tmp_path, content: str, message: str) -> None:
    path = tmp_path / "truth.json"
    path.write_text(content)
    with pytest.raises(InputError, match=message) as info:
        load_truth(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


@given(
    x=st.floats(-3.0, 3.0), y=st.floats(-3.0, 3.0), w=st.floats(0.05, 1.5), d=st.floats(0.05, 1.5),
    z_min=st.floats(0.0, 1.5), tall=st.floats(0.02, 1.5), seed=st.integers(0, 2**16),
)
def test_rays_stop_at_the_first_surface(x, y, w, d, z_min, tall, seed) -> None:
    # Independent check of the ray caster: the hit point lies on the prism's surface or the
    # floor, and no point of the ray before it lies inside the prism.
    prism = box("b", x, y, x + w, y + d, z_min, z_min + tall)
    scene = Scene((prism,), Robot(sensor_height=1.0))
    assume(not (prism.polygon.buffer(1e-6).contains(shapely.Point(0, 0)) and z_min <= 1.0 <= z_min + tall))
    rng = np.random.default_rng(seed)
    directions = rng.normal(size=(200, 3))
    ranges, surface = cast_rays(scene, directions, max_range=20.0)
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    hit = surface != NOTHING
    points = unit[hit] * ranges[hit, None]
    z_floor = points[:, 2] + 1.0
    on_prism = surface[hit] == 0
    footprint = prism.polygon
    distance_to_side = shapely.distance(footprint.boundary, shapely.points(points[on_prism, :2]))
    on_cap = np.isclose(z_floor[on_prism], prism.z_min) | np.isclose(z_floor[on_prism], prism.z_max)
    assert ((distance_to_side < 1e-9) | on_cap).all()
    assert np.allclose(z_floor[~on_prism], 0.0)
    fractions = np.linspace(0.0, 0.999, 60)
    for direction, length in zip(unit[hit], ranges[hit]):
        before = fractions[:, None] * length * direction
        z = before[:, 2] + 1.0
        inside = shapely.contains_xy(footprint, before[:, 0], before[:, 1]) & (z > prism.z_min) & (z < prism.z_max)
        assert not inside.any() and (z >= -1e-9).all()
    # A ray that hits nothing goes up or reaches the floor beyond the 20 m limit.
    down = unit[~hit, 2] < 0
    assert (-1.0 / unit[~hit][down, 2] > 20.0).all()


def test_a_simulated_log_is_written_as_compact_csv_that_reads_back(tmp_path) -> None:
    from occtool.io import read_log
    from occtool.simulate import save_features_csv, simulate_scene

    features, _ = simulate_scene("office", n_features=300, seed=2)
    path = tmp_path / "features.csv"
    save_features_csv(features, path, ["occtool simulate office", "second line"])
    lines = path.read_text().splitlines()
    assert lines[:3] == ["# occtool simulate office", "# second line", "x,y,z,m"]
    # 0.1 mm coordinates and 3-decimal evidence, the synthetic logs' documented precision.
    assert all(len(value.split(".")[1]) == (3 if k == 3 else 4)
               for line in lines[3:] for k, value in enumerate(line.split(",")))
    back = read_log(path).single().features
    np.testing.assert_allclose(back.points, features.points, atol=0.5e-4 + 1e-12)
    np.testing.assert_allclose(back.evidence, features.evidence, atol=0.5e-3 + 1e-12)
