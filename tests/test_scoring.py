"""occtool.scoring's held-out points, world rays, world grid and its Nav2 reading, on answers worked out by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import expit

import occtool.scoring
from occtool.errors import InputError
from occtool.features import Features, Pose, Position
from occtool.fuse import FREE, OCCUPIED, UNKNOWN
from occtool.grid import OCTOMAP_DEFAULTS, logit
from occtool.scoring import (
    beam_test_points,
    grid_raster,
    holdout_blocks,
    holdout_test_points,
    world_grid,
    world_rays,
)


def test_every_public_name_is_in_the_lazy_table_and_imports():
    assert sorted(occtool.scoring.__all__) == sorted(occtool.scoring._LAZY)
    for name in occtool.scoring.__all__:
        assert getattr(occtool.scoring, name) is not None


def test_planar_beam_points_lie_on_each_beam_up_to_the_margin():
    starts = np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 1.0]])
    ends = np.array([[2.0, 0.0], [0.0, 0.05], [1.0, 4.0]])  # the middle one is shorter than the margin
    occupied, free = beam_test_points(starts, ends, seed=7, per_beam=3, margin=0.1)
    np.testing.assert_array_equal(occupied, ends)  # every return is an occupied point, short ones too
    assert free.shape == (6, 2)  # none from the short beam
    fraction = np.random.default_rng(7).uniform(0.0, 1.0, size=(2, 3))
    np.testing.assert_allclose(free[:3], np.column_stack([1.9 * fraction[0], np.zeros(3)]))
    np.testing.assert_allclose(free[3:], np.column_stack([np.ones(3), 1.0 + 2.9 * fraction[1]]))
    again = beam_test_points(starts, ends, seed=7, per_beam=3, margin=0.1)[1]
    np.testing.assert_array_equal(again, free)
    assert not np.array_equal(beam_test_points(starts, ends, seed=8, per_beam=3, margin=0.1)[1], free)


def test_beam_points_in_space_measure_the_whole_beam():
    # A beam rising 4 m over 3 m: 5 m long, so the free points stop 4.9 m along it (the
    # plane alone would stop them 2.9 m along, 4.83 m in space).
    occupied, free = beam_test_points(np.zeros((1, 3)), np.array([[0.0, 3.0, 4.0]]), seed=0, per_beam=200)
    along = np.linalg.norm(free, axis=1)
    assert free.shape == (200, 3) and along.max() <= 4.9 and along.max() > 4.85
    np.testing.assert_allclose(free[:, 1] / 3.0, free[:, 2] / 4.0)  # on the beam


def test_beam_points_are_the_published_ones_to_the_last_bit():
    # The log scorer measured its beams with norm, the grid tuner with hypot; one generator
    # keeps both, so no published score moves by a rounding.
    rng = np.random.default_rng(3)
    starts, ends = rng.uniform(-5, 5, (50, 3)), rng.uniform(-5, 5, (50, 3))
    for d, length in ((2, np.hypot(*(ends[:, :2] - starts[:, :2]).T)), (3, np.linalg.norm(ends - starts, axis=1))):
        s, e = starts[:, :d], ends[:, :d]
        fraction = np.random.default_rng(1).uniform(0.0, 1.0, size=(50, 5))
        reach = ((length - 0.1) / length)[:, None] * fraction
        expected = (s[:, None, :] + reach[:, :, None] * (e - s)[:, None, :]).reshape(-1, d)
        assert np.array_equal(beam_test_points(s, e, seed=1)[1], expected)


def _scan(index: int, pose: Pose, points: list[list[float]], evidence: list[float]) -> Position:
    return Position(index, Features(np.array(points, dtype=float), np.array(evidence, dtype=float)), pose)


def test_world_rays_place_each_scan_at_its_pose():
    scans = [_scan(0, Pose(x=1.0, y=2.0, yaw=math.pi / 2), [[1.0, 0.0, 0.3], [2.0, 0.0, 0.3]], [1.0, 0.0]),
             _scan(1, Pose(x=-1.0, y=0.0, yaw=0.0), [[0.5, 0.5, 0.3]], [0.9])]
    starts, ends, returns, owner = world_rays(scans)
    np.testing.assert_allclose(starts, [[1, 2, 0], [1, 2, 0], [-1, 0, 0]])
    np.testing.assert_allclose(ends, [[1, 3, 0.3], [1, 4, 0.3], [-0.5, 0.5, 0.3]], atol=1e-12)
    np.testing.assert_array_equal(returns, [True, False, True])
    np.testing.assert_array_equal(owner, [0, 0, 1])


def test_held_out_scans_give_points_of_their_returns_only():
    scans = [_scan(0, Pose(x=1.0, y=2.0, yaw=math.pi / 2), [[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]], [1.0, 0.0])]
    occupied, free = holdout_test_points(scans, seed=2)
    np.testing.assert_allclose(occupied, [[1.0, 3.0, 0.0]], atol=1e-12)  # the free ray gives none
    assert free.shape == (5, 3)
    np.testing.assert_allclose(free[:, 0], 1.0, atol=1e-12)
    assert (free[:, 1] >= 2.0).all() and (free[:, 1] <= 2.9 + 1e-12).all()


def test_holdout_blocks_refuse_a_share_or_block_out_of_range():
    for holdout, block in ((0.0, 40), (1.0, 40), (0.1, 0)):
        with pytest.raises(InputError):
            holdout_blocks(400, holdout, block)
    assert holdout_blocks(400, 0.25, 40, seed=1).sum() == 80  # round(0.25 * 400 / 40) = 2 blocks (2.5 rounds to 2)


def test_world_grid_sums_octomaps_hits_and_misses_per_beam_and_clamps():
    # Four beams along x from (1.01, 2.01) to (1.51, 2.01): ten cells of 0.05 m missed, the
    # eleventh hit, each four times; and one free ray (no return) misses all its cells.
    pose = Pose(x=1.01, y=2.01)
    scans = [_scan(k, pose, [[0.5, 0.0, 0.0]], [1.0]) for k in range(4)]
    grid = world_grid(scans, 0.05)
    np.testing.assert_allclose(grid.lower, [1.0, 2.0, 0.0])
    z = 0.025
    hit, miss = logit(OCTOMAP_DEFAULTS.prob_hit), logit(OCTOMAP_DEFAULTS.prob_miss)
    p = grid.occupancy(np.array([[1.26, 2.01, z], [1.51, 2.01, z]]))
    np.testing.assert_allclose(p, expit([4 * miss, min(4 * hit, logit(OCTOMAP_DEFAULTS.clamping_thres_max))]),
                               rtol=1e-6)
    # Clamped below: ten more misses stop at the lower threshold.
    grid = world_grid(scans + [_scan(4 + k, pose, [[0.5, 0.0, 0.0]], [0.0]) for k in range(10)], 0.05)
    p = grid.occupancy(np.array([[1.26, 2.01, z]]))
    np.testing.assert_allclose(p, [OCTOMAP_DEFAULTS.clamping_thres_min], rtol=1e-5)


def test_grid_raster_reads_the_world_grid_as_nav2_does():
    pose = Pose(x=1.01, y=2.01)
    one = world_grid([_scan(0, pose, [[0.5, 0.0, 0.0], [0.0, 0.2, 0.0]], [1.0, 1.0])], 0.05)
    raster = grid_raster(one)
    assert raster.resolution == 0.05 and raster.origin == pytest.approx((1.0, 2.0))
    row, col, inside = raster.cell_of(np.array([[1.51, 2.01], [1.26, 2.01], [1.26, 2.16]]))
    assert inside.all()
    # One hit (p 0.7) is occupied, one miss (p 0.4) not yet free, a cell no beam crossed unknown.
    assert list(raster.cells[row, col]) == [OCCUPIED, UNKNOWN, UNKNOWN]
    four = grid_raster(world_grid([_scan(k, pose, [[0.5, 0.0, 0.0]], [1.0]) for k in range(4)], 0.05))
    row, col, _ = four.cell_of(np.array([[1.51, 2.01], [1.26, 2.01]]))
    assert list(four.cells[row, col]) == [OCCUPIED, FREE]  # four misses: p 0.165 <= 0.196


def test_the_layers_grid_scoring_compare_import_only_downwards():
    import ast
    from pathlib import Path

    package = Path(occtool.scoring.__file__).parent.parent
    above = {"grid": ("occtool.scoring", "occtool.compare"), "scoring": ("occtool.compare",)}
    for layer, forbidden in above.items():
        for path in (package / layer).glob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                         else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
                assert not [n for n in names if n.startswith(forbidden)], f"{path.name} imports {names}"
