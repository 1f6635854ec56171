"""What a row of the raster's tiles asks of a world map, answered a tile at a time from the
few segments or positions that can matter there (:func:`tile_walls`, :func:`tile_position_distances`).

A cell of the raster asks the walls for the MAX over the ridges of its :data:`NEIGHBOURS`
nearest segment middles within reach, and the distance to the nearest of their bands
(:meth:`WorldMap._wall_values`, :meth:`WorldMap._wall_distances`), and the positions for the
nearest one (:meth:`WorldMap.free_value`). Asked cell by cell, each is a k-d tree query; most
of them can be answered for a whole tile from a short list instead, with the same float64
numbers:

* a segment matters to a cell only where its ridge rises above the least occupancy the
  raster's base takes there (:meth:`WorldMap.floor_level`: a ridge below it changes neither
  the drawn occupancy nor the cells) or its band lies within ``within`` of it; both happen
  within :func:`influence` of its middle, so a tile lists the segments whose influence
  reaches its box (its *relevant* segments);
* where at most :data:`NEIGHBOURS` middles lie within the farthest a relevant segment can
  matter plus the box's half-diagonal, every segment that matters to a cell of the tile is
  among its nearest: each cell takes the MAX and MIN over the relevant segments (their
  middles within the queries' reaches, the same test as the tree's), a few numbers a cell;
* a tile crowded with segments (a wall's thick of short ones) is split in four and its
  quarters sorted the same way; the cells of crowded small tiles ask the tree as before;
* the nearest position to a cell lies within the nearest to its tile's centre plus the
  box's whole diagonal: a tile's cells take the MIN over those few (the tree's squared
  distance, then its root), or ask the tree where there are many.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.fuse._world import NEIGHBOURS

FloatArray = NDArray[np.float64]
#: What :func:`tile_walls` answers, each ``(tiles, rows, columns)``: the MAX over every ridge and
#: over the trusted ones, the distances to the nearest band counted (a doubted wall's or a
#: trusted one's) and to the nearest trusted one.
Walls = tuple[FloatArray, FloatArray, FloatArray, FloatArray]

#: Added to a tile's radii so that rounding never drops a segment or position a cell would meet.
_SLACK = 1e-6
#: A tile whose cells may have more candidate positions than this, less one, asks the tree
#: cell by cell (a raster of a few huge tiles would otherwise measure every cell to every position).
POSITION_CANDIDATES = 32
#: A crowded tile is split in four while its sides are longer than this (cells): its
#: quarters list fewer segments, and the tree is asked about fewer cells.
SMALLEST_SIDE = 4


def influence(world: Any, within: float, floor: float, least_trust: float, *, all_ridges: bool = True) -> FloatArray:
    """How far from each segment's middle it can matter to a cell of the raster (metres;
    ``-inf``: nowhere): its ridge above ``floor`` (every segment's, or without ``all_ridges``
    only the trusted ones': the raster's cells draw no other) or its band within ``within`` (the
    segments of trust >= ``least_trust``: the bands the cells ask about).

    The ridge (:meth:`WorldMap._ridges`) exceeds ``floor`` only less than ``w (1 - floor / p)``
    beyond the thickness across the line (``w`` the widest slope on either side, ``p`` the peak)
    and ``width (1 - floor / p)`` past the half-length along it; the band is within ``within``
    only ``within`` beyond both; a point inside either rectangle is nearer the middle than its corner.
    """
    world._segment_tree()  # the segments' frames
    _, _, _, half = world._frames
    share = 1.0 - floor / world.peak
    sloped = np.where(world.facing == 0, world.width, max(world.front_width, world.back_width))
    ridge = np.where(share > 0, np.hypot(world.thickness + sloped * share, half + world.width * share), -np.inf)
    if not all_ridges:
        ridge[world.trust < world.wall_share] = -np.inf
    band = np.where(world.trust >= least_trust, np.hypot(world.thickness + within, half + within), -np.inf)
    return np.maximum(ridge, band)


def _pairs(tree: Any, centres: FloatArray, radius: float) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """The tiles (their ``centres``) and the points of ``tree`` within ``radius`` of them, as
    pairs sorted by tile (one query for all of them: no list a tile)."""
    from scipy.spatial import cKDTree

    pairs = cKDTree(centres).sparse_distance_matrix(tree, radius, output_type="ndarray")
    order = np.argsort(pairs["i"], kind="stable")
    return pairs["i"][order].astype(np.intp), pairs["j"][order].astype(np.intp)


def _rank(tiles: NDArray[np.intp], count: int) -> NDArray[np.intp]:
    """Each pair's place among its tile's pairs (the pairs sorted by tile)."""
    starts = np.concatenate([[0], np.cumsum(np.bincount(tiles, minlength=count))[:-1]])
    return np.arange(tiles.size) - starts[tiles]


def tile_walls(world: Any, x: FloatArray, y: FloatArray, centres: FloatArray, half: FloatArray,
               within: float, doubted_trust: float, matters: FloatArray | None = None, *,
               all_ridges: bool = True) -> Walls:
    """The walls' values and band distances at tiles' cells: MAX over the ridges of every
    segment and of the trusted ones (``-inf`` where none matters), and the distances to the
    nearest band of a segment of trust >= ``doubted_trust`` and of a trusted one (``inf``
    beyond ``within``), each ``(tiles, rows, columns)``.

    ``x``: ``(tiles, columns)`` and ``y``: ``(tiles, rows)`` the cells' centres; ``centres``
    and ``half`` each tile's middle and the farthest its cells lie from it; ``matters``: the
    segments' :func:`influence` (``None``: above :meth:`WorldMap.floor_level`, every
    segment's). A value at or below the floor ``matters`` was measured for, or of a segment
    it leaves out, may read ``-inf`` (the raster draws the same), otherwise the numbers are
    those of :meth:`WorldMap._wall_values` and :meth:`WorldMap._wall_distances`. Without
    ``all_ridges`` the MAX over every ridge is not wanted (it is left ``-inf`` where the tiles'
    lists answer).
    A tile too crowded to list its segments is split in four (while its sides are even and
    longer than :data:`SMALLEST_SIDE`), and what is still crowded asks the tree cell by cell."""
    count, rows, columns = x.shape[0], y.shape[1], x.shape[1]
    shape = (count, rows, columns)
    every, of_trusted = np.full(shape, -np.inf), np.full(shape, -np.inf)
    near_doubted, near_trusted = np.full(shape, np.inf), np.full(shape, np.inf)
    if len(world) and matters is None:
        matters = influence(world, within, world.floor_level(), doubted_trust)
    if not len(world) or not count or matters is None or not np.isfinite(matters).any():
        return every, of_trusted, near_doubted, near_trusted
    tree = world._segment_tree()
    tiles, segments = _pairs(tree, centres, float(matters.max() + half.max()) + 2 * _SLACK)
    distance = np.hypot(centres[tiles, 0] - world._frames[0][segments, 0],
                        centres[tiles, 1] - world._frames[0][segments, 1])
    relevant = distance < matters[segments] + half[tiles] + _SLACK
    # The farthest a relevant segment's middle can lie from a cell it matters to; the middles
    # nearer a cell than that lie within it plus the half-diagonal of the tile's centre.
    farthest = np.zeros(count)
    np.maximum.at(farthest, tiles[relevant], np.minimum(matters[segments], distance + half[tiles])[relevant])
    crowd = np.bincount(tiles[distance < farthest[tiles] + half[tiles] + _SLACK], minlength=count)
    touched = np.bincount(tiles[relevant], minlength=count) > 0
    listed = touched & (crowd <= min(NEIGHBOURS, len(world)))
    _listed_walls(world, x, y, tiles[relevant & listed[tiles]], segments[relevant & listed[tiles]],
                  within, doubted_trust, (every if all_ridges else None, of_trusted, near_doubted, near_trusted))
    crowded = np.flatnonzero(touched & ~listed)
    if not crowded.size:
        return every, of_trusted, near_doubted, near_trusted
    inner = (crowded.size, rows, columns)
    if rows % 2 == 0 and columns % 2 == 0 and min(rows, columns) > SMALLEST_SIDE:
        quarters = _quarters(x[crowded], y[crowded])
        answers = tile_walls(world, *quarters, within, doubted_trust, matters, all_ridges=all_ridges)
        # Back from (row half, column half, tile, rows, columns) to the tiles' own cells.
        answers = tuple(a.reshape(2, 2, crowded.size, rows // 2, columns // 2).transpose(2, 0, 3, 1, 4).reshape(inner)
                        for a in answers)
    else:
        xy = np.column_stack([np.broadcast_to(x[crowded, None, :], inner).ravel(),
                              np.broadcast_to(y[crowded, :, None], inner).ravel()])
        answers = cell_walls(world, xy, within, doubted_trust)
    for whole, answer in zip((every, of_trusted, near_doubted, near_trusted), answers):
        whole[crowded] = answer.reshape(inner)
    return every, of_trusted, near_doubted, near_trusted


def cell_walls(world: Any, xy: FloatArray, within: float, doubted_trust: float) -> Walls:
    """``(*world._wall_values(xy), *world._wall_distances(xy, within, doubted_trust))``, the
    same numbers, from one neighbour query a point, not two.

    Each of those asks the tree for the :data:`NEIGHBOURS` nearest middles within its own
    reach (the ridges' and the bands'), and takes the MAX or MIN over them. Here the tree is
    asked once for one more neighbour within the larger reach: the nearest within a smaller
    reach are the first of them that lie within it (the tree's own test, a squared distance
    below the squared reach), and a MAX or MIN over a set does not depend on its order. Where
    the last neighbour wanted and the one after it lie equally far within the reach, which of
    them the tree keeps is its own choice: those points ask both queries as before."""
    from occtool.fuse._world import _BLOCK

    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    count = xy.shape[0]
    every, of_trusted = np.full(count, -np.inf), np.full(count, -np.inf)
    near_doubted, near_trusted = np.full(count, np.inf), np.full(count, np.inf)
    if not len(world) or not count:
        return every, of_trusted, near_doubted, near_trusted
    tree = world._segment_tree()
    middle = world._frames[0]
    ridge_reach = world._reach(max(world.width, world.front_width, world.back_width))
    band_reach = world._reach(within + 1e-9)
    reach = max(ridge_reach, band_reach)
    trusted = world.trust >= world.wall_share
    counted = world.trust >= doubted_trust
    wanted = min(NEIGHBOURS, len(world))
    asked = min(NEIGHBOURS + 1, len(world))
    tied: list[NDArray[np.intp]] = []
    for low in range(0, count, _BLOCK):
        rows = slice(low, low + _BLOCK)
        block = xy[rows]
        distance, index = tree.query(block, k=asked, distance_upper_bound=reach)
        distance = np.asarray(distance).reshape(block.shape[0], asked)
        index = np.asarray(index).reshape(block.shape[0], asked)
        if asked > wanted:
            tie = (distance[:, wanted - 1] == distance[:, wanted]) & np.isfinite(distance[:, wanted])
            if tie.any():
                tied.append(low + np.flatnonzero(tie))
            distance, index = distance[:, :wanted], index[:, :wanted]
        found = np.isfinite(distance)
        s = np.where(found, index, 0)
        dx, dy = block[:, :1] - middle[s, 0], block[:, 1:] - middle[s, 1]
        squared = dx * dx + dy * dy
        across, along = world._offsets(block[:, :1], block[:, 1:], s)
        value = np.where(found & (squared < ridge_reach * ridge_reach), world._ridges(s, across, along), -np.inf)
        every[rows] = value.max(axis=1)
        of_trusted[rows] = np.where(trusted[s], value, -np.inf).max(axis=1)
        gap = np.where(found & (squared < band_reach * band_reach), world._gaps(s, across, along), np.inf)
        near_doubted[rows] = np.where(counted[s], gap, np.inf).min(axis=1)
        near_trusted[rows] = np.where(trusted[s], gap, np.inf).min(axis=1)
    near_doubted[near_doubted > within] = np.inf
    near_trusted[near_trusted > within] = np.inf
    if tied:
        ties = np.concatenate(tied)
        answers = (*world._wall_values(xy[ties]), *world._wall_distances(xy[ties], within, doubted_trust))
        for whole, answer in zip((every, of_trusted, near_doubted, near_trusted), answers):
            whole[ties] = answer
    return every, of_trusted, near_doubted, near_trusted


def _quarters(x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Each tile's four quarters (lower rows first, left columns first, then the tiles) as
    :func:`tile_walls` takes tiles: their cells' columns and rows, middles and half-diagonals."""
    columns, rows = x.shape[1] // 2, y.shape[1] // 2
    qx = np.concatenate([x[:, :columns], x[:, columns:]] * 2)
    qy = np.concatenate([y[:, :rows]] * 2 + [y[:, rows:]] * 2)
    lower, upper = np.column_stack([qx.min(axis=1), qy.min(axis=1)]), np.column_stack([qx.max(axis=1), qy.max(axis=1)])
    return qx, qy, 0.5 * (lower + upper), 0.5 * np.hypot(*(upper - lower).T)


def _listed_walls(world: Any, x: FloatArray, y: FloatArray, tiles: NDArray[np.intp], segments: NDArray[np.intp],
                  within: float, doubted_trust: float,
                  out: tuple[FloatArray | None, FloatArray, FloatArray, FloatArray]) -> None:
    """:func:`tile_walls` of the tiles that list their segments (``tiles``, ``segments``:
    the pairs, sorted by tile), into ``out`` (its first ``None``: every ridge's MAX not
    wanted): one pass over the tiles' first segments, one
    over their second, and so on (at most :data:`NEIGHBOURS`)."""
    every, of_trusted, near_doubted, near_trusted = out
    middle = world._frames[0]
    # The trees' tests: a squared distance below the squared reach (scipy's cKDTree.query).
    ridge_reach, band_reach = (reach * reach for reach in (
        world._reach(max(world.width, world.front_width, world.back_width)), world._reach(within + 1e-9)))
    trusted = world.trust >= world.wall_share
    counted = world.trust >= doubted_trust
    rank = _rank(tiles, x.shape[0])
    for place in range(int(rank.max()) + 1 if rank.size else 0):
        chosen = rank == place
        t, s = tiles[chosen], segments[chosen][:, None, None]
        cx, cy = x[t][:, None, :], y[t][:, :, None]
        dx, dy = cx - middle[s, 0], cy - middle[s, 1]
        squared = dx * dx + dy * dy
        across, along = world._offsets(cx, cy, s)
        value = np.where(squared < ridge_reach, world._ridges(s, across, along), -np.inf)
        if every is not None:
            every[t] = np.maximum(every[t], value)
        of_trusted[t] = np.maximum(of_trusted[t], np.where(trusted[s], value, -np.inf))
        gap = np.where(squared < band_reach, world._gaps(s, across, along), np.inf)
        gap[gap > within] = np.inf
        near_doubted[t] = np.minimum(near_doubted[t], np.where(counted[s], gap, np.inf))
        near_trusted[t] = np.minimum(near_trusted[t], np.where(trusted[s], gap, np.inf))


def tile_position_distances(world: Any, x: FloatArray, y: FloatArray, centres: FloatArray,
                            half: FloatArray) -> FloatArray:
    """Distance from each cell of tiles (``x``: ``(tiles, columns)``, ``y``: ``(tiles, rows)``)
    to the nearest of the map's positions, ``(tiles, rows, columns)``: the numbers of
    :meth:`WorldMap._position_distance` (``centres``, ``half``: each tile's middle and the
    farthest its cells lie from it)."""
    count, rows, columns = x.shape[0], y.shape[1], x.shape[1]
    nearest = np.full((count, rows, columns), np.inf)
    if not count:
        return nearest
    # The nearest few positions of each tile's centre: the first is the nearest, and those
    # within it plus the tile's diagonal are the candidates (all of them unless the last is too).
    known = min(POSITION_CANDIDATES, world.positions.shape[0])
    distance, index = world._position_tree().query(centres, k=known)
    distance, index = np.asarray(distance).reshape(count, known), np.asarray(index).reshape(count, known)
    candidate = distance < distance[:, :1] + 2 * half[:, None] + _SLACK
    listed = ~candidate[:, -1] | (known == world.positions.shape[0])
    tiles, column = np.nonzero(candidate & listed[:, None])
    found = index[tiles, column]
    rank = _rank(tiles, count)
    for place in range(int(rank.max()) + 1 if rank.size else 0):
        chosen = rank == place
        t, p = tiles[chosen], found[chosen]
        dx = x[t] - world.positions[p, 0][:, None]
        dy = y[t] - world.positions[p, 1][:, None]
        # The tree's own sum (x first, then y); the root of the least is the least root.
        nearest[t] = np.minimum(nearest[t], dx[:, None, :] * dx[:, None, :] + (dy * dy)[:, :, None])
    listed_tiles = np.flatnonzero(listed)
    nearest[listed_tiles] = np.sqrt(nearest[listed_tiles])
    asked = np.flatnonzero(~listed)
    if asked.size:
        xy = np.column_stack([np.broadcast_to(x[asked, None, :], (asked.size, rows, columns)).ravel(),
                              np.broadcast_to(y[asked, :, None], (asked.size, rows, columns)).ravel()])
        nearest[asked] = world._position_distance(xy).reshape(asked.size, rows, columns)
    return nearest


__all__ = ["POSITION_CANDIDATES", "SMALLEST_SIDE", "cell_walls", "influence", "tile_position_distances", "tile_walls"]
