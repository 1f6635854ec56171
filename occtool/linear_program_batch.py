"""Many small linear programmes at once: :func:`solve_lps`, :func:`solve_lp`'s answers in a batch.

A fit places a few dozen centre pieces, each by its own programme of 3 or 4 unknowns and
a few dozen to a few hundred rows (``occtool.fit._construction``). One by one, each took
about 0.25 ms of :func:`~occtool.linear_program.solve_lp`, nearly all of it Python's
overhead around a dozen pivots on tiny arrays. Here the programmes of one call are
stacked (padded to the most inequalities) and every step of ``solve_lp``'s dual simplex
(its module docstring describes the method) is taken in all of them at once, with the
same rules and tolerances: the same entering and leaving inequalities, so the same final
basis in the same order, and the vertex is computed from it by the same operations
(``np.linalg.inv`` and the same products, one matrix at a time): the same bits.

One product differs: the violations of a step (``x1 @ Gt``) come from one stacked
product, whose last bit may differ from the product of a single programme where BLAS
splits the row blocks differently. That moves the intermediate vertex by a rounding
error and can change a choice only between two inequalities whose violations tie within
it; the answer would then be another optimal vertex within the tolerances. It has not
happened on the ~72,000 programmes of the Freiburg campus map's 1571 keyframes (the same
coefficients) nor on the Intel lab's 900 positions (the same model files).

Cost: a batch costs about its count of steps (the most pivots any of its programmes takes,
a dozen or so) times some 40 numpy operations, nearly independent of its width: 64
programmes of the campus in ~46 us each against ``solve_lp``'s ~230 us.

Whatever leaves the common path is solved again by ``solve_lp`` alone, so its answer is
``solve_lp``'s: invalid or unusual data (a zero row, crossed bounds), Bland's rule after
a run of degenerate pivots, an iteration cap, a singular basis, an optimum or an
infeasibility proof that leans on an artificial bound.
"""

from __future__ import annotations

import time
from collections.abc import Generator, Sequence
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.linear_program import (
    ARTIFICIAL_SCALE,
    DEGENERATE_PIVOTS,
    DUAL_TOLERANCE,
    FINAL_DUAL_TOLERANCE,
    INFEASIBLE,
    OPTIMAL,
    PIVOT_TOLERANCE,
    PRIMAL_TOLERANCE,
    REFACTOR_EVERY,
    ROUNDING,
    ZERO_ROW,
    LinearProgramResult,
    solve_lp,
)

__all__ = ["Programme", "Stacked", "solve_lps", "solve_stacked", "solved", "solved_together"]

#: One programme as :func:`solve_lp` takes it: ``cost, A_ub, b_ub, lower, upper``.
Programme = tuple[ArrayLike, ArrayLike, ArrayLike, ArrayLike, ArrayLike]

#: Programmes given stacked, as :func:`solve_stacked` takes them: ``cost, A_ub, b_ub, rows, lower, upper``.
Stacked = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.intp],
                NDArray[np.float64], NDArray[np.float64]]
#: A computation that asks for stacked programmes to be solved: it yields them and is sent
#: their results (:func:`solved`, :func:`solved_together`), and returns its answer.
Steps = Generator[Stacked, list[LinearProgramResult], Any]
T = TypeVar("T")

#: Statuses besides scipy's: still pivoting, waiting for a refactorisation, to be solved alone.
_RUNNING, _WAITING, _ALONE = -1, -3, -2


def solve_lps(programmes: Sequence[Programme], *, max_iterations: int | None = None) -> list[LinearProgramResult]:
    """``[solve_lp(*p, max_iterations=max_iterations) for p in programmes]``, solved together.

    The programmes are independent and may differ in their rows and unknowns (those with
    the same number of unknowns are stacked, :func:`solve_stacked`). Errors are
    ``solve_lp``'s, raised when that programme is solved alone.
    """
    results: list[LinearProgramResult | None] = [None] * len(programmes)
    by_size: dict[int, list[int]] = {}
    arrays: dict[int, tuple[NDArray[np.float64], ...]] = {}
    for index, programme in enumerate(programmes):
        data = _arrays(programme)
        if data is None:
            results[index] = solve_lp(*programme, max_iterations=max_iterations)
        else:
            arrays[index] = data
            by_size.setdefault(data[0].size, []).append(index)
    for members in by_size.values():
        c, A, b, lo, hi = (np.stack([arrays[i][0] for i in members]), np.concatenate([arrays[i][1] for i in members]),
                           np.concatenate([arrays[i][2] for i in members]), np.stack([arrays[i][3] for i in members]),
                           np.stack([arrays[i][4] for i in members]))
        rows = np.array([arrays[i][1].shape[0] for i in members], dtype=np.intp)
        for i, result in zip(members, solve_stacked(c, A, b, rows, lo, hi, max_iterations=max_iterations)):
            results[i] = result
    return results  # type: ignore[return-value]


def _consistent(cost: NDArray[np.float64], A_ub: NDArray[np.float64], b_ub: NDArray[np.float64],
                rows: NDArray[np.intp], lower: NDArray[np.float64], upper: NDArray[np.float64]) -> bool:
    """Whether stacked programmes have the shapes :func:`solve_stacked` takes: ``B >= 1``
    programmes of ``d >= 1`` unknowns, each with at least one row."""
    B, d = cost.shape if cost.ndim == 2 else (0, 0)
    return (B > 0 and d > 0 and A_ub.shape == (int(rows.sum()), d) and b_ub.shape == (A_ub.shape[0],)
            and lower.shape == upper.shape == (B, d) and rows.shape == (B,) and bool((rows > 0).all()))


def solve_stacked(cost: NDArray[np.float64], A_ub: NDArray[np.float64], b_ub: NDArray[np.float64],
                  rows: NDArray[np.intp], lower: NDArray[np.float64], upper: NDArray[np.float64], *,
                  max_iterations: int | None = None) -> list[LinearProgramResult]:
    """:func:`solve_lps` of ``B`` programmes of ``d`` unknowns given stacked: programme ``i``
    minimises ``cost[i] @ x`` subject to its ``rows[i]`` (at least one) rows of ``A_ub`` and
    ``b_ub`` (the programmes' rows one after another) and ``lower[i] <= x <= upper[i]``.
    The fit forms its programmes this way, without a small array per programme."""
    if not _consistent(cost, A_ub, b_ub, rows, lower, upper):
        raise ValueError("solve_stacked: inconsistent shapes")
    d = cost.shape[1]
    limit = 200 + 50 * d if max_iterations is None else max_iterations
    results = _solved_batches(cost, A_ub, b_ub, rows, lower, upper, limit)
    ends = np.cumsum(rows)
    for i, result in enumerate(results):
        if result is None:
            start, end = int(ends[i] - rows[i]), int(ends[i])
            results[i] = solve_lp(cost[i], A_ub[start:end], b_ub[start:end], lower[i], upper[i],
                                  max_iterations=max_iterations)
    return results  # type: ignore[return-value]


#: A batch of at least :data:`SPLIT_PROGRAMMES` programmes is split in two at twice its
#: median count of rows when at least this share of them have more: each part padded to
#: its own most rows.
WIDE_SHARE = 0.1
#: ... (a smaller batch's cost is mostly its steps': a second batch's cost more than the
#: padding saved; the corridor's keyframes' programmes fitted one at a time took 1.5 times
#: as long split).
SPLIT_PROGRAMMES = 512


def _solved_batches(cost: NDArray[np.float64], A_ub: NDArray[np.float64], b_ub: NDArray[np.float64],
                    rows: NDArray[np.intp], lower: NDArray[np.float64], upper: NDArray[np.float64],
                    limit: int) -> list[LinearProgramResult | None]:
    """:meth:`_Batch.solve` of the stacked programmes, in one batch or two.

    A batch's steps work on every programme padded to the most rows of any: the MIT
    corridor's keyframes have programmes of about 70 rows and a third of about 220, and
    the narrow ones padded to the wide ones' width took twice the time. With at least
    :data:`WIDE_SHARE` of the programmes above twice the median rows, those and the others
    are two batches (each programme's answer is its own whichever batch it is in; the
    campus's few wide programmes are not worth a second batch's steps), when there are at
    least :data:`SPLIT_PROGRAMMES` of them (several fits' programmes solved together,
    :func:`solved_together`)."""
    wide = rows > 2 * np.median(rows)
    count = int(np.count_nonzero(wide))
    if rows.size < SPLIT_PROGRAMMES or count < WIDE_SHARE * rows.size or count == rows.size:
        return _Batch(cost, A_ub, b_ub, rows, lower, upper, limit).solve()
    results: list[LinearProgramResult | None] = [None] * rows.size
    starts = np.cumsum(rows) - rows
    for part in (np.flatnonzero(~wide), np.flatnonzero(wide)):
        counts = rows[part]
        # Each chosen programme's rows: from its start, one after another.
        entry = np.repeat(starts[part] - (np.cumsum(counts) - counts), counts) + np.arange(int(counts.sum()))
        solved_part = _Batch(cost[part], A_ub[entry], b_ub[entry], counts, lower[part], upper[part], limit).solve()
        for i, result in zip(part.tolist(), solved_part):
            results[i] = result
    return results


def solved(steps: Generator[Stacked, list[LinearProgramResult], T]) -> T:
    """What ``steps`` returns, each batch of programmes it yields answered by :func:`solve_stacked`."""
    try:
        request = next(steps)
        while True:
            request = steps.send(solve_stacked(*request))
    except StopIteration as stop:
        return stop.value


def solved_together(computations: Sequence[Steps]) -> list[tuple[Any, BaseException | None, float]]:
    """Each computation's ``(answer, None, seconds)``, or ``(None, the exception it raised,
    seconds)``: what
    :func:`solved` of each would return or raise, the computations run in turns, and the
    programmes they ask for at the same turn (of the same number of unknowns) solved in one
    :func:`solve_stacked` call.

    A batch costs about its count of steps, nearly independent of its width (this module's
    docstring): the ~64 programmes of one campus keyframe's fit took 2.8 ms, those of 16
    keyframes 1.3 ms a keyframe. Each programme's answer is the one it gets alone, bit for bit
    (``solve_stacked``'s steps are each programme's own; its docstring says where BLAS may
    differ). Stacked arrays a batch cannot take (no programme, inconsistent shapes) are
    solved alone, so that the computation sees the error it would see alone. ``seconds``:
    the wall time of the computation's own steps and its share of the batches' (by its
    programmes), not the others' steps."""
    outcomes: list[tuple[Any, BaseException | None, float]] = [(None, None, 0.0)] * len(computations)
    seconds = [0.0] * len(computations)
    asked: dict[int, Stacked] = {}

    def advance(i: int, send: Any = None, error: BaseException | None = None) -> None:
        steps = computations[i]
        started = time.perf_counter()
        try:
            asked[i] = steps.send(send) if error is None else steps.throw(error)
        except StopIteration as stop:
            outcomes[i] = (stop.value, None, seconds[i] + time.perf_counter() - started)
        except Exception as exc:  # noqa: BLE001  (the computation's own error, handed back)
            outcomes[i] = (None, exc, seconds[i] + time.perf_counter() - started)
        else:
            seconds[i] += time.perf_counter() - started

    for i in range(len(computations)):
        advance(i)
    while asked:
        turn, asked = asked, {}
        by_size: dict[int, list[int]] = {}
        for i, request in turn.items():
            if _consistent(*request):
                by_size.setdefault(request[0].shape[1], []).append(i)
                continue
            started = time.perf_counter()
            try:
                results = solve_stacked(*request)
            except Exception as exc:  # noqa: BLE001  (raised where the computation asked)
                seconds[i] += time.perf_counter() - started
                advance(i, error=exc)
            else:
                seconds[i] += time.perf_counter() - started
                advance(i, results)
        for members in by_size.values():
            started = time.perf_counter()
            stacked = [np.concatenate([turn[i][k] for i in members]) for k in range(6)]
            results = solve_stacked(*stacked)
            share = (time.perf_counter() - started) / len(results)
            start = 0
            for i in members:
                count = turn[i][0].shape[0]
                seconds[i] += share * count
                advance(i, results[start:start + count])
                start += count
    return outcomes


def _arrays(programme: Programme) -> tuple[NDArray[np.float64], ...] | None:
    """The programme as float arrays of the right shapes, or None to solve it alone
    (:func:`solve_lp` validates it then). Values are checked for the batch as a whole."""
    cost, A_ub, b_ub, lower, upper = programme
    c = np.asarray(cost, dtype=float)
    A = np.asarray(A_ub, dtype=float)
    b = np.asarray(b_ub, dtype=float)
    d = c.size
    if c.ndim != 1 or d == 0 or A.ndim != 2 or A.shape[0] == 0 or A.shape[1] != d or b.shape != (A.shape[0],):
        return None
    lo = np.asarray(lower, dtype=float)
    hi = np.asarray(upper, dtype=float)
    if lo.shape != (d,) or hi.shape != (d,):
        if lo.ndim or hi.ndim:
            return None
        lo, hi = np.full(d, float(lo)), np.full(d, float(hi))
    return c, A, b, lo, hi


class _Batch:
    """Programmes of one size ``d``, stacked, and their dual simplex state.

    Programme ``i``'s inequalities are columns ``0 .. n_i - 1`` of ``Gt[i]`` as in
    ``solve_lp`` (its rows, then ``-I`` and ``I`` for the bounds) over a last row
    ``-(h + tolerance)``, so that ``x1[i] @ Gt[i]`` is every inequality's violation beyond
    its tolerance; the padding columns after them read ``-inf``, never violated.

    ``x1`` is every programme's vertex with a last 1, ``y`` the multipliers, ``Binv`` ``N^-1``.
    """

    def __init__(self, c: NDArray[np.float64], A: NDArray[np.float64], b: NDArray[np.float64], m: NDArray[np.intp],
                 lo: NDArray[np.float64], hi: NDArray[np.float64], max_iterations: int) -> None:
        self.max_iterations = max_iterations
        B, d = c.shape
        self.B, self.d = B, d
        width = int(m.max()) + 2 * d
        starts = np.concatenate([[0], np.cumsum(m)[:-1]])
        # The rows normalised as solve_lp does (the same einsum, row by row).
        At = np.ascontiguousarray(A.T)
        norms = np.sqrt(np.einsum("ij,ij->j", At, At))
        # Whatever solve_lp treats apart is solved alone: NaN or infinite data, crossed
        # bounds, zero rows and rows whose squares overflow (none of them seen in the fit).
        usual = np.isfinite(c).all(axis=1) & ~np.isnan(lo).any(axis=1) & ~np.isnan(hi).any(axis=1)
        usual &= ~(lo == np.inf).any(axis=1) & ~(hi == -np.inf).any(axis=1) & ~(lo > hi).any(axis=1)
        # (Infinite or NaN entries of A make a norm non-finite.)
        usual &= np.isfinite(np.add.reduceat(norms, starts)) & np.isfinite(np.add.reduceat(b, starts))
        usual &= np.minimum.reduceat(norms, starts) > ZERO_ROW * np.maximum.reduceat(norms, starts)
        # The inequalities' g: each programme's rows, then its bounds, then padding.
        bound_owner = np.repeat(np.arange(B), 2 * d)
        bound_column = m[bound_owner] + np.tile(np.arange(2 * d), B)
        # Written into Gt directly, a coefficient row at a time: each programme's rows fill
        # the first columns of its block (``own``), scattered as scalars (a scatter of
        # whole d-wide rows took 0.1 ms a fit), then its bounds' -I and I (-0.0 off the
        # diagonal, as -np.eye has it), zeros elsewhere.
        own = np.arange(width) < m[:, None]
        Gt = np.empty((B, d + 1, width))
        Gt[:, :d] = 0.0
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            b = b / norms
            scaled = At / norms
        for k in range(d):
            Gt[:, k][own] = scaled[k]
        Gt[:, :d].transpose(0, 2, 1)[bound_owner, bound_column] = np.tile(np.hstack([-np.eye(d), np.eye(d)]).T,
                                                                          (B, 1))
        art_lo, art_hi = ~np.isfinite(lo), ~np.isfinite(hi)
        finite = np.maximum(np.where(art_lo, 0.0, np.abs(lo)), np.where(art_hi, 0.0, np.abs(hi))).max(axis=1)
        with np.errstate(invalid="ignore"):
            scale = np.maximum(np.maximum(1.0, np.maximum.reduceat(np.abs(b), starts)), finite)
        big = ARTIFICIAL_SCALE * scale
        # h of the padding is +inf: its last row -(h + tolerance) reads -inf, never violated.
        h = np.full((B, width), np.inf)
        h[own] = b
        h[bound_owner, bound_column] = np.concatenate(
            [np.where(art_lo, big[:, None], -lo), np.where(art_hi, big[:, None], hi)], axis=1).ravel()
        row = Gt[:, d]
        with np.errstate(invalid="ignore"):
            np.abs(h, out=row)
            np.maximum(row, 1.0, out=row)
            row *= -PRIMAL_TOLERANCE
            row -= h
        self.Gt, self.h, self.c = Gt, h, c
        #: The artificial bounds (infinite bounds made +-big), by column.
        self.artificial = np.zeros((B, width), dtype=bool)
        self.artificial[bound_owner, bound_column] = np.concatenate([art_lo, art_hi], axis=1).ravel()

        # The starting basis: the bound each cost pushes against (solve_lp's rule).
        use_upper = (c < 0) | ((c == 0) & ~art_hi & art_lo)
        sign = np.where(use_upper, 1.0, -1.0)
        j = np.arange(d)
        self.basis = np.where(use_upper, m[:, None] + d + j, m[:, None] + j)
        self.x1 = np.ones((B, d + 1))
        self.x1[:, :d] = sign * h[np.arange(B)[:, None], self.basis]
        self.y = -sign * c
        self.Binv = np.zeros((B, d, d))
        self.Binv[:, j, j] = sign  # np.diag(sign): +0.0 off the diagonal
        cmax = np.abs(c).max(axis=1)
        self.tol_d = DUAL_TOLERANCE * cmax
        self.final_tol_d = FINAL_DUAL_TOLERANCE * cmax
        self.iterations = np.zeros(B, dtype=np.intp)
        self.since = np.zeros(B, dtype=np.intp)
        self.degenerate = np.zeros(B, dtype=np.intp)
        self.status = np.where(usual, _RUNNING, _ALONE)

    def solve(self) -> list[LinearProgramResult | None]:
        """Each programme's result; None for those to be solved alone.

        A programme that finds nothing violated after pivots waits for a refactorisation
        (``solve_lp`` refactorises then and looks again); the waiting ones are refactorised
        together once no programme has a pivot to take: each programme's steps are
        ``solve_lp``'s whatever the order, and one stacked refactorisation costs about what
        one of a single programme does.
        """
        d = self.d
        limit = max(DEGENERATE_PIVOTS, 2 * d)
        Gt, x1, status = self.Gt, self.x1, self.status
        steps = 0
        while True:
            run = np.flatnonzero(status == _RUNNING)
            if run.size == 0:
                waiting = np.flatnonzero(status == _WAITING)
                if waiting.size == 0:
                    break
                status[waiting] = _RUNNING
                self._refactor(waiting)
                continue
            at = np.arange(run.size)
            # Violations beyond tolerance; the basic inequalities' are rounding error.
            slack = np.matmul(x1[:, None, :], Gt)[run, 0, :]
            slack[at[:, None], self.basis[run]] = -np.inf
            r = slack.argmax(axis=1)
            violation = slack[at, r]
            # (A reduction along the short axis costs more than an argmax and a gather.)
            size = np.abs(x1[run, :d])
            go = violation > ROUNDING * size[at, size.argmax(axis=1)]
            if np.count_nonzero(go) < go.size:
                # Nothing violated: refactorise and look again, or done (y checked as solve_lp does).
                stop = run[~go]
                stale = self.since[stop] > 0
                done = stop[~stale]
                fine = self.y[done, self.y[done].argmin(axis=1)] >= -self.final_tol_d[done]
                status[done] = np.where(fine, OPTIMAL, _ALONE)
                status[stop[stale]] = _WAITING
            if steps >= self.max_iterations:
                # solve_lp gives up here (status 4): its answer, alone.
                over = go & (self.iterations[run] >= self.max_iterations)
                status[run[over]] = _ALONE
                go &= ~over
            pivots = np.count_nonzero(go)
            if pivots == go.size:
                self._pivot(run, r, violation, limit)
            elif pivots:
                self._pivot(run[go], r[go], violation[go], limit)
            steps += 1
        return self._results()

    def _pivot(self, P: NDArray[np.intp], r: NDArray[np.intp], violation: NDArray[np.float64], limit: int) -> None:
        """One pivot of each programme ``P``, entering inequality ``r``."""
        d = self.d
        # The state of every programme is read and written in place when all of them pivot
        # (the first steps of a batch), not gathered and scattered.
        sel: NDArray[np.intp] | slice = slice(None) if P.size == self.B else P
        Binv = self.Binv[sel]
        w = np.matmul(self.Gt[P, :d, r][:, None, :], Binv)[:, 0, :]
        y = self.y[sel]
        at = np.arange(P.size)
        size = np.abs(w)  # max(|w|) = max(max(w), -min(w)), solve_lp's
        ptol = PIVOT_TOLERANCE * np.maximum(1.0, size[at, size.argmax(axis=1)])
        positive = w > ptol[:, None]
        safe_w = np.where(positive, w, 1.0)
        # Harris's bound with the dual tolerance, then the largest pivot within it.
        tol_d = self.tol_d[sel]
        ratio = np.where(positive, (y + tol_d[:, None]) / safe_w, np.inf)
        bound = ratio[at, ratio.argmin(axis=1)]
        blocked = bound == np.inf
        if np.count_nonzero(blocked):
            # No leaving candidate: refactorise first if N^-1 was updated since, else a
            # Farkas proof, genuine only without artificial bounds (else solve_lp's retry).
            stale = self.since[P] > 0
            leans = (self.artificial[P[:, None], self.basis[P]] & (w < -PIVOT_TOLERANCE)).any(axis=1)
            self.status[P[blocked & stale]] = _WAITING
            self.status[P[blocked & ~stale]] = np.where(leans[blocked & ~stale], _ALONE, INFEASIBLE)
            keep = ~blocked
            P, r, violation, Binv, w, y, positive, safe_w, bound, tol_d = (
                P[keep], r[keep], violation[keep], Binv[keep], w[keep], y[keep], positive[keep], safe_w[keep],
                bound[keep], tol_d[keep])
            if P.size == 0:
                return
            at = np.arange(P.size)
            sel = P
        k = np.where(positive & (y / safe_w <= bound[:, None]), w, -np.inf).argmax(axis=1)
        wk, yk = w[at, k], y[at, k]
        t = np.where(yk > 0.0, yk / wk, 0.0)
        y -= t[:, None] * w
        y[at, k] = t
        self.y[sel] = y
        # N^-1 after replacing row k of N by g_r; column k is the edge the vertex moves along.
        col = Binv[at, :, k] / wk[:, None]
        Binv -= col[:, :, None] * w[:, None, :]
        Binv[at, :, k] = col
        self.Binv[sel] = Binv
        col *= (violation + PRIMAL_TOLERANCE * np.maximum(1.0, np.abs(self.h[P, r])))[:, None]
        self.x1[sel, :d] -= col
        self.basis[P, k] = r
        self.iterations[sel] += 1
        since = self.since[sel] + 1
        self.since[sel] = since
        # solve_lp refactorises every REFACTOR_EVERY pivots (never reached in the fit).
        if np.count_nonzero(since >= REFACTOR_EVERY):
            self._refactor(P[since >= REFACTOR_EVERY])
        # A degenerate pivot leaves the multipliers where they were; Bland's rule, after a
        # run of them, is solve_lp's.
        degenerate = np.where(yk <= tol_d, self.degenerate[sel] + 1, 0)
        self.degenerate[sel] = degenerate
        self.status[P[degenerate >= limit]] = _ALONE

    def _refactor(self, R: NDArray[np.intp]) -> None:
        """``N^-1``, ``x`` and ``y`` afresh from the basis, computed as ``_DualSimplex.refactor``
        does, one matrix at a time (the same bits)."""
        d = self.d
        basis = self.basis[R]
        # N: row i the basic inequality i's g, C-ordered as Gt[:d, basis].T happens to be
        # (the product N @ x rounds differently in the other order).
        N = np.ascontiguousarray(self.Gt[R[:, None, None], np.arange(d)[None, None, :], basis[:, :, None]])
        try:
            Binv = np.linalg.inv(N)
        except np.linalg.LinAlgError:
            self.status[R] = _ALONE  # a singular basis among them: each alone
            return
        h_B = self.h[R[:, None], basis]
        x = np.matmul(Binv, h_B[:, :, None])[:, :, 0]
        x += np.matmul(Binv, (h_B - np.matmul(N, x[:, :, None])[:, :, 0])[:, :, None])[:, :, 0]
        self.status[R[~np.isfinite(x.sum(axis=1) + Binv.sum(axis=(1, 2)))]] = _ALONE
        self.Binv[R] = Binv
        self.y[R] = -np.matmul(self.c[R, None, :], Binv)[:, 0, :]
        self.x1[R, :d] = x
        self.since[R] = 0

    def _results(self) -> list[LinearProgramResult | None]:
        d = self.d
        out: list[LinearProgramResult | None] = []
        # An optimum with an artificial bound basic is solve_lp's to settle (its retry or
        # its step off the bound), as is anything numerical.
        leaning = np.asarray(self.artificial[np.arange(self.B)[:, None], self.basis].any(axis=1)).tolist()
        for i, (status, iterations) in enumerate(zip(self.status.tolist(), self.iterations.tolist())):
            if status == OPTIMAL and not leaning[i]:
                x = self.x1[i, :d].copy()
                out.append(LinearProgramResult(OPTIMAL, x, float(self.c[i] @ x), iterations))
            elif status == INFEASIBLE:
                out.append(LinearProgramResult(INFEASIBLE, None, None, iterations))
            else:
                out.append(None)
        return out
