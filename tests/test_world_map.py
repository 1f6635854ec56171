"""The world map of a run: wall segments, the observed region, the .occmap file, `occtool query`."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import shapely
from _room_log import ROOM, write_room_log
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from occtool.cli.main import cli
from occtool.errors import InputError
from occtool.fit import OccupancyRegressor
from occtool.formats.occmap import encode
from occtool.fuse import FREE, OCCUPIED, UNKNOWN, WorldMap, build_world_map, decode_map, fuse_log, load_map
from occtool.fuse._walls import fit_segments, free_in_bands
from occtool.io import read_log
from occtool.robot import Robot

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"
LASER_ROBOT = Robot(radius=0.25, sensor_height=0.3, body_height=0.5)
BAND = (-0.25, 0.2)


def quantise(world):
    """``world`` rounded to its file's precision (what build_world_map returns)."""
    return world.quantised()


def test_returns_on_a_line_make_one_segment_end_to_end():
    rng = np.random.default_rng(0)
    x = rng.uniform(0.02, 0.6, 200)
    points = np.column_stack([x, 0.5 * x + 0.1 + rng.normal(0, 0.003, x.size)])
    seg = fit_segments(points, np.zeros(x.size, dtype=np.int64), cell=2.0)
    assert len(seg) == 1
    ends = np.sort(np.array([seg.start[0, 0], seg.end[0, 0]]))
    assert np.allclose(ends, [x.min(), x.max()], atol=0.01)
    assert seg.thickness[0] == pytest.approx(0.003 * math.cos(math.atan(0.5)), rel=0.3)
    direction = (seg.end - seg.start)[0]
    assert abs(direction[1] / direction[0] - 0.5) < 0.02
    assert seg.hits[0] == 200  # its returns


def test_a_corner_is_split_until_each_cell_holds_one_line():
    t = np.linspace(0.0, 1.0, 101)
    corner = np.vstack([np.column_stack([t, np.zeros_like(t)]), np.column_stack([np.zeros_like(t), t])])
    owner = np.repeat([0, 1], t.size)
    seg = fit_segments(corner, owner, cell=1.28, max_thickness=0.005)
    # Each segment's returns lie within the thickness bound of its line, but for the one
    # finest cell (4 cm) over the corner itself.
    lengths = np.hypot(*(seg.end - seg.start).T)
    assert ((seg.thickness <= 0.005 + 1e-9) | (lengths <= 0.04 * math.sqrt(2))).all()
    assert (seg.thickness > 0.005).sum() == 1
    assert lengths.sum() == pytest.approx(2.0, abs=0.15)
    # Every return lies on one segment.
    assert seg.hits.sum() == corner.shape[0]


def test_free_in_bands_is_the_length_of_free_beams_inside_each_band():
    # One position at the origin seeing 3 m all round in 720 bins; walls 10 cm long across
    # the x axis. The band of one at 1 m is 4 cm deep (half-width 2 cm) and 14 cm long (2 cm
    # past each end): about 16 beams cross it, 4 cm each.
    poses = np.array([[0.0, 0.0, 0.0, 0.0]])
    ranges = np.full((1, 720), 3.0)
    x = np.array([1.0, 2.95, -2.0, 5.0])
    start, end = np.column_stack([x, np.full(4, -0.05)]), np.column_stack([x, np.full(4, 0.05)])

    def free(reach=8.0, thickness=0.0):
        return free_in_bands(start, end, np.full(4, thickness), poses, ranges, margin=0.1, reach=reach,
                             half_width=0.02, spacing=0.1)

    # Each beam's chord through the band at 1 m, summed over the 720 beams, for the first:
    angle = -math.pi + (np.arange(720) + 0.5) * 2 * math.pi / 720
    y_at = np.tan(angle) * 0.98, np.tan(angle) * 1.02
    inside = (np.cos(angle) > 0) & (np.abs(y_at[0]) <= 0.07) & (np.abs(y_at[1]) <= 0.07)
    chords = 0.04 / np.cos(angle[inside])
    assert chords.sum() == pytest.approx(0.64, abs=0.04)
    got = free()
    # The band's area over the beams' spacing:
    assert got[0] == pytest.approx(0.14 * 0.04 / (2 * math.pi / 720), rel=0.01)
    assert got[0] == pytest.approx(chords.sum(), rel=0.1)
    # 5 cm in front of the 3 m return the beams are not free (10 cm margin); 2 m behind the
    # position they are, over a band 2 m away (half as many beams); 5 m away, past the returns.
    assert got[1] == 0.0 and got[3] == 0.0
    assert got[2] == pytest.approx(got[0] / 2.0, rel=0.01)
    # Beyond the reach nothing is free; a thicker wall's band is its thickness either side.
    assert free(reach=0.5).tolist() == [0.0] * 4
    assert free(thickness=0.04)[0] == pytest.approx(2.0 * got[0], rel=0.01)


def test_a_wall_the_beams_pass_through_is_trusted_by_its_share_of_returns():
    from occtool.fuse._refit import wall_trust
    from occtool.fuse._sightings import RunReturns
    from occtool.observation import BIN_CENTRE

    # Ten scans from the origin, every beam ahead returning from a wall across x = 2 m; in
    # four of them a person 10 cm wide stands at 1 m, and in the six others those beams pass
    # where the person stood.
    angle = -math.pi + (np.arange(720) + 0.5) * 2 * math.pi / 720
    ahead = np.cos(angle) > 0.5
    ranges = np.zeros((10, 720))
    ranges[:, ahead] = 2.0 / np.cos(angle[ahead])
    person = ahead & (np.abs(np.tan(angle)) <= 0.05)
    ranges[:4, person] = 1.0 / np.cos(angle[person])
    run = RunReturns(np.zeros((10, 4)), ranges, ranges > 0, np.full(ranges.shape, BIN_CENTRE, dtype=np.uint8),
                     scanning_laser=True)
    points, owner = run.return_points(16.0)
    segments = fit_segments(points, owner, owner_positions=run.poses[:, :2])
    trust = wall_trust(segments, run, 8.0)
    at_person = np.abs(segments.middle[:, 0] - 1.0) < 0.01
    assert at_person.sum() == 1 and segments.hits[at_person][0] == 4 * person.sum() == 48
    # The six scans' beams through the person's band (its 10 cm and 2 cm past each end, by
    # 4 cm, at 1 m; the beams 0.5 degree apart) are free over its area over their spacing,
    # a free point every 0.1 m of them.
    length = float(np.hypot(*(segments.end - segments.start)[at_person][0]))
    assert length == pytest.approx(0.1, abs=0.01)
    free_points = 6 * (length + 0.04) * 0.04 / (2 * math.pi / 720) / 0.1
    assert trust[at_person][0] == pytest.approx(48 / (48 + free_points), rel=0.01)
    # The wall at 2 m: no beam passes it free (each ends at its return).
    assert np.all(trust[~at_person] == 1.0)


def test_a_wall_seen_from_one_side_faces_it():
    rng = np.random.default_rng(1)
    x = rng.uniform(0.0, 0.6, 300)
    wall = np.column_stack([x, rng.normal(0, 0.004, x.size)])
    above = np.column_stack([rng.uniform(-1, 1, x.size), np.full(x.size, 2.0)])
    owner = np.zeros(x.size, dtype=np.int64)

    def left_of_line_is_up(seg):
        d = (seg.end - seg.start)[0]
        return -d[0] > 0 if abs(d[0]) < abs(d[1]) else d[0] > 0  # the normal (-dy, dx) points to +y

    one = fit_segments(wall, owner, viewpoints=above, cell=2.0)
    assert len(one) == 1 and one.facing[0] == (1 if left_of_line_is_up(one) else -1)
    below = above * [1, -1]
    mixed = np.where(np.arange(x.size)[:, None] % 2 == 0, above, below)
    assert fit_segments(wall, owner, viewpoints=mixed, cell=2.0).facing.tolist() == [0]
    assert fit_segments(wall, owner, cell=2.0).facing.tolist() == [0]  # no viewpoints: both sides


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 400))
def test_segments_fitted_a_stripe_at_a_time_are_those_of_one_pass(seed, most):
    from occtool.fuse import _walls

    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 600))
    # Walls and clutter over a few metres, seen from a few positions.
    t = rng.uniform(0, 6, n)
    points = np.where(rng.random((n, 1)) < 0.7, np.column_stack([t, 0.2 * t + rng.normal(0, 0.01, n)]),
                      rng.uniform(-1, 6, (n, 2)))
    positions = rng.uniform(-3, 8, (5, 2))
    owner = rng.integers(0, 5, n)
    whole = fit_segments(points, owner, viewpoints=positions[owner], cell=0.64)
    saved = _walls.STRIPE_RETURNS
    try:
        _walls.STRIPE_RETURNS = most
        striped = fit_segments(points, owner, owner_positions=positions, cell=0.64)
    finally:
        _walls.STRIPE_RETURNS = saved
    for name in ("start", "end", "thickness", "hits", "facing"):
        np.testing.assert_array_equal(getattr(striped, name), getattr(whole, name), err_msg=name)


def _square_map(**kwargs):
    """A 2 m x 2 m observed square with one trusted wall along its right side."""
    region = shapely.MultiPolygon([shapely.box(0.0, 0.0, 2.0, 2.0)])
    return WorldMap([[2.0, 0.0]], [[2.0, 2.0]], [0.01], [1.0], region, band=BAND, **kwargs)


def test_a_wall_is_a_min_of_linear_pieces_over_the_free_level():
    world = _square_map(width=0.2, free_level=0.2)
    z = 0.0
    across = np.array([0.0, 0.01, 0.06, 0.11, 0.5])
    points = np.column_stack([2.0 - across, np.full(across.size, 1.0), np.full(across.size, z)])
    p = world.predict(points)
    expected = np.maximum(0.2, np.minimum(1.0, 1.0 - (across - 0.01) / 0.2))
    assert np.allclose(p, expected)
    # Past the end of the wall the ridge falls along it too.
    assert world.predict([[2.0, 2.1, z]])[0] == pytest.approx(0.5, abs=1e-9)  # outside the region: unknown
    assert world.predict([[1.99, 2.05, z]])[0] == pytest.approx(0.75, abs=1e-9)


def test_a_one_sided_wall_falls_steeply_in_front_and_slowly_behind():
    # The wall x = 2 runs from y = 0 to 2: its left, the normal (-1, 0), is the observed square.
    front = _square_map(width=0.2, front_width=0.125, back_width=0.6, free_level=0.2, facing=[1])
    across = np.array([0.05, 0.1])
    inside = np.column_stack([2.0 - across, np.ones(2), np.zeros(2)])
    outside = np.column_stack([2.0 + across, np.ones(2), np.zeros(2)])
    assert np.allclose(front.predict(inside), np.maximum(0.2, 1.0 - (across - 0.01) / 0.125))
    assert np.allclose(front.predict(outside), np.maximum(0.5, 1.0 - (across - 0.01) / 0.6))
    # Facing the other way the slopes swap sides; facing both, the wall is symmetric.
    back = _square_map(width=0.2, front_width=0.125, back_width=0.6, free_level=0.2, facing=[-1])
    assert np.allclose(back.predict(inside), np.maximum(0.2, 1.0 - (across - 0.01) / 0.6))
    both = _square_map(width=0.2, free_level=0.2)
    assert np.allclose(both.predict(inside), np.maximum(0.2, 1.0 - (across - 0.01) / 0.2))
    with pytest.raises(InputError, match="facing must hold -1, 0 or \\+1"):
        _square_map(facing=[2])


def test_a_segment_turned_round_by_the_file_keeps_the_side_it_faces():
    """The file stores directions in [0, pi): a segment from +x to -x is stored turned round,
    its facing with it, so that it answers as before."""
    region = shapely.MultiPolygon([shapely.box(-2, -2, 2, 2)])
    world = WorldMap([[0.5, 0.0]], [[-0.5, 0.0]], [0.01], [1.0], region, band=BAND, facing=[1])
    coded = quantise(world)
    assert (coded.end - coded.start)[0, 0] > 0 and coded.facing.tolist() == [-1]
    points = np.array([[0.0, -0.15, 0.0], [0.0, 0.15, 0.0], [0.3, 0.3, 0.0]])
    assert np.allclose(coded.predict(points), world.predict(points))
    assert np.array_equal(decode_map(encode(coded)).facing, coded.facing)


def test_free_space_reads_less_sure_away_from_the_positions():
    region = shapely.MultiPolygon([shapely.box(-20.0, -1.0, 20.0, 1.0)])
    world = WorldMap(np.zeros((0, 2)), np.zeros((0, 2)), [], [], region, band=BAND, positions=[[0.0, 0.0]])
    p = world.predict([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0], [-10.0, 0.0, 0.0], [19.0, 0.0, 0.0], [25.0, 0.0, 0.0]])
    # A cone from the position (0.1 + 0.01 d), below unknown however far; unknown outside the region.
    assert np.allclose(p, [0.1, 0.15, 0.2, 0.29, 0.5])
    far = WorldMap(np.zeros((0, 2)), np.zeros((0, 2)), [], [], shapely.MultiPolygon([shapely.box(0, -1, 100, 1)]),
                   band=BAND, positions=[[0.0, 0.0]])
    assert far.predict([[99.0, 0.0, 0.0]])[0] == pytest.approx(0.45)
    # Without positions (a version 1 file) the level is flat.
    flat = WorldMap(np.zeros((0, 2)), np.zeros((0, 2)), [], [], region, band=BAND)
    assert np.allclose(flat.predict([[0.0, 0.0, 0.0], [19.0, 0.0, 0.0]]), flat.free_level)


def test_unknown_outside_the_region_and_the_band():
    world = _square_map()
    far = world.predict([[-3.0, -3.0, 0.0], [1.0, 1.0, 0.5], [1.0, 1.0, -0.3]])
    assert np.allclose(far, 0.5)
    assert world.predict([[1.0, 1.0, 0.0]])[0] == pytest.approx(world.free_level)


def test_walls_few_positions_saw_through_read_less_occupied():
    region = shapely.MultiPolygon([shapely.box(0.0, 0.0, 4.0, 2.0)])
    world = WorldMap([[1.0, 0.0], [3.0, 0.0]], [[1.0, 2.0], [3.0, 2.0]], [0.0, 0.0], [1.0, 0.25], region, band=BAND)
    solid, passing = world.predict([[1.0, 1.0, 0.0], [3.0, 1.0, 0.0]])
    assert solid == pytest.approx(1.0) and passing == pytest.approx(0.625)
    raster = world.rasterise(0.05)
    row, col, _ = raster.cell_of([[1.0, 1.0], [3.0, 1.0], [2.0, 1.0], [5.0, 1.0]])
    # The wall most positions saw through is not drawn for Nav2 (share below 0.5; below
    # DOUBTED_TRUST too, so free on its line); past the region nothing was observed.
    assert raster.cells[row, col].tolist() == [OCCUPIED, FREE, FREE, UNKNOWN]
    assert raster.explored[row, col].tolist() == [True, True, True, False]
    # Across the trusted wall (ridge 1 falling to 0 over WIDTH 0.2 m) the cells follow its
    # occupancy: occupied to 0.07 m (0.65), then unknown; free from 0.13 m (0.35) and past
    # the wall's rim (0.125 m); a cell's centre decides.
    from occtool.raster import RASTER_FREE, RASTER_OCCUPIED

    occupied_to, free_from = (1.0 - RASTER_OCCUPIED) * world.width, (1.0 - RASTER_FREE) * world.width
    # (points inside cells whose centres lie 0.025, 0.125 and 0.175 m from the wall's line)
    assert 0.025 < occupied_to < 0.125 < max(free_from, world.wall_rim) < 0.175
    edge_row, edge_col, _ = raster.cell_of([[1.01, 1.0], [1.11, 1.0], [1.16, 1.0]])
    assert raster.cells[edge_row, edge_col].tolist() == [OCCUPIED, UNKNOWN, FREE]


def _frontier_raster(cells, explored):
    from occtool.fuse import Raster

    shape = cells.shape
    return Raster(cells, 0.05, (0.0, 0.0), np.zeros(shape, dtype=np.float32), np.zeros(shape, dtype=bool),
                  explored=explored)


def test_frontiers_lie_where_observed_free_space_meets_unexplored_space():
    """An unknown cell the run observed (a wall's edge) is no frontier; one nothing observed is;
    a gap narrower than the robot is no frontier; the point is the frontier's middle cell."""
    from occtool.fuse import frontiers_of

    cells = np.full((40, 60), FREE, dtype=np.uint8)
    explored = np.ones((40, 60), dtype=bool)
    cells[:, 0] = OCCUPIED  # walls round the room but the right side
    cells[0, :] = cells[-1, :] = OCCUPIED
    cells[1:-1, 1:3] = UNKNOWN  # the left wall's uncertain edge: observed
    cells[:, 50:] = UNKNOWN  # past x = 2.5 m nothing observed...
    explored[:, 50:] = False
    cells[1:-1, 49] = OCCUPIED  # ...behind a wall with a doorway 0.5 m wide (rows 10-19)
    cells[10:20, 49] = FREE
    cells[30:33, 49] = FREE  # and a 0.15 m gap: too narrow to be a frontier
    raster = _frontier_raster(cells, explored)
    found = frontiers_of(raster)
    # Cell (row 14, column 49): of the doorway's two middle cells, the first.
    assert found == pytest.approx(np.array([[2.475, 0.725]]))
    assert frontiers_of(raster, min_length=0.1) == pytest.approx(np.array([[2.475, 0.725], [2.475, 1.575]]))
    # Without the observed mask, the wall's uncertain edge is unexplored too.
    raster.explored = None
    assert frontiers_of(raster) == pytest.approx(np.array([[0.175, 0.975], [2.475, 0.725]]))
    # A raster with no free cell, or no unexplored cell, has no frontier.
    assert frontiers_of(_frontier_raster(np.full((5, 5), UNKNOWN, dtype=np.uint8), None)).shape == (0, 2)
    closed = np.full((5, 5), OCCUPIED, dtype=np.uint8)
    closed[1:-1, 1:-1] = FREE
    assert frontiers_of(_frontier_raster(closed, np.ones((5, 5), dtype=bool))).shape == (0, 2)


def test_quantised_map_round_trips_bit_for_bit(tmp_path):
    rng = np.random.default_rng(3)
    start = rng.uniform(-5, 5, (50, 2))
    end = start + rng.normal(0, 0.2, (50, 2))
    region = shapely.MultiPolygon([shapely.box(-4, -4, 0, 0), shapely.Point(2, 2).buffer(1.5)])
    world = quantise(WorldMap(start, end, rng.uniform(0, 0.03, 50), rng.uniform(0, 1, 50), region, band=BAND,
                              facing=rng.integers(-1, 2, 50)))
    path = tmp_path / "world.occmap"
    size = world.save(path)
    assert size == path.stat().st_size
    loaded = load_map(path)
    points = np.column_stack([rng.uniform(-6, 6, 5000), rng.uniform(-6, 6, 5000), np.zeros(5000)])
    assert np.array_equal(world.predict(points), loaded.predict(points))
    assert np.array_equal(loaded.start, world.start) and loaded.params() == world.params()
    assert np.array_equal(loaded.facing, world.facing) and (world.facing != 0).any()
    # The header and checksum are all the file adds to what predict needs.
    assert size - world.nbytes < 1000
    assert encode(loaded) == path.read_bytes()


def test_segments_keep_their_geometry_in_six_bytes_and_two_bits():
    """Middle (in its tile), direction and half-length codes: ends within a few millimetres of
    the fitted ones, a segment longer than a byte of 2 mm widens the unit instead of being
    cut; the segments listed tile by tile; the facings four to a byte."""
    from scipy.spatial import cKDTree

    from occtool.formats.occmap import TILE

    rng = np.random.default_rng(5)
    start = rng.uniform(-5, 5, (200, 2))
    end = start + rng.normal(0, 0.3, (200, 2))
    end[0] = start[0] + [2.0, 0.5]  # 1.03 m half-length
    region = shapely.MultiPolygon([shapely.box(-6, -6, 6, 6)])
    world = WorldMap(start, end, np.zeros(200), np.ones(200), region, band=BAND)
    coded = quantise(world)
    assert coded.half_unit > 0.002 and len(coded) == 200
    # Each fitted segment has its coded one, in another order.
    _, match = cKDTree(0.5 * (coded.start + coded.end)).query(0.5 * (start + end))
    assert np.unique(match).size == 200
    same = np.minimum(np.hypot(*(coded.start[match] - start).T) + np.hypot(*(coded.end[match] - end).T),
                      np.hypot(*(coded.start[match] - end).T) + np.hypot(*(coded.end[match] - start).T))
    assert same.max() < 0.02
    tile = np.floor((0.5 * (coded.start + coded.end) - coded.origin) / coded.unit / TILE + 1e-9).astype(int)
    key = tile[:, 0] * (tile[:, 1].max() + 1) + tile[:, 1]
    assert (np.diff(key) >= 0).all()
    tiles = int(np.prod(tile.max(axis=0) + 1))
    # A box's five vertices are anchors (its sides are longer than a step), in uint16; its
    # ring, part and geometry offsets uint16 too.
    assert coded.nbytes == 6 * 200 + 200 // 4 + tiles + 5 * (2 + 4) + 3 * 2 * 2
    assert np.array_equal(decode_map(encode(coded)).end, coded.end)


def test_a_crowded_tile_and_long_steps_round_trip():
    """More than 255 segments in one tile widen its counts; region vertices a step, an
    anchor or mixed come back exactly; anchors that disagree with their codes are refused."""
    from occtool.formats.occmap import _arrays, _stepped_vertices, _vertex_steps

    rng = np.random.default_rng(8)
    start = rng.uniform(0, 1.0, (400, 2))
    world = quantise(WorldMap(start, start + [0.05, 0.0], np.full(400, 0.01), np.ones(400),
                              shapely.MultiPolygon([shapely.Point(0.5, 0.5).buffer(20.0, 64)]), band=BAND))
    loaded = decode_map(encode(world))
    assert np.array_equal(loaded.start, world.start) and loaded.region.equals_exact(world.region, 0)
    counts = dict(_arrays(world)[1])["tile_counts"]
    assert counts.dtype == np.uint16 and counts.max() > 255
    walk = np.cumsum(rng.integers(-300, 301, (500, 2)) * (rng.uniform(size=(500, 1)) < 0.2)
                     + rng.integers(-127, 128, (500, 2)), axis=0)
    walk = walk - walk.min(axis=0)
    steps, anchors = _vertex_steps(walk)
    assert 1 < anchors.shape[0] < 500 and np.array_equal(_stepped_vertices(steps, anchors), walk)
    with pytest.raises(ValueError, match="anchor codes"):
        _stepped_vertices(steps, anchors[:-1])


def _version_3(world):
    """``world`` as a version 3 file (middles as two uint16 units, every region vertex whole)."""
    import json
    import struct
    import zlib

    from occtool.formats.occmap import MAGIC, _pack_facing, _segment_codes

    middles, steps, half = _segment_codes(world, world.origin, world.unit, world.half_unit)
    units = lambda xy: np.round((xy - world.origin) / world.unit).astype("<u2")  # noqa: E731
    _, coords, offsets = shapely.to_ragged_array([world.region])
    arrays = [("middles", middles), ("directions", steps), ("half_lengths", half),
              ("thickness", np.round(world.thickness * 1000).astype(np.uint8)),
              ("trust", np.round(world.trust * 255).astype(np.uint8)), ("facing", _pack_facing(world.facing)),
              ("positions", units(world.positions).reshape(-1, 2)), ("region_coords", units(coords))]
    arrays += [(f"region_offsets_{n}", np.asarray(o, dtype="<u4")) for n, o in enumerate(offsets)]
    header = {"format": "occtool.occmap", "version": 3, "unit": world.unit, "half_unit": world.half_unit,
              "origin": list(world.origin), "settings": world.params(),
              "arrays": [[n, a.dtype.name, list(a.shape)] for n, a in arrays]}
    text = json.dumps(header).encode()
    body = MAGIC + struct.pack("<I", len(text)) + text + b"".join(a.tobytes() for _, a in arrays)
    return body + struct.pack("<I", zlib.crc32(body))


def test_version_3_files_answer_as_they_did_and_are_rewritten_smaller():
    rng = np.random.default_rng(4)
    start = rng.uniform(-8, 8, (300, 2))
    world = quantise(WorldMap(start, start + rng.normal(0, 0.2, (300, 2)), rng.uniform(0, 0.03, 300),
                              rng.uniform(0, 1, 300), shapely.MultiPolygon([shapely.Point(0, 0).buffer(7.0, 32)]),
                              band=BAND, positions=rng.uniform(-3, 3, (20, 2)), facing=rng.integers(-1, 2, 300)))
    # A version 3 file listed its segments as they were fitted.
    shuffled = quantise(world)
    order = rng.permutation(300)
    for name in ("start", "end", "thickness", "trust", "facing"):
        setattr(shuffled, name, getattr(world, name)[order])
    old_bytes = _version_3(shuffled)
    old = decode_map(old_bytes, "old.occmap")
    points = np.column_stack([rng.uniform(-8, 8, (4000, 2)), np.zeros(4000)])
    assert np.array_equal(old.predict(points), world.predict(points))
    # Read into the file's order: tile by tile, as fitted within a tile.
    rows = lambda m: np.hstack([m.start, m.end, m.thickness[:, None], m.trust[:, None], m.facing[:, None]])  # noqa: E731
    assert np.array_equal(np.unique(rows(old), axis=0), np.unique(rows(world), axis=0))
    assert encode(old) == encode(decode_map(encode(old)))
    assert len(encode(old)) == len(encode(world)) < 0.85 * len(old_bytes)


def _version_1(world):
    """``world`` as a version 1 file (both end points in uint16 units)."""
    import json
    import struct
    import zlib

    from occtool.formats.occmap import MAGIC

    units = lambda xy: np.round((xy - world.origin) / world.unit).astype("<u2")  # noqa: E731
    arrays = [("segments", np.hstack([units(world.start), units(world.end)])),
              ("thickness", np.round(world.thickness * 1000).astype(np.uint8)),
              ("trust", np.round(world.trust * 255).astype(np.uint8))]
    header = {"format": "occtool.occmap", "version": 1, "unit": world.unit, "origin": list(world.origin),
              "settings": world.params(), "arrays": [[n, a.dtype.name, list(a.shape)] for n, a in arrays]}
    text = json.dumps(header).encode()
    body = MAGIC + struct.pack("<I", len(text)) + text + b"".join(a.tobytes() for _, a in arrays)
    return body + struct.pack("<I", zlib.crc32(body))


def test_version_1_files_still_load_and_later_ones_are_refused():
    world = quantise(WorldMap([[0.0, 0.0]], [[1.0, 0.0]], [0.01], [1.0], shapely.MultiPolygon(), band=BAND))
    old = decode_map(_version_1(world), "old.occmap")
    assert np.allclose(old.start, world.start, atol=0.003) and np.allclose(old.end, world.end, atol=0.003)
    assert old.half_unit is None and decode_map(encode(old)).half_unit is not None  # rewritten as version 4
    newer = _version_1(world).replace(b'"version": 1', b'"version": 9')
    import struct
    import zlib
    newer = newer[:-4] + struct.pack("<I", zlib.crc32(newer[:-4]))
    with pytest.raises(InputError, match="format version 9, this occtool reads 1, 2, 3 and 4"):
        decode_map(newer, "new.occmap")


@pytest.fixture(scope="module")
def room_map(tmp_path_factory):
    path = tmp_path_factory.mktemp("room") / "room.log"
    write_room_log(path, scans=40)
    fused, _, report = fuse_log(read_log(path), OccupancyRegressor(robot=LASER_ROBOT))
    return fused, build_world_map(fused, sightings=report.sightings)


def test_the_room_log_walls_free_inside_unknown_behind(room_map):
    fused, world = room_map
    x0, y0, x1, y1 = ROOM
    walls = np.array([[x1, 0.3, 0.0], [1.0, y1, 0.0], [1.0, y0, 0.0], [x0, 0.0, 0.0]])
    inside = np.array([[1.0, 0.25, 0.0], [0.0, 0.0, 0.0], [3.0, 1.0, 0.0]])
    behind = np.array([[x1 + 1.5, 0.3, 0.0], [1.0, y1 + 1.5, 0.0]])
    p = world.predict(np.vstack([walls, inside, behind]))
    assert (p[:4] > 0.9).all()
    # Free, rising a hundredth a metre from the nearest position.
    nearest = np.min(np.hypot(*(inside[:, None, :2] - world.positions[None]).transpose(2, 0, 1)), axis=1)
    assert np.allclose(p[4:7], world.free_level + world.free_slope * nearest)
    assert world.free_level == 0.1 and world.free_slope == 0.01 and len(world.positions) == len(fused)
    assert np.allclose(p[7:], 0.5)
    # The room's walls were seen from inside only: they fall steeply into the room, slowly behind
    # (a laser's sightings; the fused map of a laser log knows it too; told otherwise, both).
    assert (world.facing != 0).mean() > 0.9
    assert fused.scanning_laser and build_world_map(fused, sightings=None).facing.any()
    assert not build_world_map(fused, sightings=None, one_sided=False).facing.any()
    # A laser's map takes the Nav2 shares chosen for its trust; another sensor's keeps the old.
    from occtool.fuse._refit import NAV2_DOUBTED_SHARE, NAV2_WALL_SHARE
    from occtool.fuse._world import DOUBTED_TRUST, WALL_SHARE

    assert (world.wall_share, world.doubted_share) == (NAV2_WALL_SHARE, NAV2_DOUBTED_SHARE) == (0.15, 0.05)
    fused.scanning_laser = False  # the module's fixture: put back below
    try:
        other = build_world_map(fused, sightings=None)
    finally:
        fused.scanning_laser = True
    assert (other.wall_share, other.doubted_share) == (WALL_SHARE, DOUBTED_TRUST) == (0.5, 0.3)
    near = np.array([[x1 - 0.08, 0.3, 0.0], [x1 + 0.08, 0.3, 0.0]])
    assert np.diff(world.predict(near))[0] > 0.2
    # Far smaller than the fused map it came from, and than a 0.1 m byte grid of its extent.
    assert world.nbytes < fused.nbytes / 10 and world.nbytes < world.grid_bytes(0.1)
    raster = world.rasterise(0.05)
    row, col, inside_raster = raster.cell_of(np.vstack([walls, inside, behind])[:, :2])
    cells = np.where(inside_raster, raster.cells[row, col], UNKNOWN)
    assert (cells[:4] == OCCUPIED).all() and (cells[4:7] == FREE).all() and (cells[7:] == UNKNOWN).all()


def test_damaged_files_are_one_line_errors(room_map, tmp_path):
    _, world = room_map
    data = encode(world)
    for bad, why in ((data[:-10], "checksum"), (data[:20], "checksum"), (b"", "signature"),
                     (b"PK\x03\x04" + data[4:], "signature")):
        with pytest.raises(InputError, match=why) as caught:
            decode_map(bad, "world.occmap")
        assert "\n" not in str(caught.value)
    flipped = bytearray(data)
    flipped[len(data) // 2] ^= 0x10
    with pytest.raises(InputError, match="damaged"):
        decode_map(bytes(flipped))
    with pytest.raises(InputError, match="cannot read"):
        load_map(tmp_path / "absent.occmap")
    # Codes no writer makes, under a valid checksum: a facing code 3, a tile holding more
    # segments than there are, a first vertex given as a step.
    for name, value, why in (("facing", 0xFF, "segment arrays missing or misshapen: facing code 3"),
                             ("tile_counts", 0xFF, "segment arrays missing or misshapen: tile counts for"),
                             ("region_steps", 0x00, "observed region is malformed: .* anchor codes")):
        with pytest.raises(InputError, match=why) as caught:
            decode_map(_with_byte(data, name, value), "world.occmap")
        assert "\n" not in str(caught.value)


def _with_byte(data, name, value):
    """``data`` with the first byte of array ``name`` set to ``value`` and the checksum redone."""
    import json
    import struct
    import zlib

    (length,) = struct.unpack("<I", data[8:12])
    offset = 12 + length
    for array, dtype, shape in json.loads(data[12:offset])["arrays"]:
        if array == name:
            break
        offset += int(np.prod(shape, dtype=np.int64)) * np.dtype(dtype).itemsize
    coded = bytearray(data[:-4])
    coded[offset] = value
    return bytes(coded + struct.pack("<I", zlib.crc32(coded)))


@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_fuzzed_files_never_escape_as_another_error(room_map, data):
    """Any cut or byte change is an InputError or, if it keeps the checksum, a valid map."""
    _, world = room_map
    raw = bytearray(encode(world))
    cut = data.draw(st.integers(min_value=0, max_value=len(raw)))
    edits = data.draw(st.lists(st.tuples(st.integers(0, len(raw) - 1), st.integers(0, 255)), max_size=4))
    for at, value in edits:
        raw[at] = value
    try:
        decoded = decode_map(bytes(raw[:cut]) if cut < len(raw) else bytes(raw))
    except InputError as exc:
        assert "\n" not in str(exc)
    else:
        assert isinstance(decoded, WorldMap)


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args], catch_exceptions=False)


def test_map_writes_world_occmap_and_query_answers_as_the_library(tmp_path):
    log = tmp_path / "room.log"
    write_room_log(log, scans=30)
    out = tmp_path / "map"
    result = run("-q", "map", log, "-o", out, "--no-mcap", "--sensor-height", "0.3", "--body-height", "0.5")
    assert result.exit_code == 0, result.output
    world = load_map(out / "world.occmap")
    rng = np.random.default_rng(1)
    xyz = np.column_stack([rng.uniform(-4, 6, 300), rng.uniform(-3, 3.5, 300), np.zeros(300)])
    points = tmp_path / "points.csv"
    points.write_text("# query\nid,x,y,z\n" + "".join(f"{k},{x:.6f},{y:.6f},{z:.1f}\n" for k, (x, y, z)
                                                      in enumerate(xyz)))
    answer = tmp_path / "answer.csv"
    result = run("-q", "query", out / "world.occmap", points, "-o", answer)
    assert result.exit_code == 0, result.output
    lines = answer.read_text().splitlines()
    assert lines[0] == "id,x,y,z,occupancy" and len(lines) == 301
    got = np.array([float(line.split(",")[-1]) for line in lines[1:]])
    expected = world.predict(np.array([[float(v) for v in line.split(",")[1:4]] for line in lines[1:]]))
    assert np.allclose(got, expected, atol=5e-5)
    assert lines[1].split(",")[0] == "0"


@pytest.mark.parametrize(("text", "message"), [
    ("a,b\n1,2\n", "needs columns x, y and z"),
    ("x,y,z\n1,2,oops\n", "row 2 has no number"),
    ("x,y,z\n1,2,3\n1,2\n", "row 3 has no number"),
    ("x,y,z\n1,2,nan\n", "not finite"),
    ("", "empty file"),
])
def test_query_bad_points_are_one_line_and_write_nothing(room_map, tmp_path, text, message):
    _, world = room_map
    world.save(tmp_path / "w.occmap")
    points = tmp_path / "p.csv"
    points.write_text(text)
    result = CliRunner().invoke(cli, ["-q", "query", str(tmp_path / "w.occmap"), str(points), "-o",
                                      str(tmp_path / "out.csv")])
    assert result.exit_code == 1
    assert message in result.output and len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "out.csv").exists()


def test_query_a_damaged_map_is_one_line(tmp_path):
    bad = tmp_path / "bad.occmap"
    bad.write_bytes(b"\x89OCCMAP\n" + b"\0" * 40)
    points = tmp_path / "p.csv"
    points.write_text("x,y,z\n0,0,0\n")
    result = CliRunner().invoke(cli, ["-q", "query", str(bad), str(points), "-o", str(tmp_path / "o.csv")])
    assert result.exit_code == 1 and "not a readable occtool map" in result.output
    assert len(result.output.strip().splitlines()) == 1


def test_a_lasers_every_beam_places_walls_a_cameras_cloud_its_nearest_per_degree():
    """returns_of_positions: half-degree bins for a scanning laser's positions (a return each
    half degree lands in a bin of its own), one-degree bins for a dense cloud."""
    from occtool.features import Features, Pose
    from occtool.fuse import returns_of_positions

    class Position:
        def __init__(self, points):
            self.features = Features(points, np.full(len(points), 0.9))
            self.pose = Pose()

    robot = Robot()
    z = 0.5 * sum(robot.body_band)
    beams = np.radians(np.arange(-90.0, 90.0, 0.5) + 0.25)  # at the bins' centres
    laser = np.column_stack([3.0 * np.cos(beams), 3.0 * np.sin(beams), np.full(beams.size, z)])
    run = returns_of_positions([Position(laser)], robot)
    assert run.ranges.shape[1] == 720 and run.returned.sum() == beams.size
    rng = np.random.default_rng(0)
    rows = np.repeat(beams, 40)
    cloud = np.column_stack([3.0 * np.cos(rows), 3.0 * np.sin(rows), rng.uniform(*robot.body_band, rows.size)])
    dense = returns_of_positions([Position(cloud)], robot)
    assert dense.ranges.shape[1] == 360 and dense.returned.sum() == 180
    assert np.allclose(dense.ranges[dense.returned], 3.0, atol=1e-3)
    # Only a laser's walls face one side by default (a depth camera's noisy clouds keep both).
    assert run.scanning_laser and not dense.scanning_laser


def test_a_position_of_several_scans_gives_each_scans_nearest_returns_from_its_own_sensor():
    """returns_of_positions: a position gathering two scans (io's group_scans) gives a row for
    each, placed at its own sensor: the wall one scan saw behind the person the other saw is
    kept."""
    from occtool.features import Features, Pose, Position
    from occtool.fuse import returns_of_positions

    robot = Robot()
    z = 0.5 * sum(robot.body_band)
    beams = np.radians(np.arange(-90.0, 90.0, 0.5) + 0.25)
    # The position's frame: its pose at (1, 2) facing +y. Scan A from its origin sees a wall
    # 3 m ahead; scan B, 0.2 m ahead of it (x in the position's frame), a person 1 m ahead of
    # its own sensor within 5 degrees.
    wall = np.column_stack([3.0 * np.cos(beams), 3.0 * np.sin(beams), np.full(beams.size, z)])
    near = np.abs(beams) < np.radians(5.0)
    person = np.column_stack([0.2 + np.cos(beams[near]), np.sin(beams[near]), np.full(near.sum(), z)])
    position = Position(0, Features(np.vstack([wall, person]), np.full(beams.size + near.sum(), 0.9)),
                        pose=Pose(1.0, 2.0, 0.0, math.pi / 2),
                        scan_origins=np.array([[0.0, 0.0, 0.0], [0.2, 0.0, 0.0]]),
                        scan_sizes=np.array([beams.size, near.sum()]))
    run = returns_of_positions([position], robot)
    assert len(run) == 2
    assert np.allclose(run.poses, [[1.0, 2.0, 0.0, math.pi / 2], [1.0, 2.2, 0.0, math.pi / 2]])
    assert run.returned[0].sum() == beams.size and np.allclose(run.ranges[0][run.returned[0]], 3.0, atol=1e-3)
    assert run.returned[1].sum() == near.sum() and np.allclose(run.ranges[1][run.returned[1]], 1.0, atol=1e-3)
    # Each return where it was: the person 1.2 m ahead of the position (+y), the wall 3 m.
    points, owner = run.return_points(16.0)
    assert np.allclose(points[owner == 1], [1.0, 3.2], atol=0.1)
    assert np.allclose(np.hypot(*(points[owner == 0] - [1.0, 2.0]).T), 3.0, atol=1e-3)
    # The position as one scan: the person hides the wall behind it.
    alone = returns_of_positions([Position(0, position.features, pose=position.pose)], robot)
    assert len(alone) == 1 and alone.returned[0].sum() == beams.size
    assert (alone.ranges[0][alone.returned[0]] < 2.0).sum() > near.sum() // 2


@pytest.mark.parametrize("facing", [0, 1, -1])
def test_the_nav2_raster_is_free_only_clear_of_trusted_walls_and_occupied_on_them(facing):
    """Safety of the trinary cells: a free cell is observed, at most RASTER_FREE, farther
    than the rim from every trusted wall and than the doubted rim from every doubted one;
    every cell on a trusted wall's band is occupied; an untrusted wall is not drawn."""
    from occtool.raster import RASTER_FREE, RASTER_OCCUPIED

    region = shapely.MultiPolygon([shapely.box(0.0, 0.0, 3.0, 2.0)])
    world = WorldMap([[1.0, 0.2], [2.2, 0.0]], [[1.3, 1.8], [2.2, 2.0]], [0.01, 0.02], [0.9, 0.3], region,
                     band=BAND, facing=[facing, 0], positions=[[0.5, 1.0]])
    raster = world.rasterise(0.05)
    ny, nx = raster.cells.shape
    jj, ii = np.mgrid[0:ny, 0:nx]
    x0, y0 = raster.origin
    centres = np.column_stack([x0 + (ii.ravel() + 0.5) * 0.05, y0 + (jj.ravel() + 0.5) * 0.05])
    cells = raster.cells.ravel()
    trusted = world.wall_distance(centres, within=world.wall_rim)
    doubted = world.wall_distance(centres, trusted=False, within=world.doubted_wall_rim)  # trust 0.3: doubted
    free = cells == FREE
    assert free.any() and (cells == OCCUPIED).any()
    assert world.observed(centres[free]).all() and (trusted[free] > world.wall_rim).all()
    assert world.doubted_wall_rim > 0 and (doubted[free] > world.doubted_wall_rim).all()
    drawn = np.maximum(world.free_value(centres), world.wall_value(centres, trusted=True))
    assert (drawn[free] <= RASTER_FREE).all() and (cells[drawn >= RASTER_OCCUPIED] == OCCUPIED).all()
    assert (cells[trusted <= world.wall_half_width] == OCCUPIED).all()
    # The untrusted wall (trust 0.3 < share 0.5, but >= DOUBTED_TRUST) at x = 2.2: not
    # drawn, unknown on its line, free 10 cm off it, away from the other.
    row, col, _ = raster.cell_of([[2.2, 1.0], [2.1, 1.0]])
    assert raster.cells[row, col].tolist() == [UNKNOWN, FREE]


def test_the_nav2_rasters_shares_are_the_maps_own_and_a_file_without_them_keeps_its_old_ones(tmp_path):
    """WorldMap.wall_share and doubted_share: a wall of trust 0.2 is drawn at a share of 0.15,
    only doubted (its line unknown) at 0.5 with a doubted share of 0.1, and free at 0.3 (the
    share files kept before doubted_share, which a file without it reads)."""
    from occtool.fuse._world import DOUBTED_TRUST

    region = shapely.MultiPolygon([shapely.box(0.0, 0.0, 3.0, 2.0)])

    def on_the_wall(**shares):
        world = WorldMap([[1.5, 0.0]], [[1.5, 2.0]], [0.01], [0.2], region, band=BAND, positions=[[0.5, 1.0]],
                         **shares).quantised()
        raster = world.rasterise(0.05)
        row, col, _ = raster.cell_of([[1.5, 1.0]])
        return int(raster.cells[row[0], col[0]]), world

    assert on_the_wall(wall_share=0.15, doubted_share=0.05)[0] == OCCUPIED
    assert on_the_wall(wall_share=0.5, doubted_share=0.1)[0] == UNKNOWN
    cell, world = on_the_wall()
    assert cell == FREE and world.doubted_share == DOUBTED_TRUST == 0.3
    # The header keeps the shares; one without doubted_share (files before it) reads 0.3.
    world.doubted_share = 0.05
    world.save(tmp_path / "w.occmap")
    assert load_map(tmp_path / "w.occmap").doubted_share == 0.05
    assert b"doubted_share" not in (FIXTURES / "maps" / "intel.occmap").read_bytes()
    old = load_map(FIXTURES / "maps" / "intel.occmap")
    assert old.doubted_share == DOUBTED_TRUST and old.wall_share == 0.5


@pytest.mark.parametrize("name", ["intel", "fr079"])
def test_a_real_runs_map_has_frontiers_on_the_boundary_of_what_it_observed(name):
    """Intel's and FR-079's rooms were not all looked into: their Nav2 rasters have exploration
    points, each a free cell beside a cell nothing observed."""
    from occtool.fuse import frontiers_of, load_map

    raster = load_map(FIXTURES / "maps" / f"{name}.occmap").rasterise(0.05)
    found = frontiers_of(raster)
    assert len(found) >= 10
    row, col, inside = raster.cell_of(found)
    assert inside.all() and (raster.cells[row, col] == FREE).all()
    unexplored = (raster.cells == UNKNOWN) & ~raster.explored
    beside = np.zeros(len(found), dtype=bool)
    for d_row, d_col in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        beside |= unexplored[np.clip(row + d_row, 0, raster.shape[0] - 1), np.clip(col + d_col, 0, raster.shape[1] - 1)]
    assert beside.all()


@settings(max_examples=6, deadline=None)
@given(seed=st.integers(0, 2**16), shrink=st.floats(0.0, 3.0), grow=st.floats(0.0, 40.0))
def test_a_region_rounded_alone_is_the_region_of_the_map_rounded(seed, shrink, grow):
    """quantise_region(region, *extent(...)) is the region WorldMap(...).quantised() keeps,
    to the bit: the free region of build_world_map, rounded without a second map's segments.
    The walls and positions may reach past the region (the grid's origin is theirs)."""
    from occtool.formats.occmap import quantise_region
    from occtool.fuse._world import extent

    world = load_map(FIXTURES / "maps" / "intel.occmap")
    rng = np.random.default_rng(seed)
    region = shapely.buffer(world.region, -shrink)
    positions = rng.uniform(-20.0, 20.0, (7, 2)) * (1.0 + grow / 20.0)
    start = world.start + rng.normal(0.0, 1e-3, world.start.shape)
    mapped = WorldMap(start, world.end, world.thickness, world.trust, region, band=world.band,
                      positions=positions, facing=world.facing).quantised()
    alone = quantise_region(region, *extent(start, world.end, positions, region))
    assert shapely.to_wkb(alone) == shapely.to_wkb(mapped.region)


@settings(max_examples=40, deadline=None)
@given(positions=st.integers(1, 40), bins=st.sampled_from([8, 24, 720]), coarse=st.sampled_from([4, 8, 120]),
       seed=st.integers(0, 2**16))
def test_stored_ranges_read_as_the_float64_ranges_they_are_made_of(positions, bins, coarse, seed):
    """StoredRanges (uint16 returns and reaches) read rows, slices, index arrays, elements and
    masks as position_ranges' float64 array, bit for bit."""
    from occtool.fuse._sightings import StoredRanges, _ranges
    from occtool.observation import NO_OBSTACLE

    rng = np.random.default_rng(seed)
    returns = rng.integers(0, 60000, (positions, bins)).astype(np.uint16)
    returns[rng.random((positions, bins)) < 0.4] = NO_OBSTACLE
    reaches = rng.integers(0, 5000, (positions, 2, coarse)).astype(np.uint16)
    whole, stored = _ranges(returns, reaches), StoredRanges(returns, reaches)
    assert stored.shape == whole.shape and len(stored) == positions
    assert np.asarray(stored).tobytes() == whole.tobytes()
    k = int(rng.integers(-positions, positions))
    low, high = sorted(rng.integers(0, positions + 1, 2).tolist())
    rows = rng.integers(0, positions, 9)
    cols = rng.integers(0, bins, 9)
    for key in (k, slice(low, high), rows, (rows, cols), (k, cols), whole > 3.0, (slice(low, high), 0)):
        assert np.asarray(stored[key]).tobytes() == whole[key].tobytes(), key
