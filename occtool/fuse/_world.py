"""The map of a run in the world frame: walls as min/max pieces, the observed region, unknown elsewhere.

A :class:`FusedMap` keeps every keyframe's tree, reach and returns: a megabyte and more
for a building, more than a grid of it. :func:`build_world_map` refits what those local
models observed into one world-frame function of a few kilobytes:

* **walls**: the positions' returns summarised into short segments
  (:func:`occtool.fuse._walls.fit_segments`); segment ``s`` is the ridge
  ``MIN(p_s, p_s - k_s (u - t_s), p_s + k_s (u + t_s), p_s - k_s (v - l_s), p_s + k_s (v + l_s))``
  with ``u``, ``v`` the point's offsets across and along the segment from its middle
  (each linear in world x, y), ``t_s`` its thickness, ``l_s`` its half-length,
  ``k_s = p_s / WIDTH`` and ``p_s`` its trust, the share of its returns among them and
  the points the beams' free parts inside its band hold every 0.1 m
  (:func:`occtool.fuse._refit.wall_trust`), lifted to ``[0.5, 1]``: a MIN node over five
  linear pieces, the paper's form in world coordinates. A segment seen from one side only (its *facing*) falls over
  :data:`FRONT_WIDTH` on that side and :data:`BACK_WIDTH` behind: every free beam near it
  came from the front, and the returns its positions' pose errors scatter lie on both;
* **the observed region**: the union of what each local model saw (its rays up to its
  nearest return per degree, or its reach where it had none, up to
  :data:`occtool.fuse._refit.OBSERVED_REACH`), one shapely geometry; the Nav2 raster calls
  free only the part of it nearer to the positions (:meth:`WorldMap.free_space`);
* ``F = MAX(base, MAX over segments)``, ``base`` inside the observed region
  :data:`FREE_LEVEL` at the run's positions rising by :data:`FREE_SLOPE` a metre away from
  the nearest (a far beam's angle and its pose's error clear space less surely), below
  0.5; 0.5 (unknown) outside the region and at heights outside the robot's body band.

Only the segments (end points, thickness, trust), the positions and the region's vertices are stored:
:attr:`WorldMap.nbytes` counts them at the precision :mod:`occtool.formats.occmap` writes
them (a unit of :data:`UNIT` metres, 5 mm by default), which is everything
:meth:`WorldMap.predict` needs. The map is 2D: the occupancy of the robot's body band,
the map a planar robot drives by.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.formats.occmap import UNIT, MapArrays, quantise, unreadable
from occtool.formats.occmap import decode as occmap_decode
from occtool.raster import Raster

FloatArray = NDArray[np.float64]
#: What :meth:`WorldMap._near_segments` yields: a block's rows, its points' segments and
#: whether each was found, their offsets across and along.
_Nearby = tuple[slice, NDArray[np.intp], NDArray[np.bool_], FloatArray, FloatArray]

#: Occupancy falls from a wall's trust to 0 over this distance from it (metres, past its thickness) ...
WIDTH = 0.2
#: ... for a wall seen from one side only, over this distance on the side it was seen from ...
FRONT_WIDTH = 0.125
#: ... and this one behind it, where no beam of the run passed (chosen on inner splits, docs/map.md).
BACK_WIDTH = 0.6
#: Occupancy of the observed region away from walls, at a position of the run.
FREE_LEVEL = 0.1
#: ... rising by this much a metre from the nearest position (chosen on inner splits, docs/map.md),
FREE_SLOPE = 0.01
#: ... up to this (below unknown: observed space never reads unknown).
FREE_CAP = 0.45
#: Occupancy where no position observed.
UNKNOWN_LEVEL = 0.5
# The Nav2 raster's cells are occupied where the map's occupancy at their centre reaches
# occtool.raster.RASTER_OCCUPIED (map_server's own occupied_thresh) and free where it is at
# most RASTER_FREE, the run observed them and no trusted wall is within WALL_RIM, unknown
# between; the walls most positions saw through left out (chosen on inner splits of the
# four CARMEN logs' training scans, docs/map.md: against the fixed 7.5 cm wall band before
# it, trinary AUC +0.001 to +0.011 on each; its free cells are a subset of the band's).
#: A trusted wall's band is occupied in the raster however low its occupancy there: cell
#: centres within this of it (metres, past its thickness; half a 5 cm cell). The occupancy
#: threshold decides the rest (files before it kept 0.075 and draw their bands that wide).
WALL_HALF_WIDTH = 0.025
#: Observed cells this near a trusted wall (metres, past its thickness) are never free in the
#: raster, and explored where unknown: a wall's uncertain edge, not a frontier (chosen on
#: inner splits, docs/map.md).
WALL_RIM = 0.125
#: ... nor this near a *doubted* wall (metres, past its thickness): one not trusted, but
#: of a trust of at least :attr:`WorldMap.doubted_share`: a door, a
#: chair or a person some positions returned from and more saw through is not drawn, but its
#: cells are not known free either (chosen on inner splits, docs/map.md: held-out returns on
#: free cells fall on all four CARMEN logs, Intel 0.44 -> 0.33 %, FR-079 2.16 -> 1.57 %) ...
DOUBTED_WALL_RIM = 0.05
#: ... the trust (:attr:`WorldMap.doubted_share`; what a file without it reads as): below it
#: a wall is the noise of a depth camera's floor (half the segments of
#: fixtures/tum-fr3-cabinet were untrusted, most under 0.3; all of them would take 12 % of its
#: free floor, these 3.5 %). Chosen for the trust of files written without the key (the
#: share of the positions that returned from a wall among those that returned from it or saw
#: through its middle); :func:`build_world_map` gives its maps their own
#: (:data:`occtool.fuse._refit.NAV2_WALL_SHARE`, :data:`occtool.fuse._refit.NAV2_DOUBTED_SHARE`).
DOUBTED_TRUST = 0.3
#: A wall is drawn in the raster when its trust reaches this (:attr:`WorldMap.wall_share`).
WALL_SHARE = 0.5
def _peak_of(trust: FloatArray) -> FloatArray:
    """Ridge heights of walls of this ``trust`` (:attr:`WorldMap.peak`)."""
    return 0.5 + 0.5 * trust


#: Segment middles searched around a query point (the ridges of more never overlap there).
NEIGHBOURS = 12
#: Points a neighbour query answers at once: its ``(points, NEIGHBOURS)`` temporaries stay
#: a few megabytes.
_BLOCK = 1 << 15
#: A raster of at most this many cells keeps its float32 occupancy by default
#: (:meth:`WorldMap.rasterise`); a larger one holds two bytes a cell (cells, explored): the
#: Freiburg campus at 0.02 m (129 M cells) would need 0.5 GB more for it.
OCCUPANCY_CELLS = 50_000_000


def extent(start: FloatArray, end: FloatArray, positions: FloatArray, region: Any) -> tuple[FloatArray, FloatArray]:
    """World ``(x, y)`` lower and upper corners of segments (``start``, ``end`` ``(S, 2)``),
    positions ``(P, 2)`` and a region: :attr:`WorldMap.bounds` of a map of them."""
    import shapely

    boxes = [np.concatenate([start, end])] if start.shape[0] else []
    if positions.shape[0]:
        boxes.append(positions)
    if not region.is_empty:
        x0, y0, x1, y1 = shapely.bounds(region)
        boxes.append(np.array([[x0, y0], [x1, y1]]))
    if not boxes:
        return np.zeros(2), np.zeros(2)
    both = np.concatenate(boxes)
    return both.min(axis=0), both.max(axis=0)


class WorldMap:
    """A run's occupancy in the world frame: wall ridges over an observed region.

    Parameters
    ----------
    start, end
        ``(S, 2)`` world end points of the wall segments, metres.
    thickness
        ``(S,)`` each segment's spread across its line, metres.
    trust
        ``(S,)`` the share of positions that returned from the segment among those that
        returned from it or saw through it, in [0, 1].
    facing
        ``(S,)`` the side each segment was seen from: +1 the left of start -> end, -1 the
        right, 0 both (or unknown; the default for every segment).
    region
        A shapely (multi)polygon: where some position observed.
    positions
        ``(P, 2)`` world x, y of the positions that observed it (``None``: none kept, the
        free level is flat).
    band
        World heights ``(low, high)`` the map speaks for (the robot's body band).
    width, front_width, back_width, free_level, free_slope, unknown_level
        See :data:`WIDTH`, :data:`FRONT_WIDTH`, :data:`BACK_WIDTH`, :data:`FREE_LEVEL`,
        :data:`FREE_SLOPE`, :data:`UNKNOWN_LEVEL`.
    wall_half_width, wall_share, wall_rim, doubted_wall_rim, doubted_share
        The Nav2 raster's walls and their uncertain edges (:meth:`rasterise`): a wall of trust
        ``wall_share`` or more is drawn, one of trust ``doubted_share`` or more keeps its rim.
    free_reach
        The Nav2 raster calls observed space free no farther than this from a position
        (metres; 0: anywhere), unless :attr:`free_region` says where (:meth:`free_space`).
    """

    def __init__(self, start: ArrayLike, end: ArrayLike, thickness: ArrayLike, trust: ArrayLike, region: Any, *,
                 band: tuple[float, float], positions: ArrayLike | None = None, facing: ArrayLike | None = None,
                 width: float = WIDTH, front_width: float = FRONT_WIDTH, back_width: float = BACK_WIDTH,
                 free_level: float = FREE_LEVEL, free_slope: float = FREE_SLOPE,
                 unknown_level: float = UNKNOWN_LEVEL, wall_half_width: float = WALL_HALF_WIDTH,
                 wall_share: float = WALL_SHARE, wall_rim: float = WALL_RIM,
                 doubted_wall_rim: float = DOUBTED_WALL_RIM, free_reach: float = 0.0,
                 doubted_share: float = DOUBTED_TRUST) -> None:
        import shapely

        self.start = np.asarray(start, dtype=np.float64).reshape(-1, 2)
        self.end = np.asarray(end, dtype=np.float64).reshape(-1, 2)
        self.thickness = np.asarray(thickness, dtype=np.float64).reshape(-1)
        self.trust = np.asarray(trust, dtype=np.float64).reshape(-1)
        n = self.start.shape[0]
        if not (self.end.shape[0] == self.thickness.size == self.trust.size == n):
            raise InputError(f"{n} segment starts need as many ends, thicknesses and trusts")
        self.facing = (np.zeros(n, dtype=np.int8) if facing is None
                       else np.asarray(facing).astype(np.int8, casting="unsafe").reshape(-1))
        if self.facing.size != n or not np.isin(self.facing, (-1, 0, 1)).all():
            raise InputError(f"facing must hold -1, 0 or +1 for each of the {n} segments")
        for name, value in (("width", width), ("front_width", front_width), ("back_width", back_width),
                            ("wall_half_width", wall_half_width)):
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"{name} must be a positive number of metres, got {value}")
        for name, value in (("wall_rim", wall_rim), ("doubted_wall_rim", doubted_wall_rim),
                            ("free_reach", free_reach)):
            if not (math.isfinite(value) and value >= 0):
                raise InputError(f"{name} must be a number of metres >= 0, got {value}")
        if not (math.isfinite(free_slope) and free_slope >= 0):
            raise InputError(f"free_slope must be a number >= 0 (occupancy a metre), got {free_slope}")
        self.positions = (np.zeros((0, 2)) if positions is None
                          else np.asarray(positions, dtype=np.float64).reshape(-1, 2))
        if not np.isfinite(self.positions).all():
            raise InputError("positions must be finite x, y")
        for name, value in (("free_level", free_level), ("unknown_level", unknown_level), ("wall_share", wall_share),
                            ("doubted_share", doubted_share)):
            if not 0.0 <= value <= 1.0:
                raise InputError(f"{name} must lie in [0, 1], got {value}")
        if not (len(band) == 2 and band[0] <= band[1]):
            raise InputError(f"band must be (low, high) with low <= high, got {band}")
        self.region = region if region is not None else shapely.MultiPolygon()
        shapely.prepare(self.region)
        self.band = (float(band[0]), float(band[1]))
        self.width = float(width)
        self.front_width = float(front_width)
        self.back_width = float(back_width)
        self.free_level = float(free_level)
        self.free_slope = float(free_slope)
        self._position_index: Any = None
        self.unknown_level = float(unknown_level)
        self.wall_half_width = float(wall_half_width)
        self.wall_share = float(wall_share)
        self.wall_rim = float(wall_rim)
        self.doubted_wall_rim = float(doubted_wall_rim)
        self.doubted_share = float(doubted_share)
        self.free_reach = float(free_reach)
        #: Where the Nav2 raster may call observed space free (a shapely geometry inside the
        #: region, or ``None``: :meth:`free_space` says what then); not written to the file.
        self.free_region: Any = None
        #: The file's grid (:meth:`quantised` and :func:`load_map` set them): unit, metres, and
        #: origin; the unit of segments' half-lengths (``None`` in a version 1 file).
        self.unit: float | None = None
        self.origin: FloatArray | None = None
        self.half_unit: float | None = None
        self._index: Any = None

    @classmethod
    def from_arrays(cls, arrays: MapArrays) -> WorldMap:
        """The map of numbers at the file's precision (:func:`occtool.formats.occmap.quantise`,
        :func:`occtool.formats.occmap.decode`), on the file's grid."""
        world = cls(arrays.start, arrays.end, arrays.thickness, arrays.trust, arrays.region, band=arrays.band,
                    positions=arrays.positions, facing=arrays.facing, **arrays.settings)
        world.unit, world.origin, world.half_unit = arrays.unit, arrays.origin, arrays.half_unit
        return world

    def quantised(self, unit: float | None = None) -> WorldMap:
        """This map with its numbers rounded to what its file stores (a unit of ``unit``
        metres, default :data:`UNIT`) and its segments listed in the file's order: a map read
        back from its file answers as this one, bit for bit."""
        return WorldMap.from_arrays(quantise(self, unit))

    def __len__(self) -> int:
        return int(self.start.shape[0])

    # ------------------------------------------------------------------ geometry
    @property
    def peak(self) -> FloatArray:
        """Each segment's ridge height: its trust lifted to [0.5, 1] (a wall never reads free)."""
        return _peak_of(self.trust)

    @property
    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """World ``(x, y)`` lower and upper corners of the walls and the observed region."""
        return extent(self.start, self.end, self.positions, self.region)

    @property
    def nbytes(self) -> int:
        """Bytes of what :meth:`predict` needs, as the file stores it (its arrays, the header
        aside): per segment its middle in its tile, direction, half-length, thickness and
        trust (a byte each) and its facing (two bits); per tile of 1.28 m its segments' count;
        per vertex of the region a step of two int8 (and two uint16 where the step is longer) and
        its rings' and parts' offsets; per position two coordinates (uint16)
        (:mod:`occtool.formats.occmap`)."""
        from occtool.formats.occmap import array_bytes

        return array_bytes(self)

    def grid_bytes(self, resolution: float) -> int:
        """Bytes of a one-byte-a-cell grid of the map's bounding box at ``resolution`` metres:
        what the map is compared with."""
        lower, upper = self.bounds
        cells = np.ceil((upper - lower) / resolution).astype(np.int64)
        return int(np.prod(np.maximum(cells, 1)))

    def _segment_frames(self) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        middle = 0.5 * (self.start + self.end)
        span = self.end - self.start
        length = np.hypot(span[:, 0], span[:, 1])
        axis = np.where(length[:, None] > 1e-12, span / np.maximum(length, 1e-12)[:, None], [1.0, 0.0])
        return middle, axis, np.column_stack([-axis[:, 1], axis[:, 0]]), 0.5 * length

    def _segment_tree(self) -> Any:
        """The k-d tree of the segments' middles (built once, with the segments' frames)."""
        from scipy.spatial import cKDTree

        if self._index is None:
            self._frames = self._segment_frames()
            self._index = cKDTree(self._frames[0])
        return self._index

    def _neighbours(self, xy: FloatArray, reach: float) -> tuple[FloatArray, NDArray[np.intp]]:
        k = min(NEIGHBOURS, len(self))
        distance, index = self._segment_tree().query(xy, k=k, distance_upper_bound=reach)
        return np.asarray(distance).reshape(len(xy), k), np.asarray(index).reshape(len(xy), k)

    def _reach(self, beyond: float) -> float:
        """Farthest a segment's middle can lie from a point its ridge (or wall) touches."""
        half = self._frames[3] if self._index is not None else self._segment_frames()[3]
        return float(half.max() + self.thickness.max() + beyond) if len(self) else 0.0

    def wall_value(self, xy: ArrayLike, *, trusted: bool = False) -> FloatArray:
        """MAX over the segments' ridges at world ``(K, 2)`` points (``-inf`` where none reaches;
        ``trusted``: only segments of trust >= ``wall_share``)."""
        every, of_trusted = self._wall_values(xy)
        return of_trusted if trusted else every

    def _offsets(self, x: FloatArray, y: FloatArray, s: NDArray[np.intp]) -> tuple[FloatArray, FloatArray]:
        """World points' (``x``, ``y``) signed offsets across segments ``s`` (the three broadcast
        together) from their lines, and along them past their half-lengths."""
        middle, axis, normal, half = self._frames
        dx, dy = x - middle[s, 0], y - middle[s, 1]
        return dx * normal[s, 0] + dy * normal[s, 1], np.abs(dx * axis[s, 0] + dy * axis[s, 1]) - half[s]

    def _ridges(self, s: NDArray[np.intp], across: FloatArray, along: FloatArray) -> FloatArray:
        """Segments' ``s`` ridges at points this far across and along them (:meth:`_offsets`)."""
        peak = _peak_of(self.trust[s])
        # Across a one-sided wall the slope differs in front (the side it was seen from) and behind.
        facing = self.facing[s]
        width = np.where(facing == 0, self.width, np.where(across * facing >= 0, self.front_width, self.back_width))
        return np.minimum(peak, np.minimum(peak - peak / width * (np.abs(across) - self.thickness[s]),
                                           peak - peak / self.width * along))

    def _gaps(self, s: NDArray[np.intp], across: FloatArray, along: FloatArray) -> FloatArray:
        """Distances from points this far across and along segments ``s`` to their bands."""
        return np.hypot(np.maximum(np.abs(across) - self.thickness[s], 0.0), np.maximum(along, 0.0))

    def _near_segments(self, xy: FloatArray, reach: float) -> Iterator[_Nearby]:
        """The points' few nearest segments (their middles within ``reach``), a block of points
        at a time (bounded temporaries): the block's rows, the segments (``(n, k)``, ``0`` where
        none), whether one was found there, and the offsets (:meth:`_offsets`)."""
        for low in range(0, xy.shape[0], _BLOCK):
            block = xy[low:low + _BLOCK]
            distance, index = self._neighbours(block, reach)
            found = np.isfinite(distance)
            s = np.where(found, index, 0)
            yield slice(low, low + block.shape[0]), s, found, *self._offsets(block[:, :1], block[:, 1:], s)

    def _wall_values(self, xy: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """:meth:`wall_value` over every segment and over the trusted ones, in one neighbour query."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        every = np.full(xy.shape[0], -np.inf)
        of_trusted = every.copy()
        if not len(self) or not xy.shape[0]:
            return every, of_trusted
        trusted = self.trust >= self.wall_share
        reach = self._reach(max(self.width, self.front_width, self.back_width))
        for rows, s, found, across, along in self._near_segments(xy, reach):
            value = np.where(found, self._ridges(s, across, along), -np.inf)
            every[rows] = value.max(axis=1)
            of_trusted[rows] = np.where(trusted[s], value, -np.inf).max(axis=1)
        return every, of_trusted

    def wall_distance(self, xy: ArrayLike, *, trusted: bool = True, within: float | None = None) -> FloatArray:
        """Distance from world ``(K, 2)`` points to the nearest segment's band (its line widened by
        its thickness; ``trusted``: only segments of trust >= ``wall_share``); ``inf`` beyond
        ``within`` of every band (default :attr:`wall_half_width`)."""
        every, of_trusted = self._wall_distances(xy, self.wall_half_width if within is None else within)
        return of_trusted if trusted else every

    def _wall_distances(self, xy: ArrayLike, within: float, least_trust: float = 0.0) -> tuple[FloatArray, FloatArray]:
        """:meth:`wall_distance` to the segments of trust >= ``least_trust`` and to the trusted
        ones, in one neighbour query."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        every = np.full(xy.shape[0], np.inf)
        of_trusted = every.copy()
        if not len(self) or not xy.shape[0]:
            return every, of_trusted
        trusted = self.trust >= self.wall_share
        counted = self.trust >= least_trust
        for rows, s, found, across, along in self._near_segments(xy, self._reach(within + 1e-9)):
            gap = np.where(found, self._gaps(s, across, along), np.inf)
            every[rows] = np.where(counted[s], gap, np.inf).min(axis=1)
            of_trusted[rows] = np.where(trusted[s], gap, np.inf).min(axis=1)
        every[every > within] = np.inf
        of_trusted[of_trusted > within] = np.inf
        return every, of_trusted

    def free_value(self, xy: ArrayLike) -> FloatArray:
        """Occupancy of observed space away from walls at world ``(K, 2)`` points:
        :attr:`free_level` plus :attr:`free_slope` a metre from the nearest position, under
        :data:`FREE_CAP`; flat without positions."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if self.flat_free or not xy.shape[0]:
            return np.full(xy.shape[0], min(self.free_level, FREE_CAP))
        return self.free_values(self._position_distance(xy))

    @property
    def flat_free(self) -> bool:
        """Whether observed space reads one level everywhere (no positions kept, or no slope)."""
        return not self.positions.shape[0] or self.free_slope == 0.0

    def free_values(self, distance: FloatArray) -> FloatArray:
        """:meth:`free_value` at points this far from the nearest position (metres)."""
        return np.minimum(self.free_level + self.free_slope * distance, FREE_CAP)

    def floor_level(self) -> float:
        """The least occupancy :meth:`predict` reads anywhere before the walls (observed or not):
        a ridge at or below it changes nothing there."""
        return min(self.free_level, FREE_CAP, self.unknown_level)

    def _position_tree(self) -> Any:
        """The k-d tree of the positions (built once)."""
        from scipy.spatial import cKDTree

        if self._position_index is None:
            self._position_index = cKDTree(self.positions)
        return self._position_index

    def _position_distance(self, xy: FloatArray) -> FloatArray:
        return np.asarray(self._position_tree().query(xy)[0], dtype=np.float64)

    def free_space(self, xy: ArrayLike) -> NDArray[np.bool_]:
        """Whether the Nav2 raster may call observed space free at world ``(K, 2)`` points
        (:meth:`rasterise`): inside :attr:`free_region` when the map holds one (the map
        built by :func:`build_world_map` does; its file does not keep it), else within
        :attr:`free_reach` of a position (everywhere when that is 0 or no position is kept)."""
        import shapely

        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if self.free_region is not None:
            return np.asarray(shapely.contains_xy(self.free_region, xy[:, 0], xy[:, 1]), dtype=bool)
        if self.free_reach > 0.0 and self.positions.shape[0] and xy.shape[0]:
            return self._position_distance(xy) <= self.free_reach
        return np.ones(xy.shape[0], dtype=bool)

    def observed(self, xy: ArrayLike) -> NDArray[np.bool_]:
        """Whether world ``(K, 2)`` points lie in the observed region."""
        import shapely

        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        if self.region.is_empty:
            return np.zeros(xy.shape[0], dtype=bool)
        return np.asarray(shapely.contains_xy(self.region, xy[:, 0], xy[:, 1]), dtype=bool)

    # ------------------------------------------------------------------ queries
    def predict(self, points_world: ArrayLike) -> FloatArray:
        """Occupancy in [0, 1] at world points ``(K, 3)`` (x, y, z; z in the poses' datum, so a
        2D laser's plane is the poses' z): 0.5 where no position observed or outside the band."""
        points = np.asarray(points_world, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise InputError(f"query points must be (K, 3) x, y, z, got shape {points.shape}")
        if not np.isfinite(points).all():
            raise InputError("query points must be finite numbers")
        out = np.full(points.shape[0], self.unknown_level)
        band = (points[:, 2] >= self.band[0] - 1e-9) & (points[:, 2] <= self.band[1] + 1e-9)
        xy = points[band, :2]
        observed = self.observed(xy)
        base = np.full(xy.shape[0], self.unknown_level)
        base[observed] = self.free_value(xy[observed])
        out[band] = np.clip(np.maximum(base, self.wall_value(xy)), 0.0, 1.0)
        return out

    def rasterise(self, resolution: float = 0.05, *, max_cells: int | None = None, executor: Any = None,
                  occupancy: bool | None = None, spill: Any = None) -> Raster:
        """Free / occupied / unknown cells, as Nav2 loads them, from the occupancy of the
        trusted walls (:meth:`predict` without the walls most positions saw through, which the
        trinary map does not draw) at the cell's centre: occupied where it reaches
        :data:`occtool.raster.RASTER_OCCUPIED` or within :attr:`wall_half_width` of a trusted wall's band;
        free where the run observed the cell near a position (:meth:`free_space`: a far beam's
        angle and its pose's error clear space less surely), it is at most
        :data:`occtool.raster.RASTER_FREE` and the cell lies farther than :attr:`wall_rim` from a
        trusted wall's band and than
        :attr:`doubted_wall_rim` from a doubted one's (trust >= :attr:`doubted_share`);
        unknown elsewhere (a wall's uncertain edge, what nobody observed). Row 0 is the
        bottom; ``probability`` is :meth:`predict` at the cell centres; ``explored`` marks
        the cells the run observed or placed a wall near (within those rims: the unknown
        among them are uncertain, not unexplored: no frontier lies there). ``executor`` (an
        :class:`occtool.executor.Executor`, e.g. a Dask cluster's) computes its bands of rows;
        the raster is the same wherever they ran. ``occupancy``: keep ``probability`` (four
        bytes a cell); ``None``: when the raster has at most :data:`OCCUPANCY_CELLS` cells.
        ``max_cells``: refuse a larger raster (``None``: any; a run's memory is checked
        before it starts, :func:`occtool.fuse.check_map_memory`). ``spill``: a folder where a
        large raster's cells are kept in a temporary file rather than in memory
        (:func:`occtool.fuse._rasterise.rasterise`)."""
        from occtool.fuse._rasterise import raster_shape
        from occtool.fuse._rasterise import rasterise as rasterise_strips

        if not (math.isfinite(resolution) and resolution > 0):
            raise InputError(f"resolution must be a positive number of metres, got {resolution}")
        origin, nx, ny = raster_shape(self, resolution)
        if max_cells is not None and nx * ny > max_cells:
            raise InputError(f"a {resolution} m raster of the map needs {nx}x{ny} cells: use a coarser resolution")
        if occupancy is None:
            occupancy = nx * ny <= OCCUPANCY_CELLS
        # Cell by cell as described above, a strip of rows at a time (occtool.fuse._rasterise):
        # one query for the bands round the trusted and the doubted walls (exact up to the widest).
        return rasterise_strips(self, float(resolution), nx, ny, origin,
                                max(self.wall_half_width, self.wall_rim, self.doubted_wall_rim), self.doubted_share,
                                executor=executor, occupancy=occupancy, spill=spill)

    def params(self) -> dict[str, Any]:
        """The map's scalar settings (what the file's header holds besides the arrays; a file
        written before :attr:`free_reach` reads as 0, so that merging it with a later map is
        refused as merging maps of other settings is; one written before
        :attr:`doubted_share` reads as :data:`DOUBTED_TRUST`, the share it was drawn with)."""
        return {"band": list(self.band), "width": self.width, "front_width": self.front_width,
                "back_width": self.back_width, "free_level": self.free_level,
                "free_slope": self.free_slope,
                "unknown_level": self.unknown_level, "wall_half_width": self.wall_half_width,
                "wall_share": self.wall_share, "wall_rim": self.wall_rim, "doubted_wall_rim": self.doubted_wall_rim,
                "free_reach": self.free_reach, "doubted_share": self.doubted_share}

    def save(self, path: Any, *, overwrite: bool = True) -> int:
        """Write the map to ``path`` (:mod:`occtool.formats.occmap`, atomically); returns its bytes."""
        from occtool.formats.occmap import save_map

        return save_map(self, path, overwrite=overwrite)


def decode_map(data: bytes, name: str = "occmap") -> WorldMap:
    """The :class:`WorldMap` of a ``.occmap`` file's bytes (:func:`occtool.formats.occmap.decode`);
    a damaged or foreign file is one :class:`InputError` naming ``name``."""
    return _from_file(occmap_decode(data, name), name)


def _from_file(arrays: MapArrays, name: str) -> WorldMap:
    import inspect

    # The header's settings must be the map's keywords (a file's own names, not any keyword).
    known = {key for key, p in inspect.signature(WorldMap).parameters.items()
             if p.kind is p.KEYWORD_ONLY and isinstance(p.default, float)}
    unknown = sorted(set(arrays.settings) - known)
    if unknown:
        raise unreadable(name, f"unknown setting {unknown[0][:40]!r}")
    try:
        return WorldMap.from_arrays(arrays)
    except (InputError, TypeError, KeyError, IndexError, ValueError) as exc:
        # Numbers the file holds that no map takes (a band upside down, a facing of 2).
        raise unreadable(name, str(exc)) from None


__all__ = ["OCCUPANCY_CELLS", "UNIT", "WorldMap", "decode_map"]
