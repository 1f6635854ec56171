"""The fit's fast paths give exactly the numbers of the plain ones they stand in for."""

from __future__ import annotations

import numpy as np
import pytest

import occtool.fit._focus as focus_module
import occtool.fit._profile as profile_module
import occtool.guard as guard_module
from occtool.features import FeatureGeometry, Features, wrap_angle
from occtool.fit import focus_samples, frontier_samples, join_samples, sorted_within_bins
from occtool.fit._focus import focused_blocks, focused_with_frontier
from occtool.fit._profile import first_obstacle_distance_in_bins, order_within_bins
from occtool.fit._screen import _neighbours_of, screen_features
from occtool.fit._sight import SortedRays
from occtool.guard import Support
from occtool.robot import Robot
from occtool.sensor import SAMPLE_KINDS, Samples, SensorModel
from occtool.simulate import simulate_scene
from occtool.tree import EVALUATION_CHUNK, MinMaxTree, Op

ROBOT = Robot()
COLUMNS = ("alpha", "h", "r", "m", "weight", "kind")


def test_wrap_angle_is_the_modulo_formula_bit_for_bit():
    rng = np.random.default_rng(0)
    edges = [np.pi, -np.pi, 0.0, -0.0, 3 * np.pi, -3 * np.pi, np.nextafter(np.pi, 0.0), np.nextafter(-np.pi, 0.0),
             2 * np.pi, -2 * np.pi, 1e-300, -1e-300]
    alpha = np.concatenate([edges, rng.uniform(-4 * np.pi, 4 * np.pi, 10_000), rng.uniform(-np.pi, np.pi, 10_000)])
    expected = np.mod(alpha + np.pi, 2.0 * np.pi) - np.pi
    wrapped = wrap_angle(alpha)
    np.testing.assert_array_equal(wrapped, expected)
    np.testing.assert_array_equal(np.signbit(wrapped), np.signbit(expected))
    assert wrap_angle(3 * np.pi) == np.mod(3 * np.pi + np.pi, 2.0 * np.pi) - np.pi


@pytest.mark.parametrize("per_bin", [3, 500])  # the two-key sort, and a sort a bin
def test_grouping_within_bins_is_a_stable_two_key_sort(per_bin):
    rng = np.random.default_rng(per_bin)
    bins = rng.integers(0, 12, 12 * per_bin)
    values = np.round(rng.uniform(0.0, 5.0, bins.size), 1)  # many ties
    order, bounds = order_within_bins(bins, values, 12)
    np.testing.assert_array_equal(order, np.lexsort((values, bins)))
    grouped, same_bounds = sorted_within_bins(bins, values, 12)
    np.testing.assert_array_equal(grouped, values[np.lexsort((values, bins))])
    np.testing.assert_array_equal(bounds, same_bounds)
    np.testing.assert_array_equal(np.diff(bounds), np.bincount(bins, minlength=12))


@pytest.mark.parametrize("layout", ["spread", "ties", "bins", "crowded"])
def test_the_bucket_search_of_sorted_rays_is_searchsorted(layout):
    rng = np.random.default_rng(len(layout))
    if layout == "spread":
        keys = rng.normal(size=3000)
    elif layout == "ties":
        keys = rng.integers(0, 1500, 3000).astype(float)
    elif layout == "bins":  # as the sight index's: bin * 4 + elevation
        keys = 4.0 * rng.integers(0, 120, 3000) + rng.uniform(-1.5, 1.5, 3000)
    else:  # one bucket holds too many keys: a binary search
        keys = np.concatenate([rng.uniform(0.0, 1.0, 100), np.full(500, 0.5)])
    keys = np.sort(keys)
    fine = SortedRays.build(keys, keys, keys, queries=10**6)  # many queries: a finer table
    assert fine.n_buckets == 16 * keys.size
    assert fine.first is not None or layout == "crowded"
    for side in ("left", "right"):
        queries = np.concatenate([keys, np.nextafter(keys, np.inf), np.nextafter(keys, -np.inf)])
        np.testing.assert_array_equal(fine.search(queries, side), np.searchsorted(keys, queries, side=side))
    rays = SortedRays.build(keys, keys, keys)
    assert (rays.first is None) == (layout == "crowded")
    queries = np.concatenate([rng.choice(keys, 2000), np.nextafter(rng.choice(keys, 2000), np.inf),
                              np.nextafter(rng.choice(keys, 2000), -np.inf),
                              rng.uniform(keys[0] - 1.0, keys[-1] + 1.0, 2000)])
    for side in ("left", "right"):
        for asked in (queries, np.append(queries, [-np.inf, np.inf])):  # the table, and a binary search
            np.testing.assert_array_equal(rays.search(asked, side), np.searchsorted(keys, asked, side=side))
    owner, position = rays.pairs(queries - 0.01, queries + 0.01)
    expected = [(i, j) for i, q in enumerate(queries[:300])
                for j in np.flatnonzero((keys >= q - 0.01) & (keys <= q + 0.01))]
    chosen = owner < 300
    assert list(zip(owner[chosen].tolist(), position[chosen].tolist())) == expected


def test_first_obstacles_from_each_bins_nearest_hits_equal_the_full_sort(monkeypatch):
    # Few hits a bin tried first (one to 16), so that windows reach past them and the
    # nearest are widened again and again; distances on grids (ties, windows ending
    # exactly on a hit), at the sensor, and surfaces behind sparse mismatches.
    rng = np.random.default_rng(0)
    for trial in range(1500):
        n_bins = int(rng.integers(1, 8))
        n = int(rng.integers(1, 600))
        bins = rng.integers(0, n_bins, n)
        layout = trial % 5
        if layout == 0:
            distance = rng.uniform(0.0, 5.0, n)
        elif layout == 1:
            distance = np.round(rng.uniform(0.0, 5.0, n) / 0.05) * 0.05
        elif layout == 2:
            distance = np.round(rng.uniform(0.0, 3.0, n) * 64) / 64
        elif layout == 3:
            distance = np.abs(rng.uniform(0.2, 4.0, n_bins)[bins] + np.round(rng.normal(0.0, 0.03, n), 3))
        else:
            distance = np.where(rng.random(n) < 0.1, 0.0, np.round(rng.exponential(1.0, n), 2))
        support = int(rng.choice([1, 1, 2, 3, 6, 20, 100]))
        front = int(rng.choice([0, 1, 3, 10, 50, 200]))
        cap = float(rng.choice([np.inf, 1.0, 1.03, 0.5]))
        monkeypatch.setattr(profile_module, "NEAREST_FIRST", 10**9)
        full = first_obstacle_distance_in_bins(bins, distance, n_bins, support, front=front, cap=cap)
        monkeypatch.setattr(profile_module, "NEAREST_FIRST", int(rng.choice([1, 2, 4, 8, 16])))
        nearest = first_obstacle_distance_in_bins(bins, distance, n_bins, support, front=front, cap=cap)
        np.testing.assert_array_equal(nearest, full)


def _samples(n: int, seed: int) -> Samples:
    rng = np.random.default_rng(seed)
    kind = rng.choice([SAMPLE_KINDS[k] for k in ("hit", "near", "robot", "floor", "footprint")], n,
                      p=[0.4, 0.3, 0.2, 0.05, 0.05]).astype(np.int8)
    # Ranges to 0.1 m (ties), some bins short of the focus range so that the frontier shows.
    r = np.round(rng.uniform(0.1, 3.6, n) * np.where(rng.random(n) < 0.5, 1.0, 0.5), 1)
    return Samples(rng.uniform(-np.pi, np.pi, n), -rng.uniform(0.0, 0.09, n), r, np.ones(n), np.ones(n), kind)


@pytest.mark.parametrize("planar", [False, True])
def test_pruned_frontier_and_fused_focus_equal_the_plain_ones(monkeypatch, planar):
    samples = _samples(400_000, 3)  # ray ends beyond FRONTIER_PRUNE
    pruned = frontier_samples(samples, ROBOT, 4.0, planar=planar)
    fused = focused_with_frontier(samples, ROBOT, 4.0, planar=planar, floor_is_obstacle=False)
    monkeypatch.setattr(focus_module, "FRONTIER_PRUNE", 10**12)
    plain = frontier_samples(samples, ROBOT, 4.0, planar=planar)
    joined = join_samples(focus_samples(samples, ROBOT, 4.0), plain)
    assert len(plain) > 0
    for name in COLUMNS:
        np.testing.assert_array_equal(getattr(pruned, name), getattr(plain, name))
        np.testing.assert_array_equal(getattr(fused, name), getattr(joined, name))
        assert getattr(fused, name).dtype == getattr(joined, name).dtype


@pytest.mark.parametrize("floor", ["free", "drop", "obstacle"])
def test_focused_sample_blocks_equal_the_focused_samples(monkeypatch, floor):
    # Blocks of hits, near, robot, footprint and background samples, some free rays
    # (evidence 0) and floor features: only the kept samples are written, the same ones
    # as the plain focus and frontier of all samples keep and add (the blocks' frontier pruned).
    rng = np.random.default_rng(7)
    n = 30_000
    a = rng.uniform(-np.pi, np.pi, n)
    z = rng.uniform(-1.1, 0.4, n)
    d = np.where(z > 0.0, rng.uniform(0.8, 1.0, n), rng.uniform(1.0, 5.0, n))  # nearer above the body band
    points = np.column_stack([d * np.cos(a), d * np.sin(a), z])
    features = Features(points, np.where(rng.random(n) < 0.1, 0.0, rng.uniform(0.3, 1.0, n)))
    sensor = SensorModel(floor=floor, background_samples=2000)
    blocks = sensor._sample_blocks(features, ROBOT, np.random.default_rng(1), turn=0.4)
    whole = sensor._samples(features, ROBOT, np.random.default_rng(1), turn=0.4)
    for planar in (False, True):
        monkeypatch.setattr(focus_module, "FRONTIER_PRUNE", 1000)
        fused = focused_blocks(blocks, ROBOT, 3.0, planar=planar, floor_is_obstacle=floor == "obstacle")
        monkeypatch.setattr(focus_module, "FRONTIER_PRUNE", 10**12)
        plain = join_samples(focus_samples(whole, ROBOT, 3.0, floor_is_obstacle=floor == "obstacle"),
                             frontier_samples(whole, ROBOT, 3.0, planar=planar))
        assert 0 < len(fused) < len(whole)
        for name in COLUMNS:
            np.testing.assert_array_equal(getattr(fused, name), getattr(plain, name))
            assert getattr(fused, name).dtype == getattr(plain, name).dtype


def test_one_support_query_serves_the_seen_from_above_test():
    rng = np.random.default_rng(4)
    a = rng.uniform(-1.0, 1.0, 3000)
    z = rng.uniform(-0.9, 0.5, 3000)
    points = np.column_stack([2.0 * np.cos(a), 2.0 * np.sin(a), z])
    support = Support(points, spacing=0.02)
    confirmed, neighbours = support._confirmed(points[:500], 6, steep=True)
    assert neighbours is not None
    np.testing.assert_array_equal(confirmed, support.confirmed(points[:500], 6))
    np.testing.assert_array_equal(support.seen_from_above(points[:500], neighbours),
                                  support.seen_from_above(points[:500]))


@pytest.mark.parametrize("block", [1 << 16, 97])  # all at once, and in blocks
def test_support_queries_count_each_points_neighbours_within_reach(monkeypatch, block):
    # The index asks queries in the order of its cells, not in the points' order: each point's
    # count is still the brute-force count of support points within reach (embedded distance < 1).
    monkeypatch.setattr(guard_module, "SUPPORT_QUERY_BLOCK", block)
    rng = np.random.default_rng(12)
    a = rng.uniform(-np.pi, np.pi, 2500)
    points = np.column_stack([np.cos(a), np.sin(a), rng.uniform(-0.5, 0.5, 2500)]) * rng.uniform(0.5, 3.0, (2500, 1))
    support = Support(points, spacing=0.03)
    asked = points[rng.permutation(2500)[:600]]
    needed = rng.integers(1, 9, 600)
    embedded, asked_embedded = support._embedded(support.points), support._embedded(asked)
    within = (np.linalg.norm(asked_embedded[:, None, :] - embedded[None, :, :], axis=2) < 1.0).sum(axis=1)
    assert 0 < (within >= needed).sum() < 600
    np.testing.assert_array_equal(support.confirmed(asked, needed), within >= needed)


def test_screening_some_features_gives_those_the_answer_of_screening_all():
    features, _ = simulate_scene("office", n_features=6000, seed=3)
    geometry = FeatureGeometry.of(features)
    screened = np.random.default_rng(0).random(len(features)) < 0.3
    options = dict(basis="trig", focus=True, focus_range=4.0, geometry=geometry)
    every = screen_features(features, SensorModel(), ROBOT, **options)
    some = screen_features(features, SensorModel(), ROBOT, screened=screened, **options)
    assert every.mismatch[screened].any() and every.mismatch[~screened].any()
    np.testing.assert_array_equal(some.mismatch, every.mismatch & screened)
    np.testing.assert_array_equal(some.obstacle, every.obstacle)
    assert some.origin == every.origin


def test_support_of_rows_is_the_support_of_those_points(monkeypatch):
    monkeypatch.setattr(guard_module, "SUPPORT_SAMPLE", 700)  # a subsample of every 5th row
    rng = np.random.default_rng(8)
    a = rng.uniform(-1.0, 1.0, 6000)
    points = np.column_stack([2.0 * np.cos(a), 2.0 * np.sin(a), rng.uniform(-0.9, 0.5, 6000)])
    rows = np.flatnonzero(rng.random(6000) < 0.55)
    taken, gathered = Support.of_rows(points, rows, 0.02), Support(points[rows], 0.02)
    assert taken.step == gathered.step > 1
    np.testing.assert_array_equal(taken.points, gathered.points)
    np.testing.assert_array_equal(taken.confirmed(points[:400], 12), gathered.confirmed(points[:400], 12))
    np.testing.assert_array_equal(taken.seen_from_above(points[:400]), gathered.seen_from_above(points[:400]))


def test_the_neighbours_of_confirmed_returns_are_their_chunks_rows():
    rng = np.random.default_rng(9)
    a = rng.uniform(-1.0, 1.0, 3000)
    points = np.column_stack([2.0 * np.cos(a), 2.0 * np.sin(a), rng.uniform(-0.9, 0.5, 3000)])
    support = Support(points, spacing=0.02)
    chunks = [np.sort(rng.choice(np.arange(lo, lo + 500), 300, replace=False)) for lo in (0, 500, 1000)]
    found = [(chosen, support._confirmed(points[chosen], 6, steep=True)[1]) for chosen in chunks]
    # Some in a chunk, some in none (those are queried): all as one query finds them.
    positions = rng.permutation(np.concatenate([rng.permutation(np.concatenate(chunks))[:247], [1600, 1700, 2999]]))
    distance, index = _neighbours_of(positions, found, support, points)
    expected_distance, expected_index = support.tree.query(support._embedded(points[positions]), k=16,
                                                           distance_upper_bound=1.0)
    np.testing.assert_array_equal(distance, expected_distance)
    np.testing.assert_array_equal(index, expected_index)
    assert _neighbours_of(positions, [], support, points) is None  # no query shared


def test_chunked_evaluation_equals_evaluation_a_chunk_at_a_time():
    rng = np.random.default_rng(5)
    W = rng.normal(size=(12, 5))
    W[:, 3] = np.abs(W[:, 3]) + 0.1
    tree = MinMaxTree("trig", W, Op("max", (Op("min", (0, 1, 2, 3)), Op("min", (4, 5, 6, 7)),
                                            Op("min", (8, 9, 10)), 11)))
    n = 3 * EVALUATION_CHUNK + 17
    alpha, h, r = rng.uniform(-np.pi, np.pi, n), rng.uniform(-1.0, 0.0, n), rng.uniform(0.0, 4.0, n)
    # Up to EVALUATION_CHUNK points are evaluated whole, through the plain path.
    parts = [tree.predict(alpha[i:i + 1000], h[i:i + 1000], r[i:i + 1000]) for i in range(0, n, 1000)]
    np.testing.assert_array_equal(tree.predict(alpha, h, r), np.concatenate(parts))
    active = [tree.active_piece(alpha[i:i + 1000], h[i:i + 1000], r[i:i + 1000]) for i in range(0, n, 1000)]
    np.testing.assert_array_equal(tree.active_piece(alpha, h, r), np.concatenate(active))


def test_a_run_of_pieces_reduced_at_once_equals_their_minimum_one_by_one():
    # min(0, 1, 2, 3) over consecutive rows takes one reduction; min(min(0), 1, 2, 3) the
    # pairwise path. Identical and zero pieces make ties and signed zeros: the same bits.
    rng = np.random.default_rng(6)
    W = rng.normal(size=(12, 5))
    W[:, 3] = np.abs(W[:, 3]) + 0.1
    W[5] = W[4]
    W[8] = [0.0, 0.0, 0.0, 1.0, -0.0]
    W[9] = [-0.0, 0.0, -0.0, 1.0, 0.0]
    groups = [(0, 1, 2, 3), (4, 5, 6, 7), (8, 9, 10, 11)]
    at_once = MinMaxTree("trig", W, Op("max", tuple(Op("min", g) for g in groups)))
    one_by_one = MinMaxTree("trig", W, Op("max", tuple(Op("min", (Op("min", (g[0],)), *g[1:])) for g in groups)))
    n = 2 * EVALUATION_CHUNK + 5
    alpha, h = rng.uniform(-np.pi, np.pi, n), rng.uniform(-1.0, 0.0, n)
    r = np.where(rng.random(n) < 0.3, 0.0, rng.uniform(0.0, 4.0, n))
    for args in ((alpha, h, r), (alpha[:100], h[:100], r[:100])):
        fast, plain = at_once.predict(*args), one_by_one.predict(*args)
        np.testing.assert_array_equal(fast, plain)
        np.testing.assert_array_equal(np.signbit(fast), np.signbit(plain))


def test_a_node_of_one_child_first_under_another_leaves_the_pieces_alone():
    # max(min(p0), p1, p2): min(p0) is p0's own row of values, which the max must not reduce into.
    W = np.array([[0.0, 0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 2.0, -1.0], [0.0, 0.0, 1.0, 1.0, 0.0]])
    tree = MinMaxTree("trig", W, Op("max", (Op("min", (0,)), 1, 2)))
    r = np.linspace(0.0, 2.0, 9)
    h = np.full(9, -0.5)
    expected = np.maximum(np.maximum(r, 2.0 * r - 1.0), h + r)
    np.testing.assert_array_equal(tree.predict(0.0, h, r), expected)
    grid = tree.predict(np.zeros((3, 1)), -0.5, r[None, :])  # broadcast inputs: read-only rows
    np.testing.assert_array_equal(grid, np.broadcast_to(expected, (3, 9)))
