"""The min/max tree: evaluation, MIN/MAX algebra of the inverse, serialisation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from occtool.errors import ModelFormatError
from occtool.tree import InverseTree, MinMaxTree, Op


def random_tree(seed: int, basis: str = "trig", n_groups: int = 3, per_group: int = 3) -> MinMaxTree:
    rng = np.random.default_rng(seed)
    k = 5 if basis == "trig" else 4
    n = n_groups * per_group
    coefficients = rng.normal(size=(n, k))
    coefficients[:, -2] = rng.uniform(0.1, 3.0, n)  # c > 0
    root = Op("max", tuple(Op("min", tuple(range(g * per_group, (g + 1) * per_group))) for g in range(n_groups)))
    return MinMaxTree(basis, coefficients, root)


def test_max_of_two_pieces_known_values():
    tree = MinMaxTree("linear", [[0.0, 0.0, 1.0, -1.0], [0.0, 0.0, 2.0, -3.0]], Op("max", (0, 1)))
    assert tree.predict(0.0, 0.0, [0.0, 1.0, 2.0, 3.0]).tolist() == [-1.0, 0.0, 1.0, 3.0]
    # F = max(r - 1, 2r - 3) reaches 1 at r = 2 (both), 3 at r = 3 (second piece).
    assert tree.inverse().range(0.0, 0.0, [1.0, 3.0]).tolist() == [2.0, 3.0]
    assert tree.active_piece(0.0, 0.0, [0.0, 3.0]).tolist() == [0, 1]


def test_inverse_swaps_min_and_max():
    tree = random_tree(1)
    inverse = tree.inverse()
    assert inverse.root.op == "min"
    assert all(child.op == "max" for child in inverse.root.children)


@given(seed=st.integers(0, 10_000), basis=st.sampled_from(["trig", "linear"]),
       alpha=st.floats(-np.pi, np.pi), h=st.floats(-1.0, 0.5), m=st.floats(-2.0, 3.0))
def test_inverse_inverts(seed, basis, alpha, h, m):
    tree = random_tree(seed, basis)
    r = tree.inverse().range(alpha, h, m)
    assert np.isclose(tree.predict(alpha, h, r), m, rtol=1e-9, atol=1e-9)


@given(seed=st.integers(0, 10_000), alpha=st.floats(-np.pi, np.pi), h=st.floats(-1.0, 0.5),
       r1=st.floats(0.0, 10.0), dr=st.floats(1e-6, 10.0))
def test_monotone_in_range(seed, alpha, h, r1, dr):
    tree = random_tree(seed)
    assert tree.predict(alpha, h, r1 + dr) > tree.predict(alpha, h, r1)


def test_trig_basis_has_no_seam():
    tree = random_tree(3, "trig")
    eps = 1e-9
    below = tree.predict(np.pi - eps, -0.5, 1.0)
    above = tree.predict(-np.pi + eps, -0.5, 1.0)
    assert abs(float(below) - float(above)) < 1e-6


def test_dict_round_trip_is_exact():
    tree = random_tree(5)
    again = MinMaxTree.from_dict(tree.to_dict())
    assert again == tree
    inverse = tree.inverse()
    assert InverseTree.from_dict(inverse.to_dict()) == inverse


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda d: d.update(basis="cubic"), "unknown basis"),
        (lambda d: d["pieces"][0].pop("c"), "coefficients"),
        (lambda d: d["pieces"][0].update(c="x"), "not a number"),
        (lambda d: d.update(tree={"op": "avg", "children": [0]}), "op"),
        (lambda d: d.update(tree={"op": "max", "children": [0, 99]}), "out of range"),
        (lambda d: d.update(tree={"op": "max", "children": [0, 0]}), "exactly once"),
    ],
)
def test_malformed_tree_rejected(mutate, message):
    data = random_tree(2).to_dict()
    mutate(data)
    with pytest.raises(ModelFormatError, match=message):
        MinMaxTree.from_dict(data)


def test_non_positive_range_weight_is_not_invertible():
    tree = MinMaxTree("linear", [[0.0, 0.0, 0.0, 1.0]], 0)
    with pytest.raises(ValueError):
        tree.inverse()


# --- the inverse's evaluation over sweeps ------------------------------------------------


def shared_weight_tree(seed: int, basis: str = "trig") -> MinMaxTree:
    """Groups like a fitted model's: the side pieces share the height weight and the
    constant of a centre piece, and one node mixes pieces and subtrees."""
    rng = np.random.default_rng(seed)
    k = 5 if basis == "trig" else 4
    coefficients = rng.normal(size=(11, k))
    coefficients[:, -2] = rng.uniform(0.1, 3.0, 11)  # c > 0
    for group in (0, 4):
        coefficients[group + 2:group + 4, -3:] = coefficients[group, -3:]  # same b, c, d
    coefficients[9, -3] = coefficients[8, -3]  # same b only
    root = Op("max", (Op("min", (0, 1, 2, 3)), Op("min", (4, 5, 6, 7)), Op("min", (8, Op("max", (9, 10))))))
    return MinMaxTree(basis, coefficients, root)


def plain_range(inverse: InverseTree, alpha, h, m) -> np.ndarray:
    """Every piece at every point, then the tree: the evaluation ``range`` must agree with."""
    return super(InverseTree, inverse)._eval(alpha, h, m)


SWEEPS = {
    "angles x heights": (np.linspace(-np.pi, np.pi, 90)[None, :], np.linspace(-0.9, 0.1, 13)[:, None], 0.6),
    "heights x angles": (np.linspace(-np.pi, np.pi, 90)[:, None], np.linspace(-0.9, 0.1, 13)[None, :], 0.4),
    "levels x heights x angles": (
        np.linspace(-3, 3, 40),
        np.linspace(-1, 0, 7)[:, None],
        np.array([0.2, 0.9])[:, None, None],
    ),
    "levels along the angles": (np.linspace(-3, 3, 40), np.linspace(-1, 0, 7)[:, None], np.linspace(0, 1, 40)),
    "angles at one height": (np.linspace(-3, 3, 50), -0.5, 0.6),
    "one angle, many heights": (0.3, np.linspace(-1, 0.5, 30)[:, None], np.array([0.1, 0.6, 2.0])),
    "points": (np.linspace(-3, 3, 25), np.linspace(-1, 0, 25), np.linspace(0, 1, 25)),
    "scalars": (0.3, -0.2, 0.6),
    "empty": (np.empty((0, 4)), 0.1, 0.5),
}


@pytest.mark.parametrize("basis", ["trig", "linear"])
@pytest.mark.parametrize("sweep", list(SWEEPS))
@pytest.mark.parametrize("make", [random_tree, shared_weight_tree])
def test_the_inverse_over_a_sweep_is_every_piece_at_every_point(make, sweep, basis):
    inverse = make(7, basis).inverse()
    alpha, h, m = SWEEPS[sweep]
    expected = plain_range(inverse, alpha, h, m)
    got = inverse.range(alpha, h, m)
    assert got.shape == expected.shape == np.broadcast_shapes(np.shape(alpha), np.shape(h), np.shape(m))
    np.testing.assert_allclose(got, expected, rtol=1e-13, atol=1e-13)


def test_the_inverse_of_a_single_piece_and_non_finite_inputs():
    inverse = MinMaxTree("trig", [[0.5, -0.2, 1.0, 2.0, -1.0]], 0).inverse()
    alpha, h = np.linspace(-3, 3, 8)[None, :], np.array([[-0.5], [np.inf], [np.nan]])
    expected = plain_range(inverse, alpha, h, 0.6)
    np.testing.assert_allclose(inverse.range(alpha, h, 0.6), expected, rtol=1e-13)  # same inf and NaN too
    tree = shared_weight_tree(3).inverse()
    for alpha, h, m in [([0.0, np.nan], [[-0.5], [np.inf]], 0.6), ([0.0, 1.0], [[-0.5], [0.0]], [np.inf, np.nan])]:
        np.testing.assert_allclose(tree.range(alpha, h, m), plain_range(tree, alpha, h, m), rtol=1e-13)


@pytest.mark.parametrize("block", [1, 7, 64])
def test_the_inverse_in_blocks_and_flattened(monkeypatch, block):
    import occtool.tree._inverse

    monkeypatch.setattr(occtool.tree._inverse, "INVERSE_BLOCK", block)
    inverse = shared_weight_tree(11).inverse()
    rng = np.random.default_rng(0)
    for alpha, h, m in [
        (np.linspace(-3, 3, 30)[None, :], np.linspace(-1, 0, 9)[:, None], 0.6),  # rows in blocks
        (np.linspace(-3, 3, 100)[None, :], -0.5, np.array([[0.2], [0.7]])),  # rows longer than a block
        (rng.uniform(-3, 3, (3, 1, 20)), rng.uniform(-1, 0, (1, 4, 1)), rng.uniform(0, 1, (3, 4, 1))),
    ]:
        np.testing.assert_allclose(
            inverse.range(alpha, h, m), plain_range(inverse, alpha, h, m), rtol=1e-13, atol=1e-13
        )


@pytest.mark.parametrize("basis", ["trig", "linear"])
@pytest.mark.parametrize("make", [random_tree, shared_weight_tree])
def test_the_inverse_of_a_small_sweep_as_rows_is_the_compiled_programs(monkeypatch, make, basis):
    """A sweep of at most INVERSE_BLOCK piece values goes through the tree's rows
    (_range_rows), a larger one through its compiled program: the same numbers, bit for bit."""
    import occtool.tree._inverse

    inverse = make(5, basis).inverse()
    sweeps = [*SWEEPS.values(), (np.linspace(-3, 3, 8)[None, :], np.array([[-0.5], [np.inf], [np.nan]]), 0.6),
              (0.3, np.array([[-0.5], [0.0]]), np.array([np.inf, np.nan, 0.2]))]
    for alpha, h, m in sweeps:
        shape = np.broadcast_shapes(np.shape(alpha), np.shape(h), np.shape(m))
        row = int(np.prod(shape[1:]))  # a block of one row: the program, not flattened
        monkeypatch.setattr(occtool.tree._inverse, "INVERSE_BLOCK", max(row, 1))
        expected = inverse.range(alpha, h, m)
        monkeypatch.setattr(occtool.tree._inverse, "INVERSE_BLOCK", 1 << 30)
        np.testing.assert_array_equal(inverse.range(alpha, h, m), expected)


def plain_horizontal_bound(inverse: InverseTree, lo, hi, h_edges, m) -> np.ndarray:
    """Every piece's least ``r^2 - h^2`` over every box at once, then the tree, then the
    root: the numbers :meth:`InverseTree.horizontal_lower_bound` must give, bit for bit."""
    k = len(inverse.coefficients[0]) - 3
    W = inverse.coefficients
    if inverse.basis == "linear":
        angle = np.minimum(W[:, :1] * lo, W[:, :1] * hi)
    else:
        def trig(alpha):
            return W[:, :1] * np.cos(alpha) + W[:, 1:2] * np.sin(alpha)
        inside = np.mod(np.arctan2(W[:, 1:2], W[:, :1]) + np.pi - lo, 2.0 * np.pi) <= hi - lo
        angle = np.where(inside, -np.hypot(W[:, :1], W[:, 1:2]), np.minimum(trig(lo), trig(hi)))
    u = (angle + (W[:, k + 1] * m + W[:, k + 2])[:, None])[:, None, :]
    b, edges = W[:, k][:, None, None], h_edges[None, :, None]
    r = u + b * edges
    q = np.where(r >= 0, r * r - edges * edges, -1.0)
    box = np.minimum(q[:, :-1], q[:, 1:])
    vertex = np.clip(-u * b / (b * b - 1.0), edges[:, :-1], edges[:, 1:])
    rv = u + b * vertex
    curved = np.minimum(box, np.where(rv >= 0, rv * rv - vertex * vertex, -1.0))
    box = np.where(np.abs(b) > 1.0, curved, box)

    def tree(node):
        if isinstance(node, int):
            return box[node]
        return (np.minimum if node.op == "min" else np.maximum).reduce([tree(c) for c in node.children])

    return np.sqrt(np.maximum(tree(inverse.root), 0.0))


@pytest.mark.parametrize("block", [1, 300, 1000, None])  # 1, 3 and 10 angles a block, all
@pytest.mark.parametrize("basis", ["trig", "linear"])
def test_the_horizontal_lower_bound_in_blocks_is_every_piece_in_every_box(monkeypatch, block, basis):
    import occtool.tree._inverse

    if block is not None:
        monkeypatch.setattr(occtool.tree._inverse, "BOUND_BLOCK", block)
    rng = np.random.default_rng(block or 0)
    for make in (random_tree, shared_weight_tree):
        model = make(3, basis)
        coefficients = model.coefficients.copy()
        coefficients[::3, -3] = rng.choice([-2.0, -1.0, 1.0, 1.5], size=len(coefficients[::3]))  # |b| >= 1 too
        inverse = MinMaxTree(basis, coefficients, model.root).inverse()
        lo = np.sort(rng.uniform(-np.pi, np.pi - 0.2, 50))
        hi = lo + rng.uniform(0.0, 0.2, 50)
        h_edges = np.sort(rng.uniform(-1.5, 0.3, 9))
        for m in (-1.0, 0.6, 2.0):  # levels reached behind the sensor too
            expected = plain_horizontal_bound(inverse, lo, hi, h_edges, m)
            got = inverse.horizontal_lower_bound(lo, hi, h_edges, m)
            assert got.shape == (8, 50)
            np.testing.assert_array_equal(got, expected)
    assert inverse.horizontal_lower_bound(lo, hi, h_edges[:1], 0.6).shape == (0, 50)


def test_the_inverse_is_the_same_from_several_threads():
    from concurrent.futures import ThreadPoolExecutor

    trees = [shared_weight_tree(seed).inverse() for seed in range(4)]
    alpha, h = np.linspace(-3, 3, 200)[None, :], np.linspace(-1, 0, 50)[:, None]
    expected = [plain_range(tree, alpha, h, 0.6) for tree in trees]
    with ThreadPoolExecutor(4) as pool:
        results = list(pool.map(lambda i: [trees[i % 4].range(alpha, h, 0.6) for _ in range(20)], range(8)))
    for i, runs in enumerate(results):
        for got in runs:
            np.testing.assert_allclose(got, expected[i % 4], rtol=1e-13, atol=1e-13)


TURN_EDGES = [0.0, -0.0, 2 * np.pi, -2 * np.pi, 4 * np.pi, np.pi, -np.pi, 3 * np.pi, 1e-300, -1e-300,
              np.nextafter(2 * np.pi, 0), np.nextafter(-2 * np.pi, 0), np.nextafter(4 * np.pi, 0), 1e-17, -1e-17]


@given(
    angles=st.lists(st.one_of(st.floats(-8, 8), st.sampled_from(TURN_EDGES)), min_size=1, max_size=6),
    starts=st.lists(st.tuples(st.one_of(st.floats(-8, 8), st.sampled_from(TURN_EDGES)),
                              st.one_of(st.floats(-0.1, 7), st.sampled_from(TURN_EDGES[:10]))), min_size=1, max_size=6),
    shift=st.sampled_from([0.0, 2 * np.pi, -2 * np.pi, 1e-16, -1e-16]),
)
def test_an_angle_within_an_interval_is_what_np_mod_says(angles, starts, shift):
    from occtool.tree._inverse import _within_turn

    angle = np.array(angles)[:, None]
    given_start, width = np.array(starts).T
    for start in (given_start, angle[:1, 0] + shift, angle[:1, 0] + shift + width[:1]):  # at the ends too
        expected = np.mod(angle - start[None, :], 2 * np.pi) <= width[None, :len(start)]
        np.testing.assert_array_equal(_within_turn(angle, start, width[:len(start)]), expected)
