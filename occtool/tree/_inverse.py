"""The inverse tree ``r = F^-1(alpha, h, m)`` and its free-distance bound, evaluated by compiled
programs in reused scratch buffers."""


from __future__ import annotations

import math
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.tree._minmax import INVERSE_BASES, FloatArray, Node, Op, _PieceTree, angle_terms

#: Output elements :meth:`InverseTree.range` evaluates at once: its few tree-level buffers
#: (8 bytes an element each) then stay in a core's L2 cache.
INVERSE_BLOCK = 1 << 16
#: Piece values (pieces x height edges x angles) :meth:`InverseTree.horizontal_lower_bound`
#: forms at once: a navigation map's 64 pieces x 8 edges x 361 angles (1.5 MB), in one
#: block, which took 0.37 ms where blocks of 128 angles took 0.50.
BOUND_BLOCK = 1 << 18


_SCRATCH = threading.local()


def _scratch_buffers(count: int, shape: tuple[int, ...]) -> list[FloatArray]:
    """``count`` scratch arrays of ``shape``, reused by later calls in the same thread.

    At most :data:`BOUND_BLOCK` elements each (more only for a free-distance bound over
    so many heights that one ray's pieces x heights exceed it), so a thread keeps a few
    MB in all. Fresh arrays of that size come from the kernel page by page:
    freeing a few of them at once makes the C allocator hand the memory back, and filling
    new ones then costs more than the evaluation itself (0.2 ms of 0.7 ms for 97 x 360).
    """
    pool: list[FloatArray] = _SCRATCH.__dict__.setdefault("buffers", [])
    size = math.prod(shape)
    for index in range(count):
        if index == len(pool):
            pool.append(np.empty(size))
        elif pool[index].size < size:
            pool[index] = np.empty(size)
    return [buffer[:size].reshape(shape) for buffer in pool[:count]]


class _Leaves:
    """Step of a compiled inverse tree: the MIN or MAX (``op``) of the sibling pieces
    ``pieces``, which share their ``h``/``m`` part ``rest``, written into ``buffer``."""

    # A plain class, not a dataclass, as the other steps: each dataclass made was about
    # 1 ms of a fresh process's import (four here), for records only this module reads.
    __slots__ = ("pieces", "op", "rest", "buffer")

    def __init__(self, pieces: NDArray[np.intp], op: str, rest: int, buffer: int) -> None:
        self.pieces, self.op, self.rest, self.buffer = pieces, op, rest, buffer


class _Reduce:
    """Step of a compiled inverse tree: ``buffers[target] = op(buffers[target], buffers[source])``."""

    __slots__ = ("op", "target", "source")

    def __init__(self, op: str, target: int, source: int) -> None:
        self.op, self.target, self.source = op, target, source



def _compile_parts(steps: list[Any], op: str, level: int, parts: list[Any],
                   compile_node: Callable[[Node, int], int], leaf: Callable[[Any, int], Any]) -> int:
    """Append the steps of a node's ``parts`` (leaf runs and child nodes): the first into buffer
    ``level``, each later one into ``level + 1`` and reduced into ``level`` by ``op``; returns
    the deepest buffer used. ``leaf(part, target)`` makes a leaf run's step."""
    deepest = level
    for index, part in enumerate(parts):
        target = level if index == 0 else level + 1
        if isinstance(part, tuple):
            steps.append(leaf(part, target))
        else:
            deepest = max(deepest, compile_node(part, target))
        if index:
            deepest = max(deepest, target)
            steps.append(_Reduce(op, level, target))
    return deepest

class _Program:
    """An inverse tree compiled for inputs whose ``h``/``m`` part varies over ``columns``.

    Every piece is split into an angle part ``U`` (angle terms, constant, and the terms of
    inputs that are scalars) and the rest ``W`` (the terms of the other inputs). Sibling
    pieces with the same ``W`` weights are reduced on their small ``U`` parts first:
    rounding is monotone, so ``max(U1 + W, U2 + W) == max(U1, U2) + W`` exactly, and a
    MIN/MAX node of four pieces of which three share a height weight costs two
    broadcast additions instead of four.
    """

    def __init__(self, tree: InverseTree, columns: tuple[int, ...]) -> None:
        weights = tree.coefficients[:, list(columns)]
        keys: dict[tuple[float, ...], int] = {}
        self.rest_of = np.array([keys.setdefault(tuple(row), len(keys)) for row in weights.tolist()], dtype=np.intp)
        self.rest_weights = np.array(list(keys), dtype=np.float64).reshape(len(keys), len(columns))
        self.steps: list[_Leaves | _Reduce] = []
        self.n_buffers = self._compile(tree.root, 0) + 1

    def _compile(self, node: Node, level: int) -> int:
        """Append the steps that evaluate ``node`` into buffer ``level``; return the deepest buffer used."""
        if isinstance(node, int):
            self.steps.append(_Leaves(np.array([node]), "min", int(self.rest_of[node]), level))
            return level
        groups: dict[int, list[int]] = {}
        for child in node.children:
            if isinstance(child, int):
                groups.setdefault(int(self.rest_of[child]), []).append(child)
        parts: list[Node | tuple[int, list[int]]] = [
            *groups.items(), *(c for c in node.children if not isinstance(c, int))]
        return _compile_parts(self.steps, node.op, level, parts, self._compile,
                              lambda part, target: _Leaves(np.array(part[1]), node.op, part[0], target))


def _within_turn(angle: FloatArray, start: FloatArray, width: FloatArray) -> NDArray[np.bool_]:
    """``np.mod(angle - start, 2 pi) <= width``: ``(L, N)`` for ``(L, 1)`` angles and ``(N,)``
    starts and widths: whether each angle lies in each interval, counter-clockwise from
    its start.

    Bit for bit what :func:`numpy.mod` gives (``fmod``, plus the turn where that is
    negative) when every difference lies within ``(-2 pi, 4 pi)`` (angles and starts
    within a turn or two, as a sweep's), where ``fmod`` subtracts at most one turn,
    exactly; a few comparisons instead of ``np.mod``'s division (several times as slow).
    """
    turn = 2.0 * np.pi
    difference = angle - start[None, :]
    # Rounding is monotone: the extreme differences are those of the extreme inputs.
    if not (start.size and float(angle.min()) - float(start.max()) > -turn
            and float(angle.max()) - float(start.min()) < 2.0 * turn):
        return np.mod(difference, turn) <= width[None, :]
    # A difference past a turn takes one off, a negative one takes one on; the rest are
    # compared as they are. (A difference d >= turn with d <= width also has d - turn <=
    # width, rounding being monotone, and one taken off stays >= 0, so it is not put back.)
    # Two masked operations in place: 6 passes over (L, N) instead of the 13 of testing
    # the three cases apart (45 of 80 us on a navigation map's 64 x 361).
    np.subtract(difference, turn, out=difference, where=difference >= turn)
    np.add(difference, turn, out=difference, where=difference < 0.0)
    within: NDArray[np.bool_] = difference <= width
    return within


class _Rows:
    """Step of a :class:`_RowProgram`: ``buffers[buffer] = op`` over the piece rows ``start:stop``."""

    __slots__ = ("op", "start", "stop", "buffer")

    def __init__(self, op: str, start: int, stop: int, buffer: int) -> None:
        self.op, self.start, self.stop, self.buffer = op, start, stop, buffer


class _Groups:
    """Step of a :class:`_RowProgram`: ``buffers[buffer] = op`` over ``groups`` groups of
    ``size`` consecutive piece rows from ``start``, each reduced by ``inner`` first (into
    ``buffers[buffer + 1]``)."""

    __slots__ = ("op", "inner", "start", "groups", "size", "buffer")

    def __init__(self, op: str, inner: str, start: int, groups: int, size: int, buffer: int) -> None:
        self.op, self.inner, self.start, self.groups, self.size, self.buffer = op, inner, start, groups, size, buffer


def _consecutive_runs(pieces: list[int]) -> list[tuple[int, int]]:
    """``(start, stop)`` of each run of consecutive piece indices in ``pieces``, ascending."""
    runs: list[tuple[int, int]] = []
    for piece in sorted(pieces):
        if runs and runs[-1][1] == piece:
            runs[-1] = (runs[-1][0], piece + 1)
        else:
            runs.append((piece, piece + 1))
    return runs


class _RowProgram:
    """A tree compiled to evaluate on a ``(L, points)`` array of piece values, one row a piece.

    The leaf children of a node are reduced a run of consecutive pieces at a time (one
    ``reduce`` over a slice of rows, no copy), and a node over equal groups of consecutive
    pieces (a fitted tree: a MIN of MAX groups) in two reductions over its rows seen as
    ``(groups, size, points)``, instead of a call or two per piece. MIN and MAX pick one
    of their inputs, so any order of reduction gives the same numbers as
    :func:`_evaluate` wherever there is no NaN.
    """

    def __init__(self, root: Node) -> None:
        self.steps: list[_Rows | _Groups | _Reduce] = []
        self.n_buffers = self._compile(root, 0) + 1

    def _compile(self, node: Node, level: int) -> int:
        """Append the steps that evaluate ``node`` into buffer ``level``; return the deepest buffer used."""
        if isinstance(node, int):
            self.steps.append(_Rows("min", node, node + 1, level))
            return level
        groups = self._groups(node, level)
        if groups is not None:
            self.steps.append(groups)
            return level + 1
        parts: list[Node | tuple[int, int]] = [
            *_consecutive_runs([c for c in node.children if isinstance(c, int)]),
            *(c for c in node.children if not isinstance(c, int))]
        return _compile_parts(self.steps, node.op, level, parts, self._compile,
                              lambda part, target: _Rows(node.op, part[0], part[1], target))

    @staticmethod
    def _groups(node: Op, level: int) -> _Groups | None:
        """``node`` as one :class:`_Groups` step, when its children are nodes of one op,
        each over a run of consecutive pieces, the runs equally long and together one run."""
        inner: set[str] = set()
        runs: list[tuple[int, int]] = []
        for child in node.children:
            if not isinstance(child, Op) or not all(isinstance(piece, int) for piece in child.children):
                return None
            inner.add(child.op)
            runs.extend(_consecutive_runs([piece for piece in child.children if isinstance(piece, int)]))
        if len(runs) < 2 or len(runs) != len(node.children) or len(inner) != 1:
            return None
        runs.sort()
        size = runs[0][1] - runs[0][0]
        if any(stop - start != size for start, stop in runs) or any(
                following[0] != previous[1] for previous, following in zip(runs, runs[1:])):
            return None
        return _Groups(node.op, inner.pop(), runs[0][0], len(runs), size, level)

    def run(self, values: FloatArray, buffers: list[FloatArray]) -> FloatArray:
        """The tree on ``values`` (``(L, *points)``, a piece a row, any strides), in
        ``buffers`` (at least ``n_buffers`` flat arrays of at least ``L * points``
        elements); returns a view of ``buffers[0]`` of the points' shape."""
        points = values.shape[1:]
        n = math.prod(points)
        outputs = [buffer[:n].reshape(points) for buffer in buffers]
        for step in self.steps:
            ufunc = np.minimum if step.op == "min" else np.maximum
            if isinstance(step, _Rows):
                ufunc.reduce(values[step.start:step.stop], axis=0, out=outputs[step.buffer])
            elif isinstance(step, _Groups):
                rows = values[step.start:step.start + step.groups * step.size].reshape(
                    step.groups, step.size, *points)
                inner = buffers[step.buffer + 1][:step.groups * n].reshape(step.groups, *points)
                (np.minimum if step.inner == "min" else np.maximum).reduce(rows, axis=1, out=inner)
                ufunc.reduce(inner, axis=0, out=outputs[step.buffer])
            else:
                ufunc(outputs[step.target], outputs[step.source], out=outputs[step.target])
        return outputs[0]


class InverseTree(_PieceTree):
    """The inverted occupancy function ``r = F^-1(alpha, h, m)``.

    Each piece is ``r = (angle terms) + b*h + m_weight*m + d`` with ``m_weight = 1/c > 0``;
    the nodes are those of the :class:`MinMaxTree` with MIN and MAX exchanged.
    """

    _names = INVERSE_BASES

    def _program(self, columns: tuple[int, ...]) -> _Program:
        """The tree compiled for an ``h``/``m`` part over coefficient ``columns`` (built once)."""
        cache = self.__dict__.setdefault("_programs", {})
        if columns not in cache:
            cache[columns] = _Program(self, columns)
        return cache[columns]

    def range(self, alpha: ArrayLike, h: ArrayLike, m: ArrayLike) -> FloatArray:
        """The distance ``r`` at which ``F(alpha, h, r) = m`` (may be negative: the level
        is reached before the sensor). Inputs broadcast together."""
        # The angle part of every piece is formed on alpha's own shape and the h/m part on
        # theirs ((L, N) and (L, H) for a sweep of N angles x H heights); a piece (or a set
        # of siblings, see _Program) then costs one broadcast addition into a buffer,
        # reduced in place into its parent's. No (L x points) array is made: for 32 pieces,
        # 360 angles and 100 heights that array is 9 MB, and allocating, filling and
        # reducing it took 4-5 ms where this takes about 0.5 ms.
        alpha, h, m = (np.asarray(v, dtype=np.float64) for v in (alpha, h, m))
        shape = np.broadcast_shapes(alpha.shape, h.shape, m.shape)
        size = math.prod(shape)
        rest_size = math.prod(np.broadcast_shapes(*(v.shape for v in (h, m) if v.size > 1)))
        if size <= 1 or (alpha.size == size and rest_size == size):
            # A single point, or points where alpha, h and m all vary (a fit's samples):
            # nothing to share between pieces' parts, the plain evaluation is as fast.
            return self._eval(alpha, h, m)
        ndim = max(len(shape), 1)
        alpha, h, m = (v.reshape((1,) * (ndim - v.ndim) + v.shape) for v in (alpha, h, m))
        rows = (shape or (1,))[0]
        if rows and size // rows > INVERSE_BLOCK:
            # Rows too long to block (a flat sweep): evaluate the flattened points.
            alpha, h, m = (np.broadcast_to(v, shape).ravel() if v.size > 1 else v.reshape(()) for v in (alpha, h, m))
            return self.range(alpha, h, m).reshape(shape)
        out = np.empty(shape or (1,))
        if size == 0:
            return out.reshape(shape)
        k = len(self._names[self.basis]) - 3
        # Scalar h or m go into the angle part's constant; the others make the rest.
        constant = self.coefficients[:, k + 2].copy()
        rest_inputs, columns = [], []
        for column, value in ((k, h), (k + 1, m)):
            if value.size == 1:
                constant += self.coefficients[:, column] * value.reshape(())
            else:
                rest_inputs.append(value)
                columns.append(column)
        if self.n_pieces * size <= INVERSE_BLOCK:
            return self._range_rows(alpha, rest_inputs, columns, constant, out).reshape(shape)
        program = self._program(tuple(columns))
        step = max(1, INVERSE_BLOCK // (size // rows))
        # Parts of inputs that do not change along the first axis are formed once.
        # (mypy: numpy's stubs keep the () shape of the flattened branch above.)
        angle_part = self._angle_part(alpha, constant) if alpha.shape[0] == 1 else None  # type: ignore[misc]
        rest_part = self._rest_part(program, rest_inputs) if all(v.shape[0] == 1 for v in rest_inputs) else None  # type: ignore[misc]
        scratch = _scratch_buffers(program.n_buffers - 1, (min(step, rows),) + out.shape[1:])
        for first in range(0, rows, step):
            block = slice(first, first + step)
            target = out[block]
            buffers = [target] + [buffer[:len(target)] for buffer in scratch]
            angles = angle_part if angle_part is not None else self._angle_part(alpha[block], constant)
            rest = rest_part if rest_part is not None else self._rest_part(
                program, [v[block] if v.shape[0] > 1 else v for v in rest_inputs])  # type: ignore[misc]
            self._run(program, angles, rest, buffers)
        return out.reshape(shape)

    def _range_rows(self, alpha: FloatArray, rest_inputs: list[FloatArray], columns: list[int],
                    constant: FloatArray, out: FloatArray) -> FloatArray:
        """:meth:`range` of a sweep small enough for every piece's value at once (``L`` x
        points at most :data:`INVERSE_BLOCK`), written into ``out``: the tree over those
        values as rows (:class:`_RowProgram`).

        A navigation map's slices are such a sweep (64 pieces x 2 heights x 360 angles) of
        a model swept once: compiling its :class:`_Program` (a Python step for each piece)
        and running it cost more than the evaluation (0.5 ms a map of 64 pieces, 0.15 ms
        this way). The same numbers: each piece's value is its angle part plus its rest,
        formed as :meth:`_rest_part` forms them, and the program's reducing siblings of
        equal weights before adding their rest gives the same (rounding is monotone).
        """
        program = self._row_program()
        lead = (self.n_pieces,) + (1,) * out.ndim
        # Buffer 0 of the program (the result) only ever holds one row: ``out`` itself.
        values, *scratch = _scratch_buffers(program.n_buffers, (self.n_pieces,) + out.shape)
        angles = self._angle_part(alpha, constant)
        if rest_inputs:
            terms = sorted(zip(rest_inputs, self.coefficients[:, columns].T), key=lambda term: term[0].size)
            rest: FloatArray = terms[0][1].reshape(lead) * terms[0][0]
            for value, weights in terms[1:]:
                rest = rest + weights.reshape(lead) * value
            np.add(angles, rest, out=values)
        else:
            np.copyto(values, angles)
        program.run(values.reshape(self.n_pieces, -1), [out.reshape(-1)] + [b.reshape(-1) for b in scratch])
        return out

    def horizontal_lower_bound(self, alpha_low: ArrayLike, alpha_high: ArrayLike, h_edges: ArrayLike,
                               m: float) -> FloatArray:
        """A lower bound of the free horizontal distance over boxes of pan angle x height.

        The free horizontal distance at ``(alpha, h)`` is ``sqrt(r^2 - h^2)`` with ``r`` the
        range where the level ``m`` is reached (0 where it is reached before height ``h``
        or before the sensor). For the boxes ``[alpha_low[i], alpha_high[i]] x
        [h_edges[j], h_edges[j + 1]]`` this returns ``(len(h_edges) - 1, len(alpha_low))``
        numbers no larger than that distance anywhere in the box: the navigation map then
        holds between its rays and cuts exactly, with no Lipschitz margin. (The linear
        basis jumps at +-pi: an interval must not cross it.)

        Why it holds: ``sqrt(max(r^2 - h^2, 0))`` of ``max(r, 0)`` is non-decreasing in
        ``r``, so it commutes with the tree's MIN and MAX and can be taken piece by piece.
        A piece is ``r = u(alpha) + b h`` with ``u`` the angle terms plus ``m``'s term and the
        offset; its least ``u`` over the angle interval is closed-form (a cosine's largest
        value, or a line's). With ``r >= 0`` at both height ends, ``(u + b h)^2 - h^2`` grows
        with ``u`` and is a quadratic in ``h`` whose least value over the height interval
        lies at an end or at its vertex. The bound of a MIN node is the MIN of its
        children's; the MAX of the children's bounds bounds a MAX node from below.
        """
        lo = np.asarray(alpha_low, dtype=np.float64).ravel()
        hi = np.asarray(alpha_high, dtype=np.float64).ravel()
        h_edges = np.asarray(h_edges, dtype=np.float64).ravel()
        k = len(self._names[self.basis]) - 3
        W = self.coefficients
        # u: least angle part over each interval, plus m's term and the offset: (L, N).
        u = self._least_angle_part(lo, hi) + (W[:, k + 1] * m + W[:, k + 2])[:, None]
        n_pieces, n_angles = u.shape
        n_boxes = max(h_edges.size - 1, 0)
        least = np.empty((n_boxes, n_angles))
        if least.size == 0:
            return least
        # r and r^2 - h^2 at every height edge once: a box's least value lies at one of its
        # two edges (concave in h when |b| <= 1), shared with its neighbour; b h and h^2 once.
        height_part = W[:, k][:, None] * h_edges[None, :]
        edge_squares = (h_edges * h_edges)[:, None, None]
        curved = np.flatnonzero(np.abs(W[:, k]) > 1.0)
        program = self._row_program()
        # Blocks of angles, so that the (heights, L, angles) values stay in reused buffers:
        # made whole each call, they were a few MB, which the C allocator handed back to the
        # kernel and took back page by page each time (half the time of a navigation map).
        step = max(1, BOUND_BLOCK // (n_pieces * h_edges.size))
        block = min(step, n_angles)
        edge_values, box, *levels = _scratch_buffers(
            2 + program.n_buffers, (h_edges.size, n_pieces, block))
        # Heights first, then pieces, then angles: a height's r^2 - h^2 and a box's least of
        # its two edges are then operations on whole (L, angles) slabs, which numpy runs as
        # one loop; pieces first made them a loop per piece and height over a block's angles
        # (0.55 of 1 ms of a campus map's bound, 0.37 this way).
        weights = W[:, k][None, :, None]
        for first in range(0, n_angles, step):
            n = min(step, n_angles - first)
            angles = slice(first, first + n)
            q = edge_values.reshape(-1)[:h_edges.size * n_pieces * n].reshape(h_edges.size, n_pieces, n)
            np.add(u[None, :, angles], height_part.T[:, :, None], out=q)
            # Where r < 0 the level is reached before the sensor: nothing is free. r is
            # clamped to 0 there, which gives -h^2 <= 0 where the exact bound says -1: the
            # same once the tree's result is clamped to 0 below (max(., 0) is monotone, so
            # it commutes with MIN and MAX), and fmax turns a NaN (inf - inf) into 0 too.
            np.fmax(q, 0.0, out=q)
            np.multiply(q, q, out=q)
            np.subtract(q, edge_squares, out=q)
            boxes = box.reshape(-1)[:n_boxes * n_pieces * n].reshape(n_boxes, n_pieces, n)
            np.minimum(q[:-1], q[1:], out=boxes)
            if curved.size:
                # (b^2 - 1) h^2 + 2 u b h + u^2 is convex only when |b| > 1: then its vertex counts too.
                bc = weights[:, curved]
                h0, h1 = h_edges[:-1, None, None], h_edges[1:, None, None]
                uc = u[curved, angles][None, :, :]
                vertex = np.clip(-uc * bc / (bc * bc - 1.0), h0, h1)
                rv = uc + bc * vertex
                boxes[:, curved] = np.minimum(boxes[:, curved], np.where(rv >= 0, rv * rv - vertex * vertex, -1.0))
            tree = program.run(boxes.transpose(1, 0, 2), [level.reshape(-1) for level in levels])
            least[:, angles] = tree
        # sqrt(max(., 0)) is increasing, so it commutes with the tree: taken once, at the end.
        return np.sqrt(np.maximum(least, 0.0, out=least), out=least)

    def _least_angle_part(self, lo: FloatArray, hi: FloatArray) -> FloatArray:
        """``(L, N)``: each piece's least angle terms over the intervals ``[lo, hi]``."""
        W = self.coefficients
        if self.basis == "linear":
            a = W[:, :1]
            return np.minimum(a * lo[None, :], a * hi[None, :])
        a1, a2 = W[:, :1], W[:, 1:2]
        least = np.minimum(a1 * np.cos(lo) + a2 * np.sin(lo), a1 * np.cos(hi) + a2 * np.sin(hi))
        # a1 cos + a2 sin = R cos(alpha - phi) reaches -R at alpha = phi + pi.
        radius = np.hypot(a1, a2)
        trough = np.arctan2(a2, a1) + np.pi
        np.copyto(least, -radius, where=_within_turn(trough, lo, hi - lo))
        return least

    def _row_program(self) -> _RowProgram:
        """The tree compiled over rows of piece values (built once)."""
        cache = self.__dict__.setdefault("_programs", {})
        if "rows" not in cache:
            cache["rows"] = _RowProgram(self.root)
        return cache["rows"]

    def _angle_part(self, alpha: FloatArray, constant: FloatArray) -> FloatArray:
        """``(L, *alpha.shape)``: each piece's constant plus its angle terms."""
        k = len(self._names[self.basis]) - 3
        lead = (self.n_pieces,) + (1,) * alpha.ndim
        part: FloatArray = constant.reshape(lead)
        for column, weights in zip(angle_terms(self.basis, alpha), self.coefficients[:, :k].T):
            part = part + weights.reshape(lead) * column
        return part

    @staticmethod
    def _rest_part(program: _Program, inputs: list[FloatArray]) -> FloatArray | None:
        """``(distinct weights, *broadcast shape)``: the h/m part of each set of pieces, smaller input first."""
        if not inputs:
            return None
        ndim = inputs[0].ndim
        lead = (len(program.rest_weights),) + (1,) * ndim
        terms = sorted(zip(inputs, program.rest_weights.T), key=lambda term: term[0].size)
        part: FloatArray = terms[0][1].reshape(lead) * terms[0][0]
        for value, weights in terms[1:]:
            part = part + weights.reshape(lead) * value
        return part

    @staticmethod
    def _run(program: _Program, angles: FloatArray, rest: FloatArray | None, buffers: list[FloatArray]) -> None:
        for step in program.steps:
            if isinstance(step, _Leaves):
                if len(step.pieces) == 1:
                    part = angles[step.pieces[0]]
                else:
                    part = (np.minimum if step.op == "min" else np.maximum).reduce(angles[step.pieces], axis=0)
                if rest is None:
                    np.copyto(buffers[step.buffer], part)
                else:
                    np.add(part, rest[step.rest], out=buffers[step.buffer])
            elif step.op == "min":
                np.minimum(buffers[step.target], buffers[step.source], out=buffers[step.target])
            else:
                np.maximum(buffers[step.target], buffers[step.source], out=buffers[step.target])
