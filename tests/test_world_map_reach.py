"""How far the 2D world map's observed region and walls reach, and how far its Nav2 raster's
free cells do (issue 35: ACES seed 1's held-out block looks at walls seen from ~20 m)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from occtool.fuse import FREE, UNKNOWN, WorldMap, load_map
from occtool.fuse._refit import _simplified, _with_far_walls
from occtool.fuse._sightings import RunReturns
from occtool.fuse._walls import fit_segments
from occtool.observation import BIN_CENTRE

BAND = (-0.25, 0.2)
CORRIDOR = shapely.MultiPolygon([shapely.box(-20.0, -1.0, 20.0, 1.0)])


def _cell(raster, x, y):
    row, col, inside = raster.cell_of([[x, y]])
    assert inside[0]
    return int(raster.cells[row[0], col[0]]), bool(raster.explored[row[0], col[0]])


def test_far_observed_space_is_graded_in_the_map_and_unknown_in_the_raster(tmp_path):
    world = WorldMap(np.zeros((0, 2)), np.zeros((0, 2)), [], [], CORRIDOR, band=BAND, positions=[[0.0, 0.0]],
                     free_reach=8.0).quantised()
    # The map grades the whole region (0.1 + 0.01 a metre) ...
    assert np.allclose(world.predict([[5.0, 0.0, 0.0], [12.0, 0.0, 0.0]]), [0.15, 0.22], atol=1e-6)
    # ... the raster calls it free only within 8 m of a position; farther it is unknown and
    # unexplored (a frontier may still lead there).
    raster = world.rasterise(0.1)
    assert _cell(raster, 5.0, 0.0) == (FREE, True)
    assert _cell(raster, 12.0, 0.0) == (UNKNOWN, False)
    # The file keeps the reach, so a loaded map draws the same raster.
    world.save(tmp_path / "w.occmap")
    loaded = load_map(tmp_path / "w.occmap")
    assert loaded.free_reach == 8.0
    assert np.array_equal(loaded.rasterise(0.1).cells, raster.cells)
    # The map build_world_map returns holds the region its raster may free, which the file does not.
    world.free_region = shapely.MultiPolygon([shapely.box(-3.0, -1.0, 3.0, 1.0)])
    shapely.prepare(world.free_region)
    narrow = world.rasterise(0.1)
    assert _cell(narrow, 2.0, 0.0) == (FREE, True) and _cell(narrow, 5.0, 0.0) == (UNKNOWN, False)
    assert np.array_equal(narrow.probability, raster.probability)


def test_a_map_without_a_free_reach_frees_its_whole_region_and_merges_only_with_its_kind():
    from occtool.errors import InputError
    from occtool.fuse import merge_maps

    old = WorldMap(np.zeros((0, 2)), np.zeros((0, 2)), [], [], CORRIDOR, band=BAND, positions=[[0.0, 0.0]])
    assert old.params()["free_reach"] == 0.0
    assert _cell(old.rasterise(0.1), 12.0, 0.0) == (FREE, True)
    new = WorldMap(np.zeros((0, 2)), np.zeros((0, 2)), [], [], CORRIDOR, band=BAND, positions=[[0.0, 0.0]],
                   free_reach=8.0)
    for maps in ([old, new], [new, old]):
        with pytest.raises(InputError, match="differ in free_reach"):
            merge_maps(maps)
    with pytest.raises(InputError, match="free_reach"):
        WorldMap(np.zeros((0, 2)), np.zeros((0, 2)), [], [], CORRIDOR, band=BAND, free_reach=-1.0)


def _wall_returns(poses, wall_x, bins=720):
    """Each position's nearest return per bin on a wall across x = ``wall_x`` (|y| < 6 m)."""
    ranges = np.zeros((len(poses), bins))
    angles = -math.pi + (np.arange(bins) + 0.5) * (2.0 * math.pi / bins)
    for k, (x, y, _, yaw) in enumerate(poses):
        a = angles + yaw
        with np.errstate(divide="ignore", invalid="ignore"):
            r = (wall_x - x) / np.cos(a)
        hit = (r > 0) & (np.abs(y + r * np.sin(a)) < 6.0)
        ranges[k, hit] = r[hit]
    return RunReturns(np.asarray(poses, dtype=np.float64), ranges, ranges > 0,
                      np.full(ranges.shape, BIN_CENTRE, dtype=np.uint8), scanning_laser=True)


def test_walls_seen_only_from_afar_are_added_and_nearer_walls_kept():
    fit = {"cell": 0.64, "max_thickness": 0.03, "min_returns": 3}
    run = _wall_returns([[0.0, 0.0, 0.0, 0.0]], 20.0)
    near, owner = run.return_points(16.0)
    assert near.shape[0] == 0  # the wall is 20 m away: no wall within the walls' reach
    none = fit_segments(near, owner, **fit)
    far = _with_far_walls(none, run, near, 16.0, 30.0, True, fit)
    middle = far.middle
    assert len(far) > 0 and np.allclose(middle[:, 0], 20.0, atol=0.05)
    # A position 2 m from the wall places it itself: the far returns add nothing there.
    run = _wall_returns([[0.0, 0.0, 0.0, 0.0], [18.0, 0.0, 0.0, 0.0]], 20.0)
    near, owner = run.return_points(16.0)
    segments = fit_segments(near, owner, viewpoints=run.poses[owner, :2], **fit)
    assert len(segments) > 0
    assert _with_far_walls(segments, run, near, 16.0, 30.0, True, fit) is segments


@pytest.mark.parametrize("block", [1, 7, 1 << 18])
def test_far_returns_checked_a_block_of_near_returns_at_a_time_are_those_of_one_tree(monkeypatch, block):
    """The far returns within FAR_WALL_GAP of a near one are found a block of near returns
    at a time (FAR_TREE_RETURNS): the same far walls as one tree of them all."""
    from occtool.fuse import _refit

    fit = {"cell": 0.64, "max_thickness": 0.03, "min_returns": 3}
    # A wall 20 m from the origin and 3.5 m from a second position, which places it: the
    # origin's far returns on it are dropped; another 25 m from the origin, which only it
    # saw: its far returns make walls.
    run = _wall_returns([[0.0, 0.0, 0.0, 0.0], [16.5, 3.0, 0.0, 0.0]], 20.0)
    extra = _wall_returns([[0.0, 0.0, 0.0, 0.0]], 25.0)
    run = RunReturns(np.vstack([run.poses, extra.poses]), np.vstack([run.ranges, extra.ranges]),
                     np.vstack([run.returned, extra.returned]), np.vstack([run.offsets, extra.offsets]),
                     scanning_laser=True)
    near, owner = run.return_points(16.0)
    segments = fit_segments(near, owner, viewpoints=run.poses[owner, :2], **fit)
    whole = _with_far_walls(segments, run, near, 16.0, 30.0, True, fit)
    monkeypatch.setattr(_refit, "FAR_TREE_RETURNS", block)
    blocks = _with_far_walls(segments, run, near, 16.0, 30.0, True, fit)
    added = whole.middle[len(segments):]
    assert len(added) > 0 and np.allclose(added[:, 0], 25.0, atol=0.05) and len(blocks) == len(whole)
    for field in ("start", "end", "thickness", "hits", "facing"):
        assert np.array_equal(getattr(blocks, field), getattr(whole, field))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**16), gap=st.sampled_from([0.01, 0.05, 0.2, 5.0]))
def test_a_region_simplified_a_group_of_polygons_at_a_time_is_simplified_whole(seed, gap):
    """The observed region's polygons are simplified in groups of those within a few
    tolerances of each other: the same geometry, byte for byte, as one simplification."""
    rng = np.random.default_rng(seed)
    polygons = []
    for k in range(6):  # wobbly rings with holes, some a gap apart, some far
        centre = np.array([k * (4.0 + gap) if k % 3 else k * 40.0, 0.0])
        angles = np.linspace(0, 2 * np.pi, 80, endpoint=False)
        radius = 2.0 + 0.02 * rng.standard_normal(80)
        shell = centre + np.column_stack([radius * np.cos(angles), radius * np.sin(angles)])
        hole = centre + 0.5 * np.column_stack([np.cos(angles), np.sin(angles)]) * (1 + 0.02 * rng.random(80))[:, None]
        polygons.append(shapely.Polygon(shell, [hole[::-1]]))
    region = shapely.union_all(polygons)
    whole = shapely.simplify(region, 0.03, preserve_topology=True)
    assert shapely.to_wkb(_simplified(region, 0.03)) == shapely.to_wkb(whole)
