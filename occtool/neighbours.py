"""Nearest neighbours within a reach, in numpy: the queries the return guard makes.

The guard (:mod:`occtool.guard`) asks, for a few thousand returns, which support points
lie within a fixed reach, and for a few thousand ray directions, how far their nearest
neighbour is. ``scipy.spatial.cKDTree`` answers both, but importing it costs a fresh
process about 0.3-0.4 s of CPU on this project's machine (``scipy.spatial`` loads
``scipy.sparse``, ``scipy.linalg``, ``scipy.special``, ...): three times a whole fit of
10k features. These answers are cKDTree's to the bit: distances are the square root of
the squared differences summed in coordinate order (as cKDTree sums them), a neighbour
counts when that sum is below the squared reach, and missing neighbours are ``inf`` with
index ``n``; only which of several points at exactly the same distance comes first may
differ (the guard reads no order among them).

The points are hashed into a grid of cells at least the reach wide, so a query's
neighbours lie in its own cell and the ``3 ** d`` around it; the candidates are gathered
a block of queries at a time, so memory stays bounded whatever the density.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

#: Candidate pairs (query, point) looked at in one block: at least PAIR_BLOCK, more when
#: there would be over MAX_BLOCKS blocks, at most PAIR_BLOCK_MAX. Small blocks' dozen
#: temporaries stay within the core's cache and are reused from the heap block after
#: block (narrow aisle, 10k features, 304k pairs: 1 << 20 a block touched 8,200 fresh
#: pages in the first fit of a process, 1 << 15 3,600; that fit took 134 -> 108 ms CPU,
#: median of 6); a million features' tens of millions of pairs take large blocks, whose
#: per-block overhead 1 << 15 made 5-15 % of the fit.
PAIR_BLOCK = 1 << 15
PAIR_BLOCK_MAX = 1 << 20
MAX_BLOCKS = 32
#: Most pairs (point, point) :func:`nearest_other_distance` compares all at once.
BRUTE_FORCE_PAIRS = 1 << 18
#: Most queries in one block: at most 1 << 16, a block's query numbers are sorted as 16-bit keys.
ROW_BLOCK = 1 << 16
#: Cells per dimension at most (wider cells beyond: the keys stay within 64 bits).
MAX_CELLS = 1 << 14
#: Cells are this much wider than the reach, so rounding in the cell index never puts a
#: neighbour within reach two cells away.
CELL_MARGIN = 1.01


class NeighbourIndex:
    """Points (``(n, d)``) indexed for queries of their nearest neighbours within ``reach``.

    :meth:`query` is ``cKDTree(points).query(x, k, distance_upper_bound=bound)`` for any
    ``bound <= reach``.
    """

    def __init__(self, points: ArrayLike, reach: float = 1.0) -> None:
        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 2:
            raise ValueError(f"points must be (n, d), got shape {points.shape}")
        if not (math.isfinite(reach) and reach > 0.0):
            raise ValueError(f"reach must be a positive number, got {reach}")
        self.n, self.d = points.shape
        self.reach = float(reach)
        self._lower = points.min(axis=0) if self.n else np.zeros(self.d)
        span = points.max(axis=0) - self._lower if self.n else np.zeros(self.d)
        self._cell = np.maximum(CELL_MARGIN * self.reach, span / MAX_CELLS)
        cells = self._cells_of(points)
        # Cells run 1..count in each dimension; 0 and count + 1 hold no point (a query's
        # neighbouring cells may lie there), so a key never wraps into another cell's.
        self._count = cells.max(axis=0) if self.n else np.zeros(self.d, dtype=np.int64)
        self._stride = np.ones(self.d, dtype=np.int64)
        for axis in range(self.d - 2, -1, -1):
            self._stride[axis] = self._stride[axis + 1] * (self._count[axis + 1] + 2)
        key = self._keys_of(cells)
        self._order = np.argsort(key, kind="stable")
        self._keys = key[self._order]
        # Columns in key order: a block's gathers read each coordinate alone.
        self._columns = [np.ascontiguousarray(points[self._order, axis]) for axis in range(self.d)]
        # The last dimension has stride 1: a cell and its two neighbours along it are one
        # run of keys, so the 3 ** d cells around a query are 3 ** (d - 1) runs.
        offsets = np.array(list(itertools.product((-1, 0, 1), repeat=self.d - 1)), dtype=np.int64)
        self._run_keys = self._keys_of(np.column_stack([offsets, np.zeros(len(offsets), dtype=np.int64)]))

    def _cells_of(self, points: FloatArray) -> NDArray[np.int64]:
        return np.floor((points - self._lower) / self._cell).astype(np.int64) + 1

    def _keys_of(self, cells: NDArray[np.int64]) -> NDArray[np.int64]:
        key = cells[..., 0] * self._stride[0]
        for axis in range(1, self.d):
            key += cells[..., axis] * self._stride[axis]
        return key

    def query(self, x: ArrayLike, k: int = 1, distance_upper_bound: float | None = None
              ) -> tuple[FloatArray, NDArray[np.intp]]:
        """The ``k`` nearest points within ``distance_upper_bound`` (default: the reach)
        of each row of ``x``: ``(m, k)`` distances, nearest first (``inf`` where fewer
        are within it), and their indices (``n`` there)."""
        bound = self.reach if distance_upper_bound is None else float(distance_upper_bound)
        if bound > self.reach:
            raise ValueError(f"distance_upper_bound {bound} is beyond the index's reach {self.reach}")
        x = np.asarray(x, dtype=np.float64).reshape(-1, self.d)
        m, k = x.shape[0], int(k)
        distance = np.full((m, k), np.inf)
        index = np.full((m, k), self.n, dtype=np.intp)
        if m == 0 or self.n == 0 or k < 1:
            return distance, index
        order, first, last = self._candidates(x)
        x = x[order]
        per_query = (last - first).sum(axis=1)
        # Blocks of queries with at most `pairs` candidates (one query alone may have more).
        running = np.cumsum(per_query)
        pairs = min(PAIR_BLOCK_MAX, max(PAIR_BLOCK, int(running[-1]) // MAX_BLOCKS))
        start = 0
        while start < m:
            before = running[start - 1] if start else 0
            stop = max(start + 1, int(np.searchsorted(running, before + pairs, side="right")))
            stop = min(stop, start + ROW_BLOCK)
            self._query_block(x[start:stop], order[start:stop], first[start:stop], last[start:stop], k,
                              bound * bound, distance, index)
            start = stop
        return distance, index

    def _candidates(self, x: FloatArray) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]:
        """The queries in the order of their cells' keys, and for each (in that order) the
        runs of key-sorted points in the ``3 ** d`` cells around its own: ``(m, 3 ** (d - 1))``
        first and last positions."""
        # A query beyond the points' cells is moved to the nearest of them: its neighbours
        # within reach (none, or those of the outermost cells) are among that cell's
        # neighbours, and every candidate's distance is tested. Its neighbouring cells
        # then lie within the padding, so no key wraps into another cell's.
        key = self._keys_of(np.clip(self._cells_of(x), 1, np.maximum(self._count, 1)))
        order = np.argsort(key, kind="stable")
        key = key[order]
        # Queries in one cell share its runs: each cell's are looked up once.
        new = np.r_[True, key[1:] != key[:-1]]
        keys = key[new][:, None] + self._run_keys[None, :]
        cell = np.cumsum(new) - 1
        first = np.searchsorted(self._keys, keys - 1, side="left")
        last = np.searchsorted(self._keys, keys + 1, side="right")
        return order, first[cell], last[cell]

    def _query_block(self, x: FloatArray, rows: NDArray[np.intp], first: NDArray[np.intp], last: NDArray[np.intp],
                     k: int, bound2: float, distance: FloatArray, index: NDArray[np.intp]) -> None:
        """The answers of the queries ``x`` (rows ``rows`` of the answer) from their runs."""
        counts = last - first
        per_row = counts.sum(axis=1)
        total = int(per_row.sum())
        if total == 0:
            return
        runs = np.flatnonzero(counts.ravel())
        run_counts = counts.ravel()[runs]
        # Positions (in key order) of every candidate: each run laid end to end, by query.
        position = np.arange(total) + np.repeat(first.ravel()[runs] - (np.cumsum(run_counts) - run_counts),
                                                run_counts)
        # The squared distance summed in coordinate order from 0, as cKDTree sums it.
        squared = self._columns[0].take(position)
        squared -= np.repeat(x[:, 0], per_row)
        squared *= squared
        for axis in range(1, self.d):
            step = self._columns[axis].take(position)
            step -= np.repeat(x[:, axis], per_row)
            step *= step
            squared += step
        near = np.flatnonzero(squared < bound2)
        if near.size == 0:
            return
        position, squared = position[near], squared[near]
        owner = np.repeat(np.arange(per_row.size), per_row)[near]
        # Nearest first within each query: by distance, then (stably) by query, as 16-bit
        # keys, which numpy sorts by radix in one pass (a block holds at most ROW_BLOCK
        # queries). The order of np.lexsort((squared, owner)), but for which of exactly
        # equal distances comes first; 86k pairs: 4.8 ms, 7.2 as one complex sort.
        ranked = np.argsort(squared)
        ranked = ranked[np.argsort(owner.astype(np.uint16).take(ranked), kind="stable")]
        position, squared = position[ranked], squared[ranked]
        found = np.bincount(owner, minlength=per_row.size)
        owner = np.repeat(np.arange(per_row.size), found)
        rank = np.arange(owner.size) - np.repeat(np.cumsum(found) - found, found)
        kept = np.flatnonzero(rank < k)
        target = rows[owner[kept]]
        distance[target, rank[kept]] = np.sqrt(squared[kept])
        index[target, rank[kept]] = self._order[position[kept]]


def nearest_other_distance(points: ArrayLike) -> FloatArray:
    """Each point's distance to its nearest other point (``inf`` alone): the second column
    of ``cKDTree(points).query(points, k=2)[0]`` (0 for a repeated point)."""
    points = np.asarray(points, dtype=np.float64)
    n = points.shape[0]
    result = np.full(n, np.inf)
    if n < 2:
        return result
    span = float((points.max(axis=0) - points.min(axis=0)).max())
    if span == 0.0:
        return np.zeros(n)
    # Start from twice the spacing of n points spread evenly over the largest faces of the
    # box that holds the middle 96 % of them along each axis (one round for most ray
    # sets, a narrow cone of rays with a stray one included), and widen the reach for the
    # points with no neighbour within it (a neighbour found within the reach is the
    # nearest: every point nearer lies in the cells searched).
    dimension = points.shape[1]
    tail = n // 50
    ends = np.partition(points, (tail, n - 1 - tail), axis=0)
    extent = np.sort(ends[n - 1 - tail] - ends[tail])[::-1][: max(dimension - 1, 1)]
    extent = extent[extent > 0.0]
    reach = 2.0 * float(np.prod(extent) / n) ** (1.0 / extent.size) if extent.size else span
    pending = np.arange(n)
    while pending.size:
        if pending.size * n <= BRUTE_FORCE_PAIRS:
            # A few left (rays far from the rest): against every point at once.
            squared = np.zeros((pending.size, n))
            for axis in range(dimension):
                step = points[:, axis][None, :] - points[pending, axis][:, None]
                squared += step * step
            result[pending] = np.sqrt(np.partition(squared, 1, axis=1)[:, 1])
            break
        last = reach > CELL_MARGIN * span * math.sqrt(dimension)  # every other point within it
        index = NeighbourIndex(points, reach=reach)
        distance, _ = index.query(points[pending], k=2, distance_upper_bound=reach)
        found = np.isfinite(distance[:, 1])
        result[pending[found]] = distance[found, 1]
        pending = pending[~found]
        if last:
            break
        reach *= 4.0
    return result


__all__ = ["NeighbourIndex", "nearest_other_distance"]
