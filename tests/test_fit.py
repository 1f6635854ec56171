"""The estimator: constraints, inversion, determinism, floor and pallet, seam."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from occtool.errors import InputError, NotFittedError
from occtool.features import Features
from occtool.fit import (
    DEFAULT_PIECES,
    MORE_PIECES_FROM,
    MOST_DEFAULT_PIECES,
    OccupancyRegressor,
    box_qp,
    contradicted_features,
    default_pieces,
    first_obstacle_distance,
    fit_together,
    frontier_samples,
    segment_near_runs,
    sorted_within_bins,
)
from occtool.robot import Robot
from occtool.sensor import SensorModel
from occtool.simulate import simulate_scene

ROBOT = Robot()


def ring_room(n: int = 3000, seed: int = 0, radius: float = 2.0, pallet: bool = False,
              floor: bool = True) -> Features:
    """Features on a cylindrical wall around the robot, the floor inside it and optionally
    a 15 cm pallet at 1 m ahead (x > 0, |y| < 0.3)."""
    rng = np.random.default_rng(seed)
    parts = []
    a = rng.uniform(-np.pi, np.pi, n)
    z = rng.uniform(-1.0, 1.0, n)
    parts.append(np.column_stack([radius * np.cos(a), radius * np.sin(a), z]))
    if floor:
        a = rng.uniform(-np.pi, np.pi, n)
        d = rng.uniform(0.9, radius - 0.05, n)
        parts.append(np.column_stack([d * np.cos(a), d * np.sin(a), np.full(n, -ROBOT.sensor_height)]))
    if pallet:
        k = n // 3
        y = rng.uniform(-0.3, 0.3, k)
        zz = rng.uniform(-1.0, -0.85, k)
        parts.append(np.column_stack([np.full(k, 1.0), y, zz]))
        # the pallet's top, seen from above
        x = rng.uniform(1.0, 1.4, k)
        parts.append(np.column_stack([x, rng.uniform(-0.3, 0.3, k), np.full(k, -0.85)]))
    points = np.concatenate(parts)
    return Features(points, np.full(points.shape[0], 0.9))


@pytest.fixture(scope="module")
def fitted() -> OccupancyRegressor:
    return OccupancyRegressor(pieces=16).fit(ring_room(pallet=True))


def test_methods_need_fit():
    model = OccupancyRegressor()
    for call in (lambda: model.predict(0.0, 0.0, 1.0), lambda: model.inverse_range(0.0, 0.0, 0.6), model.invert):
        with pytest.raises(NotFittedError):
            call()


def test_init_only_stores_parameters():
    model = OccupancyRegressor(pieces=-3, basis="cubic")
    assert model.pieces == -3 and model.basis == "cubic"
    with pytest.raises(InputError, match="pieces"):
        model.fit(ring_room(200))


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"seed": -1}, "seed"),
    ({"seed": 1.5}, "seed"),
    ({"focus_range": float("inf")}, "focus range"),
    ({"focus_range": float("nan")}, "focus range"),
])
def test_parameters_out_of_their_domain_are_input_errors(kwargs, message):
    with pytest.raises(InputError, match=message):
        OccupancyRegressor(**kwargs).fit(ring_room(200))


@pytest.mark.parametrize("basis", ["trig", "linear"])
def test_constraints_hold_exactly(basis):
    model = OccupancyRegressor(pieces=12, basis=basis, c_min=1.5, a_max=5.0, b_max=2.0).fit(ring_room(1500))
    tree = model.tree_
    assert tree.n_pieces == 12
    assert (tree.c >= 1.5).all()
    assert (tree.angle_weight <= 5.0).all()
    assert (np.abs(tree.b) <= 2.0).all()
    assert model.slope_bounds_["c_min"] >= 1.5 and model.slope_bounds_["a_max"] <= 5.0


def test_constraints_hold_after_refit_sweeps():
    model = OccupancyRegressor(pieces=8, max_sweeps=3, a_max=4.0, b_max=1.0).fit(ring_room(1500))
    assert (model.tree_.angle_weight <= 4.0).all() and (np.abs(model.tree_.b) <= 1.0).all()
    assert (model.tree_.c >= model.c_min).all()
    assert all(b <= a + 1e-12 for a, b in zip(model.loss_history_, model.loss_history_[1:]))


def test_fit_is_deterministic():
    features = ring_room(1500, seed=4, pallet=True)
    a = OccupancyRegressor(pieces=8, seed=3).fit(features)
    b = OccupancyRegressor(pieces=8, seed=3).fit(features)
    assert np.array_equal(a.tree_.coefficients, b.tree_.coefficients)
    assert a.tree_ == b.tree_


def test_fits_together_are_the_fits_alone():
    """fit_together runs a few fits in turns, their programmes in one batch: each model is
    the one its own fit makes (its tree's numbers bit for bit), a failed fit its error."""
    chunk = [ring_room(900, seed=s, pallet=s % 2 == 0, radius=1.5 + 0.5 * s) for s in range(3)]
    chunk.insert(1, Features(np.zeros((0, 3)), np.zeros(0)))
    params = {"pieces": 12, "seed": 2}
    together = fit_together(params, chunk)
    assert isinstance(together[1], InputError)
    for model, features in zip(together[::2] + together[3:], chunk[::2] + chunk[3:]):
        alone = OccupancyRegressor(**params).fit(features)
        assert isinstance(model, OccupancyRegressor) and model.fit_seconds_ >= 0
        assert model.tree_.coefficients.tobytes() == alone.tree_.coefficients.tobytes()
        assert model.tree_ == alone.tree_
        assert model.loss_history_ == alone.loss_history_


def test_free_inside_the_wall_occupied_beyond(fitted):
    alpha = np.array([np.pi / 2, -np.pi / 2, np.pi])
    r = fitted.inverse_range(alpha, -0.5, 0.6)
    horizontal = np.sqrt(r**2 - 0.25)
    assert (horizontal <= 2.0).all() and (horizontal > 1.2).all()


def test_pallet_blocks_and_floor_does_not():
    # Pallet at 1 m ahead: the crossing at the pallet's height lies in front of it,
    # while the floor inside the wall (behind, no pallet) keeps the way free.
    model = OccupancyRegressor(pieces=16).fit(ring_room(pallet=True))
    h = -0.9
    ahead = float(np.sqrt(model.inverse_range(0.0, h, 0.6) ** 2 - h * h))
    behind = float(np.sqrt(model.inverse_range(np.pi, h, 0.6) ** 2 - h * h))
    assert ahead <= 1.0
    assert behind > 1.2
    assert model.predict(0.0, h, np.hypot(1.05, h)) > model.predict(np.pi, h, np.hypot(1.05, h))


def test_floor_as_obstacle_shrinks_free_space():
    features = ring_room(2000)
    free = OccupancyRegressor(pieces=8).fit(features)
    blocked = OccupancyRegressor(pieces=8, sensor=SensorModel(floor="obstacle")).fit(features)
    h = -0.9
    a = np.linspace(-np.pi, np.pi, 36, endpoint=False)
    assert np.median(blocked.inverse_range(a, h, 0.6)) < np.median(free.inverse_range(a, h, 0.6)) - 0.2


@settings(max_examples=40)
@given(alpha=st.floats(-np.pi, np.pi), h=st.floats(-0.95, 0.0), m=st.floats(0.05, 1.0))
def test_inverse_range_inverts(fitted, alpha, h, m):
    r = fitted.inverse_range(alpha, h, m)
    if r > 0:
        assert np.isclose(fitted.predict(alpha, h, r), m, atol=1e-9)
    else:
        assert fitted.predict(alpha, h, 0.0) >= m - 1e-12


@settings(max_examples=40)
@given(alpha=st.floats(-np.pi, np.pi), h=st.floats(-1.0, 0.5), r=st.floats(0.0, 5.0), dr=st.floats(1e-4, 2.0))
def test_fitted_model_is_monotone_in_range(fitted, alpha, h, r, dr):
    assert fitted.predict(alpha, h, r + dr) > fitted.predict(alpha, h, r)


def test_inverse_range_broadcasts(fitted):
    alpha = np.linspace(-np.pi, np.pi, 7)[None, :]
    h = np.array([-0.9, -0.5, 0.0])[:, None]
    assert fitted.inverse_range(alpha, h, 0.6).shape == (3, 7)


@pytest.mark.parametrize("yaw", [0.7, 2.0, -2.9, np.pi])
def test_rotation_rotates_the_range_profile(yaw):
    # The trig fit measures pan angles from the hits' mean direction, so turning the
    # features turns the whole model: the inverse range profile moves by exactly the yaw.
    features = ring_room(2500, seed=2, pallet=True, radius=1.8)
    base = OccupancyRegressor(pieces=16).fit(features)
    turned = OccupancyRegressor(pieces=16).fit(features.rotated(yaw))
    alpha = np.linspace(-np.pi, np.pi, 180, endpoint=False)
    for h in (-0.9, -0.5, 0.0):
        a = base.inverse_range(alpha, h, 0.6)
        b = turned.inverse_range(alpha + yaw, h, 0.6)
        assert np.allclose(a, b, atol=1e-9)


def test_trig_basis_has_no_seam_behind_the_robot():
    features = ring_room(2000, seed=5, radius=1.6)
    model = OccupancyRegressor(pieces=12).fit(features.rotated(np.pi))
    eps = 1e-6
    left = model.inverse_range(np.pi - eps, -0.5, 0.6)
    right = model.inverse_range(-np.pi + eps, -0.5, 0.6)
    assert abs(float(left) - float(right)) < 1e-4


def test_no_usable_features():
    only_floor = Features.from_xyz([1.0, 2.0], [0.0, 1.0], [-1.0, -1.0], 0.9)
    with pytest.raises(InputError, match="no features"):
        OccupancyRegressor(sensor=SensorModel(floor="drop")).fit(only_floor)


def test_first_obstacle_ignores_isolated_outliers():
    rng = np.random.default_rng(0)
    alpha = rng.uniform(-0.05, 0.05, 60)
    distance = np.concatenate([np.full(58, 2.0) + rng.normal(0, 0.01, 58), [0.5, 0.9]])
    first = first_obstacle_distance(alpha, distance, 120)
    assert first[60] == pytest.approx(2.0, abs=0.05) or first[59] == pytest.approx(2.0, abs=0.05)


@given(st.lists(st.floats(-3, 3), min_size=3, max_size=3), st.floats(0.1, 2.0))
def test_box_qp_stays_in_box_and_beats_clipping(target, bound):
    gram = np.array([[2.0, 0.5, 0.0], [0.5, 1.0, 0.2], [0.0, 0.2, 1.5]])
    rhs = gram @ np.array(target)
    lower, upper = np.full(3, -bound), np.full(3, bound)
    x = box_qp(gram, rhs, lower, upper)
    assert (x >= lower).all() and (x <= upper).all()
    objective = lambda v: 0.5 * v @ gram @ v - rhs @ v  # noqa: E731
    assert objective(x) <= objective(np.clip(np.array(target), lower, upper)) + 1e-9


def test_overhanging_table_top_cuts_every_height():
    # A table top 0.7 m above the floor (sensor at 1 m): its features lie at h = -0.3 only,
    # yet the robot (1 m tall) cannot pass under it, so at every body height the free
    # range ahead must end at the table's edge at 1 m (its nearest returns, a few mm beyond).
    rng = np.random.default_rng(3)
    room = ring_room(2500, seed=3, radius=2.0)
    k = 800
    top = np.column_stack([rng.uniform(1.0, 1.6, k), rng.uniform(-0.4, 0.4, k), np.full(k, -0.3)])
    features = Features.concatenate([room, Features(top, np.full(k, 0.9))])
    model = OccupancyRegressor(pieces=16).fit(features)
    for h in (-0.9, -0.6, -0.3, 0.0):
        horizontal = np.sqrt(np.maximum(model.inverse_range(0.0, h, 0.6) ** 2 - h * h, 0.0))
        assert horizontal <= 1.005
    behind = np.sqrt(model.inverse_range(np.pi, -0.6, 0.6) ** 2 - 0.36)
    assert behind > 1.3


def _wall_with_mismatches() -> tuple[Features, np.ndarray]:
    """A wall 2 m ahead seen at many tilts, plus two mismatches 0.45 m ahead at mid tilt."""
    rng = np.random.default_rng(3)
    pan = rng.uniform(-0.02, 0.02, 400)
    tilt = rng.uniform(-0.6, 0.3, 400)
    x = np.full(400, 2.0)
    wall = np.column_stack([x, x * np.tan(pan), x * np.tan(tilt) / np.cos(pan)])
    mismatches = np.array([[0.45, 0.003, -0.10], [0.47, 0.006, -0.11]])
    points = np.vstack([wall, mismatches])
    is_mismatch = np.r_[np.zeros(400, bool), np.ones(2, bool)]
    return Features(points, np.full(len(points), 0.9)), is_mismatch


def test_mismatches_that_other_rays_see_through_are_contradicted():
    features, is_mismatch = _wall_with_mismatches()
    contradicted = contradicted_features(features)
    assert contradicted[is_mismatch].all()
    assert contradicted[~is_mismatch].mean() < 0.02


def test_a_table_top_seen_from_above_is_not_contradicted():
    # Rays graze a horizontal top 0.25 m below the sensor from 0.9 m to 1.6 m ahead: each
    # ends on the top a little beyond its neighbour, which must not read as seeing through.
    d = np.linspace(0.9, 1.6, 300)
    pan = np.linspace(-0.02, 0.02, 300)
    points = np.column_stack([d * np.cos(pan), d * np.sin(pan), np.full(300, -0.25)])
    assert not contradicted_features(Features(points, np.full(300, 0.9))).any()


def test_close_mismatches_do_not_box_the_robot_in():
    # A round room (wall at 2 m) and three mismatches 0.45 m ahead, within 2 cm: without
    # the line-of-sight test they form an "obstacle" and the map ends 0.43 m ahead.
    room = ring_room(8000, seed=6, floor=False)
    points = np.array([[0.45, 0.0, -0.10], [0.46, 0.0, -0.12], [0.47, 0.0, -0.11]])
    model = OccupancyRegressor(pieces=16).fit(Features.concatenate([room, Features(points, np.full(3, 0.9))]))
    r = model.inverse_range(np.linspace(-0.1, 0.1, 21), -0.1, 0.6)
    assert np.sqrt(r**2 - 0.01).min() > 1.2


def _floor_rays(ends: np.ndarray, per_bin: int = 20) -> Features:
    """Floor features on 120 pan-angle bins (3 degrees each), ending at ``ends[bin]`` metres."""
    bins = np.repeat(np.arange(120), per_bin)
    alpha = -np.pi + (bins + np.tile(np.linspace(0.1, 0.9, per_bin), 120)) * (2 * np.pi / 120)
    # Rays spread over the last 40 % of each bin's reach.
    distance = ends[bins] * np.tile(np.linspace(0.6, 1.0, per_bin), 120)
    points = np.column_stack([distance * np.cos(alpha), distance * np.sin(alpha),
                              np.full(alpha.size, -ROBOT.sensor_height)])
    return Features(points, np.full(alpha.size, 0.9))


def _frontier_bins(features: Features) -> set[int]:
    samples = SensorModel().samples(features, ROBOT)
    frontier = frontier_samples(samples, ROBOT, focus_range=2.5)
    return set(np.floor((frontier.alpha + np.pi) / (2 * np.pi / 120)).astype(int).tolist())


def test_a_gap_between_sparse_rays_is_not_a_frontier_but_an_edge_is():
    ends = np.full(120, 3.0)
    ends[30] = 1.0  # one bin whose few rays happen to end short: a sampling gap
    ends[80:90] = 1.0  # ten bins that see no farther: an unseen stretch (a white wall)
    closed = _frontier_bins(_floor_rays(ends))
    assert 30 not in closed
    assert set(range(80, 90)) <= closed
    assert closed == set(range(80, 90))


def test_office_doorway_stays_open_with_sparse_features():
    # At 2k features a 3-degree bin in the doorway once held only floor features ending
    # at 1.7 m; its frontier closed the whole doorway (seeds 0 and 2).
    from occtool.navigation import navigation_map
    from occtool.simulate import simulate_scene

    bounds = sorted(np.arctan2([1.2, 1.2], [-0.3, 0.7]))  # the doorway's jambs
    for seed in (0, 2):
        features, _ = simulate_scene("office", n_features=2000, seed=seed)
        model = OccupancyRegressor(seed=seed).fit(features)
        nav = navigation_map(model.inverse_range, robot=ROBOT, slope_bounds=model.slope_bounds_)
        angles = np.arctan2(nav.exploration_points[:, 1], nav.exploration_points[:, 0])
        assert ((angles >= bounds[0]) & (angles <= bounds[1])).sum() >= 1, seed


@given(st.lists(st.tuples(st.integers(0, 11), st.floats(0, 50)), max_size=200))
def test_sorted_within_bins_matches_a_two_key_sort(pairs):
    bins = np.array([b for b, _ in pairs], dtype=np.intp)
    values = np.array([v for _, v in pairs], dtype=np.float64)
    grouped, bounds = sorted_within_bins(bins, values, 12)
    order = np.lexsort((values, bins))
    np.testing.assert_array_equal(grouped, values[order])
    np.testing.assert_array_equal(np.diff(bounds), np.bincount(bins, minlength=12))


def test_beams_that_returned_nothing_open_their_directions():
    # A 180-degree laser 0.3 m above the floor: a wall on the right half, nothing within
    # range on the left, where the beams are written at 5 m with evidence 0 (free rays).
    robot = Robot(sensor_height=0.3, body_height=0.4)
    angles = np.linspace(-np.pi / 2, np.pi / 2, 361)
    wall = angles < 0
    r = np.where(wall, 1.2 / np.maximum(np.cos(angles + np.pi / 4), 0.3), 5.0)
    points = np.column_stack([r * np.cos(angles), r * np.sin(angles), np.zeros_like(r)])
    evidence = np.where(wall, 0.9, 0.0)
    with_free_rays = OccupancyRegressor(robot=robot).fit(Features(points, evidence))
    without = OccupancyRegressor(robot=robot).fit(Features(points[wall], evidence[wall]))
    left = np.linspace(0.3, 1.3, 11)
    assert with_free_rays.inverse_range(left, 0.0, 0.6).min() > 2.5
    # Without them the left half is unseen, and the frontier closes it by the robot.
    assert without.inverse_range(left, 0.0, 0.6).max() < 0.6
    # The wall stays in front of where it is, either way.
    for model in (with_free_rays, without):
        assert model.inverse_range(np.array([-0.8]), 0.0, 0.6)[0] <= 1.2 / np.cos(-0.8 + np.pi / 4)


def dense_segment_near_runs(profile, far, n_segments, max_length):
    """The segmentation DP over the full (cuts x cuts) cost matrix: the reference.

    Dynamic programming over cut positions: a run costs the area between the profile
    and the run's nearest value (what a conservative piece gives away), a stretch of far
    bins may be skipped for free. Returns ``(first, end)`` pairs, ``end`` exclusive.
    """
    n = profile.shape[0]
    y = profile.astype(np.float64)
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    length = j - i
    sums = np.concatenate([[0.0], np.cumsum(y)])
    # run_min[i, j] = min(y[i:j]): a running minimum along each row of y[j - 1], started at i.
    run_min = np.minimum.accumulate(np.where(j > i, y[np.maximum(j - 1, 0)], np.inf), axis=1)
    area = sums[j] - sums[i] - np.where(length >= 1, run_min, 0.0) * length
    cost = np.where((length >= 1) & (length <= max_length), np.maximum(area, 0.0) + 1e-9 * length**2, np.inf)
    far_count = np.concatenate([[0], np.cumsum(far)])
    skip = np.where((length >= 1) & (far_count[j] - far_count[i] == length), 0.0, np.inf)
    columns = np.arange(n + 1)
    # best[g][j]: least cost covering bins [0, j) with g runs; a skip may follow a run.
    best = np.full(n + 1, np.inf)
    best[0] = 0.0
    best = np.minimum(best, (best[:, None] + skip).min(axis=0))
    layers = [best]
    run_from, skip_from = [None], [np.argmin(best[:, None] + skip, axis=0)]
    for _ in range(n_segments):
        total = layers[-1][:, None] + cost
        from_run = np.argmin(total, axis=0)
        after_run = total[from_run, columns]
        skipped = after_run[:, None] + skip
        from_skip = np.argmin(skipped, axis=0)
        after_skip = skipped[from_skip, columns]
        use_skip = after_skip < after_run
        layers.append(np.where(use_skip, after_skip, after_run))
        run_from.append(from_run)
        skip_from.append(np.where(use_skip, from_skip, -1))
    finals = [layer[n] for layer in layers]
    g = int(np.argmin(finals))
    if not np.isfinite(finals[g]) or g == 0:
        return [(0, n)]
    segments = []
    position = n
    while g > 0:
        source = int(skip_from[g][position])
        if source >= 0:
            position = source
        start = int(run_from[g][position])
        segments.append((start, position))
        position = start
        g -= 1
    return segments[::-1]


@settings(max_examples=200, deadline=None)
@given(st.integers(3, 120), st.integers(1, 9), st.integers(1, 130), st.integers(0, 2**32 - 1))
def test_banded_segmentation_equals_the_dense_dynamic_programme(n, n_segments, max_length, seed):
    rng = np.random.default_rng(seed)
    # Few distinct values: ties everywhere, where the two must still choose alike.
    profile = np.minimum(rng.choice([0.8, 1.2, 1.5, 2.25, 3.0], n), 2.25)
    far = profile >= 2.25
    assert segment_near_runs(profile, far, n_segments, max_length) == \
        dense_segment_near_runs(profile, far, n_segments, max_length)


def test_near_mismatches_need_more_support_than_a_near_box_has():
    # Corridor, 2k features, seed 5: two mismatches 0.32-0.34 m away in one pan bin, 26 cm
    # apart in height, passed for an obstacle and boxed the robot in (empty map).
    from occtool.navigation import navigation_map
    from occtool.simulate import Scene, box, simulate_scene

    features, _ = simulate_scene("corridor", n_features=2000, seed=5)
    model = OccupancyRegressor(seed=5).fit(features)
    nav = navigation_map(model.inverse_range, robot=ROBOT, slope_bounds=model.slope_bounds_)
    assert nav.polygon.area > 1.0
    # A real box 0.45 m ahead, seen by the same sparse camera, still stops the map.
    scene = Scene((box("crate", 0.45, -0.3, 0.9, 0.3, 0.0, 0.6), box("wall", 2.5, -3, 2.6, 3, 0.0, 2.5)))
    features, _ = simulate_scene(scene, n_features=2000, seed=1)
    model = OccupancyRegressor(seed=1).fit(features)
    alpha, h = np.linspace(-0.3, 0.3, 7), np.linspace(-0.95, -0.45, 3)[:, None]
    ahead = np.sqrt(model.inverse_range(alpha, h, 0.6) ** 2 - h**2)
    # At the crate's face, up to the sensor model's depth error (3 %) ...
    assert np.all(ahead <= 0.45 / np.cos(alpha) * 1.03)
    assert ahead.min() > 0.35  # ... and not far in front of it
    # ... and the robot's body keeps clear of it.
    import shapely

    crate = shapely.box(0.45, -0.3, 0.9, 0.3)
    assert model.navigation_map().polygon.intersection(crate.buffer(model.robot_.radius * 0.98)).is_empty


def test_estimator_contract_get_set_params_repr():
    model = OccupancyRegressor(pieces=16, focus_range=3.0)
    params = model.get_params()
    assert params["pieces"] == 16 and params["focus_range"] == 3.0 and "progress" not in params
    assert list(params) == list(OccupancyRegressor._get_param_names())
    assert model.set_params(pieces=8) is model and model.pieces == 8
    with pytest.raises(InputError, match="no parameter 'piece'"):
        model.set_params(piece=3)
    assert repr(model) == "OccupancyRegressor(pieces=8, focus_range=3.0)"
    assert repr(OccupancyRegressor()) == "OccupancyRegressor()"
    with pytest.raises(TypeError):
        OccupancyRegressor(16)  # keyword-only, as scikit-learn estimators


def test_sklearn_clone_gives_an_unfitted_twin_that_fits_the_same():
    base = pytest.importorskip("sklearn.base")
    features, _ = simulate_scene("office", n_features=1500, seed=4)
    model = OccupancyRegressor(pieces=12, seed=3).fit(features)
    twin = base.clone(model)
    assert twin.get_params(deep=False).keys() == model.get_params(deep=False).keys()
    assert not hasattr(twin, "tree_")
    twin.fit(features)
    assert twin.tree_ == model.tree_
    assert model.fit_seconds_ > 0


def test_progress_is_a_fit_argument_called_per_group():
    calls = []
    features, _ = simulate_scene("office", n_features=1500, seed=4)
    OccupancyRegressor(pieces=12).fit(features, progress=lambda done, total: calls.append((done, total)))
    assert calls and calls[-1][0] == calls[-1][1] and [c[0] for c in calls] == list(range(1, len(calls) + 1))


@given(st.integers(min_value=1, max_value=50_000_000))
def test_default_pieces_grow_with_the_features_in_whole_groups_up_to_a_cap(n):
    pieces = default_pieces(n)
    assert pieces % 4 == 0 and DEFAULT_PIECES <= pieces <= MOST_DEFAULT_PIECES
    assert (pieces == DEFAULT_PIECES) if n <= MORE_PIECES_FROM else pieces >= DEFAULT_PIECES
    assert default_pieces(n + 1_000) >= pieces  # never fewer for more features
    if n >= 4 * MORE_PIECES_FROM:
        assert pieces == MOST_DEFAULT_PIECES


def test_pieces_none_fits_the_count_s_default_and_a_number_overrides_it():
    small, large = ring_room(3000), ring_room(2 * MORE_PIECES_FROM)
    assert OccupancyRegressor().fit(small).tree_.n_pieces == DEFAULT_PIECES
    assert OccupancyRegressor().fit(large).tree_.n_pieces == default_pieces(len(large)) > DEFAULT_PIECES
    assert OccupancyRegressor(pieces=DEFAULT_PIECES).fit(large).tree_.n_pieces == DEFAULT_PIECES
    # Groups are checked against the pieces the fit places, also when the count picks them.
    with pytest.raises(InputError, match=r"groups must be between 1 and the number of pieces \(64\)"):
        OccupancyRegressor(groups=65).fit(small)
    with pytest.raises(InputError, match="pieces must be a whole number"):
        OccupancyRegressor(pieces=float("nan")).fit(small)


@pytest.mark.parametrize("basis", ["trig", "linear"])
def test_projecting_rows_at_once_equals_projecting_each(basis):
    """_Refitter.project_rows is a piece's projection row by row, bit for bit (the
    construction projects its pieces at once): clip, the disc by pan_weight, an ulp shaved."""
    from types import SimpleNamespace

    from occtool.fit._construction import _Fitter
    from occtool.fit._refit import pan_weight

    def project(fitter, piece):
        piece = np.clip(piece, fitter.lower, fitter.upper)
        if fitter.k_angle == 2:
            norm = pan_weight(piece[0], piece[1])
            if norm > fitter.p.a_max:
                piece[:2] *= fitter.p.a_max / norm
                while pan_weight(piece[0], piece[1]) > fitter.p.a_max:
                    piece[:2] = np.nextafter(piece[:2], 0.0)
        return piece

    k = 2 if basis == "trig" else 1
    lower = np.array([-12.0] * k + [-8.0, 0.25, -np.inf])
    upper = np.array([12.0] * k + [8.0, np.inf, np.inf])
    fitter = SimpleNamespace(k_angle=k, lower=lower, upper=upper, p=SimpleNamespace(a_max=12.0))
    rng = np.random.default_rng(7)
    W = rng.normal(0.0, 10.0, (4000, k + 3))
    # A pair one ulp over the disc once scaled (the loader's regression), and rows on it.
    W[0, :2] = [-6.3453855919518025, -10.185091147822414]
    W[1, :k] = 12.0
    expected = np.array([project(fitter, row.copy()) for row in W])
    got = _Fitter.project_rows(fitter, W.copy())
    assert got.tobytes() == expected.tobytes()


def test_a_planar_frontier_stands_past_each_bin_s_farthest_end():
    """_frontier's planar extent (one reduction over the bins) is each bin's farthest ray
    end, as the rank-th farthest by partition gives it for rank 1."""
    from occtool.fit._focus import FRONTIER_MARGIN, UNSEEN_CLEARANCE, _frontier
    from occtool.fit._profile import FOCUS_ANGLE_BINS

    rng = np.random.default_rng(3)
    bins = rng.integers(0, FOCUS_ANGLE_BINS, 700)
    bins = bins[(bins % 7 != 0)]  # some bins without ends
    distance = rng.uniform(0.2, 3.0, bins.size)
    frontier = _frontier([(distance[:300], bins[:300]), (distance[300:], bins[300:])], 700, ROBOT, 4.0, True)
    extent = np.zeros(FOCUS_ANGLE_BINS)
    for b in range(FOCUS_ANGLE_BINS):
        if (bins == b).any():
            extent[b] = np.partition(distance[bins == b], -1)[-1]
    extent = np.maximum(extent, np.minimum(np.roll(extent, 1), np.roll(extent, -1)))
    short = np.flatnonzero(extent < 4.0)
    reach = np.maximum(extent[short] * (1.0 + FRONTIER_MARGIN), ROBOT.radius + UNSEEN_CLEARANCE)
    D = np.sqrt(frontier.r**2 - frontier.h**2)
    assert np.allclose(D, np.repeat(reach, D.size // short.size), rtol=0, atol=1e-12)
