"""Tests of occtool.linear_program_batch: a batch's answers are solve_lp's, one by one, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from occtool.linear_program import LinearProgramResult, solve_lp
from occtool.linear_program_batch import (
    SPLIT_PROGRAMMES,
    WIDE_SHARE,
    solve_lps,
    solve_stacked,
    solved,
    solved_together,
)
from tests.test_linear_program import load_captured


def assert_same(batched: LinearProgramResult, alone: LinearProgramResult) -> None:
    assert batched.status == alone.status
    assert batched.iterations == alone.iterations
    if alone.x is None:
        assert batched.x is None and batched.fun is None
    else:
        assert batched.x is not None
        assert batched.x.tobytes() == alone.x.tobytes()
        assert batched.fun == alone.fun


def fit_like(rng: np.random.Generator, rows: int) -> tuple:
    """A programme shaped as the fit's: a free offset and three bounded weights, rows
    ``[1, cos - 1, sin, h]`` below ``sqrt(D^2 + h^2)``, sometimes with a floor that may make
    it infeasible."""
    edges = rng.integers(3, max(4, rows // 9))
    delta = np.linspace(-0.3, 0.3, edges)
    h = np.linspace(-0.25, 0.2, 9)
    D = rng.uniform(0.5, 4.0, edges)
    A = np.column_stack([np.ones(edges * 9), np.repeat(np.cos(delta) - 1, 9), np.repeat(np.sin(delta), 9),
                         np.tile(h, edges)])
    b = np.sqrt(np.repeat(D, 9) ** 2 + np.tile(h, edges) ** 2)
    if rng.random() < 0.6:
        floor = rng.uniform(0.3, 1.0) * b.min() * rng.uniform(0.9, 1.6, b.size)
        A, b = np.vstack([A, -A]), np.concatenate([b, -floor])
    c = -np.abs(A[: edges * 9]).sum(axis=0) * rng.uniform(0.5, 1.5, 4)
    bound = rng.uniform(0.5, 3.0)
    return c, A, b, np.array([-np.inf, -bound, -bound, -bound]), np.array([np.inf, 0.0, bound, bound])


def test_captured_programmes_batched_equal_alone():
    programmes = [(p["c"], p["A"], p["b"], p["lower"], p["upper"]) for p in load_captured()]
    for batched, programme in zip(solve_lps(programmes), programmes):
        assert_same(batched, solve_lp(*programme))


@pytest.mark.parametrize("seed", range(4))
def test_fit_like_programmes_batched_equal_alone(seed):
    rng = np.random.default_rng(seed)
    programmes = [fit_like(rng, int(rng.integers(30, 400))) for _ in range(60)]
    results = solve_lps(programmes)
    statuses = {r.status for r in results}
    assert statuses == {0, 2}, "the batch should hold optimal and infeasible programmes"
    for batched, programme in zip(results, programmes):
        assert_same(batched, solve_lp(*programme))


def test_stacked_equals_alone_and_list():
    rng = np.random.default_rng(7)
    programmes = [fit_like(rng, int(rng.integers(30, 200))) for _ in range(12)]
    c = np.array([p[0] for p in programmes])
    A = np.concatenate([p[1] for p in programmes])
    b = np.concatenate([p[2] for p in programmes])
    rows = np.array([p[1].shape[0] for p in programmes])
    lower = np.array([p[3] for p in programmes])
    upper = np.array([p[4] for p in programmes])
    for stacked, listed, programme in zip(solve_stacked(c, A, b, rows, lower, upper), solve_lps(programmes),
                                          programmes):
        assert_same(stacked, solve_lp(*programme))
        assert_same(listed, stacked)


def test_a_batch_split_by_its_rows_answers_as_alone():
    """A large batch whose wide programmes are many is solved as two batches, each padded to
    its own most rows: every answer is still solve_lp's, bit for bit."""
    rng = np.random.default_rng(5)
    programmes = [fit_like(rng, 600) if rng.random() < 0.25 else fit_like(rng, 40)
                  for _ in range(SPLIT_PROGRAMMES + 8)]
    stacked = _stacked(programmes)
    rows = stacked[3]
    assert np.count_nonzero(rows > 2 * np.median(rows)) >= WIDE_SHARE * rows.size
    for batched, programme in zip(solve_stacked(*stacked), programmes, strict=True):
        assert_same(batched, solve_lp(*programme))


def test_unusual_programmes_in_a_batch_are_solve_lps():
    """Whatever leaves the common path (unbounded, artificial bounds at the optimum, a zero
    row, crossed bounds, no rows, other sizes, scalar bounds, Bland's rule, the iteration
    cap) is settled as solve_lp settles it."""
    rng = np.random.default_rng(3)
    duplicated = np.tile([[1.0, 1.0], [1.0, -1.0]], (12, 1))
    programmes = [
        fit_like(rng, 100),
        ([0.0, -1.0], [[0.0, 1.0], [1.0, 1.0]], [2.0, 3.0], -np.inf, np.inf),  # x0 free of cost
        ([-1.0, -1.0], [[1.0, 0.0]], [1.0], -np.inf, np.inf),  # unbounded
        ([1.0, 1.0], [[0.0, 0.0], [1.0, 1.0]], [1.0, 4.0], 0.0, 5.0),  # a zero row
        ([1.0, 1.0], [[0.0, 0.0], [1.0, 1.0]], [-1.0, 4.0], 0.0, 5.0),  # an infeasible zero row
        ([1.0, 2.0], [[1.0, 1.0]], [4.0], [3.0, 0.0], [2.0, 1.0]),  # crossed bounds
        ([1.0, -2.0], np.zeros((0, 2)), [], [-1.0, -3.0], [2.0, 5.0]),  # no rows
        ([0.0, 0.0, -1.0], [[1.0, 1.0, 1.0], [-1.0, 0.0, 0.0]], [1.0, 0.0], -np.inf, np.inf),  # d = 3
        ([-1.0, -1.0], duplicated, np.zeros(24), -1.0, 1.0),  # degenerate: rows through one point
        fit_like(rng, 200),
    ]
    results = solve_lps(programmes)
    for batched, programme in zip(results, programmes):
        assert_same(batched, solve_lp(*programme))
    capped = solve_lps(programmes, max_iterations=2)
    for batched, programme in zip(capped, programmes):
        assert_same(batched, solve_lp(*programme, max_iterations=2))


def test_invalid_programmes_raise_as_solve_lp():
    with pytest.raises(ValueError):
        solve_lps([([1.0, 1.0], [[1.0, 1.0, 1.0]], [1.0], 0.0, 1.0)])
    with pytest.raises(ValueError):
        solve_lps([([1.0, np.nan], [[1.0, 1.0]], [1.0], 0.0, 1.0)])
    with pytest.raises(ValueError):
        solve_stacked(np.ones((2, 2)), np.ones((3, 2)), np.ones(3), np.array([1, 1]), np.zeros((2, 2)),
                      np.ones((2, 2)))


def _stacked(programmes: list) -> tuple:
    return (np.array([p[0] for p in programmes]), np.concatenate([p[1] for p in programmes]),
            np.concatenate([p[2] for p in programmes]), np.array([p[1].shape[0] for p in programmes]),
            np.array([p[3] for p in programmes]), np.array([p[4] for p in programmes]))


def _asking(batches: list):
    """A computation that asks for each of ``batches`` in turn and returns every answer."""
    answers = []
    for batch in batches:
        answers.append((yield batch))
    return answers


def test_solved_together_answers_each_as_alone():
    """The batches several computations ask for at the same turn are solved together (of
    the same number of unknowns; other sizes and shapes a batch cannot take apart), and
    each answer is the one the computation gets alone, bit for bit; an error is raised
    inside the computation that asked, as alone."""
    rng = np.random.default_rng(11)
    plans = [[_stacked([fit_like(rng, int(rng.integers(30, 300))) for _ in range(int(rng.integers(1, 9)))])
              for _ in range(int(rng.integers(1, 4)))] for _ in range(6)]
    three = (np.array([[0.0, 0.0, -1.0]]), np.array([[1.0, 1.0, 1.0], [-1.0, 0.0, 0.0]]), np.array([1.0, 0.0]),
             np.array([2]), np.full((1, 3), -np.inf), np.full((1, 3), np.inf))
    plans.append([three, plans[0][0]])  # d = 3 beside d = 4
    bad = (np.ones((2, 2)), np.ones((3, 2)), np.ones(3), np.array([1, 1]), np.zeros((2, 2)), np.ones((2, 2)))
    plans.append([plans[1][0], bad, plans[2][0]])  # raises ValueError at its second turn
    outcomes = solved_together([_asking(plan) for plan in plans])
    for plan, (answers, error, seconds) in zip(plans[:-1], outcomes):
        assert error is None and seconds >= 0
        alone = solved(_asking(plan))
        assert len(answers) == len(alone) == len(plan)
        for together, single in zip(answers, alone):
            for a, b in zip(together, single, strict=True):
                assert_same(a, b)
    answers, error, _ = outcomes[-1]
    assert answers is None and isinstance(error, ValueError)
    with pytest.raises(ValueError):
        solved(_asking(plans[-1]))
