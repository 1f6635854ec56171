"""The union of a run's polygons a group of overlapping ones at a time (occtool.fuse._union)."""

from __future__ import annotations

import numpy as np
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from occtool.fuse._union import overlapping_groups, union_in_groups


def _squares(corners: list[tuple[float, float]], side: float = 1.0) -> np.ndarray:
    return np.array([shapely.box(x, y, x + side, y + side) for x, y in corners], dtype=object)


def test_groups_are_chains_of_overlapping_boxes_in_the_order_given():
    # 0 and 3 overlap, 3 and 1 overlap: one group through 3; 2 stands alone; 4 is empty.
    squares = _squares([(0, 0), (1.8, 0), (10, 10), (0.9, 0)])
    geometries = np.concatenate([squares, [shapely.Polygon()]])
    groups = overlapping_groups(shapely.bounds(geometries))
    assert [g.tolist() for g in groups] == [[0, 1, 3], [2]]
    # Boxes 1.0 m apart join once grown by half of it.
    apart = _squares([(0, 0), (2, 0)])
    assert len(overlapping_groups(shapely.bounds(apart))) == 2
    assert [g.tolist() for g in overlapping_groups(shapely.bounds(apart), margin=0.5)] == [[0, 1]]
    assert overlapping_groups(shapely.bounds(np.array([shapely.Polygon()], dtype=object))) == []


def test_one_group_is_union_all_itself():
    squares = _squares([(0, 0), (0.5, 0.5), (0.2, 0.9)])
    assert shapely.to_wkb(union_in_groups(squares)) == shapely.to_wkb(shapely.union_all(squares))


def test_each_group_passes_through_then_before_the_next():
    squares = _squares([(0, 0), (0.5, 0), (5, 0)])
    seen = []

    def then(union):
        seen.append(round(union.area, 9))
        return shapely.buffer(union, -0.1)

    region = union_in_groups(squares, then=then)
    assert seen == [1.5, 1.0]
    assert region.geom_type == "MultiPolygon" and len(region.geoms) == 2
    assert abs(region.area - (1.3 * 0.8 + 0.8 * 0.8)) < 1e-9


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(0, 20), st.floats(0, 20), st.floats(0.1, 4)), min_size=1, max_size=25))
def test_the_same_point_set_as_one_union(discs):
    geometries = np.array([shapely.Point(x, y).buffer(r, quad_segs=4) for x, y, r in discs], dtype=object)
    whole = shapely.union_all(geometries)
    grouped = union_in_groups(geometries)
    assert shapely.get_type_id(grouped) in (3, 6)
    assert abs(grouped.area - whole.area) <= 1e-9 * max(whole.area, 1.0)
    assert shapely.symmetric_difference(grouped, whole).area <= 1e-9 * max(whole.area, 1.0)
