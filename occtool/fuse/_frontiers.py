"""The frontiers of a large raster found a strip of rows at a time (:func:`frontiers_in_strips`).

:func:`occtool.fuse.frontiers_of` labels the whole raster at once: a label (int32) and a few
flags a cell, ~120 MB at the peak for the Freiburg campus's 20.6 million cells. Here each
strip of rows is labelled on its own; the pieces of a frontier that a strip boundary cut
are joined where two of their cells touch across it (8-connected, as the labelling is), and
the frontiers' sizes, centroids and points are then computed from their cells in the order
:func:`frontiers_of` meets them (row-major), with the same arithmetic: the points are the
same, bit for bit, in the same order.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.raster import FREE, UNKNOWN

FloatArray = NDArray[np.float64]

#: Cells labelled at a time (a whole number of rows, at least one).
STRIP_CELLS = 1 << 20


def _unexplored(raster: Any, low: int, high: int) -> NDArray[np.bool_]:
    """Rows ``low`` to ``high`` (exclusive, clipped to the raster) unknown and unexplored,
    padded with a column of True each side and a row of True where the raster ends."""
    rows, cols = raster.shape
    out = np.ones((high - low, cols + 2), dtype=bool)
    a, b = max(low, 0), min(high, rows)
    unknown = raster.cells[a:b] == UNKNOWN
    if raster.explored is not None:
        unknown &= ~raster.explored[a:b]
    out[a - low:b - low, 1:-1] = unknown
    return out


def frontiers_in_strips(raster: Any, min_length: float, *, strip_cells: int = STRIP_CELLS) -> FloatArray:
    """:func:`occtool.fuse.frontiers_of` of ``raster`` with ``min_length``, computed a strip
    of rows (``strip_cells`` cells) at a time: the same points in the same order."""
    from scipy import ndimage
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rows, cols = raster.shape
    step = max(1, strip_cells // max(cols, 1))
    eight = np.ones((3, 3), dtype=bool)
    cell_rows, cell_cols, cell_ids = [], [], []
    joins: list[NDArray[np.int64]] = []
    count = 0
    previous: NDArray[np.int64] | None = None  # the last strip's bottom row of ids (-1: none)
    for low in range(0, rows, step):
        high = min(low + step, rows)
        beyond = _unexplored(raster, low - 1, high + 1)
        touches = beyond[:-2, 1:-1] | beyond[2:, 1:-1] | beyond[1:-1, :-2] | beyond[1:-1, 2:]
        labels, found = ndimage.label((raster.cells[low:high] == FREE) & touches, structure=eight)
        r, c = np.nonzero(labels)
        ids = labels[r, c].astype(np.int64) - 1 + count
        cell_rows.append(r.astype(np.int64) + low)
        cell_cols.append(c.astype(np.int64))
        cell_ids.append(ids)
        top = np.full(cols, -1, dtype=np.int64)
        first = r == 0
        top[c[first]] = ids[first]
        if previous is not None:
            # Pieces touching across the boundary (8-connected) are one frontier.
            for shift in (-1, 0, 1):
                upper = previous[max(0, -shift):cols - max(0, shift)]
                lower = top[max(0, shift):cols - max(0, -shift)]
                both = (upper >= 0) & (lower >= 0)
                joins.append(np.stack([upper[both], lower[both]]))
        previous = np.full(cols, -1, dtype=np.int64)
        last = r == high - low - 1
        previous[c[last]] = ids[last]
        count += found
    if count == 0:
        return np.zeros((0, 2))
    pairs = np.concatenate(joins, axis=1) if joins else np.zeros((2, 0), dtype=np.int64)
    graph = coo_matrix((np.ones(pairs.shape[1]), (pairs[0], pairs[1])), shape=(count, count))
    count, component = connected_components(graph, directed=False)
    rows_of = np.concatenate(cell_rows)
    cols_of = np.concatenate(cell_cols)
    group = component[np.concatenate(cell_ids)]
    return frontier_points(raster, rows_of, cols_of, group, count, min_length)


def frontier_points(raster: Any, rows: NDArray[np.intp], cols: NDArray[np.intp], group: NDArray[np.int64],
                    count: int, min_length: float) -> FloatArray:
    """One point a frontier of ``count``: frontier cells ``(rows, cols)`` in row-major order,
    ``group`` numbering each one's frontier; frontiers shorter than ``min_length`` metres
    dropped, each other's cell nearest its centroid kept (ties: the first in row-major
    order), ordered by size, largest first, then by position (:func:`occtool.fuse.frontiers_of`)."""
    sizes = np.bincount(group, minlength=count)
    centre_row = np.bincount(group, rows, count) / sizes
    centre_col = np.bincount(group, cols, count) / sizes
    spread = (rows - centre_row[group]) ** 2 + (cols - centre_col[group]) ** 2
    order = np.lexsort((np.arange(len(group)), spread, group))
    nearest = order[np.r_[0, np.flatnonzero(np.diff(group[order])) + 1]]
    keep = nearest[sizes[group[nearest]] * raster.resolution >= min_length]
    keep = keep[np.lexsort((cols[keep], rows[keep], -sizes[group[keep]]))]
    return np.column_stack([raster.origin[0] + (cols[keep] + 0.5) * raster.resolution,
                            raster.origin[1] + (rows[keep] + 0.5) * raster.resolution])


__all__ = ["STRIP_CELLS", "frontier_points", "frontiers_in_strips"]
