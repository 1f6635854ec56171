"""Walls as linear pieces: the run's returns summarised into short segments in the world frame.

:func:`fit_segments` cuts the plane into square cells and fits each cell's returns with
one line by their second moments (principal axis, its spread across the line); a cell
whose returns do not lie on one line within ``max_thickness`` is split in four, down to
``min_cell``. Each segment keeps its end points (the extreme projections of its returns
on the axis), its thickness (the returns' spread across it), how many positions
returned from it and, given where each return was seen from, the side it was seen from
(its *facing*: a wall seen from one side only hides what lies behind it, so returns
scattered behind its line meet no free beam there). Everything is done on every cell at
once: a few passes of ``np.unique`` and ``np.bincount``, no loop over points.

:func:`free_in_bands` measures, per segment, how much of the positions' beams passed
through its band well before their own return: a wall the beams often passed through was
not there for long (people, doors), and the map trusts it less: a counting model whose
cells are the segments' bands.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.fuse._sightings import _POSITIONS_AT_ONCE

FloatArray = NDArray[np.float64]

#: The first (largest) cell side, metres.
CELL = 0.64
#: Cells are not split below this side, metres.
MIN_CELL = 0.04
#: Returns within this standard deviation of their cell's line lie on one segment, metres.
MAX_THICKNESS = 0.03
#: A cell needs at least this many returns for a line; fewer at the finest side are a dot.
MIN_RETURNS = 3
#: A segment faces one side when at least this share of its returns were seen from it.
FACING_SHARE = 0.9


@dataclass
class Segments:
    """Line pieces in the world frame: ``start``, ``end`` ``(S, 2)`` metres, ``thickness``
    ``(S,)`` (the returns' standard deviation across the line), ``hits`` ``(S,)`` (the
    returns it was fitted to) and ``facing`` ``(S,)``: +1 when its returns were
    seen from the left of start -> end (the side of the normal ``(-dy, dx)``), -1 from the
    right, 0 from both or unknown."""

    start: FloatArray
    end: FloatArray
    thickness: FloatArray
    hits: NDArray[np.int64]
    facing: NDArray[np.int8]

    def __len__(self) -> int:
        return int(self.start.shape[0])

    @property
    def middle(self) -> FloatArray:
        return 0.5 * (self.start + self.end)


def _line_moments(points: FloatArray, cell: NDArray[np.intp], n_cells: int) -> tuple[FloatArray, ...]:
    """Per cell: count, mean, principal direction (unit), spread along and across it."""
    count = np.bincount(cell, minlength=n_cells).astype(np.float64)
    safe = np.maximum(count, 1.0)
    mx = np.bincount(cell, points[:, 0], n_cells) / safe
    my = np.bincount(cell, points[:, 1], n_cells) / safe
    dx, dy = points[:, 0] - mx[cell], points[:, 1] - my[cell]
    sxx = np.bincount(cell, dx * dx, n_cells) / safe
    sxy = np.bincount(cell, dx * dy, n_cells) / safe
    syy = np.bincount(cell, dy * dy, n_cells) / safe
    # The 2x2 covariance's eigen decomposition in closed form.
    half_trace = 0.5 * (sxx + syy)
    radius = np.hypot(0.5 * (sxx - syy), sxy)
    minor = np.maximum(half_trace - radius, 0.0)
    theta = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    return count, mx, my, np.cos(theta), np.sin(theta), np.sqrt(minor)


#: Returns in one stripe of cells at most (unless one column of cells holds more):
#: :func:`fit_segments` works a stripe at a time, so a large run's temporaries are a stripe's.
STRIPE_RETURNS = 1 << 18


def fit_segments(points: FloatArray, owner: NDArray[np.intp], *, viewpoints: FloatArray | None = None,
                 owner_positions: FloatArray | None = None,
                 cell: float = CELL, min_cell: float = MIN_CELL, max_thickness: float = MAX_THICKNESS,
                 min_returns: int = MIN_RETURNS, facing_share: float = FACING_SHARE) -> Segments:
    """Segments through world returns ``(N, 2)`` of positions ``owner`` ``(N,)``.

    A cell of side ``cell`` (then half, down to ``min_cell``) whose returns number at least
    ``min_returns`` and lie within ``max_thickness`` (standard deviation) of their principal
    axis becomes one segment; the returns of the other cells go on to the next, finer side.
    At the finest side every cell left is a segment, however few or scattered its returns.
    ``viewpoints`` ``(N, 2)``: where each return was seen from (its position), or
    ``owner_positions`` ``(P, 2)``: where each position is (the viewpoints are
    ``owner_positions[owner]``, never made whole); a segment faces the side that at least
    ``facing_share`` of its returns were seen from (without viewpoints every segment faces
    both).

    The cells of side ``cell`` are taken a stripe of columns at a time
    (:data:`STRIPE_RETURNS`): a cell and the finer cells in it lie in one stripe, so each is
    fitted to the same returns in the same order as all at once, and the segments come in
    the same order, by side, then column, then row of their cell.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    owner = np.asarray(owner, dtype=np.int64).reshape(-1)
    if viewpoints is not None:
        viewpoints = np.asarray(viewpoints, dtype=np.float64).reshape(-1, 2)
        if viewpoints.shape[0] != points.shape[0]:
            raise ValueError(f"{points.shape[0]} returns need as many viewpoints, got {viewpoints.shape[0]}")
    if not points.shape[0]:
        empty = np.zeros((0, 2))
        return Segments(empty, empty.copy(), np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int8))
    origin = points.min(axis=0)
    column = np.floor((points[:, 0] - origin[0]) / cell)
    stripes = _stripes(np.bincount(column.astype(np.int64)), STRIPE_RETURNS)
    by_side: dict[int, list[tuple[NDArray[np.generic], ...]]] = {}
    for low, high in stripes:
        taken = slice(None) if len(stripes) == 1 else np.flatnonzero((column >= low) & (column < high))
        sights = (viewpoints[taken] if viewpoints is not None else
                  owner_positions[owner[taken]] if owner_positions is not None else None)
        for depth, fields in _fit_cells(points[taken], sights, origin, cell=float(cell),
                                        min_cell=min_cell, max_thickness=max_thickness, min_returns=min_returns,
                                        facing_share=facing_share):
            by_side.setdefault(depth, []).append(fields)
    del column
    # By side, then by stripe: a stripe's cells come column by column, row by row, and the
    # stripes are runs of columns in order, as one pass over every return gives them.
    parts = [fields for depth in sorted(by_side) for fields in by_side[depth]]
    return Segments(*(np.concatenate([part[k] for part in parts]) for k in range(5)))


def _stripes(counts: NDArray[np.int64], most: int) -> list[tuple[int, int]]:
    """Runs of columns ``[low, high)`` holding at most ``most`` returns together (a column
    holding more on its own)."""
    ends = np.cumsum(counts)
    stripes, low, base = [], 0, 0
    while low < counts.size:
        high = max(int(np.searchsorted(ends, base + most, side="right")), low + 1)
        stripes.append((low, high))
        base, low = int(ends[high - 1]), high
    return stripes


def _fit_cells(points: FloatArray, viewpoints: FloatArray | None, origin: FloatArray, *, cell: float,
               min_cell: float, max_thickness: float, min_returns: int,
               facing_share: float) -> list[tuple[int, tuple[NDArray[np.generic], ...]]]:
    """:func:`fit_segments` of the returns of whole cells of side ``cell`` from ``origin``:
    for each side (0 the first, ``cell``) that made segments, their start, end, thickness,
    hits and facing, by column then row of their cell."""
    out: list[tuple[int, tuple[NDArray[np.generic], ...]]] = []
    pending = np.arange(points.shape[0])
    side, depth = cell, 0
    while pending.size:
        last = side / 2.0 < min_cell - 1e-12
        p = points[pending]
        ij = np.floor((p - origin) / side).astype(np.int64)
        height = int(ij[:, 1].max()) + 1
        key = ij[:, 0] * height + ij[:, 1]
        del ij
        keys, which = np.unique(key, return_inverse=True)
        which = which.reshape(-1)
        count, mx, my, ux, uy, spread = _line_moments(p, which, keys.size)
        accept = last | ((count >= min_returns) & (spread <= max_thickness))
        taken = accept[which]
        if taken.any():
            rows = np.flatnonzero(accept)
            renumber = np.full(keys.size, -1, dtype=np.int64)
            renumber[rows] = np.arange(rows.size)
            c = renumber[which[taken]]
            q, w = p[taken], which[taken]
            along = (q[:, 0] - mx[w]) * ux[w] + (q[:, 1] - my[w]) * uy[w]
            low = np.full(rows.size, np.inf)
            high = np.full(rows.size, -np.inf)
            np.minimum.at(low, c, along)
            np.maximum.at(high, c, along)
            centre = np.column_stack([mx[rows], my[rows]])
            axis = np.column_stack([ux[rows], uy[rows]])
            sides = _facing(q, viewpoints[pending[taken]] if viewpoints is not None else None,
                            ux[w], uy[w], c, rows.size, facing_share)
            sides[high - low <= 1e-9] = 0  # a dot has no line to face from
            out.append((depth, (centre + low[:, None] * axis, centre + high[:, None] * axis, spread[rows],
                                count[rows].astype(np.int64),
                                sides.astype(np.int8))))
        pending = pending[~taken]
        side /= 2.0
        depth += 1
    return out


def _facing(returns: FloatArray, viewpoints: FloatArray | None, ux: FloatArray, uy: FloatArray,
            segment: NDArray[np.int64], n_segments: int, share: float) -> NDArray[np.int8]:
    """Per segment, the side of its line (+1 left of its axis ``(ux, uy)``, -1 right, 0 both)
    that at least ``share`` of its ``returns`` were seen from (``viewpoints``, one per return)."""
    if viewpoints is None:
        return np.zeros(n_segments, dtype=np.int8)
    left = (viewpoints[:, 0] - returns[:, 0]) * -uy + (viewpoints[:, 1] - returns[:, 1]) * ux
    from_left = np.bincount(segment, left > 0, n_segments)
    seen = np.bincount(segment, left != 0, n_segments)
    out = np.zeros(n_segments, dtype=np.int8)
    out[(seen > 0) & (from_left >= share * seen)] = 1
    out[(seen > 0) & (seen - from_left >= share * seen)] = -1
    return out


def free_in_bands(start: FloatArray, end: FloatArray, thickness: FloatArray, poses: FloatArray,
                  distances: Any, *, margin: float, reach: float, half_width: float,
                  spacing: float) -> FloatArray:
    """Metres of the positions' free beams inside each segment's band.

    A segment's band is its line widened to ``half_width`` or its ``thickness`` either side,
    whichever is more, and lengthened by ``half_width`` past each end. ``poses`` ``(P, 4)``
    are x, y, z, yaw; ``distances`` ``(P, bins)`` (an array, or
    :class:`occtool.fuse._sightings.StoredRanges`, read a block of rows at a time) each position's
    range per pan bin (its nearest return, or how far it saw where it had none; 0 where it saw
    nothing). A beam is
    free up to ``margin`` before its range, and no farther than ``reach``.

    Summed over a position's beams, the length of their free parts inside a small area is
    the area over the beams' spacing there (``distance * 2 pi / bins``); each band is
    measured so at points no more than ``spacing`` apart along it (each standing for its
    share of the band's area), each counted where its own bin's beam passed it free.
    """
    from scipy.spatial import cKDTree

    vector = end - start
    length = np.hypot(vector[:, 0], vector[:, 1])
    axis = vector / np.maximum(length, 1e-12)[:, None]
    along, width = length + 2.0 * half_width, 2.0 * np.maximum(thickness, half_width)
    parts = np.maximum(np.ceil(along / spacing - 1e-9).astype(np.int64), 1)
    owner = np.repeat(np.arange(start.shape[0]), parts)
    step = np.arange(owner.size) - np.repeat(np.cumsum(parts) - parts, parts)
    offset = ((step + 0.5) / parts[owner] - 0.5) * along[owner]
    points = 0.5 * (start + end)[owner] + offset[:, None] * axis[owner]
    bins = distances.shape[1]
    # Sum over the positions that passed each point of 1 / distance (the beams' spacing there).
    inverse = np.zeros(points.shape[0])
    if points.shape[0] == 0:
        return inverse
    index = cKDTree(points)
    block = np.zeros((0, bins))
    for k in range(poses.shape[0]):  # a loop over positions, each vectorised over its points
        if k % _POSITIONS_AT_ONCE == 0:  # the distances read a block of positions at a time
            block = np.asarray(distances[k:k + _POSITIONS_AT_ONCE], dtype=np.float64)
        row = block[k % _POSITIONS_AT_ONCE]
        x, y, _, yaw = poses[k]
        far = float(min(reach, row.max()))
        if far <= margin:
            continue
        near = np.asarray(index.query_ball_point((x, y), far), dtype=np.intp)
        if near.size == 0:
            continue
        dx, dy = points[near, 0] - x, points[near, 1] - y
        c, s = math.cos(yaw), math.sin(yaw)
        alpha = np.arctan2(-s * dx + c * dy, c * dx + s * dy)
        b = np.clip(np.floor((alpha + math.pi) / (2.0 * math.pi) * bins).astype(np.intp), 0, bins - 1)
        distance = np.hypot(dx, dy)
        passed = distance < np.minimum(row[b], reach) - margin
        inverse[near[passed]] += 1.0 / np.maximum(distance[passed], margin)
    area = (along * width / parts)[owner]
    free = np.bincount(owner, inverse * area * (bins / (2.0 * math.pi)), minlength=start.shape[0]).astype(np.float64)
    return free
