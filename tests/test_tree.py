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
