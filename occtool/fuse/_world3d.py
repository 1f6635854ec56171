"""The world map of a run in 3D (issue 35): planar patches as slabs under one MAX, over the crossed free space.

:class:`WorldMap3D` is the paper's occupancy function ``m = F(x, y, z)`` of the world frame:

* each surface patch (:mod:`occtool.fuse._patches`) is a slab: a MIN over seven linear pieces,
  its peak (the patch's trust) and, for its two faces and its four edges, the peak falling
  ``1 / falloff`` a metre beyond the half-thickness (faces) or the half-extent (edges);
* the map is the MAX over the patches and a constant for the cell the point lies in: the
  ``free_level`` where a training ray crossed the cell before its return, 0.5 (unknown) where
  none did.

So the free space reaches every return, not only each position's nearest, and a point near a
surface ranks above the free space around it and by how near it is. The map answers in the
frame of the rays it was built from (:mod:`occtool.fuse._log3d` builds it of a log's).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.formats.occmap3d import free_table, rigid
from occtool.fuse._patches import (
    EXTENT,
    PatchCodes,
    PatchGeometry,
    cell_keys,
    concatenate,
    counted_unique,
    fewest_returns,
    fit_patches,
    free_cells_and_crossings,
    geometry,
    index_keys,
    level_box,
    trust_codes,
)

FloatArray = NDArray[np.float64]

#: Default cell edge of the patches and of the free space (metres).
RESOLUTION = 0.2
#: Occupancy of crossed free space (below every patch's ridge near its surface).
FREE_LEVEL = 0.1
#: Occupancy where no training ray passed.
UNKNOWN = 0.5
#: Classes of crossed cells by how often the rays crossed them: class ``c`` holds the cells
#: that ``2 ** c`` to ``2 ** (c + 1) - 1`` points of the walk (every half cell along the rays)
#: fell in, the last class every cell above.
FREE_CLASSES = 16
#: Walk points per square metre of a cell's face at which a crossed cell's occupancy has
#: fallen ``1 - 1/e`` of the way from :data:`UNKNOWN` to the free level: a cell a ray or two
#: grazed is barely known to be free (a held-out return may well lie there: a surface seen
#: only by the held-out frames), one hundreds crossed is. 1600 is 64 points (about 32
#: rays) for a 0.2 m cell; on the TUM cabinet's seed-1 split of bench/heldout3d.py it took
#: the held-out AUC from 0.883 / 0.834 (3D / band, one free level) to 0.904 / 0.879.
FREE_SATURATION = 1600.0
#: The free space is kept in cells ``2 ** FREE_SHIFT`` times the patches' (0.8 m for 0.2 m
#: patches): the patches hold the surfaces' detail, the free space only how well each region
#: was seen. On the TUM cabinet (seeds 0 and 1) 0.8 m free cells scored 0.962 / 0.954 and
#: 0.922 / 0.913 (3D / band) where 0.2 m ones scored 0.962 / 0.954 and 0.902 / 0.876, in a
#: sixty-fourth of the cells.
FREE_SHIFT = 2
#: Patches consulted per query point (the nearest centres).
NEIGHBOURS = 8
#: Coarser levels of patches tried before the cell of ``resolution``: level ``l`` has cells
#: ``2 ** l`` times as large, and takes the returns of a cell that are flat (a wall, a floor).
COARSE_LEVELS = 2
#: RMS distance (metres) of a coarse cell's returns from their plane under which it is one
#: patch: about the range noise of a Kinect at 3-4 m or a lidar's plus its registration.
FLAT = 0.05
#: Query points evaluated at once: their ``(K, NEIGHBOURS)`` temporaries stay within the
#: caches (58k held-out points of the depth office: 0.12 s of CPU in chunks of 100k, 0.085 s
#: in chunks of 16k; the same answers).
QUERY_CHUNK = 1 << 14


@dataclass(eq=False)
class WorldMap3D:
    """A 3D occupancy function of the world frame: patches under one MAX over the free space.

    ``lo`` int64 ``(3,)`` and ``shape`` the box of cells (``resolution`` m) the map covers;
    ``free_keys`` the sorted linear keys of the cells training rays crossed;
    ``patches`` the surfaces at the file's precision, one list entry a level (level ``l``'s
    cells ``2 ** l`` times the resolution, its box :func:`~occtool.fuse._patches.level_box`);
    ``falloff`` and ``edge_falloff`` the distances over which a patch's ridge falls by 1
    beyond its faces and beyond its edges.
    """

    resolution: float
    lo: NDArray[np.int64]
    shape: tuple[int, int, int]
    free_keys: NDArray[np.int64]
    patches: list[PatchCodes]
    falloff: float
    edge_falloff: float
    free_level: float = FREE_LEVEL
    frame: str = "the frame of the log's poses"
    #: ``(4, 4)`` rigid transform from the frame queries are given in (the log's poses) to the
    #: frame the map was built in (e.g. a depth folder's world levelled on its floor); None:
    #: the same frame.
    to_map: FloatArray | None = None
    #: uint8 ``(F,)`` each crossed cell's class (:data:`FREE_CLASSES`), in the order of
    #: ``free_keys``, and the occupancy of each class; None (a version-5 file): every crossed
    #: cell is at ``free_level``.
    free_codes: NDArray[np.uint8] | None = None
    free_table: FloatArray | None = None
    #: The free space's cells are ``2 ** free_shift`` times the resolution (its box
    #: :func:`~occtool.fuse._patches.level_box` of that level); a patch's half-extent along
    #: its plane is ``extent`` times its cell (version 6; a version-5 patch holds its own).
    free_shift: int = 0
    extent: float = 1.0
    #: The ``saturation`` the free table was made with (:func:`occtool.formats.occmap3d.free_table`).
    free_saturation: float = 0.0
    #: The cells of ``resolution`` the training rays crossed (sorted keys into the map's box),
    #: kept from the build for the Nav2 band (:func:`occtool.fuse.project_band`) and not
    #: stored in the file: the free space the file holds is coarser (``free_shift``).
    fine_free_keys: NDArray[np.int64] | None = field(default=None, repr=False, compare=False)
    #: ``(B, 3)`` the training returns no patch took (their cells held too few), kept from
    #: the build as ``fine_free_keys`` is: the Nav2 band never calls their cells free.
    bare_points: FloatArray | None = field(default=None, repr=False, compare=False)
    #: How the resolution was chosen (:func:`map_log_3d`; not stored in the file).
    choice: dict[str, Any] | None = field(default=None, repr=False, compare=False)
    _geometry: PatchGeometry | None = field(default=None, repr=False)
    _trees: Any = field(default=None, repr=False)
    _encoded: Any = field(default=None, repr=False, compare=False)

    @property
    def patch_count(self) -> int:
        """Patches over every level."""
        return sum(len(codes) for codes in self.patches)

    @property
    def geometry(self) -> PatchGeometry:
        """The patches as floats, derived from their codes."""
        if self._geometry is None:
            parts = []
            for level, codes in enumerate(self.patches):
                low, shape = level_box(self.lo, self.shape, level)
                parts.append(geometry(codes, low, shape, self.resolution * (1 << level), self.extent))
            self._geometry = concatenate(parts)
        return self._geometry

    @property
    def free_box(self) -> tuple[NDArray[np.int64], tuple[int, int, int], float]:
        """The free space's box of cells: lowest cell index, shape, cell edge (metres)."""
        low, shape = level_box(self.lo, self.shape, self.free_shift)
        return low, shape, self.resolution * (1 << self.free_shift)

    @property
    def band_free(self) -> tuple[NDArray[np.int64], tuple[int, int, int], float, NDArray[np.int64]]:
        """The finest crossed cells known: the build's cells of ``resolution`` where the map
        was built here, else the file's free space (lowest cell, shape, edge, sorted keys)."""
        if self.fine_free_keys is not None:
            return self.lo, self.shape, self.resolution, self.fine_free_keys
        return (*self.free_box, self.free_keys)

    @property
    def bounds(self) -> FloatArray:
        """``(2, 3)`` lowest and highest world corner of the box."""
        low = self.lo * self.resolution
        return np.vstack([low, low + np.asarray(self.shape) * self.resolution])

    def linear_pieces(self, index: int) -> FloatArray:
        """``(7, 4)`` rows ``(a, b, c, d)``: patch ``index``'s ridge is the MIN of ``a x + b y + c z + d``."""
        g = self.geometry
        peak = g.trust[index]
        rows = [np.array([0.0, 0.0, 0.0, peak])]
        for axis, half, slope in ((g.normals[index], g.thickness[index], 1.0 / self.falloff),
                                  (g.u[index], g.extents[index, 0], 1.0 / self.edge_falloff),
                                  (g.v[index], g.extents[index, 1], 1.0 / self.edge_falloff)):
            for sign in (1.0, -1.0):
                # peak - slope (sign * axis . (x - c) - half)
                w = -slope * sign * axis
                rows.append(np.append(w, peak + slope * (sign * float(axis @ g.centres[index]) + half)))
        return np.array(rows)

    def ridge(self, xyz: FloatArray, index: NDArray[np.intp]) -> FloatArray:
        """The ridges of patches ``index`` (any shape) at points ``xyz`` (that shape + (3,)), floored at 0."""
        g = self.geometry
        diff = xyz - g.centres[index]
        over = np.maximum.reduce([
            (np.abs(np.einsum("...k,...k->...", diff, g.normals[index])) - g.thickness[index]) / self.falloff,
            (np.abs(np.einsum("...k,...k->...", diff, g.u[index])) - g.extents[index, 0]) / self.edge_falloff,
            (np.abs(np.einsum("...k,...k->...", diff, g.v[index])) - g.extents[index, 1]) / self.edge_falloff,
        ])
        return np.maximum(g.trust[index] - np.maximum(over, 0.0), 0.0)

    def background(self, xyz: FloatArray) -> FloatArray:
        """The constant of each point's cell: the free level where rays crossed it, else 0.5."""
        keys = cell_keys(xyz, *self.free_box)
        at = np.clip(np.searchsorted(self.free_keys, keys), 0, max(self.free_keys.size - 1, 0))
        free = (keys >= 0) & (self.free_keys.size > 0) & (self.free_keys[at] == keys) if self.free_keys.size else (
            np.zeros(keys.shape, dtype=bool))
        if self.free_codes is None or self.free_table is None:
            return np.where(free, self.free_level, UNKNOWN)
        return np.where(free, self.free_table[self.free_codes[at]] if self.free_keys.size else UNKNOWN, UNKNOWN)

    def predict(self, xyz: ArrayLike) -> FloatArray:
        """Occupancy in [0, 1] at ``(K, 3)`` points of the poses' frame (moved by ``to_map``
        first): MAX of the cell's constant and the ridges of the nearest :data:`NEIGHBOURS`
        patches of each level."""
        points = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
        if self.to_map is not None:
            points = points @ self.to_map[:3, :3].T + self.to_map[:3, 3]
        return np.maximum(self.background(points), self.ridges(points))

    def ridges(self, points: FloatArray) -> FloatArray:
        """The MAX of the patches' ridges at ``(K, 3)`` points of the map's own frame (0 where
        none reaches): the nearest :data:`NEIGHBOURS` patches of each level."""
        out = np.zeros(points.shape[0])
        if self.patch_count == 0 or points.shape[0] == 0:
            return out
        g = self.geometry
        if self._trees is None:
            # occtool's own index answers as cKDTree does (but for which of exactly equal
            # distances comes first), without scipy.spatial's import: 0.3-0.45 s of CPU a
            # process, a sixth of a TUM cabinet's 3D map.
            from occtool.neighbours import NeighbourIndex

            self._trees = []
            first = 0
            for codes in self.patches:
                members = np.arange(first, first + len(codes))
                first += len(codes)
                if members.size:
                    # No ridge is above 0 farther from its centre than its half-diagonal plus a falloff.
                    reach = float(np.sqrt(np.sum(g.extents[members].max(axis=0) ** 2)
                                          + g.thickness[members].max() ** 2)) + max(self.falloff, self.edge_falloff)
                    self._trees.append((NeighbourIndex(g.centres[members], reach), members, reach))
        for tree, members, reach in self._trees:
            k = min(NEIGHBOURS, members.size)
            for begin in range(0, points.shape[0], QUERY_CHUNK):
                chunk = points[begin:begin + QUERY_CHUNK]
                _, found = tree.query(chunk, k=k, distance_upper_bound=reach)
                index = np.asarray(found).reshape(chunk.shape[0], k)
                # Only the neighbours within reach (a third or less of them on the bench's
                # sequences) can rise above 0: the ridges of those, the rest stay 0.
                row, column = np.nonzero(index < members.size)
                ridge = np.zeros(index.shape)
                ridge[row, column] = self.ridge(chunk[row], members[index[row, column]])
                out[begin:begin + QUERY_CHUNK] = np.maximum(out[begin:begin + QUERY_CHUNK], ridge.max(axis=1))
        return out

    def __call__(self, xyz: ArrayLike) -> FloatArray:
        return self.predict(xyz)

    def __len__(self) -> int:
        return self.patch_count

    def to_bytes(self) -> bytes:
        """The map's ``.occmap`` file (version 6), encoded once (:attr:`nbytes`, the summary
        and the file all ask for it; a map's numbers do not change once built, its frame
        transform is part of the key)."""
        from occtool.formats import occmap3d

        key = (self.frame, None if self.to_map is None else self.to_map.tobytes())
        if self._encoded is None or self._encoded[0] != key:
            self._encoded = (key, occmap3d.encode(self))
        return self._encoded[1]

    @property
    def nbytes(self) -> int:
        """Bytes of its file."""
        return len(self.to_bytes())

    @property
    def free_cells(self) -> int:
        """Cells training rays crossed."""
        return int(self.free_keys.size)

    def grid_bytes(self, resolution: float = 0.1) -> int:
        """Bytes of a byte-a-voxel grid of ``resolution`` holding what this map knows: its
        crossed cells and its patches' cells, each ``(self.resolution / resolution) ** 3``
        voxels (the figure the 3D grids of bench/heldout3d.py are charged)."""
        known = self.free_cells * 8 ** self.free_shift + sum(len(codes) * 8 ** level
                                                              for level, codes in enumerate(self.patches))
        return int(round(known * (self.resolution / resolution) ** 3))

    def save(self, path: str | os.PathLike[str], *, overwrite: bool = True) -> int:
        """Write the map (``.occmap``, version 6) atomically; returns the bytes written."""
        from occtool.formats.occmap import write_file

        return write_file(self.to_bytes(), path, overwrite=overwrite)


def build_world_map_3d(origins: ArrayLike, ends: ArrayLike, hits: ArrayLike | None = None, *,
                       resolution: float = RESOLUTION, falloff: float | None = None,
                       edge_falloff: float | None = None, margin: float | None = None, free_level: float = FREE_LEVEL,
                       coarse_levels: int = COARSE_LEVELS, flat: float | None = None,
                       saturation: float = FREE_SATURATION, free_shift: int = FREE_SHIFT,
                       extent: float = EXTENT, min_returns: int | None = None) -> WorldMap3D:
    """A :class:`WorldMap3D` of world-frame rays.

    Parameters
    ----------
    origins, ends
        ``(N, 3)`` each ray's sensor position and end point (or ``(3,)`` origins: one sensor).
    hits
        ``(N,)`` whether a ray ends on a return (False: a free-only ray, cut at the sensor's
        range); all True if omitted.
    resolution
        Cell edge of the patches and of the free space (metres).
    falloff
        Distance over which a ridge falls from its peak to 0 beyond a face or an edge
        (default half a cell).
    edge_falloff
        The same beyond an edge, along the plane (default a cell: a surface goes on past
        where the training returns stopped more often than a slab thickens).
    coarse_levels
        How many coarser levels of patches to try (:data:`COARSE_LEVELS`).
    flat
        RMS distance from their plane under which a coarse cell's returns are one patch
        (default :data:`FLAT`).
    margin
        A return's ray is free up to this short of it (default a quarter of a cell).
    saturation
        How many walk points a crossed cell needs to be believed free (:data:`FREE_SATURATION`).
    free_shift
        The free space's cells are ``2 ** free_shift`` times ``resolution`` (:data:`FREE_SHIFT`).
    extent
        A patch's half-extent along its plane, as a share of its cell.
    min_returns
        Fewest returns a cell of the finest level needs for a patch (default
        :func:`~occtool.fuse._patches.fewest_returns`: a share of the mean of the cells').
    """
    # No copies of the rays where none is needed: a run's millions of rays are 48 bytes each
    # an array of them (:data:`occtool.fuse._memory.RAY_BYTES`).
    end = np.asarray(ends, dtype=np.float64).reshape(-1, 3)
    origin = np.asarray(origins, dtype=np.float64)
    hit = np.ones(end.shape[0], dtype=bool) if hits is None else np.asarray(hits, dtype=bool).reshape(-1)
    if origin.shape != end.shape and origin.size == 3:  # one sensor's origin: every ray's
        origin = np.broadcast_to(origin.reshape(3), end.shape)
    if hit.shape[0] != end.shape[0] or origin.shape != end.shape:
        raise InputError("origins, ends and hits must describe the same rays")
    finite = np.isfinite(end).all(axis=1) & np.isfinite(origin).all(axis=1)
    if not finite.all():
        end, origin, hit = end[finite], origin[finite], hit[finite]
    if not (resolution > 0.0 and math.isfinite(resolution)):
        raise InputError(f"the resolution must be a positive number of metres, not {resolution}")
    falloff = 0.5 * resolution if falloff is None else float(falloff)
    edge_falloff = resolution if edge_falloff is None else float(edge_falloff)
    margin = 0.25 * resolution if margin is None else float(margin)
    flat = FLAT if flat is None else float(flat)
    if end.shape[0] == 0:
        lo, size = np.zeros(3, dtype=np.int64), np.ones(3, dtype=np.int64)
    else:
        lowest = np.minimum(end.min(axis=0), origin.min(axis=0))
        lo = np.floor(lowest / resolution).astype(np.int64)
        size = np.floor(np.maximum(end.max(axis=0), origin.max(axis=0)) / resolution).astype(np.int64) - lo + 1
    shape3 = (int(size[0]), int(size[1]), int(size[2]))
    direction = end - origin
    length = np.linalg.norm(direction, axis=1)
    direction /= np.maximum(length, 1e-12)[:, None]
    # Coarse levels first: a flat coarse cell (a stretch of wall or floor) is one patch; what
    # is left (corners, clutter) goes down a level, and the finest level takes everything.
    remaining = np.flatnonzero(hit)
    min_returns = fewest_returns(end[remaining], resolution) if min_returns is None else int(min_returns)
    levels: list[PatchCodes] = []
    counts: list[NDArray[np.int64]] = []
    for level in range(coarse_levels, -1, -1):
        low, box = level_box(lo, shape3, level)
        codes, taken, taken_counts = fit_patches(
            end[remaining], direction[remaining], low, box,
            resolution * (1 << level), None if level == 0 else flat, min_returns)
        levels.append(codes)
        counts.append(taken_counts)
        remaining = remaining[~taken]
    levels, counts = levels[::-1], counts[::-1]
    fine, walked, crossings = free_cells_and_crossings(origin, direction, length, hit, levels, lo, shape3,
                                                       resolution, margin, extent)
    del direction, length
    for codes, hits_per, crossed in zip(levels, counts, crossings):
        codes.trust = trust_codes(hits_per / np.maximum(hits_per + crossed, 1))
    # The free space's coarser cells: the walk's points of the fine cells they hold, as many
    # as a walk in steps of half a coarse cell would have put there.
    free_low, free_shape = level_box(lo, shape3, free_shift)
    i, rest = np.divmod(fine, shape3[1] * shape3[2])
    j, k = np.divmod(rest, shape3[2])
    coarse = index_keys((np.column_stack([i, j, k]) + lo) >> free_shift, free_low, free_shape)
    free, points = counted_unique(coarse, walked)
    scaled = points / float(1 << free_shift)
    free_codes = np.clip(np.floor(np.log2(np.maximum(scaled, 1.0))), 0, FREE_CLASSES - 1).astype(np.uint8)
    return WorldMap3D(float(resolution), lo, shape3, free, levels, falloff, edge_falloff, free_level,
                      free_codes=free_codes, free_table=free_table(resolution * (1 << free_shift), free_level,
                                                                   saturation, FREE_CLASSES),
                      free_shift=free_shift, extent=extent, free_saturation=saturation, fine_free_keys=fine,
                      bare_points=end[remaining])


def load_map_3d(path: str | os.PathLike[str]) -> WorldMap3D:
    """Read a 3D ``.occmap`` (version 5 or 6, :mod:`occtool.formats.occmap3d`)."""
    from occtool.formats import occmap3d

    return from_arrays(occmap3d.read_map3d(path))


def from_arrays(arrays: Any) -> WorldMap3D:
    """The map of a 3D file's numbers (:class:`occtool.formats.occmap3d.Map3DArrays`)."""
    from dataclasses import fields

    return WorldMap3D(**{item.name: getattr(arrays, item.name) for item in fields(arrays)})


__all__ = ["RESOLUTION", "WorldMap3D", "build_world_map_3d", "from_arrays", "load_map_3d", "rigid"]
