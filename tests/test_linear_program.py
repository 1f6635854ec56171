"""Tests of occtool.linear_program.solve_lp, the dense dual simplex for the fit's programmes.

References: scipy.optimize.linprog (HiGHS). HiGHS's presolve reports some unbounded
programmes as infeasible (its "infeasible or unbounded"); an infeasible answer from it is
therefore confirmed with the presolve off, which tells the two apart.
"""

from __future__ import annotations

from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog

import occtool.linear_program as lp
from occtool.linear_program import LinearProgramResult, solve_lp, split_bounds

# Ten of the twenty programmes of one fit (programmes 0, 3, 4, 7, 9, 10, 11, 14, 15 and 16,
# in the order solved), captured from OccupancyRegressor().fit on
# simulate_scene('office', n_features=10000, seed=1), with scipy's answers
# (linprog(method="highs-ds", options={"presolve": False})). Three are infeasible: the fit
# then retries with fewer rows, which is the programme after each.
CAPTURED = Path(__file__).resolve().parent.parent / "fixtures" / "lp" / "captured.npz"


def load_captured() -> list[dict]:
    data = np.load(CAPTURED)
    programmes = []
    for n in range(int(data["count"])):
        p = {key: data[f"p{n}_{key}"] for key in ("c", "b", "lower", "upper", "status", "x", "fun", "index")}
        p["A"] = data[f"A{int(data[f'p{n}_matrix'])}"]
        programmes.append(p)
    return programmes


def scipy_bounds(lower: np.ndarray, upper: np.ndarray) -> list[tuple[float | None, float | None]]:
    return [(None if np.isinf(lo) else float(lo), None if np.isinf(hi) else float(hi)) for lo, hi in zip(lower, upper)]


def reference(c, A, b, lower, upper):
    """scipy's answer; an infeasible one confirmed without presolve (see the module docstring)."""
    kwargs = dict(A_ub=A if len(A) else None, b_ub=b if len(A) else None, bounds=scipy_bounds(lower, upper))
    result = linprog(c, method="highs", **kwargs)
    if result.status == 2:
        result = linprog(c, method="highs", options={"presolve": False}, **kwargs)
    return result


def assert_feasible(x, A, b, lower, upper, rtol=1e-8):
    x = np.asarray(x)
    assert np.all(np.isfinite(x))
    if len(A):
        slack = A @ x - b
        allowed = rtol * (1.0 + np.abs(b) + np.abs(A) @ np.abs(x))
        assert np.all(slack <= allowed), f"row violated by {float((slack - allowed).max())}"
    assert np.all(x >= lower - rtol * (1.0 + np.abs(np.where(np.isfinite(lower), lower, 0.0))))
    assert np.all(x <= upper + rtol * (1.0 + np.abs(np.where(np.isfinite(upper), upper, 0.0))))


def unique_optimum(c, A, b, lower, upper) -> bool:
    """Whether the optimal point is unique, from scipy's multipliers: every inequality with a
    nonzero multiplier is tight at every optimal point (complementary slackness), so if their
    normals span all unknowns, the optimum is one point."""
    ref = linprog(c, A_ub=A, b_ub=b, bounds=scipy_bounds(lower, upper), method="highs-ds")
    assert ref.status == 0
    threshold = 1e-9 * max(1.0, float(np.abs(c).max()))
    eye = np.eye(len(c))
    normals = [A[np.abs(ref.ineqlin.marginals) > threshold]]
    normals.append(eye[np.abs(ref.lower.marginals) > threshold])
    normals.append(eye[np.abs(ref.upper.marginals) > threshold])
    tight = np.vstack(normals)
    return bool(tight.shape[0] >= len(c) and np.linalg.matrix_rank(tight, tol=1e-9 * np.abs(tight).max()) == len(c))


# --- the captured programmes -------------------------------------------------------------


@pytest.mark.parametrize("n", range(10))
def test_captured_programme_matches_scipy(n):
    p = load_captured()[n]
    c, A, b, lower, upper = p["c"], p["A"], p["b"], p["lower"], p["upper"]
    result = solve_lp(c, A, b, lower, upper)
    assert result.status == int(p["status"])
    if result.status != 0:
        assert result.x is None and result.fun is None
        return
    fun = float(p["fun"])
    assert result.fun == pytest.approx(fun, rel=1e-10, abs=1e-12)
    assert result.fun == pytest.approx(float(c @ result.x), rel=1e-14, abs=1e-14)
    assert_feasible(result.x, A, b, lower, upper, rtol=1e-10)
    # Where the optimum is one point (all of these, as it happens), x is scipy's x.
    assert unique_optimum(c, A, b, lower, upper), f"programme {int(p['index'])}: optimum not unique"
    np.testing.assert_allclose(result.x, p["x"], rtol=1e-9, atol=1e-10)


def test_captured_programmes_are_the_fits_shape():
    """Guard on the fixture itself: 4 unknowns, one free, and hundreds of rows."""
    programmes = load_captured()
    assert [int(p["status"]) for p in programmes] == [0, 2, 0, 0, 0, 2, 0, 0, 2, 0]
    for p in programmes:
        assert p["A"].shape[1] == 4 and p["A"].shape[0] >= 100
        assert np.isinf(p["lower"][0]) and np.isinf(p["upper"][0])
        assert np.isfinite(p["lower"][1:]).all() and np.isfinite(p["upper"][1:]).all()


def test_captured_programmes_are_deterministic():
    for p in load_captured()[:4]:
        first = solve_lp(p["c"], p["A"], p["b"], p["lower"], p["upper"])
        second = solve_lp(p["c"], p["A"].copy(), p["b"].copy(), p["lower"], p["upper"])
        assert first.status == second.status and first.iterations == second.iterations
        if first.x is not None:
            assert np.array_equal(first.x, second.x)


# --- small programmes with known answers -------------------------------------------------


def test_textbook_vertex():
    # max x + y  s.t.  x + 2y <= 4, 3x + y <= 6, x, y >= 0: the vertex (8/5, 6/5).
    result = solve_lp([-1.0, -1.0], [[1.0, 2.0], [3.0, 1.0]], [4.0, 6.0], 0.0, np.inf)
    assert result.status == 0 and result.success and result.message == "optimal"
    np.testing.assert_allclose(result.x, [1.6, 1.2], rtol=1e-14)
    assert result.fun == pytest.approx(-2.8, rel=1e-14)


def test_box_only_optimum_is_a_corner():
    result = solve_lp([1.0, -2.0], np.zeros((0, 2)), [], [-1.0, -3.0], [2.0, 5.0])
    assert result.status == 0 and result.iterations == 0
    np.testing.assert_array_equal(result.x, [-1.0, 5.0])
    assert result.fun == -11.0


def test_free_unknowns_meet_at_a_v():
    # min y  s.t.  y >= x, y >= -x (both free): the apex (0, 0).
    result = solve_lp([0.0, 1.0], [[1.0, -1.0], [-1.0, -1.0]], [0.0, 0.0], -np.inf, np.inf)
    assert result.status == 0
    np.testing.assert_allclose(result.x, [0.0, 0.0], atol=1e-12)
    assert result.fun == pytest.approx(0.0, abs=1e-12)


def test_free_unknown_without_cost_rests_finite():
    # x has no cost and no row pins it: any x is optimal; the answer must not be the
    # artificial bound (1e6 * scale) but a finite, HiGHS-like 0.
    result = solve_lp([0.0, 1.0], [[0.0, -1.0]], [-2.0], -np.inf, np.inf)
    assert result.status == 0
    np.testing.assert_allclose(result.x, [0.0, 2.0], atol=1e-12)
    # x <= -5: on its way back from the artificial bound at -1e6, x stops at the row.
    result = solve_lp([0.0, 1.0], [[0.0, -1.0], [1.0, 0.0]], [-2.0, -5.0], -np.inf, np.inf)
    assert result.status == 0
    np.testing.assert_allclose(result.x, [-5.0, 2.0], rtol=1e-12)
    assert result.fun == pytest.approx(2.0, rel=1e-12)


def test_degenerate_pencil_of_rows():
    # Many rows through (1, 1), duplicated and scaled: max x + y is at (1, 1) exactly.
    rows = np.array([[1.0, 1.0], [1.0, 0.0], [0.0, 1.0], [2.0, 1.0], [1.0, 2.0], [3.0, 3.0]])
    A = np.vstack([rows, rows, 2.0 * rows])
    b = A @ np.array([1.0, 1.0])
    result = solve_lp([-1.0, -1.0], A, b, -np.inf, np.inf)
    assert result.status == 0
    np.testing.assert_allclose(result.x, [1.0, 1.0], rtol=1e-12)
    assert result.fun == pytest.approx(-2.0, rel=1e-12)


def test_parallel_rows_keep_the_tighter_one():
    A = np.array([[0.0, 1.0], [0.0, 2.0], [0.0, 1.0], [0.0, 0.5]])
    b = np.array([3.0, 4.0, 2.5, 2.0])  # y <= 3, y <= 2, y <= 2.5, y <= 4
    result = solve_lp([0.0, -1.0], A, b, [0.0, -np.inf], [1.0, np.inf])
    assert result.status == 0
    assert result.x[1] == pytest.approx(2.0, rel=1e-14)


def test_equal_bounds_fix_an_unknown():
    result = solve_lp([1.0, 1.0], [[-1.0, -1.0]], [-3.0], [2.0, -np.inf], [2.0, np.inf])
    assert result.status == 0
    np.testing.assert_allclose(result.x, [2.0, 1.0], rtol=1e-14)


def test_infeasible_strip():
    # x >= 2 and x <= 1.
    result = solve_lp([1.0, 0.0], [[-1.0, 0.0], [1.0, 0.0]], [-2.0, 1.0], -np.inf, np.inf)
    assert result.status == 2 and result.x is None and result.fun is None
    assert not result.success


def test_infeasible_bounds_and_zero_rows():
    assert solve_lp([1.0], [[1.0]], [1.0], [2.0], [1.0]).status == 2  # lower > upper
    assert solve_lp([1.0, 1.0], [[0.0, 0.0]], [-1.0], 0.0, 1.0).status == 2  # 0 <= -1
    # A zero row that holds is dropped.
    result = solve_lp([1.0, 1.0], [[0.0, 0.0], [-1.0, -1.0]], [1.0, -1.0], 0.0, 1.0)
    assert result.status == 0 and result.fun == pytest.approx(1.0)


def test_unbounded_ray():
    # min -x  s.t.  y <= 1, x - y <= 5 (x free, y >= 0): x is capped at 6; without the
    # second row the ray x -> inf is left.
    bounded = solve_lp([-1.0, 0.0], [[0.0, 1.0], [1.0, -1.0]], [1.0, 5.0], [-np.inf, 0.0], np.inf)
    assert bounded.status == 0 and bounded.fun == pytest.approx(-6.0)
    unbounded = solve_lp([-1.0, 0.0], [[0.0, 1.0]], [1.0], [-np.inf, 0.0], np.inf)
    assert unbounded.status == 3 and unbounded.x is None and unbounded.message == "unbounded"
    # Unbounded along a direction no single unknown gives: (x, y) -> (t, t).
    diagonal = solve_lp([-1.0, -1.0], [[1.0, -1.0], [-1.0, 1.0]], [1.0, 1.0], -np.inf, np.inf)
    assert diagonal.status == 3


def test_infeasibility_beats_unboundedness():
    # The ray x -> -inf exists, but y cannot satisfy its rows: infeasible, as scipy says.
    result = solve_lp([1.0, 0.0], [[0.0, 1.0], [0.0, -1.0]], [-1.0, 0.0], -np.inf, np.inf)
    assert result.status == 2


@pytest.mark.parametrize("delta", [1e-3, 1e-7])
def test_optimum_beyond_the_artificial_box(delta):
    # Two nearly parallel rows meet at (2/delta + 1, 2/delta); with delta = 1e-7 that is
    # beyond the first artificial box (1e6) and needs the larger one.
    A = np.array([[1.0, -1.0], [-1.0, 1.0 + delta]])
    result = solve_lp([-1.0, -1.0], A, [1.0, 1.0], -np.inf, np.inf)
    assert result.status == 0
    x1 = 2.0 / delta
    np.testing.assert_allclose(result.x, [x1 + 1.0, x1], rtol=1e-7)


def test_no_rows_and_scalar_bounds():
    result = solve_lp([1.0, 2.0, -1.0], np.empty((0, 3)), np.empty(0), -1.0, 1.0)
    assert result.status == 0
    np.testing.assert_array_equal(result.x, [-1.0, -1.0, 1.0])
    assert solve_lp([1.0], np.empty((0, 1)), [], -np.inf, np.inf).status == 3


def test_iteration_cap_gives_status_4():
    p = load_captured()[0]
    result = solve_lp(p["c"], p["A"], p["b"], p["lower"], p["upper"], max_iterations=2)
    assert result.status == 4 and result.x is None and result.iterations == 2


def test_invalid_input_raises():
    with pytest.raises(ValueError):
        solve_lp([1.0, 1.0], [[1.0, 1.0, 1.0]], [1.0], 0.0, 1.0)
    with pytest.raises(ValueError):
        solve_lp([1.0, 1.0], [[1.0, 1.0]], [1.0, 2.0], 0.0, 1.0)
    with pytest.raises(ValueError):
        solve_lp([1.0, np.nan], [[1.0, 1.0]], [1.0], 0.0, 1.0)
    with pytest.raises(ValueError):
        solve_lp([1.0, 1.0], [[1.0, np.inf]], [1.0], 0.0, 1.0)
    with pytest.raises(ValueError):
        solve_lp([1.0, 1.0], [[1.0, 1.0]], [np.nan], 0.0, 1.0)
    with pytest.raises(ValueError):
        solve_lp([1.0, 1.0], [[1.0, 1.0]], [1.0], [np.inf, 0.0], 1.0)
    with pytest.raises(ValueError):
        solve_lp([1.0, 1.0], [[1.0, 1.0]], [1.0], 0.0, [1.0, 2.0, 3.0])
    with pytest.raises(ValueError):
        solve_lp([], np.empty((0, 0)), [], 0.0, 1.0)


def test_huge_entries_are_normalised_not_overflowed():
    # Squares of 1e200 overflow; the row is still x + y <= 1 after normalisation.
    result = solve_lp([-1.0, -1.0], [[1e200, 1e200]], [1e200], 0.0, np.inf)
    assert result.status == 0 and result.fun == pytest.approx(-1.0)


def test_split_bounds():
    lower, upper = split_bounds([(None, None), (-0.5, 0.0), (1.0, None)])
    np.testing.assert_array_equal(lower, [-np.inf, -0.5, 1.0])
    np.testing.assert_array_equal(upper, [np.inf, 0.0, np.inf])


def test_result_is_frozen():
    result = solve_lp([1.0], [[1.0]], [1.0], 0.0, 1.0)
    assert isinstance(result, LinearProgramResult)
    with pytest.raises(AttributeError):
        result.status = 2  # type: ignore[misc]


# --- random programmes against scipy -----------------------------------------------------


@st.composite
def programmes(draw, max_rows: int = 300):
    """Random programmes of several kinds, many degenerate. The bulk numbers come from a
    seeded numpy generator (drawing hundreds of floats one by one is slow in hypothesis);
    the structure (sizes, kinds, bound patterns, where the degeneracies go) is drawn."""
    d = draw(st.integers(1, 6))
    m = draw(st.integers(1, max_rows))
    kind = draw(st.sampled_from(["gaussian", "integer", "pencil", "polytope", "scaled"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    centre = rng.integers(-2, 3, size=d).astype(float) if draw(st.booleans()) else rng.normal(size=d)
    if kind == "gaussian":
        A = rng.normal(size=(m, d))
        b = A @ centre + rng.uniform(0.0, 2.0, size=m)
    elif kind == "integer":  # small integers: parallel rows, ties, exact degeneracy
        A = rng.integers(-2, 3, size=(m, d)).astype(float)
        b = rng.integers(-2, 4, size=m).astype(float)
    elif kind == "pencil":  # every row through one point
        A = rng.integers(-3, 4, size=(m, d)).astype(float)
        b = A @ centre
    elif kind == "polytope":  # a point strictly inside, some rows through it
        A = rng.normal(size=(m, d))
        b = A @ centre + np.where(rng.random(m) < 0.3, 0.0, rng.uniform(0.0, 1.0, size=m))
    else:  # rows and offsets over six orders of magnitude
        A = rng.normal(size=(m, d)) * 10.0 ** rng.uniform(-3, 3, size=(m, 1))
        b = (A @ centre) + np.abs(rng.normal(size=m)) * 10.0 ** rng.uniform(-3, 3, size=m)
    if draw(st.booleans()):  # duplicated and positively scaled rows
        copies = rng.integers(0, m, size=draw(st.integers(1, max(1, m // 2))))
        factor = rng.choice([1.0, 2.0, 0.5], size=copies.size)
        A = np.vstack([A, A[copies] * factor[:, None]])
        b = np.concatenate([b, b[copies] * factor])
    if draw(st.booleans()):  # zero rows that hold
        zero = rng.random(A.shape[0]) < 0.2
        A[zero] = 0.0
        b[zero] = np.abs(b[zero])
    if draw(st.booleans()):  # an infeasible pair: a x <= t and a x >= t + gap
        a = rng.normal(size=d)
        t = float(a @ centre)
        A = np.vstack([A, a, -a])
        b = np.concatenate([b, [t, -(t + draw(st.sampled_from([0.1, 1.0])))]])
    pattern = draw(st.lists(st.sampled_from(["free", "lower", "upper", "box", "fixed"]), min_size=d, max_size=d))
    lower = np.full(d, -np.inf)
    upper = np.full(d, np.inf)
    for j, kind_j in enumerate(pattern):
        width = float(rng.integers(0, 4)) if draw(st.booleans()) else float(rng.uniform(0.0, 3.0))
        if kind_j in ("lower", "box"):
            lower[j] = centre[j] - width
        if kind_j in ("upper", "box"):
            upper[j] = centre[j] + width
        if kind_j == "fixed":
            lower[j] = upper[j] = centre[j]
    cost_kind = draw(st.sampled_from(["gaussian", "integer", "sparse"]))
    if cost_kind == "gaussian":
        c = rng.normal(size=d)
    elif cost_kind == "integer":
        c = rng.integers(-2, 3, size=d).astype(float)
    else:
        c = np.where(rng.random(d) < 0.5, 0.0, rng.normal(size=d))
    return c, A, b, lower, upper


def check_against_scipy(c, A, b, lower, upper):
    ref = reference(c, A, b, lower, upper)
    assume(ref.status in (0, 2, 3))
    result = solve_lp(c, A, b, lower, upper)
    assert result.status == ref.status, (result, ref.message)
    if result.status == 0:
        assert result.fun == pytest.approx(ref.fun, rel=1e-7, abs=1e-7)
        assert_feasible(result.x, A, b, lower, upper)
    else:
        assert result.x is None and result.fun is None
    return result, ref


@pytest.mark.slow
@settings(max_examples=200)
@given(programmes())
def test_random_programmes_match_scipy(programme):
    check_against_scipy(*programme)


@settings(max_examples=80)
@given(programmes(max_rows=60))
def test_random_programmes_with_blands_rule_throughout(programme):
    """The anti-cycling rule alone (as if every pivot had been degenerate), refactorising
    after every pivot: the slow paths give the same answers."""
    with mock.patch.object(lp, "DEGENERATE_PIVOTS", 0), mock.patch.object(lp, "REFACTOR_EVERY", 1):
        check_against_scipy(*programme)


@settings(max_examples=40)
@given(st.integers(1, 6), st.integers(1, 300), st.integers(0, 2**32 - 1))
def test_random_unique_optimum_is_scipys(d, m, seed):
    """Generic (non-degenerate) programmes have one optimal point: the same as scipy's."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(m, d))
    b = rng.uniform(0.1, 2.0, size=m)
    lower = np.where(rng.random(d) < 0.5, -np.inf, -rng.uniform(0.5, 3.0, size=d))
    upper = np.where(rng.random(d) < 0.5, np.inf, rng.uniform(0.5, 3.0, size=d))
    c = rng.normal(size=d)
    result, ref = check_against_scipy(c, A, b, lower, upper)
    if result.status == 0:
        assume(unique_optimum(c, A, b, lower, upper))
        np.testing.assert_allclose(result.x, ref.x, rtol=1e-7, atol=1e-8)


@settings(max_examples=40)
@given(st.integers(1, 8), st.integers(0, 2**32 - 1))
def test_unbounded_and_free_programmes(d, seed):
    """Few rows and free unknowns: unbounded ones, and bounded ones whose free unknowns of
    zero cost must come back finite."""
    rng = np.random.default_rng(seed)
    m = int(rng.integers(1, 2 * d + 2))
    A = rng.integers(-2, 3, size=(m, d)).astype(float)
    b = rng.integers(0, 3, size=m).astype(float)
    c = np.where(rng.random(d) < 0.3, 0.0, rng.integers(-2, 3, size=d).astype(float))
    free = rng.random(d) < 0.6
    lower = np.where(free, -np.inf, -1.0)
    upper = np.where(free, np.inf, 1.0)
    result, _ = check_against_scipy(c, A, b, lower, upper)
    if result.status == 0:
        assert np.abs(result.x).max() < 1e5
