"""Issue 35, item 3: the floor is the lowest large horizontal surface many positions see,
never the most populated layer, and ``map`` warns as ``fit`` does when the data and
``--sensor-height`` disagree."""

from __future__ import annotations

import json
import logging
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from occtool._floor import common_floor, lowest_layer
from occtool.features import Features, Pose, Position, RangeLog
from occtool.io.depth import estimate_floor
from occtool.robot import Robot

TABLE_HEIGHT = 0.75
CAMERA_HEIGHT = 1.4


def kitchen(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World points (z up, floor at 0) of 20 hand-held camera positions 1.4 m up round a
    2 x 1.2 m table: every position sees the table top, 14 see a 2 x 2 m patch of floor
    too, each sees a wall. The table holds four times the floor's returns."""
    rng = np.random.default_rng(seed)
    points, groups, origins = [], [], []
    for k in range(20):
        angle = 2 * np.pi * k / 20
        camera = np.array([2.2 * np.cos(angle), 2.2 * np.sin(angle), CAMERA_HEIGHT + rng.normal(0, 0.05)])
        table = np.column_stack([rng.uniform(-1.0, 1.0, 600), rng.uniform(-0.6, 0.6, 600),
                                 TABLE_HEIGHT + rng.normal(0, 0.005, 600)])
        parts = [table]
        if k % 10 < 7:
            centre = 0.5 * camera[:2] + rng.normal(0, 0.2, 2)
            floor = np.column_stack([centre + rng.uniform(-1.0, 1.0, (150, 2)), rng.normal(0, 0.005, 150)])
            parts.append(floor[~((np.abs(floor[:, 0]) < 1.0) & (np.abs(floor[:, 1]) < 0.6))])
        wall = np.column_stack([np.full(200, 4.0), rng.uniform(-3, 3, 200), rng.uniform(0.0, 2.5, 200)])
        parts.append(wall)
        cloud = np.vstack(parts)
        points.append(cloud)
        groups.append(np.full(cloud.shape[0], k))
        origins.append(camera)
    return np.vstack(points), np.concatenate(groups), np.array(origins)


def test_a_table_top_with_more_returns_than_the_floor_is_not_the_floor():
    points, groups, origins = kitchen()
    table = np.abs(points[:, 2] - TABLE_HEIGHT) < 0.03
    floor = np.abs(points[:, 2]) < 0.03
    assert table.sum() > 3 * floor.sum()  # the most populated layer is the table top
    found = estimate_floor(points, np.array([0.0, 0.0, 1.0]), groups=groups, origins=origins)
    assert found is not None
    normal, offset, _ = found
    assert normal[2] > 0.999 and abs(offset) < 0.01


def test_a_tilted_world_is_levelled_by_the_floor_not_the_table():
    # 3DMatch's world is the first camera's: turn the kitchen 20 degrees about x.
    points, groups, origins = kitchen(1)
    c, s = np.cos(np.radians(20)), np.sin(np.radians(20))
    turn = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    found = estimate_floor(points @ turn.T, np.array([0.0, 0.0, 1.0]), groups=groups, origins=origins @ turn.T)
    assert found is not None
    normal, offset, _ = found
    assert np.degrees(np.arccos(min(1.0, normal @ (turn @ [0, 0, 1])))) < 1.0 and abs(offset) < 0.01


def test_a_layer_few_positions_see_is_not_the_floor():
    # Two of twenty positions see a large layer 0.5 m below everyone else's floor (a reflection).
    layers = np.r_[np.full(18, 0.0) + np.linspace(-0.02, 0.02, 18), -0.5, -0.52]
    floor, members = common_floor(layers)
    assert abs(floor) < 0.01 and members.sum() == 18


def test_a_small_or_sparse_layer_is_not_a_position_s_floor():
    rng = np.random.default_rng(3)
    # A 0.5 x 0.5 m box top (0.25 m²) below a floor: too small to be a floor.
    box = np.column_stack([rng.uniform(0, 0.5, (400, 2)), np.full(400, -1.2)])
    floor = np.column_stack([rng.uniform(-2, 2, (400, 2)), np.full(400, -1.0)])
    assert lowest_layer(np.vstack([box, floor]), top=0.0)[0] == pytest.approx(-1.0)
    # A 2D laser's plane at the sensor is no layer below it.
    assert lowest_layer(np.column_stack([rng.uniform(-3, 3, (400, 2)), np.zeros(400)]), top=0.0) is None


# --- the data against --sensor-height: one check for fit and map -----------------------------


def kitchen_log(seed: int = 0) -> RangeLog:
    """The kitchen's positions, each in its camera's frame (z up) with its pose."""
    points, groups, origins = kitchen(seed)
    positions = []
    for k, camera in enumerate(origins):
        local = points[groups == k] - camera
        positions.append(Position(k, Features(local, np.full(local.shape[0], 0.9)),
                                  Pose(float(camera[0]), float(camera[1]), float(camera[2]), 0.0)))
    return RangeLog(positions, source="kitchen")


def seen_height() -> float:
    """The median height of the cameras that see the floor."""
    origins = kitchen()[2]
    return float(np.median(origins[np.arange(20) % 10 < 7, 2]))


def test_the_log_check_finds_the_floor_below_the_table_top(caplog):
    from occtool.fit import OccupancyRegressor
    from occtool.modelset import estimator_for_log

    log = kitchen_log()
    with caplog.at_level(logging.WARNING, logger="occtool"):
        estimator_for_log(OccupancyRegressor(robot=Robot(sensor_height=1.4)), log.positions)
    assert not [r for r in caplog.records if "sensor-height" in r.getMessage()]
    caplog.clear()
    # The table top taken for the floor, as the densest layer was: the camera 0.65 m above it.
    with caplog.at_level(logging.WARNING, logger="occtool"):
        estimator_for_log(OccupancyRegressor(robot=Robot(sensor_height=0.65)), log.positions)
    (message,) = [r.getMessage() for r in caplog.records if "sensor-height" in r.getMessage()]
    assert "14 of the 20 positions" in message and message.endswith(f"give --sensor-height {seen_height():.2f}")


def test_with_no_height_given_the_data_s_floor_sets_the_sensor_height():
    from occtool.fit import OccupancyRegressor
    from occtool.modelset import estimator_for_log

    estimator = estimator_for_log(OccupancyRegressor(), kitchen_log().positions, planar_defaults=True)
    assert estimator.robot.sensor_height == pytest.approx(seen_height(), abs=0.006)
    # The camera 1.05 m above the floor: within FLOOR_DISAGREEMENT of the default, kept.
    low = kitchen_log()
    low = RangeLog([replace(p, pose=replace(p.pose, z=p.pose.z - 0.35),
                            features=Features(p.features.points + [0.0, 0.0, 0.35], p.features.evidence))
                    for p in low.positions], source="low")
    assert estimator_for_log(OccupancyRegressor(), low.positions, planar_defaults=True).robot is None


@pytest.fixture(scope="module")
def low_scan(tmp_path_factory) -> Path:
    """One x y z scan of a room from a scanner 0.08 m above its floor (OctoMap's scan.dat
    in small): a floor that holds most returns, walls 3 m either side and 6 m ahead."""
    rng = np.random.default_rng(4)
    floor = np.column_stack([rng.uniform(0.3, 6.0, 3000), rng.uniform(-3, 3, 3000), rng.normal(-0.08, 0.005, 3000)])
    walls = [np.column_stack([rng.uniform(0, 6, 600), np.full(600, side), rng.uniform(-0.08, 2.5, 600)])
             for side in (-3.0, 3.0)]
    ahead = np.column_stack([np.full(600, 6.0), rng.uniform(-3, 3, 600), rng.uniform(-0.08, 2.5, 600)])
    path = tmp_path_factory.mktemp("scan") / "scan.xyz"
    np.savetxt(path, np.vstack([floor, *walls, ahead]), fmt="%.4f")
    return path


def run(*args: object):
    from occtool.cli.main import cli

    return CliRunner().invoke(cli, [str(a) for a in args])


def test_map_warns_as_fit_does_when_the_data_and_sensor_height_disagree(low_scan, tmp_path):
    fitted = run("fit", low_scan, "-o", tmp_path / "m.json", "--sensor-height", "1")
    mapped = run("map", low_scan, "-o", tmp_path / "map", "--sensor-height", "1", "--no-mcap", "--no-register")
    assert fitted.exit_code == 0 and mapped.exit_code == 0, fitted.output + mapped.output
    line = "WARNING the floor lies 0.08 m below the sensor, not 1 m as --sensor-height says: give --sensor-height 0.08"
    assert line in " ".join(fitted.output.split()) and line in " ".join(mapped.output.split())


def test_map_with_no_height_given_takes_the_data_s_floor(low_scan, tmp_path):
    from occtool.fuse import load_map

    result = run("map", low_scan, "-o", tmp_path / "map", "--no-mcap", "--no-register", "--world", "2d")
    assert result.exit_code == 0, result.output
    assert "--sensor-height 0.08 taken from the data instead of the default 1" in " ".join(result.output.split())
    # The body band (0.05 to 1 m above the floor) in the world: 0.08 m lower than the sensor.
    assert load_map(tmp_path / "map" / "world.occmap").band == pytest.approx((0.05 - 0.08, 1.0 - 0.08))
    # A room, not a strip: free floor across it.
    summary = json.loads((tmp_path / "map" / "summary.json").read_text())
    assert summary["raster"]["cells"]["free"] * 0.05 ** 2 > 15.0
    # The 3D map (the default for a 3D scan) puts its band's ground 0.08 m under the sensor too.
    result = run("map", low_scan, "-o", tmp_path / "map3d", "--no-mcap", "--no-register")
    assert result.exit_code == 0, result.output
    summary = json.loads((tmp_path / "map3d" / "summary.json").read_text())
    assert summary["world_map"]["kind"] == "3d"
    assert summary["raster"]["cells"]["free"] * 0.05 ** 2 > 15.0
    assert summary["raster"]["cells"]["occupied"] * 0.05 > 10.0  # the walls, not the floor
