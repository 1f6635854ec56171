"""The comparison of the parametric model with the grids, as a library function."""

from __future__ import annotations

import json

import numpy as np
import pytest
import shapely
import shapely.geometry
from hypothesis import given
from hypothesis import strategies as st

from occtool.compare import compare_grid, report_json, tree_bytes
from occtool.errors import InputError
from occtool.features import Features
from occtool.fit import OccupancyRegressor
from occtool.robot import Robot
from occtool.scoring import FREE_FRACTIONS, holdout_points, polygon_iou, roc_auc, split_holdout
from occtool.simulate import simulate_scene

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")


def _round_room(radius: float = 1.2, n: int = 3000, seed: int = 0) -> Features:
    """Features on a cylindrical wall around the robot, plus some floor."""
    rng = np.random.default_rng(seed)
    alpha = rng.uniform(-np.pi, np.pi, n)
    z = rng.uniform(-0.9, 1.0, n)
    wall = Features.from_xyz(radius * np.cos(alpha), radius * np.sin(alpha), z, rng.uniform(0.7, 1.0, n))
    d = rng.uniform(0.4, radius, n // 4)
    a = rng.uniform(-np.pi, np.pi, n // 4)
    floor = Features.from_xyz(d * np.cos(a), d * np.sin(a), np.full(n // 4, -1.0), 0.9)
    return Features.concatenate([wall, floor])


# ------------------------------------------------------------------ pieces


def test_roc_auc_known_answers() -> None:
    assert roc_auc(np.array([0.9, 0.8]), np.array([0.1, 0.2, 0.3])) == 1.0
    assert roc_auc(np.array([0.1]), np.array([0.5, 0.9])) == 0.0
    assert roc_auc(np.full(4, 0.5), np.full(7, 0.5)) == 0.5
    assert np.isnan(roc_auc(np.array([]), np.array([0.1])))


@given(
    occupied=st.lists(st.sampled_from([0.0, 0.2, 0.5, 0.7, 1.0]), min_size=1, max_size=20),
    free=st.lists(st.sampled_from([0.0, 0.2, 0.5, 0.7, 1.0]), min_size=1, max_size=20),
)
def test_roc_auc_is_the_pairwise_win_rate(occupied: list[float], free: list[float]) -> None:
    a, b = np.array(occupied), np.array(free)
    wins = (a[:, None] > b[None, :]).sum() + 0.5 * (a[:, None] == b[None, :]).sum()
    assert roc_auc(a, b) == pytest.approx(wins / (a.size * b.size))


def test_polygon_iou_of_overlapping_squares() -> None:
    a = shapely.box(0, 0, 2, 2)
    b = shapely.box(1, 0, 3, 2)
    assert polygon_iou(a, b) == pytest.approx(2 / 6)
    assert polygon_iou(a, a) == pytest.approx(1.0)
    assert polygon_iou(shapely.Polygon(), shapely.Polygon()) == 1.0
    assert polygon_iou(a, shapely.Polygon()) == 0.0


@given(n=st.integers(2, 500), holdout=st.floats(0.0, 0.5), seed=st.integers(0, 10))
def test_holdout_split_is_a_deterministic_partition(n: int, holdout: float, seed: int) -> None:
    train, test = split_holdout(n, holdout, seed)
    assert sorted(np.concatenate([train, test]).tolist()) == list(range(n))
    assert len(test) == round(holdout * n)
    again = split_holdout(n, holdout, seed)
    assert np.array_equal(train, again[0]) and np.array_equal(test, again[1])


def test_holdout_points_lie_on_the_rays_and_skip_floor_end_points() -> None:
    features = Features.from_xyz([2.0, 1.0], [0.0, 1.0], [0.5, -1.0], 1.0)
    occupied, free = holdout_points(features, np.array([False, True]))
    np.testing.assert_allclose(occupied, [[2.0, 0.0, 0.5]])
    assert free.shape == (2 * len(FREE_FRACTIONS), 3)
    # Every free point is a point of a ray strictly before its feature.
    for point in free:
        ratios = [np.linalg.norm(point) / np.linalg.norm(p) for p in features.points]
        assert any(np.allclose(np.cross(point, p), 0.0) and 0 < q < 1 for p, q in zip(features.points, ratios))


def test_holdout_out_of_range_is_an_input_error() -> None:
    with pytest.raises(InputError, match="held-out share"):
        split_holdout(10, 0.7, 0)


# ------------------------------------------------------------------ whole comparison


@pytest.fixture(scope="module")
def round_room_report() -> dict:
    pytest.importorskip("pyoctomap")
    features = _round_room()
    return compare_grid(
        features,
        regressor=OccupancyRegressor(pieces=8),
        navigation={"robot": Robot(), "max_range": 1.5, "n_angles": 180},
        resolution=0.1,
        octomap=True,
        seed=3,
    )


def test_report_layout_is_the_documented_one(round_room_report: dict) -> None:
    report = round_room_report
    assert report["features"] == 3750
    assert report["features_used"] + report["features_held_out"] == 3750
    for name in ("parametric", "grid", "octomap"):
        figures = report["models"][name]
        assert set(figures) >= {"samples", "build_s", "extract_s", "memory_bytes", "file_bytes"}
        assert figures["samples"] > 0 and figures["memory_bytes"] > 0 and figures["file_bytes"] > 0
        assert 0.5 < report["auc"][name] <= 1.0
    for name in ("grid", "octomap"):
        assert set(report["agreement"][name]) == {"iou"}
        ratios = report["ratios"][name]
        models = report["models"]
        assert ratios["memory"] == pytest.approx(models[name]["memory_bytes"] / models["parametric"]["memory_bytes"])
        expected_time = (models[name]["build_s"] + models[name]["extract_s"]) / (
            models["parametric"]["build_s"] + models["parametric"]["extract_s"]
        )
        assert ratios["time"] == pytest.approx(expected_time)
    assert "truth" not in report
    assert "footprint" in report["footprint_prior"]
    # The JSON text is strict JSON and reads back.
    assert json.loads(report_json(report))["models"]["grid"]["samples"] == report["models"]["grid"]["samples"]


def test_the_grids_see_the_round_room(round_room_report: dict) -> None:
    # A wall 1.2 m away all round: the reachable area is the disk of radius 1.2 - 0.25 m.
    # Both grids stay inside it, free most of it and agree with each other. (The
    # parametric model's own quality is tested with the fit.)
    reachable = shapely.Point(0, 0).buffer(1.2 - 0.25 + 0.02, quad_segs=64)
    polygons = {
        name: shapely.geometry.shape(round_room_report["polygons"][name]) for name in round_room_report["models"]
    }
    for name in ("grid", "octomap"):
        assert polygons[name].within(reachable), name
        assert polygons[name].area > 0.5 * np.pi * (1.2 - 0.25) ** 2, name
    for name, polygon in polygons.items():
        assert round_room_report["models"][name]["polygon_area"] == pytest.approx(polygon.area)
    assert polygon_iou(polygons["grid"], polygons["octomap"]) > 0.6
    for name in ("grid", "octomap"):
        assert round_room_report["agreement"][name]["iou"] == pytest.approx(
            polygon_iou(polygons["parametric"], polygons[name])
        )
    # Parameters against cells: the tree is orders of magnitude smaller.
    assert round_room_report["ratios"]["grid"]["memory"] > 100


def test_truth_and_parameters_flow_through() -> None:
    features, scene = simulate_scene("corridor", n_features=1500, seed=2)
    report = compare_grid(
        features,
        regressor=OccupancyRegressor(pieces=8),
        navigation={"robot": Robot(radius=0.2), "threshold": 0.55, "max_range": 1.0, "n_angles": 90},
        resolution=0.1,
        truth=scene,
        holdout=0.0,
        file_sizes=False,
    )
    assert report["settings"]["threshold"] == 0.55
    assert report["settings"]["robot_radius"] == 0.2
    assert set(report["truth"]) == {"parametric", "grid"}
    for name in ("parametric", "grid"):
        assert 0.0 <= report["truth"][name]["iou"] <= 1.0
        assert 0.0 <= report["truth"][name]["violation"] <= 1.0
    # Nothing held out: no AUC, written as null.
    assert np.isnan(report["auc"]["grid"])
    assert json.loads(report_json(report))["auc"]["grid"] is None
    assert report["models"]["grid"]["file_bytes"] == 0


def test_tree_bytes_counts_coefficients_and_nodes() -> None:
    model = OccupancyRegressor(pieces=4).fit(_round_room(n=800))
    tree = model.tree_
    assert tree_bytes(tree) >= tree.coefficients.nbytes + 8 * tree.n_pieces
    assert tree_bytes(tree) < 1000


def test_bad_settings_are_input_errors() -> None:
    features = _round_room(n=100)
    with pytest.raises(InputError, match="resolution"):
        compare_grid(features, regressor=OccupancyRegressor(pieces=2), navigation={}, resolution=0.0)
    with pytest.raises(InputError, match="scans"):
        compare_grid(features, regressor=OccupancyRegressor(pieces=2), navigation={}, octomap=True, octomap_scans=0)


# ------------------------------------------------------------------ unobserved space


def _planar_scan(radius: float = 1.2, gap: tuple[float, float] = (40.0, 80.0)) -> Features:
    """A planar 240-degree laser scan of a round wall, with no returns over ``gap`` degrees."""
    degrees = np.arange(-120.0, 120.0, 0.5)
    degrees = degrees[(degrees < gap[0]) | (degrees > gap[1])]
    alpha = np.radians(degrees)
    return Features.from_xyz(radius * np.cos(alpha), radius * np.sin(alpha), np.zeros_like(alpha), 0.9)


def test_unknown_space_is_recorded(round_room_report: dict) -> None:
    settings = round_room_report["settings"]
    assert settings["unknown"] == "free"
    assert settings["observed_band"] == list(Robot().body_band)
    assert "free" in round_room_report["unknown_space"]


def test_unknown_occupied_closes_what_the_laser_did_not_see() -> None:
    pytest.importorskip("pyoctomap")
    robot = Robot(sensor_height=0.3, body_height=0.4)
    features = _planar_scan()
    reports = {
        unknown: compare_grid(
            features,
            regressor=OccupancyRegressor(pieces=8, robot=robot),
            navigation={"robot": robot, "n_angles": 180},
            resolution=0.05,
            octomap=True,
            octomap_scans=1,
            file_sizes=False,
            unknown=unknown,
        )
        for unknown in ("free", "occupied")
    }
    assert reports["occupied"]["settings"]["unknown"] == "occupied"
    assert reports["occupied"]["settings"]["observed_band"] == pytest.approx(list(robot.body_band))
    assert "occupied" in reports["occupied"]["unknown_space"]
    in_gap = shapely.Point(0.8 * np.cos(np.radians(60)), 0.8 * np.sin(np.radians(60)))
    # In the widest seen sector (-120 to 40 degrees), where the robot drives out.
    ahead = shapely.Point(0.6 * np.cos(np.radians(-40)), 0.6 * np.sin(np.radians(-40)))
    for name in ("grid", "octomap"):
        free = shapely.geometry.shape(reports["free"]["polygons"][name])
        closed = shapely.geometry.shape(reports["occupied"]["polygons"][name])
        # Free: the polygon runs to the max range behind the laser, and into the gap.
        assert free.bounds[0] < -1.0
        assert free.contains(in_gap) and free.contains(ahead)
        # Occupied: the robot is not in collision and what was seen stays open; the unseen
        # rear (beyond 120 degrees) and the gap are closed.
        assert closed.contains(ahead)
        assert closed.bounds[0] > -0.3
        assert not closed.intersects(in_gap)
        assert closed.area < 0.5 * free.area
        # The parametric model closes unseen directions too: the grids now agree with it better.
        assert reports["occupied"]["agreement"][name]["iou"] > reports["free"]["agreement"][name]["iou"]
    # Only the grids' polygons change.
    assert reports["occupied"]["polygons"]["parametric"] == reports["free"]["polygons"]["parametric"]
    assert reports["occupied"]["auc"] == reports["free"]["auc"]


def test_bad_unknown_is_an_input_error() -> None:
    with pytest.raises(InputError, match="'free' or 'occupied'"):
        compare_grid(_round_room(n=100), regressor=OccupancyRegressor(pieces=2), navigation={}, unknown="unknown")


def test_an_empty_polygon_says_why(round_room_report: dict) -> None:
    # The round room leaves every model room to move: no warnings.
    assert all(figures["warnings"] == [] for figures in round_room_report["models"].values())
    # A wall 0.3 m away all round: the 10 cm cells of the grid that hold it reach inside
    # the 0.25 m robot's radius, so the grid's robot is in collision where it stands.
    rng = np.random.default_rng(1)
    alpha = rng.uniform(-np.pi, np.pi, 3000)
    wall = Features.from_xyz(0.3 * np.cos(alpha), 0.3 * np.sin(alpha), rng.uniform(-0.9, 0.0, 3000), 0.9)
    report = compare_grid(
        wall,
        regressor=OccupancyRegressor(pieces=8),
        navigation={"robot": Robot(), "max_range": 1.5, "n_angles": 180},
        resolution=0.1,
    )
    assert report["models"]["grid"]["polygon_area"] == 0.0
    for name, figures in report["models"].items():
        in_collision = any("in collision where it stands" in note for note in figures["warnings"])
        assert in_collision == (figures["polygon_area"] == 0.0), name


def test_also_unknown_gives_the_other_reading_from_the_same_build() -> None:
    # One build, both readings: the second reading's polygon is the one a separate run gives.
    robot = Robot(sensor_height=0.3, body_height=0.4)
    features = _planar_scan()
    settings = dict(regressor=OccupancyRegressor(pieces=8, robot=robot), navigation={"robot": robot, "n_angles": 180},
                    resolution=0.05, file_sizes=False)
    both = compare_grid(features, **settings, unknown="occupied", also_unknown=("free",))
    alone = compare_grid(features, **settings, unknown="free")
    free_polygon = shapely.geometry.shape(alone["polygons"]["grid"])
    reading = both["readings"]["free"]["grid"]
    assert reading["polygon_area"] == pytest.approx(free_polygon.area)
    assert reading["agreement"]["iou"] == pytest.approx(alone["agreement"]["grid"]["iou"])
    assert "readings" not in alone
    with pytest.raises(InputError):
        compare_grid(features, **settings, also_unknown=("maybe",))


def test_auc_in_front_of_the_first_obstacle_leaves_out_what_lies_behind_it() -> None:
    from occtool.scoring import in_front_of_first_obstacle

    # A wall 1.2 m away all round: a point at 1.0 m is in front of it, at 1.5 m behind it,
    # and a point above the body band is out of it either way.
    features = _round_room()
    robot = Robot()
    free = np.array([[1.0, 0.0, -0.5], [1.5, 0.0, -0.5], [0.0, 1.0, 0.5]])
    assert in_front_of_first_obstacle(free, features, robot, occupied=False).tolist() == [True, False, False]
    occupied = np.array([[1.2, 0.0, -0.5], [0.0, -1.25, -0.2], [2.5, 0.0, -0.5]])
    assert in_front_of_first_obstacle(occupied, features, robot, occupied=True).tolist() == [True, True, False]


def test_the_report_scores_the_front_points_too(round_room_report: dict) -> None:
    report = round_room_report
    assert set(report["auc_front"]) == set(report["auc"])
    counts = report["auc_front_points"]
    assert 0 < counts["occupied"] <= report["auc_points"]["occupied"]
    assert 0 < counts["free"] <= report["auc_points"]["free"]
    assert all(0.5 < value <= 1.0 for value in report["auc_front"].values())
