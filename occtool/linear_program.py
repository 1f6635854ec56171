"""A dense dual simplex for small linear programmes with many rows.

The fit (``occtool.fit``) solves a few dozen programmes per model, each with 3 or 4
unknowns and a few hundred to a few thousand inequality rows. ``scipy.optimize.linprog``
spends almost all of its 2-4 ms per call on fixed overhead for such a shape; this module
solves them directly in numpy, in a small fraction of that time.

Problem::

    minimise    cost @ x
    subject to  A_ub @ x <= b_ub
                lower <= x <= upper          (either bound may be -inf / +inf)

Method (:func:`solve_lp`)
-------------------------
A *dual simplex over the rows*. Every row and every box bound is one inequality
``g @ x <= h``; the rows are normalised to unit Euclidean length (``h`` then measures a
distance in the units of ``x``), rows of (near) zero length are checked once and dropped.
A *basis* is a set of ``d`` inequalities held tight, defining the vertex
``x = N^-1 h_B`` (``N`` stacks their ``g``), and multipliers ``y = -N^-T cost`` with
``cost + N^T y = 0``. The basis is *dual feasible* when ``y >= 0``; it is optimal once the
vertex also satisfies every other inequality.

* Start: for every unknown the bound its cost pushes against (``lower`` for ``cost_j > 0``,
  ``upper`` for ``cost_j < 0``, a finite one for ``cost_j == 0``), which is dual feasible.
  An infinite bound is replaced by an *artificial* one at ``+-M``, ``M = 1e6 * S`` where
  ``S`` is the programme's scale (1, the largest finite bound and the largest row offset
  ``|b_i| / |a_i|``, whichever is largest).
* Iteration: the most violated inequality ``r`` (largest ``g_r @ x - h_r``, computed for all
  rows in one matrix product) enters; ``w = N^-T g_r``; the basic inequality ``k`` that leaves
  comes from a two-pass (Harris) ratio test on ``y_k / w_k`` over ``w_k > 0``, preferring the
  largest pivot ``w_k`` among the near-ties; ``N^-1`` is updated by the rank-one pivot formula
  and recomputed from scratch every 25 pivots and before any answer is returned. No entering
  candidate at all (no ``w_k > 0``) proves the programme infeasible (Farkas).
* Degeneracy: after ``max(10, 2 d)`` consecutive pivots that do not move the multipliers
  (``y_k`` of the leaving inequality within the dual tolerance, as with duplicated rows,
  rows through a common point or zero costs) the rule switches to Bland's (the smallest
  index among the violated inequalities enters, the smallest index among the exact ratio
  ties leaves), which cannot cycle, until a pivot makes progress again.
* Artificial bounds: if one is still tight at the optimum of the boxed programme with a
  positive multiplier, the objective would keep improving beyond it: a recession direction
  ``r`` (``A r <= 0``, ``r`` inside the sign pattern of the finite bounds, ``|r_j| <= 1``,
  ``cost @ r < 0``) is looked for with the same solver; if there is one the programme is
  unbounded (status 3), otherwise its optimum lies beyond ``M`` and the solve is repeated
  with ``M`` 1e4 times larger (twice at most, then status 4). An infeasibility proof that
  needs an artificial bound is treated the same way. An artificial bound tight with a zero
  multiplier (a flat direction of the optimum, e.g. a free unknown of zero cost) is released
  by a primal step along the flat edge until a real inequality blocks or the unknown
  reaches 0 (the value HiGHS gives a free nonbasic column), so ``x`` never holds ``+-M``.

Tolerances (relative; the rows are normalised, so they are independent of the rows' scale):

* primal feasibility: a row holds when ``a_i @ x - b_i <= 1e-9 * max(|a_i|, |b_i|)``
  (``|a_i|`` Euclidean), i.e. within ``1e-9`` of the row's distance from the origin or
  ``1e-9`` absolute in ``x``'s units, whichever is larger; a bound ``x_j >= l_j`` alike with
  ``1e-9 * max(1, |l_j|)``. Violations below ``1e-14 * max|x|`` count as rounding error
  (they matter only while ``x`` holds an artificial bound), and so do those of the basic
  inequalities, which hold by construction;
* dual feasibility: the ratio test keeps ``y >= -1e-9 * max|cost|`` (Harris); the same
  threshold decides whether a multiplier counts as zero (a degenerate pivot, an artificial
  bound that holds the optimum only by chance). A final basis whose refactorised ``y``
  falls below ``-1e-7 * max|cost|`` gives status 4 (never seen in the tests);
* pivots: ``w_k`` takes part in the ratio test when ``w_k > 1e-9 * max(1, max|w|)``;
* zero rows: ``|a_i| <= 1e-13 * max_i |a_i|``; such a row is infeasible when
  ``b_i < -1e-9 * max(1, max|b|)``, and dropped otherwise.

These are tighter than HiGHS's defaults (1e-7 absolute), so on programmes whose status
hinges on a margin between the two (a feasible region thinner than 1e-7) the answers may
differ; elsewhere they agree to rounding. Everything is deterministic: no random
perturbation, ties go to the lowest index.

Limits: meant for few unknowns (``d <= 10`` or so: every pivot costs ``O(m d)`` for the
violations plus ``O(d^2)``) and any number of rows; it does not scale the columns, so the
unknowns should have comparable magnitudes, as they do in the fit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["LinearProgramResult", "solve_lp", "split_bounds"]

#: scipy.optimize.linprog's status codes (an exhausted iteration cap is reported as 4).
OPTIMAL, INFEASIBLE, UNBOUNDED, NUMERICAL = 0, 2, 3, 4

PRIMAL_TOLERANCE = 1e-9
DUAL_TOLERANCE = 1e-9
PIVOT_TOLERANCE = 1e-9
ZERO_ROW = 1e-13
ARTIFICIAL_SCALE = 1e6
ARTIFICIAL_GROWTH = 1e4
ARTIFICIAL_RETRIES = 2
REFACTOR_EVERY = 25
#: Consecutive degenerate pivots (at least 2 d) before Bland's rule; 0: Bland's rule throughout.
DEGENERATE_PIVOTS = 10
FINAL_DUAL_TOLERANCE = 1e-7
ROUNDING = 1e-14

_MESSAGES = {
    OPTIMAL: "optimal",
    INFEASIBLE: "infeasible",
    UNBOUNDED: "unbounded",
    NUMERICAL: "numerical difficulties or iteration limit",
}


@dataclass(frozen=True)
class LinearProgramResult:
    """The outcome of :func:`solve_lp`.

    ``status`` follows ``scipy.optimize.linprog``: 0 optimal, 2 infeasible, 3 unbounded,
    4 numerical difficulties or iteration limit. ``x`` and ``fun`` (``cost @ x``) are set
    only when the status is 0, as scipy's HiGHS methods do. ``iterations`` counts simplex
    pivots, including those of any internal re-solve.
    """

    status: int
    x: NDArray[np.float64] | None
    fun: float | None
    iterations: int

    @property
    def success(self) -> bool:
        return self.status == OPTIMAL

    @property
    def message(self) -> str:
        return _MESSAGES.get(self.status, "unknown")


def split_bounds(
    bounds: Sequence[tuple[float | None, float | None]],
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``linprog``-style ``[(lower, upper), ...]`` (None for unbounded) as two arrays with +-inf."""
    lower = np.array([-np.inf if lo is None else float(lo) for lo, _ in bounds], dtype=float)
    upper = np.array([np.inf if hi is None else float(hi) for _, hi in bounds], dtype=float)
    return lower, upper


def solve_lp(
    cost: ArrayLike,
    A_ub: ArrayLike,
    b_ub: ArrayLike,
    lower: ArrayLike,
    upper: ArrayLike,
    *,
    max_iterations: int | None = None,
) -> LinearProgramResult:
    """Minimise ``cost @ x`` subject to ``A_ub @ x <= b_ub`` and ``lower <= x <= upper``.

    ``cost`` has ``d`` entries, ``A_ub`` is ``(m, d)`` (``m`` may be 0), ``b_ub`` has ``m``;
    ``lower`` and ``upper`` are scalars or ``d`` entries, ``-inf``/``+inf`` for no bound
    (:func:`split_bounds` converts ``linprog``'s list of pairs). A lower bound above its
    upper bound makes the programme infeasible. ``max_iterations`` caps the simplex pivots
    of each internal solve (default ``200 + 50 d``; reaching it gives status 4). The method
    and its tolerances are described in the module's docstring.

    Raises ``ValueError`` for inconsistent shapes, NaN or infinite data (other than the
    bounds), a lower bound of ``+inf`` or an upper bound of ``-inf``.
    """
    c = np.asarray(cost, dtype=float).ravel()
    d = c.size
    if d == 0:
        raise ValueError("the programme needs at least one unknown")
    A = np.asarray(A_ub, dtype=float)
    if A.size == 0:
        A = np.zeros((0, d))
    if A.ndim != 2 or A.shape[1] != d:
        raise ValueError(f"A_ub must have shape (m, {d}), got {A.shape}")
    b = np.asarray(b_ub, dtype=float).ravel()
    m = A.shape[0]
    if b.size != m:
        raise ValueError(f"b_ub must have {m} entries, got {b.size}")
    lo, hi = _bound_list(lower, d), _bound_list(upper, d)
    if not np.isfinite(c).all():
        raise ValueError("cost must be finite")
    if any(math.isnan(v) or v == math.inf for v in lo) or any(math.isnan(v) or v == -math.inf for v in hi):
        raise ValueError("bounds must not be NaN, a lower bound +inf or an upper bound -inf")
    if max_iterations is None:
        max_iterations = 200 + 50 * d
    if any(low > up for low, up in zip(lo, hi)):
        return LinearProgramResult(INFEASIBLE, None, None, 0)

    # The rows, transposed (a matrix-vector product is fastest that way round) and of unit
    # length; (near) zero rows are settled here.
    At = np.ascontiguousarray(A.T)
    norms = np.sqrt(np.einsum("ij,ij->j", At, At))
    if m:
        if not (math.isfinite(float(norms.sum())) and math.isfinite(float(b.sum()))):
            if not (np.isfinite(A).all() and np.isfinite(b).all()):
                raise ValueError("A_ub and b_ub must be finite")
            # Entries so large that their squares overflow: scale each row first.
            peak = np.abs(At).max(axis=0)
            peak[peak == 0.0] = 1.0
            norms = peak * np.sqrt(np.einsum("ij,ij->j", At / peak, At / peak))
        top = float(norms.max())
        if float(norms.min()) <= ZERO_ROW * top:
            zero = norms <= ZERO_ROW * top
            if (b[zero] < -PRIMAL_TOLERANCE * max(1.0, float(np.abs(b).max()))).any():
                return LinearProgramResult(INFEASIBLE, None, None, 0)
            keep = ~zero
            At, b, norms = np.ascontiguousarray(At[:, keep]), b[keep], norms[keep]
            m = b.size
    # G^T: the rows, then -I (lower bounds) and I (upper bounds), and a last row for -h.
    Gt = np.empty((d + 1, m + 2 * d))
    np.divide(At, norms, out=Gt[:d, :m])
    Gt[:d, m:] = _bound_block(d)
    b = b / norms

    finite = [abs(v) for v in lo + hi if math.isfinite(v)]
    scale = max(1.0, float(np.abs(b).max()) if m else 0.0, *finite)
    big = ARTIFICIAL_SCALE * scale
    iterations = 0
    for _ in range(ARTIFICIAL_RETRIES + 1):
        outcome, x, its = _solve_boxed(c, Gt, b, lo, hi, big, max_iterations)
        iterations += its
        if outcome == _ARTIFICIAL_TIGHT:
            # Does the objective keep improving along a ray of the programme?
            ray_status, ray, its = _solve_boxed(
                c, Gt.copy(), np.zeros(m),
                [0.0 if math.isfinite(v) else -1.0 for v in lo],
                [0.0 if math.isfinite(v) else 1.0 for v in hi],
                big, max_iterations,
            )
            iterations += its
            if ray_status != OPTIMAL or ray is None:
                return LinearProgramResult(NUMERICAL, None, None, iterations)
            if float(c @ ray) < -DUAL_TOLERANCE * float(np.abs(c).max()):
                return LinearProgramResult(UNBOUNDED, None, None, iterations)
            outcome = _BEYOND_BOX
        if outcome == _BEYOND_BOX:
            big *= ARTIFICIAL_GROWTH
            continue
        if outcome == OPTIMAL and x is not None:
            return LinearProgramResult(OPTIMAL, x, float(c @ x), iterations)
        return LinearProgramResult(outcome, None, None, iterations)
    return LinearProgramResult(NUMERICAL, None, None, iterations)


def _bound_list(bound: ArrayLike, d: int) -> list[float]:
    values = np.asarray(bound, dtype=float)
    if values.ndim == 0:
        return [float(values)] * d
    if values.shape != (d,):
        raise ValueError(f"bounds must be scalars or have {d} entries, got shape {values.shape}")
    return values.tolist()


_BOUND_BLOCKS: dict[int, NDArray[np.float64]] = {}


def _bound_block(d: int) -> NDArray[np.float64]:
    """``[-I, I]``, the bounds' columns of ``G^T`` (cached: it is the same for every call)."""
    block = _BOUND_BLOCKS.get(d)
    if block is None:
        block = _BOUND_BLOCKS[d] = np.hstack([-np.eye(d), np.eye(d)])
        block.flags.writeable = False
    return block


# Internal outcomes of one boxed solve, besides scipy's codes.
_BEYOND_BOX = -1  # an infeasibility proof leans on an artificial bound
_ARTIFICIAL_TIGHT = -2  # an artificial bound holds the optimum with a positive multiplier


def _solve_boxed(
    c: NDArray[np.float64],
    Gt: NDArray[np.float64],
    b: NDArray[np.float64],
    lo: list[float],
    hi: list[float],
    big: float,
    max_iterations: int,
) -> tuple[int, NDArray[np.float64] | None, int]:
    """Dual simplex on unit rows ``A x <= b`` and the box, infinite bounds made ``+-big``.

    ``Gt`` holds ``[A, -I, I]^T`` in its first ``d`` rows; its last row is written here.
    Returns the outcome, ``x`` when optimal, and the number of pivots.
    """
    d = c.size
    m = b.size
    n = m + 2 * d
    art_lo = [not math.isfinite(v) for v in lo]
    art_hi = [not math.isfinite(v) for v in hi]
    h = np.empty(n)
    h[:m] = b
    h[m:] = [big if a else -v for v, a in zip(lo, art_lo)] + [big if a else v for v, a in zip(hi, art_hi)]
    # The last row of G^T: -(h + tolerance), tolerance = PRIMAL_TOLERANCE * max(1, |h|).
    row = Gt[d]
    np.abs(h, out=row)
    np.maximum(row, 1.0, out=row)
    row *= -PRIMAL_TOLERANCE
    row -= h

    # The starting basis: the bound each cost pushes against (N = diag(sign), N^-1 = N).
    cl = c.tolist()
    use_upper = [cj < 0 or (cj == 0 and ah is False and al is True) for cj, al, ah in zip(cl, art_lo, art_hi)]
    sign = np.array([1.0 if u else -1.0 for u in use_upper])
    basis = np.array([m + d + j if u else m + j for j, u in enumerate(use_upper)], dtype=np.intp)
    x = sign * h[basis]
    y = (-sign * c).tolist()

    state = _DualSimplex(Gt, h, c, basis, np.diag(sign), x, y)
    status = state.run(max_iterations)
    if status == INFEASIBLE or (status == OPTIMAL and state.artificial_in_basis(m)):
        artificial = np.zeros(n, dtype=bool)
        artificial[m:] = art_lo + art_hi
    if status == INFEASIBLE:
        # A Farkas proof g_r = N^T w, w <= 0: genuine only without artificial bounds.
        assert state.proof is not None
        if (artificial[state.basis] & (state.proof < -PIVOT_TOLERANCE)).any():
            return _BEYOND_BOX, None, state.iterations
    if status != OPTIMAL:
        return status, None, state.iterations
    if state.artificial_in_basis(m):
        in_basis = artificial[state.basis]
        if in_basis.any():
            if (np.array(state.y)[in_basis] > state.tol_d).any():
                return _ARTIFICIAL_TIGHT, None, state.iterations
            state.release_artificial(artificial)
    return OPTIMAL, state.x, state.iterations


class _DualSimplex:
    """The basis, its inverse and multipliers, and the pivoting loop.

    ``Gt`` is ``(d + 1, n)``: the ``n`` inequalities ``g @ x <= h`` as columns over a last row
    ``-(h + tolerance)``, so that ``x1 @ Gt`` with ``x1 = [x, 1]`` is every inequality's
    violation beyond its tolerance in one product. The multipliers ``y`` are a list: with
    a handful of unknowns, plain floats are quicker than numpy's per-call overhead.
    """

    def __init__(
        self,
        Gt: NDArray[np.float64],
        h: NDArray[np.float64],
        c: NDArray[np.float64],
        basis: NDArray[np.intp],
        Binv: NDArray[np.float64],
        x: NDArray[np.float64],
        y: list[float],
    ) -> None:
        self.Gt, self.h, self.c = Gt, h, c
        self.d = d = c.size
        self.basis = basis.copy()
        self.Binv = Binv
        self.x1 = np.empty(d + 1)
        self.x1[:d] = x
        self.x1[d] = 1.0
        self.y = y
        cmax = float(np.abs(c).max())
        self.tol_d = DUAL_TOLERANCE * cmax
        self.final_tol_d = FINAL_DUAL_TOLERANCE * cmax
        self.iterations = 0
        self.since_refactor = 0
        self.proof: NDArray[np.float64] | None = None

    def artificial_in_basis(self, m: int) -> bool:
        """Whether a bound (perhaps artificial) is basic: ``m`` is the number of rows."""
        return bool((self.basis >= m).any())

    @property
    def x(self) -> NDArray[np.float64]:
        return self.x1[: self.d].copy()

    def refactor(self) -> bool:
        """``N^-1``, ``y`` and ``x`` afresh from the basis; False if ``N`` is singular."""
        N = self.Gt[: self.d, self.basis].T
        try:
            Binv = np.linalg.inv(N)
        except np.linalg.LinAlgError:
            return False
        h_B = self.h[self.basis]
        x = Binv @ h_B
        x += Binv @ (h_B - N @ x)  # one step of iterative refinement
        if not math.isfinite(float(x.sum() + Binv.sum())):
            return False
        self.Binv = Binv
        self.y = (-(self.c @ Binv)).tolist()
        self.x1[: self.d] = x
        self.since_refactor = 0
        return True

    def run(self, max_iterations: int) -> int:
        """Pivot until optimal, infeasible (``proof`` set), out of pivots or singular."""
        Gt, h = self.Gt, self.h
        d = self.d
        x1 = self.x1
        x = x1[:d]
        tol_d = self.tol_d
        degenerate_limit = max(DEGENERATE_PIVOTS, 2 * d) if DEGENERATE_PIVOTS > 0 else 0
        degenerate_run = 0
        bland = degenerate_limit == 0
        while True:
            slack = x1 @ Gt  # violations beyond tolerance
            # The basic inequalities hold by construction: what they show is rounding error,
            # as is anything below ROUNDING * |x| (large while artificial bounds are basic).
            slack[self.basis] = -math.inf
            floor = ROUNDING * max(map(abs, x.tolist()))
            if bland:
                violated = np.flatnonzero(slack > floor)
                r = int(violated[0]) if violated.size else -1
            else:
                r = int(slack.argmax())
                if slack[r] <= floor:
                    r = -1
            if r < 0:
                if self.since_refactor:
                    if not self.refactor():
                        return NUMERICAL
                    continue
                if min(self.y) < -self.final_tol_d:
                    return NUMERICAL
                return OPTIMAL
            if self.iterations >= max_iterations:
                return NUMERICAL
            w = Gt[:d, r] @ self.Binv  # N^-T g_r: g_r in terms of the basic inequalities
            wl = w.tolist()
            y = self.y
            ptol = PIVOT_TOLERANCE * max(1.0, max(wl), -min(wl))
            # Ratio test over w_i > 0: Harris's bound with the dual tolerance, then the largest
            # pivot within it (Bland: the exact minimum ratio, lowest index among ties).
            bound = math.inf
            for i in range(d):
                wi = wl[i]
                if wi > ptol:
                    q = ((y[i] if y[i] > 0.0 else 0.0) if bland else y[i] + tol_d) / wi
                    if q < bound:
                        bound = q
            if bound == math.inf:
                if self.since_refactor:
                    if not self.refactor():
                        return NUMERICAL
                    continue
                self.proof = w
                return INFEASIBLE
            k = -1
            if bland:
                basis = self.basis
                for i in range(d):
                    wi = wl[i]
                    if wi > ptol and (y[i] if y[i] > 0.0 else 0.0) / wi <= bound and (k < 0 or basis[i] < basis[k]):
                        k = i
            else:
                best = 0.0
                for i in range(d):
                    wi = wl[i]
                    if wi > ptol and y[i] / wi <= bound and wi > best:
                        best, k = wi, i
            wk = wl[k]
            yk = y[k]
            t = yk / wk if yk > 0.0 else 0.0
            # Multipliers: y - t w on the basis, t for the entering inequality.
            y = [yi - t * wi for yi, wi in zip(y, wl)]
            y[k] = t
            self.y = y
            # N^-1 after replacing row k of N by g_r; column k of it is the edge along
            # which the vertex moves (the other basic inequalities stay tight) until r is.
            Binv = self.Binv
            col = Binv[:, k] / wk
            Binv -= np.multiply.outer(col, w)
            Binv[:, k] = col
            hr = float(h[r])
            col *= float(slack[r]) + PRIMAL_TOLERANCE * max(1.0, abs(hr))  # the violation
            x -= col
            self.basis[k] = r
            self.iterations += 1
            self.since_refactor += 1
            if self.since_refactor >= REFACTOR_EVERY and not self.refactor():
                return NUMERICAL
            # A degenerate pivot leaves the multipliers (and the dual objective) where they were.
            degenerate_run = degenerate_run + 1 if yk <= tol_d else 0
            bland = degenerate_run >= degenerate_limit

    def release_artificial(self, artificial: NDArray[np.bool_]) -> None:
        """Step off artificial bounds held with zero multipliers, along the flat edges.

        The objective changes by at most the dual tolerance times the step.
        """
        d = self.d
        G = self.Gt[:d].T
        h = self.h
        for _ in range(2 * d):
            self.refactor()
            positions = np.flatnonzero(artificial[self.basis])
            if positions.size == 0:
                return
            k = int(positions[0])
            # Direction q keeps the other basic inequalities tight and loosens k: g_k q = -1.
            q = -self.Binv[:, k]
            x = self.x
            rate = G @ q
            slack = h - G @ x
            blocking = np.flatnonzero((rate > PIVOT_TOLERANCE) & ~artificial)
            j = int(np.flatnonzero(G[self.basis[k]])[0])
            to_zero = abs(float(x[j]))  # the unknown moves at unit rate towards 0
            if blocking.size:
                steps = np.maximum(slack[blocking], 0.0) / rate[blocking]
                i = int(np.argmin(steps))
                if steps[i] <= to_zero:
                    self.basis[k] = int(blocking[i])
                    continue
            # No real inequality in the way: rest the unknown at 0, a pseudo-bound.
            self.x1[:d] = x + to_zero * q
            artificial[self.basis[k]] = False
            h[self.basis[k]] = float(G[self.basis[k]] @ self.x1[:d])
        self.refactor()
