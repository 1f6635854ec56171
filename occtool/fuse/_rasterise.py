"""A world map's Nav2 raster computed in row strips, tile by tile (:func:`rasterise`).

Every cell of the raster depends only on its centre (:meth:`WorldMap.rasterise` says how),
so the raster is built a strip of rows at a time: the temporaries (cell centres, what the
tiles' cells ask of the walls and the positions) are those of one strip, not of the whole
extent, and only the raster itself (uint8 cells, float32 occupancy) is held whole. Before a
strip's cells are queried its square tiles are sorted by what they can meet, so that most
cells of a large map cost no query at all:

* a tile whose box lies inside the observed region is observed in every cell, one outside
  it in none; only the cells of tiles on the region's boundary are tested one by one (and
  the same for the part of it the raster may call free, :attr:`WorldMap.free_region`),
  each against the regions cut to its rows and its block of columns (:class:`_RegionBlocks`:
  a box's test costs time with every ring of the region it is tested against);
* a tile lists the few segments that can matter to its cells and the positions that can be
  the nearest to them, and its cells are measured against those alone; a tile no segment
  reaches skips the walls, and only the cells of a thick of segments ask the k-d tree one
  by one (:mod:`occtool.fuse._tile_queries`).

Both only decide tiles whose every cell would get the same answer from the per-cell
queries, so the raster is the same, byte for byte, as one computed over all cells at once,
but for a cell whose centre lies on an edge of a region (the regions' vertices and the
cells' centres lie on grids): cutting a region to a band or a block of columns rounds the
ends of the edges it crosses, and such a cell may then read inside (3 of the 315 M cells of
the campus mapped ten times over; none on Intel or the campus up to four times, docs/map.md).
"""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.fuse._tile_queries import influence, tile_position_distances, tile_walls
from occtool.raster import FREE, OCCUPIED, RASTER_FREE, RASTER_OCCUPIED, UNKNOWN, PackedFlags, Raster, SpilledCells

FloatArray = NDArray[np.float64]

#: Side of a tile, cells: large enough that the per-tile tests are few, small enough that
#: a wall's neighbourhood or the region's boundary takes few tiles' cells with it.
TILE = 16
#: Cells of one strip (a whole number of tile rows): bounds the temporaries, about 200
#: bytes a cell queried (a 2**19-cell strip: ~100 MB at most).
STRIP_CELLS = 1 << 19
#: Cells of a raster whose cells are kept in a file when a folder is given for them
#: (:func:`rasterise`'s ``spill``): below it the file's cost is not worth the memory saved.
SPILL_CELLS = 1 << 24


def raster_shape(world: Any, resolution: float) -> tuple[tuple[float, float], int, int]:
    """The raster's origin (lower-left corner, on the ``resolution`` grid) and its columns and rows."""
    lower, upper = world.bounds
    origin = np.floor(lower / resolution) * resolution
    nx, ny = (np.ceil((upper - origin) / resolution).astype(np.int64) + 1).tolist()
    return (float(origin[0]), float(origin[1])), int(nx), int(ny)


def rasterise(world: Any, resolution: float, nx: int, ny: int, origin: tuple[float, float],
              within: float, doubted_trust: float, *, tile: int = TILE,
              strip_cells: int = STRIP_CELLS, executor: Any = None, occupancy: bool = True,
              spill: str | os.PathLike[str] | None = None, spill_cells: int | None = None) -> Raster:
    """The raster of ``world`` (a :class:`WorldMap`), ``ny`` rows of ``nx`` cells from
    ``origin``, strip by strip; ``within`` is the widest wall band or rim the cells ask
    about and ``doubted_trust`` the least trust of a doubted wall (:meth:`WorldMap.rasterise`).
    ``executor`` (an :class:`occtool.executor.Executor`; ``None``: this process) computes
    the bands of rows (:func:`tile_rows`); the raster is the same wherever they ran.
    Without ``occupancy`` the raster keeps no float32 occupancy (``probability`` ``None``):
    a byte and an eighth a cell held (the cells, the explored flags packed), not five and an eighth.
    ``spill``: a folder where the cells of a raster of more than ``spill_cells`` cells
    (``None``: :data:`SPILL_CELLS`) are kept in an unnamed temporary file
    (:class:`occtool.raster.SpilledCells`), not in memory: the explored flags' eighth of a
    byte a cell held (``None``: in memory)."""
    if spill is not None and nx * ny > (SPILL_CELLS if spill_cells is None else spill_cells):
        cells: NDArray[np.uint8] | SpilledCells = SpilledCells((ny, nx), UNKNOWN, spill)
    else:
        cells = np.full((ny, nx), UNKNOWN, dtype=np.uint8)
    probability = np.empty((ny, nx), dtype=np.float32) if occupancy else None
    explored = PackedFlags((ny, nx))  # an eighth of a byte a cell
    for low, high, strip in raster_bands(world, resolution, nx, ny, origin, within, doubted_trust, tile=tile,
                                         strip_cells=strip_cells, executor=executor, occupancy=occupancy):
        cells[low:high], explored[low:high] = strip[0], strip[2]
        if probability is not None:
            probability[low:high] = strip[1]
        del strip
    from occtool.limits import release_free_memory

    release_free_memory()  # the strips' freed temporaries
    # No cell of a world map's raster holds contradicting positions: one False seen everywhere.
    conflict = np.broadcast_to(np.zeros(1, dtype=bool), (ny, nx))
    return Raster(cells, float(resolution), origin, probability, conflict, explored=explored)


#: Rows of tiles a task of :func:`raster_bands` computes at most: a band of about this many
#: strips' cells, so that a cluster's cost per task (the world map sent, its segment tree
#: built) is shared by many tiles.
BAND_STRIPS = 4


def raster_bands(world: Any, resolution: float, nx: int, ny: int, origin: tuple[float, float],
                 within: float, doubted_trust: float, *, tile: int = TILE, strip_cells: int = STRIP_CELLS,
                 executor: Any = None, occupancy: bool = True) -> Any:
    """``(low, high, (cells, probability, explored))`` of each band of rows of the raster
    :func:`rasterise` computes, bottom to top, each band :func:`tile_rows` on ``executor``
    (``None``: this process), yielded in order as they finish (``probability`` ``None``
    without ``occupancy``)."""
    from occtool.executor import in_order

    rows = max(tile, (BAND_STRIPS * strip_cells // max(nx * tile, 1)) * tile)
    bands = [(low, min(low + rows, ny)) for low in range(0, ny, rows)]
    # Bands in groups at least BLOCK_ROWS tall, whose regions are cut once for all of them.
    group = max(1, -(-BLOCK_ROWS // rows))
    xs = _centres(origin[0], resolution, nx)

    def arguments() -> Any:
        for first in range(0, len(bands), group):
            members = bands[first:first + group]
            blocks = _band_blocks(world, xs, resolution, origin[1], members[0][0], members[-1][1], tile)
            for low, high in members:
                yield (world, resolution, nx, origin, low, high, within, doubted_trust, tile, strip_cells, occupancy,
                       blocks)
            del blocks

    for (low, high), strip in zip(bands, in_order(executor, "drawing the raster", tile_rows, arguments())):
        yield low, high, strip


def tile_rows(world: Any, resolution: float, nx: int, origin: tuple[float, float], low: int, high: int,
              within: float, doubted_trust: float, tile: int = TILE, strip_cells: int = STRIP_CELLS,
              occupancy: bool = True, blocks: tuple[_RegionBlocks, _RegionBlocks | None] | None = None,
              ) -> tuple[NDArray[np.uint8], NDArray[np.float32] | None, NDArray[np.bool_]]:
    """Rows ``low`` to ``high`` (``low`` a whole number of tiles) of :func:`rasterise`'s cells,
    occupancy (``None`` without ``occupancy``) and explored flags, a row of tiles at a time,
    at most ``strip_cells`` cells at once (runs in this process or on a worker). ``blocks``:
    the observed and free regions cut to rows holding these (:func:`_band_blocks`, shared by
    a group of bands); ``None``: cut here to these rows."""

    cells = np.full((high - low, nx), UNKNOWN, dtype=np.uint8)
    probability = np.empty((high - low, nx), dtype=np.float32) if occupancy else None
    explored = np.zeros((high - low, nx), dtype=bool)
    xs = _centres(origin[0], resolution, nx)
    first = np.arange(0, nx, tile)
    last = np.minimum(first + tile, nx) - 1
    matters = None
    if len(world):
        # How far each segment can matter to a cell: its ridge above what the cells' base
        # reads anyway, and without the occupancy kept, above what the cells draw free (a
        # trusted ridge at or below RASTER_FREE is drawn as none; the others' are not drawn).
        floor = world.floor_level() if occupancy else max(world.floor_level(), RASTER_FREE)
        matters = influence(world, within, floor, doubted_trust, all_ridges=occupancy)
    # Tiles in rows of `tile` cells, at most `strip_cells` cells at a time.
    chunk = max(1, strip_cells // (tile * tile))
    pad = 0.25 * resolution
    observed_blocks, free_blocks = (_band_blocks(world, xs, resolution, origin[1], low, high, tile)
                                    if blocks is None else blocks)
    for pieces in (observed_blocks, free_blocks):
        if pieces is not None:
            pieces.prepare()  # sent to a worker, its pieces come unprepared
    for t0 in range(low, high, tile):
        t1 = min(t0 + tile, high)
        ys = origin[1] + (np.arange(t0, t1) + 0.5) * resolution
        for k0 in range(0, first.size, chunk):
            lo, hi = first[k0:k0 + chunk], last[k0:k0 + chunk]
            # The tiles' boxes round their cell centres, widened by a quarter cell so that
            # a one-cell tile is still a box; the tests below hold for the wider box too.
            boxes = (xs[lo] - pad, ys[0] - pad, xs[hi] + pad, ys[-1] + pad)
            if observed_blocks.empty:
                inside = outside = None
            else:
                inside, outside = observed_blocks.sort_tiles(lo, *boxes)
            free = _free_tiles(free_blocks, (lo, *boxes))
            # Each box's middle and half-diagonal: what the tiles' queries reach round (occtool.fuse._tile_queries).
            half = 0.5 * np.hypot(xs[hi] - xs[lo], ys[-1] - ys[0]) + pad * math.sqrt(2.0)
            middles = np.column_stack([0.5 * (xs[lo] + xs[hi]), np.full(lo.size, 0.5 * (ys[0] + ys[-1]))])
            c0, c1 = int(lo[0]), int(hi[-1]) + 1
            r0, r1 = t0 - low, t1 - low
            _strip(world, cells[r0:r1, c0:c1], None if probability is None else probability[r0:r1, c0:c1],
                   explored[r0:r1, c0:c1], xs[c0:c1], ys, lo - c0, hi - c0, inside, outside, (middles, half),
                   within, doubted_trust, free, matters, observed_blocks, free_blocks)
    return cells, probability, explored


#: Columns of a block of a band's regions (:class:`_RegionBlocks`): about 50 m at 5 cm.
BLOCK_COLUMNS = 1024
#: Rows of the regions' pieces, at least: bands (fewer rows the wider the raster) are taken
#: in groups this tall, whose regions are cut once for all of them (:func:`_band_blocks`).
BLOCK_ROWS = 256


def _centres(x0: float, resolution: float, nx: int) -> FloatArray:
    """The x of the raster's cell centres, from its left edge ``x0``."""
    return np.asarray(x0 + (np.arange(nx) + 0.5) * resolution, dtype=np.float64)


def _band_blocks(world: Any, xs: FloatArray, resolution: float, y0: float, low: int, high: int,
                 tile: int) -> tuple[_RegionBlocks, _RegionBlocks | None]:
    """The world's observed region and free region (``None``: a map without one) cut to rows
    ``low`` to ``high`` of the raster (cell centres ``xs``, bottom edge ``y0``) and to blocks of
    columns (:class:`_RegionBlocks`), with a margin of two cells that no tile box or cell
    centre of those rows comes near."""
    margin = 2.0 * resolution
    rectangle = (float(xs[0] - margin), y0 + low * resolution - margin, float(xs[-1] + margin),
                 y0 + high * resolution + margin)
    columns = max(tile, BLOCK_COLUMNS // tile * tile)
    free = getattr(world, "free_region", None)
    return (_RegionBlocks(world.region, xs, resolution, rectangle, columns),
            None if free is None else _RegionBlocks(free, xs, resolution, rectangle, columns))


class _RegionBlocks:
    """A region cut to a band of rows (:func:`_cut`), then into blocks of ``columns`` columns
    (whole tiles), each piece prepared: the tiles of a block are sorted against its piece and
    the cells along the region's boundary tested against it.

    Both tests cost time with the geometry they ask: GEOS's prepared test of a box looks at
    every ring, its point-in-polygon test walks the edges that cross the point's row, and
    cutting a region to a rectangle nodes all of it within a tenth of its width of the
    rectangle. Over whole bands of rows, the wider the raster, the thinner its bands and the
    more of them, each cut from the whole region and tested across its whole width: campus
    x10's raster spent 30 s more than ten campuses' in these. Cut once for a group of bands at
    least :data:`BLOCK_ROWS` tall, and asked a block at a time, what each costs is a block's.
    A piece answers as the whole region does for boxes and points within the margin of two
    cells round its block (:func:`_cut`), more than rounding when a point's block is found
    from its x."""

    def __init__(self, region: Any, xs: FloatArray, resolution: float, rectangle: tuple[float, float, float, float],
                 columns: int = BLOCK_COLUMNS) -> None:
        self.xs, self.resolution, self.columns = xs, resolution, columns
        self.count = -(-xs.size // columns)
        band = _cut(region, rectangle)
        #: The region has nothing in these rows.
        self.empty = bool(band.is_empty)
        if self.count == 1 or self.empty:
            self.pieces = [band] * self.count
            return
        margin = 2.0 * resolution
        self.pieces = []
        for block in range(self.count):
            first, last = block * columns, min((block + 1) * columns, xs.size) - 1
            self.pieces.append(_cut(band, (float(xs[first] - margin), rectangle[1], float(xs[last] + margin),
                                           rectangle[3])))

    def prepare(self) -> None:
        import shapely

        for piece in self.pieces:
            shapely.prepare(piece)

    def _blocks(self, column: NDArray[np.integer[Any]]) -> NDArray[np.int64]:
        return np.clip(np.asarray(column, dtype=np.int64) // self.columns, 0, self.count - 1)

    def contains(self, x: FloatArray, y: FloatArray) -> NDArray[np.bool_]:
        """Whether points (``x``, ``y``: cell centres of the band) lie in the region, as
        ``shapely.contains_xy`` of the whole region answers (:meth:`WorldMap.observed`)."""
        import shapely

        if self.count == 1:
            return np.asarray(shapely.contains_xy(self.pieces[0], x, y), dtype=bool)
        block = self._blocks(np.floor((x - self.xs[0]) / self.resolution).astype(np.int64))
        out = np.zeros(x.size, dtype=bool)
        for b in np.unique(block).tolist():
            chosen = block == b
            out[chosen] = shapely.contains_xy(self.pieces[b], x[chosen], y[chosen])
        return out

    def sort_tiles(self, first: NDArray[np.intp], left: FloatArray, bottom: float, right: FloatArray,
                   top: float) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
        """:func:`_sort_tiles` of a row of tiles (``first``: each one's first column, in order;
        the boxes as there), each block's tiles against its piece."""
        block = self._blocks(first)
        ends = np.flatnonzero(np.diff(block)) + 1
        inside, outside = np.zeros(first.size, dtype=bool), np.zeros(first.size, dtype=bool)
        for low, high in zip(np.r_[0, ends].tolist(), np.r_[ends, first.size].tolist()):
            inside[low:high], outside[low:high] = _sort_tiles(self.pieces[int(block[low])], left[low:high], bottom,
                                                              right[low:high], top)
        return inside, outside


def _cut(region: Any, rectangle: tuple[float, float, float, float]) -> Any:
    """``region`` (``None``: none) cut to ``rectangle`` (x and y, lower then upper) and
    prepared: for boxes and points inside the rectangle it answers every predicate as the
    whole region does, from the few rings that cross it. A prepared polygon's test of a box
    costs time in proportion to its rings (GEOS looks for any of them inside the box): over
    the whole region of a campus mapped ten times over, the tiles' tests grew as the square
    of the run."""
    import shapely

    if region is None:
        return None
    if region.is_empty:
        return region
    part = shapely.intersection(region, shapely.box(*rectangle))
    if shapely.get_type_id(part) == 7:
        # A collection: the polygons, and lines or points where the region's boundary runs
        # along the rectangle's, which no box or point asked lies near. Cut again, GEOS took
        # 60 ms a block for what takes 0.4 ms as polygons (campus x10's free region, 3.2 s).
        pieces = shapely.get_parts(part)
        pieces = shapely.get_parts(pieces[np.isin(shapely.get_type_id(pieces), (3, 6))])
        part = shapely.multipolygons(pieces)
    shapely.prepare(part)
    return part


def _free_tiles(free_blocks: _RegionBlocks | None,
                boxes: tuple[Any, ...]) -> tuple[NDArray[np.bool_], NDArray[np.bool_]] | None:
    """The tiles (``boxes``: their first columns, then :func:`_sort_tiles`' left and right
    sides, bottom and top) wholly inside and wholly outside the part of the observed region
    the raster may call free (:attr:`WorldMap.free_region`, cut to the band and its blocks;
    ``None``: a map without one, whose cells each ask :meth:`WorldMap.free_space`), as the
    region's own tiles are sorted."""
    if free_blocks is None:
        return None
    return free_blocks.sort_tiles(*boxes)


def _sort_tiles(geometry: Any, left: NDArray[np.floating[Any]], bottom: float, right: NDArray[np.floating[Any]],
                top: float) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """The tiles of a row (boxes from ``left`` to ``right``, ``bottom`` to ``top``) whose box
    lies in the interior of a prepared ``geometry``, and those whose box misses it.

    Runs of tiles are tested first, the whole row and then halves of the undecided runs: a
    run's box inside (outside) the geometry holds each of its tiles' inside (outside), so
    only the tiles along the geometry's boundary are tested one by one, with the same answers."""
    import shapely

    count = left.size
    inside, outside = np.zeros(count + 1, dtype=np.int64), np.zeros(count + 1, dtype=np.int64)
    starts, ends = np.zeros(1, dtype=np.intp), np.full(1, count, dtype=np.intp)
    while starts.size:
        boxes = shapely.box(left[starts], bottom, right[ends - 1], top)
        held = shapely.contains_properly(geometry, boxes)
        missed = ~shapely.intersects(geometry, boxes)
        # Each decided run's tiles marked at once: +1 at its start, -1 past its end, summed below.
        for marks, decided in ((inside, held), (outside, missed)):
            np.add.at(marks, starts[decided], 1)
            np.add.at(marks, ends[decided], -1)
        split = ~held & ~missed & (ends - starts > 1)
        middle = (starts[split] + ends[split]) // 2
        starts, ends = np.concatenate([starts[split], middle]), np.concatenate([middle, ends[split]])
    return np.cumsum(inside[:-1]) > 0, np.cumsum(outside[:-1]) > 0


def _strip(world: Any, cells: NDArray[np.uint8], probability: NDArray[np.float32] | None, explored: NDArray[np.bool_],
           xs: NDArray[np.floating[Any]], ys: NDArray[np.floating[Any]], first: NDArray[np.intp],
           last: NDArray[np.intp], inside: NDArray[np.bool_] | None, outside: NDArray[np.bool_] | None,
           boxes: tuple[FloatArray, FloatArray], within: float, doubted_trust: float,
           free: tuple[NDArray[np.bool_], NDArray[np.bool_]] | None, matters: FloatArray | None,
           observed_blocks: _RegionBlocks, free_blocks: _RegionBlocks | None) -> None:
    """One row of tiles (``ys`` its cells' rows), written into the raster's views (no
    occupancy where ``probability`` is ``None``); ``boxes``:
    the tiles' middles and half-diagonals; ``free``: the tiles inside and outside the world's
    :attr:`~WorldMap.free_region` (``None``: each cell asks :meth:`~WorldMap.free_space`);
    ``matters``: the segments' :func:`~occtool.fuse._tile_queries.influence` (``None``: computed
    here); ``observed_blocks`` and ``free_blocks``: the world's observed region and free
    region cut to the strip's band and its blocks of columns (:class:`_RegionBlocks`; ``None``:
    no free region)."""
    h, nx = ys.size, xs.size
    # The strip's cells row by row, each row padded to whole tiles (the last tile's missing
    # columns repeat its last one, and are dropped when written), and as (tiles, columns)
    # and (tiles, rows) for the tiles' queries.
    width = int(last[0] - first[0]) + 1
    shape = (h, first.size * width)
    tile_x = np.pad(np.asarray(xs, dtype=np.float64), (0, shape[1] - nx), mode="edge").reshape(-1, width)
    tile_y = np.broadcast_to(np.asarray(ys, dtype=np.float64), (first.size, h))

    def centres(index: NDArray[np.intp]) -> FloatArray:  # of cells of the strip, by their index
        return np.column_stack([tile_x.ravel()[index % shape[1]], tile_y[0][index // shape[1]]])

    if inside is None or outside is None:
        observed = np.zeros(h * shape[1], dtype=bool)
    else:
        observed = np.tile(np.repeat(inside, width), h)
        edge = np.flatnonzero(np.tile(np.repeat(~inside & ~outside, width), h))
        if edge.size:
            edge_xy = centres(edge)
            observed[edge] = observed_blocks.contains(edge_xy[:, 0], edge_xy[:, 1])  # as world.observed
    base = np.full(observed.size, world.unknown_level)
    if observed.any():
        seen = np.flatnonzero(observed)
        xy = centres(seen)
        tiles = seen % shape[1] // width
        if world.flat_free:
            base[seen] = world.free_value(xy)
        else:
            # The nearest positions of the tiles' cells, those of the tiles with a cell seen.
            wanted = np.flatnonzero(np.bincount(tiles, minlength=first.size))
            nearest = np.full((first.size, h, width), np.inf)
            nearest[wanted] = tile_position_distances(world, tile_x[wanted], tile_y[wanted], boxes[0][wanted],
                                                      boxes[1][wanted])
            base[seen] = world.free_values(nearest[tiles, seen // shape[1], seen % width])
        # Only the part of it the raster may call free counts as observed (WorldMap.rasterise).
        if free is None:
            observed[seen] = world.free_space(xy)
        else:
            # Tiles wholly inside or outside the free region are decided whole, as above.
            decided = free[0][tiles]
            edge = np.flatnonzero(~decided & ~free[1][tiles])
            if edge.size:
                assert free_blocks is not None  # the tiles were sorted against the free region
                decided[edge] = free_blocks.contains(xy[edge, 0], xy[edge, 1])  # as world.free_space
            observed[seen] = decided
    every, of_trusted, near_doubted, near_trusted = tile_walls(world, tile_x, tile_y, *boxes, within, doubted_trust,
                                                               matters, all_ridges=probability is not None)
    of_trusted, near_doubted, near_trusted = (_in_rows(answer) for answer in (of_trusted, near_doubted, near_trusted))
    wall = near_trusted <= world.wall_half_width
    rim = (near_trusted <= world.wall_rim) | (near_doubted <= world.doubted_wall_rim)
    drawn = np.maximum(base, of_trusted)
    out = np.full(observed.size, UNKNOWN, dtype=np.uint8)
    # Never free near a trusted wall, nor right at a doubted one (WorldMap.rasterise says why).
    out[observed & ~rim & (drawn <= RASTER_FREE)] = FREE
    out[wall | (drawn >= RASTER_OCCUPIED)] = OCCUPIED
    cells[...] = out.reshape(shape)[:, :nx]
    if probability is not None:
        probability[...] = np.maximum(base, _in_rows(every)).reshape(shape)[:, :nx]
    explored[...] = (observed | rim | wall).reshape(shape)[:, :nx]


def _in_rows(tiled: FloatArray) -> FloatArray:
    """A ``(tiles, rows, columns)`` answer of a row of tiles as the strip's cells, row by row."""
    return tiled.transpose(1, 0, 2).ravel()


__all__ = ["BAND_STRIPS", "SPILL_CELLS", "STRIP_CELLS", "TILE", "raster_bands", "raster_shape", "rasterise",
           "tile_rows"]
