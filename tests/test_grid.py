"""The dense occupancy grid baseline: ray traversal, log-odds fusion, prior and inversion."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from occtool.errors import InputError
from occtool.features import Features
from occtool.grid import (
    OCTOMAP_DEFAULTS,
    LogOddsParams,
    OccupancyGrid,
    build_grid,
    footprint_cells,
    logit,
    probability,
    traverse,
)
from occtool.robot import Robot
from occtool.sensor import SensorModel

HIT = float(logit(0.7))
MISS = float(logit(0.4))
coordinate = st.floats(-4.0, 4.0, allow_nan=False, allow_infinity=False)
point = st.tuples(coordinate, coordinate, coordinate)


def _wall(x: float = 2.03, n: int = 4000, seed: int = 0, evidence: float = 1.0) -> Features:
    """Features on a wall x = const facing the sensor, across y in [-2, 2], z in [-1, 1]."""
    rng = np.random.default_rng(seed)
    return Features.from_xyz(np.full(n, x), rng.uniform(-2, 2, n), rng.uniform(-0.95, 1.0, n), evidence)


# ------------------------------------------------------------------ traversal


def test_traverse_axis_aligned_ray_crosses_each_cell_once() -> None:
    seg = traverse(np.zeros(3), np.array([[1.0, 0.01, 0.01]]), 0.1)
    assert seg.cell[:, 0].tolist() == list(range(11)) or seg.cell[:, 0].tolist() == list(range(10))
    assert (seg.cell[:, 1:] == 0).all()
    assert seg.t_enter[0] == 0.0 and seg.t_exit[-1] == 1.0
    np.testing.assert_allclose(seg.t_enter[1:], seg.t_exit[:-1])
    assert seg.last.tolist() == [False] * (len(seg.ray) - 1) + [True]


def test_traverse_diagonal_ray_with_negative_direction() -> None:
    seg = traverse(np.zeros(3), np.array([[-0.35, -0.25, 0.05]]), 0.1)
    # Cells from (-1, -1, 0) to (-4, -3, 0): three x and two y crossings, five steps.
    assert len(seg.ray) == 6
    assert seg.cell[0].tolist() == [-1, -1, 0]
    assert seg.cell[-1].tolist() == [-4, -3, 0]
    assert (np.abs(np.diff(seg.cell, axis=0)).sum(axis=1) == 1).all()


@given(start=point, ends=st.lists(point, min_size=1, max_size=5), resolution=st.sampled_from([0.05, 0.1, 0.3]))
def test_traverse_is_a_connected_walk_covering_the_ray(start, ends, resolution) -> None:
    start = np.array(start)
    end = np.array(ends)
    seg = traverse(start, end, resolution)
    for i in range(end.shape[0]):
        mine = seg.ray == i
        cells = seg.cell[mine]
        if np.allclose(start, end[i]):
            continue
        # The walk starts at the start (in its cell, or beside it on a boundary), ends in
        # the end point's cell, and the pieces tile [0, 1].
        first_box = cells[0] * resolution
        assert np.all((first_box - 1e-9 <= start) & (start <= first_box + resolution + 1e-9))
        assert cells[-1].tolist() == np.floor(end[i] / resolution).astype(int).tolist()
        np.testing.assert_allclose(seg.t_enter[mine][0], 0.0, atol=1e-9)
        np.testing.assert_allclose(seg.t_exit[mine][-1], 1.0, atol=1e-9)
        np.testing.assert_allclose(seg.t_enter[mine][1:], seg.t_exit[mine][:-1], atol=1e-9)
        # Consecutive cells share a face, or (at an exact corner crossing) an edge or a corner.
        steps = np.abs(np.diff(cells, axis=0))
        assert (steps.max(axis=1, initial=1) == 1).all()
        # Every point sampled densely along the ray lies in a traversed cell.
        t = np.linspace(0.0, 1.0, 401)[1:-1]
        u = (start + t[:, None] * (end[i] - start)) / resolution
        # Points on a cell boundary are left out: rounding decides which side they fall on.
        clear = (np.abs(u - np.round(u)) > 1e-6).all(axis=1)
        sampled = np.floor(u[clear]).astype(int)
        assert {tuple(c) for c in sampled} <= {tuple(c) for c in cells}


# ------------------------------------------------------------------ fusion


def test_single_ray_gives_misses_then_one_hit() -> None:
    features = Features.from_xyz([1.03], [0.02], [0.03], 1.0)
    grid = build_grid(features, resolution=0.1, footprint_prior=False)
    along = np.array([[x, 0.02, 0.03] for x in np.arange(0.05, 1.0, 0.1)])
    np.testing.assert_allclose(
        grid.log_odds[tuple((np.floor(along / 0.1).astype(int) - grid.offset).T)], MISS, rtol=1e-6
    )
    np.testing.assert_allclose(grid.occupancy([[1.03, 0.02, 0.03]]), 0.7, rtol=1e-6)
    assert grid.samples == 11
    assert grid.observed_cells == 11
    # A point nowhere near the ray is unknown.
    assert grid.occupancy([[0.5, 0.5, 0.5]])[0] == 0.5
    assert grid.occupancy([[50.0, 0.0, 0.0]])[0] == 0.5


def test_repeated_hits_are_summed_and_clamped() -> None:
    features = Features.from_xyz(np.full(3, 1.03), np.full(3, 0.02), np.full(3, 0.03), 1.0)
    grid = build_grid(features, resolution=0.1, footprint_prior=False)
    np.testing.assert_allclose(grid.occupancy([[1.03, 0.02, 0.03]]), probability(3 * HIT), rtol=1e-6)
    many = Features.from_xyz(np.full(20, 1.03), np.full(20, 0.02), np.full(20, 0.03), 1.0)
    grid = build_grid(many, resolution=0.1, footprint_prior=False)
    np.testing.assert_allclose(grid.occupancy([[1.03, 0.02, 0.03], [0.55, 0.01, 0.01]]), [0.971, 0.1192], rtol=1e-5)


def test_sensor_model_values_between_miss_and_hit() -> None:
    sensor = SensorModel()
    features = Features.from_xyz([2.0], [0.013], [0.011], 0.8)
    grid = build_grid(features, resolution=0.05, sensor=sensor, footprint_prior=False)
    # The feature's own cell: value m = 0.8, so p = 0.4 + 0.3 * 0.8.
    np.testing.assert_allclose(grid.occupancy([[2.0, 0.013, 0.011]]), 0.64, rtol=1e-5)
    # Near the sensor the profile is ~0: a miss; occupancy never decreases towards the feature.
    along = np.column_stack([np.arange(0.025, 2.0, 0.05), np.full(40, 0.013), np.full(40, 0.011)])
    p = grid.occupancy(along)
    assert p[0] == pytest.approx(0.4, abs=0.01)
    assert (np.diff(p) >= -1e-9).all()


def test_floor_features_only_clear_space_with_the_sensor_model() -> None:
    robot = Robot()
    floor = Features.from_xyz([2.0], [0.01], [robot.floor_h], 1.0)
    as_obstacle = build_grid(floor, resolution=0.1, robot=robot, footprint_prior=False)
    free = build_grid(floor, resolution=0.1, robot=robot, sensor=SensorModel(floor="free"), footprint_prior=False)
    dropped = build_grid(floor, resolution=0.1, robot=robot, sensor=SensorModel(floor="drop"), footprint_prior=False)
    at_floor = [[2.0, 0.01, robot.floor_h + 0.001]]
    assert as_obstacle.occupancy(at_floor)[0] == pytest.approx(0.7)
    assert free.occupancy(at_floor)[0] == 0.5
    assert free.occupancy([[1.05, 0.00525, -0.525]])[0] < 0.5
    assert dropped.samples == 0 and dropped.observed_cells == 0


def test_footprint_prior_frees_the_body_cylinder() -> None:
    robot = Robot(radius=0.3)
    # A feature inside the body (a cable hanging from the robot, say) would block it in place.
    features = Features.from_xyz([0.1, 2.0], [0.05, 0.0], [-0.5, 0.0], 1.0)
    naive = build_grid(features, resolution=0.05, robot=robot, footprint_prior=False)
    prior = build_grid(features, resolution=0.05, robot=robot)
    inside = [[0.1, 0.05, -0.5]]
    assert naive.occupancy(inside)[0] == pytest.approx(0.7)
    assert prior.occupancy(inside)[0] == pytest.approx(0.1192, rel=1e-4)
    assert np.sqrt(naive.inverse_range(0.46, -0.5, 0.6) ** 2 - 0.25) < 0.15
    assert prior.inverse_range(0.46, -0.5, 0.6) == np.inf
    cells = footprint_cells(robot, 0.05)
    centres = (cells[:, :2] + 0.5) * 0.05
    assert np.hypot(centres[:, 0], centres[:, 1]).max() <= 0.3
    lo, hi = robot.body_band
    assert cells[:, 2].min() * 0.05 <= lo and (cells[:, 2].max() + 1) * 0.05 >= hi


# ------------------------------------------------------------------ inversion


@pytest.mark.parametrize("h", [-0.9, -0.5, 0.0, 0.6])
def test_inverse_range_finds_a_wall(h: float) -> None:
    grid = build_grid(_wall(), resolution=0.1, sensor=SensorModel())
    r = grid.inverse_range(0.0, h, 0.6)
    horizontal = np.sqrt(r**2 - h**2)
    # The wall at x = 2.03 lies in the cells from x = 2.0; the sensor model's rise before
    # the feature (near samples at 0.9 r) may raise occupancy up to two cells earlier.
    assert 1.8 - 1e-9 <= horizontal <= 2.0 + 1e-9
    # Away from the wall, within the grid and the level above 0.5, nothing blocks.
    assert grid.inverse_range(np.pi, h, 0.6) == np.inf


def test_inverse_range_broadcasts_and_respects_max_range() -> None:
    grid = build_grid(_wall(), resolution=0.1)
    alphas = np.linspace(-0.5, 0.5, 7)
    heights = np.array([[-0.5], [0.0]])
    r = grid.inverse_range(alphas, heights, 0.6)
    assert r.shape == (2, 7)
    horizontal = np.sqrt(r**2 - heights**2) * np.cos(alphas)
    assert np.all(np.abs(horizontal - 2.0) <= 0.1 + 1e-9)
    assert np.all(grid.inverse_range(alphas, heights, 0.6, max_range=1.5) == np.inf)
    # Levels at or below 0.5 treat the unknown space beyond the grid as blocking.
    assert np.isfinite(grid.inverse_range(np.pi, 0.0, 0.5))


@given(quarter=st.integers(1, 3), seed=st.integers(0, 1000))
def test_grid_is_equivariant_to_quarter_turns(quarter: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 60
    features = Features.from_xyz(
        rng.uniform(-3, 3, n), rng.uniform(-3, 3, n), rng.uniform(-1, 1, n), rng.uniform(0.3, 1, n)
    )
    yaw = quarter * np.pi / 2
    grid = build_grid(features, resolution=0.1, sensor=SensorModel())
    turned = build_grid(features.rotated(yaw), resolution=0.1, sensor=SensorModel())
    queries = Features.from_xyz(rng.uniform(-3, 3, 200), rng.uniform(-3, 3, 200), rng.uniform(-1, 1, 200), 1.0)
    np.testing.assert_allclose(grid.occupancy(queries.points), turned.occupancy(queries.rotated(yaw).points), atol=1e-6)
    assert grid.samples == turned.samples


def test_memory_and_shape_follow_the_extent() -> None:
    grid = build_grid(_wall(), resolution=0.1)
    nx, ny, nz = grid.shape
    assert grid.nbytes >= nx * ny * nz * 4
    assert grid.lower[0] <= -0.2 and grid.upper[0] >= 2.1
    finer = build_grid(_wall(), resolution=0.05)
    assert finer.nbytes > 7 * grid.nbytes


def test_bad_input_is_a_clear_error() -> None:
    features = _wall(n=10)
    with pytest.raises(InputError, match="resolution"):
        build_grid(features, resolution=0.0)
    with pytest.raises(InputError, match="coarser resolution="):
        build_grid(features, resolution=0.01, max_bytes=1000)
    with pytest.raises(InputError, match="no features"):
        build_grid(features.select(np.zeros(10, dtype=bool)))
    with pytest.raises(InputError, match="prob_miss"):
        LogOddsParams(prob_hit=0.4, prob_miss=0.7)
    assert OCTOMAP_DEFAULTS.clamp_log_odds == pytest.approx((logit(0.1192), logit(0.971)))


def test_bounds_crop_the_grid_but_keep_the_cells_inside() -> None:
    features = _wall()
    full = build_grid(features, resolution=0.1, sensor=SensorModel())
    cropped = build_grid(features, resolution=0.1, sensor=SensorModel(), bounds=((-1.0, -1.0, -1.0), (2.5, 1.0, 0.5)))
    assert cropped.nbytes < full.nbytes
    assert cropped.samples < full.samples
    rng = np.random.default_rng(1)
    inside = np.column_stack(
        [rng.uniform(-0.95, 2.45, 300), rng.uniform(-0.95, 0.95, 300), rng.uniform(-0.95, 0.45, 300)]
    )
    np.testing.assert_allclose(cropped.occupancy(inside), full.occupancy(inside), atol=1e-6)
    assert cropped.occupancy([[2.05, 1.5, 0.0]])[0] == 0.5
    with pytest.raises(InputError, match="bounds"):
        build_grid(features, resolution=0.1, bounds=((0, 0, 0), (0, 1, 1)))


# Levels off the exact single-hit probability 0.7, where float32 rounding decides.
@given(seed=st.integers(0, 10_000), level=st.sampled_from([0.45, 0.55, 0.6, 0.75]))
def test_inverse_range_matches_a_ray_walk_in_3d(seed: int, level: float) -> None:
    rng = np.random.default_rng(seed)
    n = 40
    features = Features.from_xyz(rng.uniform(-1.5, 1.5, n), rng.uniform(-1.5, 1.5, n), rng.uniform(-0.8, 0.3, n), 1.0)
    grid = build_grid(features, resolution=0.1, sensor=SensorModel(), footprint_prior=False)
    alphas = rng.uniform(-np.pi, np.pi, 12)
    heights = rng.uniform(-0.8, 0.3, 3)
    reach = 2.5
    r = grid.inverse_range(alphas[None, :], heights[:, None], level, max_range=reach)
    step = 0.002
    d = np.arange(step / 2, reach, step)  # not 0: the sensor axis lies on a cell corner
    for k, h in enumerate(heights):
        for m, alpha in enumerate(alphas):
            found = np.sqrt(max(r[k, m] ** 2 - h**2, 0.0))
            # Reference: walk the ray's own 3D cells and take the first at the level.
            seg = traverse([0.0, 0.0, h], [reach * np.cos(alpha), reach * np.sin(alpha), h], 0.1)
            centres = (seg.cell + 0.5) * 0.1
            at_level = grid.occupancy(centres) >= level
            expected = seg.t_enter[np.argmax(at_level)] * reach if at_level.any() else np.inf
            assert found == pytest.approx(expected, abs=1e-9) or (np.isinf(found) and np.isinf(expected))
            # A fine march along the ray meets nothing at the level before it (it may miss
            # a cell the ray only clips at a corner, so only this direction holds).
            points = np.column_stack([d * np.cos(alpha), d * np.sin(alpha), np.full_like(d, h)])
            marched = grid.occupancy(points) >= level
            if marched.any():
                assert found <= d[np.argmax(marched)] + step


# ------------------------------------------------------------------ unobserved space


def _planar_scan_grid() -> OccupancyGrid:
    """A hand-made 0.1 m grid over x in [-0.2, 1.8), y in [-0.2, 0.2), z in [-0.3, 0.3).

    Only the laser's layer (z in [0, 0.1)) is observed, free, but for a gap no beam
    crossed at x in [0.8, 1.0) and a wall hit at x in [1.5, 1.6); the other layers are
    unobserved (log-odds 0), as a planar laser leaves them.
    """
    log_odds = np.zeros((20, 4, 6), dtype=np.float32)
    plane = 3  # global layer 0, with the offset -3
    log_odds[:, :, plane] = MISS
    log_odds[10:12, :, plane] = 0.0  # global columns i = 8, 9
    log_odds[17, :, plane] = HIT  # global column i = 15
    return OccupancyGrid(log_odds=log_odds, resolution=0.1, offset=np.array([-2, -2, -3]))


def _horizontal(r: np.ndarray, h: np.ndarray) -> np.ndarray:
    return np.sqrt(np.maximum(r**2 - h**2, 0.0))


HEIGHTS = np.array([[0.05], [-0.15], [0.25]])  # the laser's layer, and two unobserved ones


def test_unknown_free_passes_the_gap_and_occupied_stops_at_it() -> None:
    grid = _planar_scan_grid()
    free = _horizontal(grid.inverse_range(0.0, HEIGHTS, 0.6, max_range=2.5), HEIGHTS)
    # Free: the gap's prior 0.5 is below the level; the wall blocks in its own layer only.
    assert free[0, 0] == pytest.approx(1.5)
    assert np.isinf(free[1:]).all()
    assert np.array_equal(
        free, _horizontal(grid.inverse_range(0.0, HEIGHTS, 0.6, max_range=2.5, unknown="free"), HEIGHTS)
    )
    # Occupied: the gap's columns were observed at no height: every height stops there.
    occupied = _horizontal(grid.inverse_range(0.0, HEIGHTS, 0.6, max_range=2.5, unknown="occupied"), HEIGHTS)
    np.testing.assert_allclose(occupied, 0.8)
    # Behind the laser the grid ends at x = -0.2; outside it nothing was observed.
    assert np.isinf(grid.inverse_range(np.pi, 0.05, 0.6, max_range=2.5))
    assert _horizontal(grid.inverse_range(np.pi, 0.05, 0.6, max_range=2.5, unknown="occupied"), 0.05) == pytest.approx(
        0.2
    )


def test_a_column_observed_at_one_height_of_the_band_counts_at_all() -> None:
    grid = _planar_scan_grid()
    grid.log_odds[10:12, :, 3] = MISS  # the gap seen after all
    occupied = _horizontal(grid.inverse_range(0.0, HEIGHTS, 0.6, max_range=2.5, unknown="occupied"), HEIGHTS)
    # In the laser's layer the wall; elsewhere the wall's column is observed (free at its
    # prior there) and the rays run on to the end of the grid, where observation stops.
    np.testing.assert_allclose(occupied[:, 0], [1.5, 1.8, 1.8])
    # A band without the laser's layer observes nothing: the rays stop at once...
    band = (-0.3, -0.05)
    assert not grid.observed_columns(band).any()
    assert grid.observed_columns((0.0, 0.0)).sum() == 20 * 4
    np.testing.assert_allclose(
        grid.inverse_range(0.0, HEIGHTS, 0.6, max_range=2.5, unknown="occupied", band=band), np.abs(HEIGHTS)
    )
    # ...but for the robot's footprint, which it stands on: columns within half a cell of
    # its disk count as observed (the first beyond 0.22 + 0.05 m starts at 0.3 m).
    standing = replace(grid, footprint=0.22)
    r = standing.inverse_range(0.0, HEIGHTS, 0.6, max_range=2.5, unknown="occupied", band=band)
    np.testing.assert_allclose(_horizontal(r, HEIGHTS), 0.3)


def test_built_grids_carry_their_footprint_prior() -> None:
    robot = Robot(radius=0.3)
    assert build_grid(_wall(n=50), resolution=0.1, robot=robot).footprint == 0.3
    assert build_grid(_wall(n=50), resolution=0.1, robot=robot, footprint_prior=False).footprint == 0.0


def test_unknown_must_be_free_or_occupied() -> None:
    grid = _planar_scan_grid()
    with pytest.raises(InputError, match="'free' or 'occupied'"):
        grid.inverse_range(0.0, 0.0, 0.6, unknown="unknown")
    with pytest.raises(InputError, match="band"):
        grid.inverse_range(0.0, 0.0, 0.6, unknown="occupied", band=(0.2, -0.2))


def test_an_evidence_zero_feature_only_clears_its_ray() -> None:
    # A laser beam that returned nothing, written at 3 m with evidence 0: free along the
    # ray, and no hit at its end, in every floor mode of the sensor model.
    beam = Features.from_xyz([3.03], [0.02], [-0.47], 0.0)
    for floor in ("free", "drop", "obstacle"):
        grid = build_grid(beam, resolution=0.1, sensor=SensorModel(floor=floor), footprint_prior=False)
        assert grid.occupancy([[3.03, 0.02, -0.47]])[0] <= 0.5, floor
        assert grid.occupancy([[1.52, 0.01, -0.235]])[0] < 0.5, floor
        assert grid.samples > 0, floor
