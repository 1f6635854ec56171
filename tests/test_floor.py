"""Issue 35, item 3: the floor is the lowest large horizontal surface many positions see,
never the most populated layer, and ``map`` warns as ``fit`` does when the data and
``--sensor-height`` disagree."""

from __future__ import annotations

import numpy as np
import pytest

from occtool._floor import common_floor, lowest_layer
from occtool.io.depth import estimate_floor

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
