"""The whole pipeline on a simulated scene: features -> fit -> extract -> evaluate."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import shapely
import shapely.affinity
from hypothesis import given, settings
from hypothesis import strategies as st

from occtool.fit import OccupancyRegressor
from occtool.navigation import NavigationWarning, navigation_map
from occtool.scoring import evaluate_navigation
from occtool.simulate import simulate_scene


@pytest.fixture(scope="module")
def office():
    return simulate_scene("office", n_features=4000, seed=0)


def _navigation(features):
    model = OccupancyRegressor().fit(features)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NavigationWarning)
        return navigation_map(model.inverse_range, robot=model.robot_, slope_bounds=model.slope_bounds_)


def _iou(a, b) -> float:
    return float(shapely.intersection(a, b).area / shapely.union(a, b).area)


@settings(max_examples=6, deadline=None)
@given(yaw=st.floats(-np.pi, np.pi))
def test_rotating_the_scene_rotates_the_navigation_polygon(office, yaw):
    features, _ = office
    straight = _navigation(features).polygon
    turned = _navigation(features.rotated(yaw)).polygon
    turned_back = shapely.affinity.rotate(turned, -yaw, origin=(0.0, 0.0), use_radians=True)
    # The model turns exactly; what is left is the map's own grid of 360 rays.
    assert _iou(straight, turned_back) > 0.97


def test_the_office_map_is_safe_and_useful(office):
    features, scene = office
    nav = _navigation(features)
    result = evaluate_navigation(nav.polygon, scene, robot_radius=nav.robot_radius, max_range=nav.max_range)
    assert result.violation <= 0.005
    assert result.iou >= 0.6
    assert len(nav.obstacle_points) > 0 and len(nav.exploration_points) > 0
