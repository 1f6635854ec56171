"""occtool.neighbours gives cKDTree's answers (the return guard's queries) without scipy."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from occtool.neighbours import NeighbourIndex, nearest_other_distance


def _cases():
    rng = np.random.default_rng(21)
    for dimension in (3, 4):
        for rounded in (False, True):
            points = rng.normal(size=(1500, dimension)) * 4.0
            if rounded:  # repeated points and ties
                points = np.round(points, 1)
            queries = np.concatenate([points[rng.integers(0, 1500, 300)],  # on the points
                                      rng.normal(size=(300, dimension)) * 4.0,
                                      rng.normal(size=(20, dimension)) * 40.0])  # beyond them
            yield points, queries


@pytest.mark.parametrize("k", [1, 5, 16])
def test_the_index_answers_as_ckdtree(k):
    for points, queries in _cases():
        reach = 1.3
        expected_distance, expected_index = cKDTree(points).query(queries, k=k, distance_upper_bound=reach)
        distance, index = NeighbourIndex(points, reach=reach).query(queries, k=k)
        expected_distance = expected_distance.reshape(-1, k)
        expected_index = expected_index.reshape(-1, k)
        # The same distances to the bit, nearest first, inf (index n) beyond reach.
        np.testing.assert_array_equal(distance, expected_distance)
        np.testing.assert_array_equal(index == len(points), expected_index == len(points))
        # The same points, but for which of two at exactly one distance comes first.
        found = np.isfinite(distance)
        mine = np.sqrt(((points[index[found]] - queries[np.nonzero(found)[0]]) ** 2).sum(axis=1))
        np.testing.assert_allclose(mine, distance[found], rtol=1e-12)


def test_a_nearer_bound_and_small_blocks_change_nothing(monkeypatch):
    import occtool.neighbours as neighbours

    points, queries = next(_cases())
    index = NeighbourIndex(points, reach=2.0)
    whole = index.query(queries, k=8, distance_upper_bound=1.5)
    monkeypatch.setattr(neighbours, "PAIR_BLOCK", 50)  # a block per query, or a few
    monkeypatch.setattr(neighbours, "MAX_BLOCKS", 1 << 30)  # (no wider blocks for many pairs)
    blocked = index.query(queries, k=8, distance_upper_bound=1.5)
    np.testing.assert_array_equal(whole[0], blocked[0])
    np.testing.assert_array_equal(whole[0], cKDTree(points).query(queries, k=8, distance_upper_bound=1.5)[0])
    with pytest.raises(ValueError, match="beyond the index's reach"):
        index.query(queries, k=1, distance_upper_bound=3.0)


def test_empty_index_and_empty_queries():
    empty = NeighbourIndex(np.zeros((0, 4)))
    distance, index = empty.query(np.ones((3, 4)), k=2)
    assert np.isinf(distance).all() and (index == 0).all()
    distance, index = NeighbourIndex(np.ones((5, 4))).query(np.zeros((0, 4)), k=2)
    assert distance.shape == (0, 2)


def test_nearest_other_distance_is_ckdtrees_second_neighbour():
    rng = np.random.default_rng(3)
    directions = rng.normal(size=(3000, 3))
    directions[:1500, 2] *= 0.05  # a dense band and a sparse rest
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    directions[10] = directions[11]  # a repeated ray
    expected = cKDTree(directions).query(directions, k=2)[0][:, 1]
    np.testing.assert_array_equal(nearest_other_distance(directions), expected)
    assert nearest_other_distance(directions)[10] == 0.0
    # A narrow cone of rays and one stray ray (the reach starts from the cone's spacing).
    pan, tilt = rng.uniform(-0.01, 0.01, (2, 2000))
    cone = np.column_stack([np.cos(tilt) * np.cos(pan), np.cos(tilt) * np.sin(pan), np.sin(tilt)])
    cone[0] = (-1.0, 0.0, 0.0)
    np.testing.assert_array_equal(nearest_other_distance(cone), cKDTree(cone).query(cone, k=2)[0][:, 1])
    assert np.isinf(nearest_other_distance(directions[:1])).all()
    np.testing.assert_array_equal(nearest_other_distance(np.ones((4, 3))), np.zeros(4))
