"""The objective of a fit and the refit sweeps: loss, constraints, box QP.

:class:`_Refitter` holds what every candidate piece is scored by (the weighted Huber loss
of the samples, hits under-predicted weighted by ``safety``) and projected onto (``c >=
c_min``, ``|b| <= b_max``, ``|dF/dalpha| <= a_max``). Its sweeps refit each piece of a
tree by bounded, Huber-weighted least squares (:func:`box_qp`) where it is active, kept
only if the loss goes down (plain alternation oscillates). The initial tree is built in
:mod:`occtool.fit._construction`, by a subclass.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cached_property
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from occtool.sensor import SAMPLE_KINDS, Samples
from occtool.tree import MinMaxTree, Op, design_matrix

FloatArray = NDArray[np.float64]
#: ``callback(done, total)``, called after each group is built and after each sweep.
ProgressCallback = Callable[[int, int], None]


class FitSettings(Protocol):
    """The estimator's parameters the construction reads (an :class:`OccupancyRegressor`;
    the pieces to place come apart, resolved from the features' count)."""

    basis: str
    groups: int | None
    c_min: float
    a_max: float
    b_max: float
    c_max: float
    c_floor: float
    level: float
    loss: str
    huber_delta: float
    safety: float
    max_sweeps: int
    tol: float
    focus: bool
    focus_range: float


#: Samples whose loss is summed at once.
LOSS_CHUNK = 1 << 16
#: Samples the reported loss and RMSE are computed over, at most (an even subsample).
LOSS_SAMPLES = 300_000


def huber_loss(residual: FloatArray, delta: float) -> FloatArray:
    """Elementwise Huber loss: quadratic within ``delta``, linear beyond."""
    a = np.abs(residual)
    return np.where(a <= delta, 0.5 * residual * residual, delta * (a - 0.5 * delta))


def box_qp(gram: FloatArray, rhs: FloatArray, lower: FloatArray, upper: FloatArray) -> FloatArray:
    """Minimise ``x'Gx/2 - rhs'x`` subject to ``lower <= x <= upper`` (small, dense G).

    An active-set method: solve for the free variables, clamp those outside their box,
    free a clamped one whose multiplier has the wrong sign, repeat. The result lies in the
    box exactly (clamped values are the bounds themselves).
    """
    k = rhs.shape[0]
    x = np.clip(np.zeros(k), lower, upper)
    free = np.ones(k, dtype=bool)
    for _ in range(4 * k + 4):
        if free.any():
            fixed = ~free
            sub_rhs = rhs[free] - gram[np.ix_(free, fixed)] @ x[fixed]
            try:
                x[free] = np.linalg.solve(gram[np.ix_(free, free)], sub_rhs)
            except np.linalg.LinAlgError:
                x[free] = np.linalg.lstsq(gram[np.ix_(free, free)], sub_rhs, rcond=None)[0]
        outside = free & ((x < lower) | (x > upper))
        if outside.any():
            x = np.clip(x, lower, upper)
            free &= ~outside
            continue
        grad = gram @ x - rhs
        wrong = ~free & (((x <= lower) & (grad < 0)) | ((x >= upper) & (grad > 0)))
        if not wrong.any():
            break
        free[int(np.argmax(np.where(wrong, np.abs(grad), -1.0)))] = True
    return np.clip(x, lower, upper)


class _Refitter:
    """The samples of one fit, the constraints on its pieces, its loss and its refit sweeps."""

    def __init__(self, params: FitSettings, samples: Samples, *, progress: ProgressCallback | None = None) -> None:
        self.p = params
        self.progress = progress
        self.samples = samples
        self.basis = params.basis
        self.k_angle = 1 if self.basis == "linear" else 2
        # Angle terms, h, r and the offset.
        self.n_terms = self.k_angle + 3
        self.m = samples.m
        self.w = samples.weight
        self.hit = samples.kind == SAMPLE_KINDS["hit"]
        # (Times a safety of 1.0 the weights are themselves, bit for bit: no copy of them.)
        self.w_safe = self.w * params.safety if params.safety != 1.0 else self.w
        self.w_total = float(self.w.sum())
        k = self.n_terms
        inf = np.inf
        self.lower = np.full(k, -inf)
        self.upper = np.full(k, inf)
        self.lower[: self.k_angle] = -params.a_max
        self.upper[: self.k_angle] = params.a_max
        self.lower[self.k_angle] = -params.b_max
        self.upper[self.k_angle] = params.b_max
        self.lower[self.k_angle + 1] = params.c_min
        self.delta = params.huber_delta if params.loss == "huber" else np.inf
        #: The final tree's values at the samples, set by :meth:`alternate`.
        self.prediction: FloatArray | None = None
        #: The samples ``prediction`` is at.
        self.loss_rows = slice(None)

    @cached_property
    def X(self) -> FloatArray:
        """The ``(samples, terms)`` design matrix: only least squares and sweeps need it,
        and at a million features it is 100 MB."""
        return design_matrix(self.basis, self.samples.alpha, self.samples.h, self.samples.r)

    # ---------------------------------------------------------------- constraints
    def project(self, piece: FloatArray) -> FloatArray:
        """Move a piece onto the constraint set (box, and the disc for trig angle terms):
        :meth:`project_rows` of one row."""
        return self.project_rows(np.asarray(piece)[None, :])[0]

    def project_rows(self, W: FloatArray) -> FloatArray:
        """Move every row of ``W`` onto the constraint set (a new array): clipped to the box,
        then with trig angle terms scaled onto the disc, in one call for a fit's few dozen
        pieces (one at a time they cost more in numpy's per-call overhead than in arithmetic)."""
        W = np.clip(W, self.lower, self.upper)
        if self.k_angle == 2:
            a_max = self.p.a_max
            # (numpy's hypot of arrays is its hypot of scalars, element by element: pan_weight's.)
            norm = np.hypot(W[:, 0], W[:, 1])
            over = np.flatnonzero(norm > a_max)
            if over.size:
                W[over, :2] *= (a_max / norm[over])[:, None]
                # hypot after scaling can exceed a_max by an ulp: the rare rows over are shaved exactly.
                for i in over.tolist():
                    while pan_weight(W[i, 0], W[i, 1]) > a_max:
                        W[i, :2] = np.nextafter(W[i, :2], 0.0)
        return W

    def solve_piece(self, rows: NDArray[np.intp] | NDArray[np.bool_], weights: FloatArray) -> FloatArray | None:
        """Bounded weighted least squares of one piece on the given samples."""
        X = self.X[rows]
        if X.shape[0] < X.shape[1]:
            return None
        Xw = X * weights[:, None]
        gram = Xw.T @ X
        rhs = Xw.T @ self.m[rows]
        gram[np.diag_indices_from(gram)] += 1e-9 * (np.trace(gram) + 1.0)
        piece = box_qp(gram, rhs, self.lower, self.upper)
        if self.k_angle == 2 and pan_weight(piece[0], piece[1]) > self.p.a_max:
            # The disc constraint is not a box: keep the direction of the angle weights,
            # fix their length at the bound and re-solve the remaining weights.
            angle = piece[:2] * (self.p.a_max / pan_weight(piece[0], piece[1]))
            rest = slice(2, None)
            sub_rhs = rhs[rest] - gram[rest, :2] @ angle
            piece = np.concatenate([angle, box_qp(gram[rest, rest], sub_rhs, self.lower[rest], self.upper[rest])])
        return self.project(piece)

    def irls_weights(self, residual: FloatArray, weights: FloatArray, hit: NDArray[np.bool_]) -> FloatArray:
        """Weights of one reweighted least-squares step: ``w min(1, delta/|res|)``, times
        ``safety`` where a hit is under-predicted."""
        if self.p.safety != 1.0:  # (times 1.0 the weights are themselves, bit for bit)
            weights = np.where(hit & (residual < 0), weights * self.p.safety, weights)
        if not np.isfinite(self.delta):
            return weights
        a = np.abs(residual)
        return weights * np.minimum(1.0, self.delta / np.maximum(a, 1e-300))

    def total_loss(self, prediction: FloatArray, rows: slice = slice(None)) -> float:
        """The weighted loss of ``prediction`` at the samples ``rows``, per unit weight."""
        m, w, w_safe = self.m[rows], self.w[rows], self.w_safe[rows]
        hit = self.hit[rows]
        # In chunks: at 2M samples whole-array temporaries (16 MB each, fresh pages every
        # time) made this 0.23 s, 160x its cost at 200k samples.
        total = 0.0
        for first in range(0, prediction.size, LOSS_CHUNK):
            part = slice(first, first + LOSS_CHUNK)
            residual = prediction[part] - m[part]
            weights = np.where(hit[part] & (residual < 0), w_safe[part], w[part])
            total += float(np.dot(weights, huber_loss(residual, self.delta)))
        return total / (self.w_total if rows == slice(None) else float(w.sum()))

    # ---------------------------------------------------------------- alternation
    def alternate(self, W: FloatArray, members: list[list[int]]) -> tuple[MinMaxTree, list[float]]:
        root = Op("max", tuple(Op("min", tuple(g)) if len(g) > 1 else g[0] for g in members))
        if len(members) == 1:
            root = root.children[0]  # type: ignore[assignment]  # one group: its min (or lone piece)
        if not self.p.max_sweeps:
            # No sweeps (the default): only the loss is wanted, from the tree's own
            # evaluation (rows per piece), not the (samples x pieces) matrix the sweeps need.
            # Over an even subsample of at most LOSS_SAMPLES samples: the loss and RMSE are
            # reported, not optimised (at a million features all 2.5M samples took 1.4 s).
            tree = MinMaxTree(self.basis, W, root)
            self.loss_rows = slice(None, None, max(1, -(-self.samples.r.size // LOSS_SAMPLES)))
            s = self.samples
            self.prediction = tree.predict(s.alpha[self.loss_rows], s.h[self.loss_rows], s.r[self.loss_rows])
            return tree, [self.total_loss(self.prediction, self.loss_rows)]
        X, m = self.X, self.m
        n = X.shape[0]
        V = X @ W.T
        G = np.column_stack([V[:, g].min(axis=1) for g in members])
        F = G.max(axis=1)
        loss = self.total_loss(F)
        history = [loss]
        group_of = {piece: gi for gi, g in enumerate(members) for piece in g}
        n_groups = len(members)
        for sweep in range(int(self.p.max_sweeps)):
            before = loss
            for piece in range(W.shape[0]):
                gi = group_of[piece]
                others = [q for q in members[gi] if q != piece]
                in_group = V[:, others].min(axis=1) if others else np.full(n, np.inf)
                if n_groups > 1:
                    other_groups = np.delete(G, gi, axis=1).max(axis=1)
                else:
                    other_groups = np.full(n, -np.inf)
                current = V[:, piece]
                active = (current <= in_group) & (current >= other_groups)
                if active.sum() < X.shape[1]:
                    continue
                rows = np.flatnonzero(active)
                candidate = self.solve_piece(rows, self.irls_weights(F[rows] - m[rows], self.w[rows], self.hit[rows]))
                if candidate is None or np.array_equal(candidate, W[piece]):
                    continue
                for step in (1.0, 0.5):
                    trial = candidate if step == 1.0 else self.project(W[piece] + step * (candidate - W[piece]))
                    values = X @ trial
                    group_value = np.minimum(in_group, values)
                    F_new = np.maximum(other_groups, group_value)
                    new_loss = self.total_loss(F_new)
                    if new_loss < loss:
                        W[piece] = trial
                        V[:, piece] = values
                        G[:, gi] = group_value
                        F = F_new
                        loss = new_loss
                        break
            history.append(loss)
            if self.progress is not None:
                offset = getattr(self, "progress_offset", 0)
                self.progress(offset + sweep + 1, offset + int(self.p.max_sweeps))
            if before - loss <= self.p.tol * max(before, 1e-12):
                break
        self.prediction = F
        return MinMaxTree(self.basis, W, root), history


def pan_weight(a1: float, a2: float) -> float:
    """``hypot(a1, a2)``, computed as :attr:`MinMaxTree.angle_weight` computes it.

    The constraint ``|dF/dalpha| <= a_max`` is checked (by the loader and the slope
    bounds) with numpy's ``hypot``, which can be an ulp above ``math.hypot`` for the same
    pair; a piece projected with the other function could then load as breaking it.
    """
    return float(np.hypot(a1, a2))
