"""The 3D world map drawn for Nav2: the robot's body band over the ground found per tile.

A robot cares about what lies between its ground clearance and the top of its body above
the ground under it, wherever that ground is. :class:`TileGround` finds that ground per
tile, grown outward from the robot's own positions over the driveable patches (a normal
within :data:`DRIVEABLE_SLOPE` of vertical): a ramp, a tilted or uneven floor is ground,
not an obstacle; a table top, higher than a slope climbs in a tile, is an obstacle.
:func:`project_band` then draws the band:

* **occupied** where a patch that is not ground and whose trust reaches the occupied level
  (:data:`~occtool.raster.RASTER_OCCUPIED`) lies at a height inside the band (sampled over
  its slab); no cell within :data:`FREE_RIM` of an occupied one is free;
* **free** only where the band was seen free: every cell of the band in that column was
  crossed by a ray, or the robot's body passed there (within its radius of a position);
* **unknown** elsewhere.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.raster import FREE, OCCUPIED, RASTER_OCCUPIED, UNKNOWN, Raster

FloatArray = NDArray[np.float64]

#: Steepest surface a ground robot drives on (degrees from horizontal): a wheelchair ramp is
#: 5 degrees, a steep road 10-15.
DRIVEABLE_SLOPE = 20.0
#: Most the ground may climb from one tile to the next (metres): a kerb or a step, not a
#: table top (0.7 m) or a chair's seat (0.45 m).
GROUND_WINDOW = 0.3
#: No cell within this of an occupied one is free (metres): a held-out return scattered off
#: a surface lands on unknown, not on free, as beside the 2D map's walls. On the Livox run's
#: seed-0 split (bench/heldout3d.py) it took the held-out returns 0.6-2 m up that land on
#: free cells from 1.5 % to 0.2 % (0.3-0.6 m: 4.3 to 0.5 %).
FREE_RIM = 0.1
#: A patch in the band whose trust reaches this (more of the rays reaching it returned than
#: passed) is not drawn occupied below the occupied level, but the cells under it and within
#: :data:`FREE_RIM` are never free: the free space is kept in cells four times the patches'
#: (:data:`occtool.fuse._world3d.FREE_SHIFT`), so a column can be crossed beside an obstacle
#: whose edge cells' patches were crossed beside it too.
BLOCKS_FREE = 0.5
#: Most raster cells drawn (memory: a few bytes each).
MAX_CELLS = 50_000_000
#: Raster cells filled at once, and patch samples drawn at once (memory, not speed).
STRIP_CELLS = 1 << 20
SAMPLES_AT_ONCE = 1 << 20


class TileGround:
    """The ground height under any world ``(x, y)``, per square tile of ``tile`` metres.

    The ground is grown outward from the robot's own positions, as a robot would drive:
    a tile holding positions starts from the ground they imply (their sensor
    ``sensor_height`` below them); each neighbouring tile takes the driveable patch
    (:data:`DRIVEABLE_SLOPE`) whose height lies nearest the ground of the tile it was reached
    from, within what a driveable slope climbs over a tile (at most :data:`GROUND_WINDOW`),
    or keeps that ground when it holds none. So a floor tilted in the map's frame, a ramp
    and a kerb far from the path stay ground, and a table top (higher than a slope climbs in
    a tile) never becomes it. Driveable patches within that climb of their tile's ground
    are ground patches (:attr:`ground_patch`), never obstacles.
    """

    def __init__(self, world: Any, positions: ArrayLike, sensor_height: float, tile: float) -> None:
        from collections import deque

        self.positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        if self.positions.shape[0] == 0:
            raise InputError("the body band's ground needs at least one position")
        self.sensor_height, self.tile = float(sensor_height), float(tile)
        self.climb = min(GROUND_WINDOW, 0.5 * self.tile * math.tan(math.radians(DRIVEABLE_SLOPE))) + 0.05
        g = world.geometry
        driveable = np.flatnonzero(g.normals[:, 2] >= math.cos(math.radians(DRIVEABLE_SLOPE)))
        bounds = np.vstack([world.bounds[:, :2], self.positions[:, :2].min(axis=0), self.positions[:, :2].max(axis=0)])
        self.low = np.floor(bounds.min(axis=0) / self.tile).astype(np.int64)
        self.shape = tuple((np.floor(bounds.max(axis=0) / self.tile).astype(np.int64) - self.low + 1).tolist())
        patch_tile = self._flat(g.centres[driveable, :2])
        order = np.argsort(patch_tile, kind="stable")
        self._heights = g.centres[driveable, 2][order]
        self._bounds = np.searchsorted(patch_tile[order], np.arange(self.shape[0] * self.shape[1] + 1))
        ground = np.full(self.shape[0] * self.shape[1], np.nan)
        seeds = self._flat(self.positions[:, :2])
        implied = self.positions[:, 2] - self.sensor_height
        order = np.argsort(seeds, kind="stable")
        starts = np.r_[0, np.flatnonzero(np.diff(seeds[order])) + 1]
        queue: deque[int] = deque()
        for begin, end in zip(starts, np.r_[starts[1:], len(order)]):
            here = int(seeds[order[begin]])
            ground[here] = self._nearest_height(here, float(np.median(implied[order[begin:end]])))
            queue.append(here)
        # Breadth first over the tiles (their count, not the points', bounds the loop).
        while queue:
            here = queue.popleft()
            i, j = divmod(here, self.shape[1])
            for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                ni, nj = i + di, j + dj
                if 0 <= ni < self.shape[0] and 0 <= nj < self.shape[1] and np.isnan(ground[ni * self.shape[1] + nj]):
                    there = ni * self.shape[1] + nj
                    ground[there] = self._nearest_height(there, float(ground[here]))
                    queue.append(there)
        self._ground = ground
        self.ground_patch = np.zeros(len(g.trust), dtype=bool)
        self.ground_patch[driveable] = np.abs(g.centres[driveable, 2] - ground[patch_tile]) <= self.climb

    def _flat(self, xy: FloatArray) -> NDArray[np.int64]:
        ij = np.clip(np.floor(xy / self.tile).astype(np.int64) - self.low, 0, np.array(self.shape) - 1)
        return np.asarray(ij[:, 0] * self.shape[1] + ij[:, 1], dtype=np.int64)

    def _nearest_height(self, tile: int, reference: float) -> float:
        """The height of a driveable patch of ``tile`` nearest ``reference`` within :attr:`climb`,
        else ``reference``."""
        values = self._heights[self._bounds[tile]:self._bounds[tile + 1]]
        if not values.size:
            return reference
        best = int(np.argmin(np.abs(values - reference)))
        return float(values[best]) if abs(values[best] - reference) <= self.climb else reference

    def __call__(self, xy: ArrayLike) -> FloatArray:
        return np.asarray(self._ground[self._flat(np.asarray(xy, dtype=np.float64).reshape(-1, 2))], dtype=np.float64)


def _patch_samples(world: Any, members: NDArray[np.intp], spacing: float) -> tuple[FloatArray, NDArray[np.intp]]:
    """Points over each patch's slab: a grid of ``spacing`` over its extent, at its two faces
    and its middle. Not out to where its ridge falls below the occupied level: that falloff
    ranks the space near a surface above the free space for a query, but the obstacle a
    robot must not enter is the surface itself (a 0.4 m cell's falloff would widen every
    wall by 0.1-0.2 m and close doorways)."""
    g = world.geometry
    grow_face = g.thickness[members]
    half_u = g.extents[members, 0]
    half_v = g.extents[members, 1]
    nu = np.maximum(np.ceil(2.0 * half_u / spacing).astype(np.int64), 1) + 1
    nv = np.maximum(np.ceil(2.0 * half_v / spacing).astype(np.int64), 1) + 1
    per = nu * nv * 3
    patch = np.repeat(np.arange(len(members)), per)
    k = np.arange(int(per.sum())) - np.repeat(np.cumsum(per) - per, per)
    face, rest = np.divmod(k, (nu * nv)[patch])
    a, b = np.divmod(rest, nv[patch])
    su = -half_u[patch] + 2.0 * half_u[patch] * a / np.maximum(nu[patch] - 1, 1)
    sv = -half_v[patch] + 2.0 * half_v[patch] * b / np.maximum(nv[patch] - 1, 1)
    sn = (face - 1) * grow_face[patch]
    index = members[patch]
    points = (g.centres[index] + su[:, None] * g.u[index] + sv[:, None] * g.v[index]
              + sn[:, None] * g.normals[index])
    return points, index


def project_band(world: Any, positions: ArrayLike, *, sensor_height: float, body_height: float,
                 ground_clearance: float = 0.05, radius: float = 0.25, resolution: float = 0.05,
                 tile: float | None = None, max_cells: int = MAX_CELLS) -> Raster:
    """The Nav2 raster of a :class:`~occtool.fuse.WorldMap3D`: its body band over the ground
    per tile (module docstring), in the map's frame.

    ``positions`` ``(N, 3)`` are the sensor's positions in the map's frame; the band runs
    from ``ground_clearance`` to ``body_height`` above the ground; ``radius`` the robot's
    (the cells its body passed are free); ``tile`` the ground's tile (default: four of the
    map's cells, at least a metre).
    """
    if not (math.isfinite(resolution) and resolution > 0):
        raise InputError(f"resolution must be a positive number of metres, got {resolution}")
    places = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if tile is None:
        tile = max(4.0 * world.resolution, 1.0)
    ground = TileGround(world, places, sensor_height, tile)
    # Free: the columns of the finest crossed cells known (the build's, where the map was
    # built here) whose band cells were all crossed.
    free_lo, shape, r, keys = world.band_free
    i, rest = np.divmod(keys, shape[1] * shape[2])
    j, k = np.divmod(rest, shape[2])
    column_xy = (np.column_stack([np.arange(shape[0] * shape[1]) // shape[1],
                                  np.arange(shape[0] * shape[1]) % shape[1]]) + free_lo[:2] + 0.5) * r
    column_ground = ground(column_xy)
    low = np.floor((column_ground + ground_clearance) / r).astype(np.int64) - free_lo[2]
    high = np.floor((column_ground + body_height) / r).astype(np.int64) - free_lo[2]
    column = i * shape[1] + j
    in_band = (k >= low[column]) & (k <= high[column])
    seen = np.bincount(column[in_band], minlength=shape[0] * shape[1])
    band_free = seen == (high - low + 1)
    band_seen = seen > 0
    # Occupied: every patch that is not ground and can reach the occupied level, and whose
    # slab reaches into the band (by its centre's height and its half-diagonal).
    g = world.geometry
    reach = np.sqrt(np.sum(g.extents ** 2, axis=1)) + g.thickness
    above = g.centres[:, 2] - ground(g.centres[:, :2])
    members = np.flatnonzero(~ground.ground_patch & (g.trust >= BLOCKS_FREE)
                             & (above + reach >= ground_clearance) & (above - reach <= body_height))
    # The raster covers what the band holds (a lidar's rays reach far above it): the columns
    # whose band was seen, the obstacles in it and the robot's footprint.
    seen_ij = np.column_stack(np.divmod(np.flatnonzero(band_seen), shape[1])) + free_lo[:2]
    corners = [seen_ij * r, (seen_ij + 1) * r, g.centres[members, :2] - reach[members, None],
               g.centres[members, :2] + reach[members, None], places[:, :2] - radius, places[:, :2] + radius]
    every = np.concatenate([c.reshape(-1, 2) for c in corners])
    low_xy, high_xy = (every.min(axis=0), every.max(axis=0)) if len(every) else (np.zeros(2), np.zeros(2))
    origin = np.floor(low_xy / resolution) * resolution
    nx, ny = (np.ceil((high_xy - origin) / resolution).astype(np.int64)).tolist()
    nx, ny = max(nx, 1), max(ny, 1)
    if nx * ny > max_cells:
        raise InputError(f"a {resolution} m raster of the map needs {nx}x{ny} cells: use a coarser resolution")
    # A raster cell's map column is separable: its x picks i, its y picks j. Rows are
    # filled in strips (memory of a strip, not of the raster, beyond the output itself).
    ci = np.floor((origin[0] + (np.arange(nx) + 0.5) * resolution) / r).astype(np.int64) - free_lo[0]
    cj = np.floor((origin[1] + (np.arange(ny) + 0.5) * resolution) / r).astype(np.int64) - free_lo[1]
    ci_in, cj_in = (ci >= 0) & (ci < shape[0]), (cj >= 0) & (cj < shape[1])
    ci, cj = np.clip(ci, 0, shape[0] - 1), np.clip(cj, 0, shape[1] - 1)
    cells = np.full((ny, nx), UNKNOWN, dtype=np.uint8)
    explored = np.zeros((ny, nx), dtype=bool)
    strip = max(1, STRIP_CELLS // nx)
    for begin in range(0, ny, strip):
        rows = slice(begin, min(begin + strip, ny))
        column = cj[rows, None] + ci[None, :] * shape[1]
        inside = cj_in[rows, None] & ci_in[None, :]
        cells[rows][inside & band_free[column]] = FREE
        explored[rows] = inside & band_seen[column]
    if len(places) and radius > 0:
        # The cells whose centres lie within the radius of a position: the robot's body was there.
        span = int(math.ceil(radius / resolution))
        offset = np.arange(-span, span + 1)
        pc = np.floor((places[:, 0] - origin[0]) / resolution).astype(np.int64)
        pr = np.floor((places[:, 1] - origin[1]) / resolution).astype(np.int64)
        col = pc[:, None, None] + offset[None, None, :]
        row = pr[:, None, None] + offset[None, :, None]
        dx = origin[0] + (col + 0.5) * resolution - places[:, 0, None, None]
        dy = origin[1] + (row + 0.5) * resolution - places[:, 1, None, None]
        near = (dx * dx + dy * dy <= radius * radius) & (col >= 0) & (col < nx) & (row >= 0) & (row < ny)
        row, col = np.broadcast_to(row, near.shape)[near], np.broadcast_to(col, near.shape)[near]
        cells[row, col] = FREE
        explored[row, col] = True
    cells, explored = cells.reshape(-1), explored.reshape(-1)
    probability = np.where(cells == FREE, np.float32(world.free_level), np.float32(0.5)).astype(np.float32)
    spacing = resolution / math.sqrt(2.0)
    near_surface = np.zeros(ny * nx, dtype=bool)  # the occupied cells, for the rim
    across = np.ceil(2.0 * g.extents[members] / spacing) + 2
    batch = np.cumsum(3 * across[:, 0] * across[:, 1]) // SAMPLES_AT_ONCE  # about as many samples a batch
    for part in np.split(members, np.flatnonzero(np.diff(batch)) + 1) if members.size else []:
        points, index = _patch_samples(world, part, spacing)
        height = points[:, 2] - ground(points[:, :2])
        col = np.floor((points[:, 0] - origin[0]) / resolution).astype(np.int64)
        row = np.floor((points[:, 1] - origin[1]) / resolution).astype(np.int64)
        ok = (height >= ground_clearance) & (height <= body_height) & (col >= 0) & (col < nx) & (row >= 0) & (row < ny)
        flat = row[ok] * nx + col[ok]
        near_surface[flat] = True
        explored[flat] = True
        solid = g.trust[index[ok]] >= RASTER_OCCUPIED
        cells[flat[solid]] = OCCUPIED
        np.maximum.at(probability, flat, g.trust[index[ok]].astype(np.float32))
    bare = getattr(world, "bare_points", None)
    if bare is not None and len(bare):
        # The returns no patch took (their cells held too few) still mark something there:
        # the footprint of each map cell holding one inside the band is not free (nor,
        # through the rim, its neighbours). The build's rays are in the map's own frame.
        inside = (bare[:, 2] - ground(bare[:, :2]) >= ground_clearance) & (
            bare[:, 2] - ground(bare[:, :2]) <= body_height)
        r = world.resolution
        cells_xy = np.unique(np.floor(bare[inside, :2] / r).astype(np.int64), axis=0)
        steps = np.minimum(np.arange(int(math.ceil(r / spacing)) + 1) * spacing, r * (1.0 - 1e-9))
        du, dv = (a.reshape(-1) for a in np.meshgrid(steps, steps, indexing="ij"))
        for part in np.array_split(cells_xy, cells_xy.shape[0] * du.size // SAMPLES_AT_ONCE + 1):
            xy = (np.repeat(part * r, du.size, axis=0) + np.column_stack([np.tile(du, len(part)),
                                                                           np.tile(dv, len(part))]))
            col = np.floor((xy[:, 0] - origin[0]) / resolution).astype(np.int64)
            row = np.floor((xy[:, 1] - origin[1]) / resolution).astype(np.int64)
            ok = (col >= 0) & (col < nx) & (row >= 0) & (row < ny)
            near_surface[row[ok] * nx + col[ok]] = True
    if near_surface.any():
        from scipy import ndimage  # lazy: scipy's import is slow

        span = int(round(FREE_RIM / resolution))
        disk = np.hypot(*np.mgrid[-span:span + 1, -span:span + 1]) <= span + 1e-9
        rim = ndimage.binary_dilation(near_surface.reshape(ny, nx), structure=disk).reshape(-1)
        cells[rim & (cells == FREE)] = UNKNOWN
        probability[rim & (probability < 0.5)] = 0.5
    return Raster(cells.reshape(ny, nx), float(resolution), (float(origin[0]), float(origin[1])),
                  probability.reshape(ny, nx), np.zeros((ny, nx), dtype=bool), explored.reshape(ny, nx))


__all__ = ["DRIVEABLE_SLOPE", "GROUND_WINDOW", "TileGround", "project_band"]
