"""A lean run's navigation outlines wait in a file (occtool.fuse._outlines)."""

from __future__ import annotations

import pickle

import numpy as np
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from occtool.fuse._outlines import SpilledNavigation, SpilledOutlines, placed_outlines
from occtool.navigation import NavigationMap


@settings(max_examples=25, deadline=None)
@given(st.lists(st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3), st.floats(0.01, 30),
                          st.integers(3, 40)), max_size=12))
def test_outlines_come_back_to_the_bit(discs):
    polygons = [shapely.Point(x, y).buffer(r, quad_segs=q) for x, y, r, q in discs] + [shapely.Polygon()]
    outlines = SpilledOutlines()
    assert [outlines.append(p) for p in polygons] == list(range(len(polygons)))
    assert len(outlines) == len(polygons)
    for k, polygon in enumerate(polygons):
        assert shapely.to_wkb(outlines[k]) == shapely.to_wkb(polygon)
    taken = outlines[np.arange(len(polygons))[::-1]]
    assert [shapely.to_wkb(p) for p in taken] == [shapely.to_wkb(p) for p in polygons[::-1]]
    np.testing.assert_array_equal(outlines.bounds, shapely.bounds(np.array(polygons, dtype=object)))


def test_a_spilled_map_is_the_map_with_its_polygon_read_back(tmp_path):
    square = shapely.box(0, 0, 2, 1)
    nav = NavigationMap(polygon=square, slices=[], obstacle_points=np.array([[1.0, 2.0]]),
                        exploration_points=np.zeros((0, 2)), threshold=0.6, effective_threshold=0.55,
                        heights=(0.1,), robot_radius=0.2, max_range=1.5, n_angles=8,
                        point_spacing=0.1)
    outlines = SpilledOutlines(tmp_path)
    spilled = SpilledNavigation(nav, outlines)
    assert list(tmp_path.iterdir()) == []  # the file has no name
    assert shapely.to_wkb(spilled.polygon) == shapely.to_wkb(square)
    assert spilled.threshold == 0.6 and spilled.obstacle_points.tolist() == [[1.0, 2.0]]
    restored = pickle.loads(pickle.dumps(spilled))
    assert isinstance(restored, NavigationMap) and shapely.to_wkb(restored.polygon) == shapely.to_wkb(square)
    # One file, in order: read back by group; anything else, as an array.
    second = SpilledNavigation(nav, outlines)
    store, bounds = placed_outlines([spilled, second])
    assert store is outlines and bounds.shape == (2, 4)
    array, none = placed_outlines([second, spilled])
    assert none is None and array.dtype == object and len(array) == 2
