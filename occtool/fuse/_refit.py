"""Refitting a run into its world map (:func:`build_world_map`): walls fitted to the returns,
trusted by their share of returns among what the beams sampled in their bands, over the
region the positions observed (:mod:`occtool.fuse._world` says what the map is)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.formats.occmap import quantise_region
from occtool.fuse._sightings import RunReturns, returns_of_fused
from occtool.fuse._walls import CELL, MAX_THICKNESS, MIN_RETURNS, Segments, fit_segments, free_in_bands
from occtool.fuse._world import WorldMap, extent
from occtool.limits import release_free_memory

FloatArray = NDArray[np.float64]

#: A beam is free up to this before its own return where it passes a wall's band (metres).
THROUGH_MARGIN = 0.1

#: A wall's trust is a counting model over its band: its returns' share among them and the
#: points its beams' free parts inside the band would hold every FREE_STEP metres (the
#: held-out scorers' spacing of free points); the band is the wall's line widened to
#: BAND_HALF_WIDTH either side (or its thickness) and lengthened by it past each end, and
#: measured at points BAND_SPACING apart (:func:`occtool.fuse._walls.free_in_bands`).
#: Chosen on inner splits of the training scans (docs/figures.md, 2026-12-04): half-width
#: 0.01 / **0.02** / 0.03 m, step 0.05 / **0.1** / 0.2 m.
FREE_STEP = 0.1
BAND_HALF_WIDTH = 0.02
BAND_SPACING = 0.1

#: The Nav2 raster of a scanning laser's map draws the walls of at least this trust and keeps
#: the rims of those of at least NAV2_DOUBTED_SHARE (:attr:`WorldMap.wall_share`,
#: :attr:`WorldMap.doubted_share`): the trust above is lower than the positions' share that
#: maps kept before it (a wall the beams graze is passed along its band), chosen on the same
#: inner splits for the trinary map's AUC with no more held-out returns on its free cells
#: than before (docs/figures.md). Other sensors' maps keep the shares chosen before
#: (:data:`occtool.fuse._world.WALL_SHARE`, :data:`occtool.fuse._world.DOUBTED_TRUST`): on
#: the depth frames of fixtures/tum-fr3-cabinet mapped in 2D these would take 22 % of the
#: free floor (3,058 free cells against 3,935 before; 4,292 with the shares before).
NAV2_WALL_SHARE = 0.15
NAV2_DOUBTED_SHARE = 0.05

#: Returns no farther than this from their position place walls (metres).
WALL_REACH = 16.0

#: Returns up to this far from their position place walls too (metres; the Freiburg campus's
#: held-out returns off its map lay by walls seen from 30-50 m, docs/figures.md) ...
FAR_WALL_REACH = 50.0
#: ... where no return within WALL_REACH of its position lies this near (metres): walls the
#: run saw only from afar (ACES seed 1, docs/figures.md), fitted on their own so that the
#: nearer walls stay as they were (at 0.3 m they lowered ACES seed 0's held-out AUC).
FAR_WALL_GAP = 2.0
#: Near returns indexed at once when the far returns are checked against them.
FAR_TREE_RETURNS = 1 << 18

#: Beams see through walls no farther than this from their position, and the Nav2 raster
#: calls observed space free no farther than this from a position (metres): a far beam's
#: angle and its pose's error place it less surely.
REGION_REACH = 8.0

#: Beams sweep the world map's observed region this far from their position (metres): its
#: free level, rising away from the positions, grades what lies past REGION_REACH.
OBSERVED_REACH = 16.0


#: Polygons farther apart than this many simplification tolerances are simplified apart
#: (:func:`_simplified`): a shortcut stays within one tolerance of the line it replaces.
SIMPLIFY_APART = 4.0


def _observed_region(distances: Any, poses: FloatArray, reach: float, simplify: float) -> Any:
    """Union of what each position (``poses`` ``(P, 4)`` x, y, z, yaw) saw: rays up to
    ``distances`` (``(P, bins)``, at most ``reach``) at the bins' centres, simplified by
    ``simplify`` metres (:func:`_simplified`; 0: not simplified).

    Made a group of overlapping views at a time (:func:`occtool.fuse._union.union_in_groups`),
    each group's views drawn when it is unioned and its union simplified before the next:
    a large run never holds all its views nor its whole unsimplified region (campus x4's
    took 72 MB and 108 MB)."""
    from occtool.fuse._union import union_in_groups

    views = _Views(distances, poses, reach)
    # Groups whose boxes are farther apart than _simplified's reach are simplified alike apart.
    return union_in_groups(views, bounds=views.bounds, margin=SIMPLIFY_APART * simplify,
                           then=(lambda union: _simplified(union, simplify)) if simplify > 0 else None)


class _Views:
    """Each position's view, the polygon of its rays (:func:`_observed_region`), drawn for the
    positions an index array names; :attr:`bounds` ``(P, 4)``, NaN for a position that saw
    nothing (no view)."""

    #: Positions whose rings are drawn at once (a large run's temporaries).
    BLOCK = 1024

    def __init__(self, distances: Any, poses: FloatArray, reach: float) -> None:
        self.distances, self.poses, self.reach = distances, poses, reach
        bins = distances.shape[1]
        self.angles = -math.pi + (np.arange(bins) + 0.5) * (2.0 * math.pi / bins)
        self.bounds = np.full((distances.shape[0], 4), np.nan)
        for low in range(0, distances.shape[0], self.BLOCK):
            rows = np.arange(low, min(low + self.BLOCK, distances.shape[0]))
            seen, rings = self._rings(rows)
            self.bounds[rows[seen]] = np.column_stack([rings[..., 0].min(axis=1), rings[..., 1].min(axis=1),
                                                       rings[..., 0].max(axis=1), rings[..., 1].max(axis=1)])

    def _rings(self, rows: NDArray[np.intp]) -> tuple[NDArray[np.bool_], FloatArray]:
        r = np.minimum(self.distances[rows], self.reach)
        seen: NDArray[np.bool_] = np.asarray((r > 0).any(axis=1))
        block = self.poses[rows]
        a = self.angles[None, :] + block[seen, 3:4]
        return seen, np.stack([block[seen, 0:1] + r[seen] * np.cos(a), block[seen, 1:2] + r[seen] * np.sin(a)],
                              axis=-1)

    def __getitem__(self, rows: NDArray[np.intp]) -> NDArray[np.object_]:
        import shapely

        views = []
        for low in range(0, len(rows), self.BLOCK):
            _, rings = self._rings(np.asarray(rows[low:low + self.BLOCK]))
            views.append(shapely.make_valid(shapely.polygons(rings)))
        return np.concatenate(views) if views else np.zeros(0, dtype=object)


def _simplified(region: Any, tolerance: float) -> Any:
    """``shapely.simplify(region, tolerance, preserve_topology=True)``, a group of the
    region's polygons at a time: those within a few tolerances of each other.

    GEOS's topology-preserving simplifier checks every shortcut against every other ring
    of the geometry, so its time grows as the square of the rings: campus x4's regions (four
    polygons, 10,000 holes) took 6.9 s against the campus's 0.36 s. A shortcut stays within
    ``tolerance`` of the line it replaces, so it can neither cross nor jump over a polygon
    farther than twice that: each group is simplified as it is within the whole, and the
    polygons come back in their order (the same WKB on the campus x1 and x4)."""
    import shapely

    from occtool.fuse._union import connected_labels

    parts = shapely.get_parts(region)
    if parts.size <= 1:
        return shapely.simplify(region, tolerance, preserve_topology=True)
    near, other = shapely.STRtree(parts).query(parts, predicate="dwithin", distance=SIMPLIFY_APART * tolerance)
    count, group = connected_labels(near, other, parts.size)
    if count == 1:
        return shapely.simplify(region, tolerance, preserve_topology=True)
    out = np.empty(parts.size, dtype=object)
    for k in range(count):
        members = np.flatnonzero(group == k)
        out[members] = shapely.get_parts(shapely.simplify(shapely.multipolygons(parts[members]), tolerance,
                                                          preserve_topology=True))
    return shapely.multipolygons(out)


#: Far returns measured at once by :func:`_with_far_walls`.
_FAR_AT_ONCE = 1 << 18


def _with_far_walls(segments: Segments, run: RunReturns, near: FloatArray, reach: float, far_reach: float,
                    one_sided: bool, fit: dict[str, Any]) -> Segments:
    """``segments`` (fitted to the returns within ``reach``, ``near``) and the walls of the
    returns between ``reach`` and ``far_reach`` that lie farther than :data:`FAR_WALL_GAP`
    from every near return: walls only far positions saw, fitted on their own so that the
    near walls stay as they were."""
    from scipy.spatial import cKDTree

    # The returns beyond reach, measured as before from the world points (the range itself
    # can round to the other side of reach; a micrometre below it takes those in).
    points, owner = run.return_points(far_reach, beyond=reach - 1e-6)
    far = np.zeros(points.shape[0], dtype=bool)
    blocks = range(0, points.shape[0], _FAR_AT_ONCE)  # a block's temporaries, not the run's
    for low in blocks:
        high = low + _FAR_AT_ONCE
        far[low:high] = np.hypot(*(points[low:high] - run.poses[owner[low:high], :2]).T) > reach
    if far.any() and near.shape[0]:
        # A tree of a block of the near returns at a time, not copied into it (every scan's
        # returns: 1.5 M on FR-079, 50 MB in one tree): a far return is near one when a
        # block's is within the gap, and only those still alone are asked of the next block.
        near = np.ascontiguousarray(near)
        for start in range(0, near.shape[0], FAR_TREE_RETURNS):
            tree = cKDTree(near[start:start + FAR_TREE_RETURNS], copy_data=False)
            for low in blocks:
                chosen = low + np.flatnonzero(far[low:low + _FAR_AT_ONCE])
                if chosen.size:
                    far[chosen] = np.isinf(tree.query(points[chosen], distance_upper_bound=FAR_WALL_GAP)[0])
            del tree
    if not far.any():
        return segments
    points, owner = points[far], owner[far]
    extra = fit_segments(points, owner, owner_positions=run.poses[:, :2] if one_sided else None, **fit)
    return Segments(*(np.concatenate([getattr(segments, f), getattr(extra, f)])
                      for f in ("start", "end", "thickness", "hits", "facing")))


def wall_trust(segments: Segments, run: RunReturns, reach: float) -> FloatArray:
    """Each segment's trust: the share of its returns among them and the free points its band
    holds, the beams of ``run`` up to ``reach`` inside it every :data:`FREE_STEP` metres up to
    :data:`THROUGH_MARGIN` before their own return (:func:`occtool.fuse._walls.free_in_bands`):
    the counting model of a grid whose cells are the walls' bands."""
    free = free_in_bands(segments.start, segments.end, segments.thickness, run.poses, run.ranges,
                         margin=THROUGH_MARGIN, reach=reach, half_width=BAND_HALF_WIDTH, spacing=BAND_SPACING)
    return np.asarray(segments.hits / np.maximum(segments.hits + free / FREE_STEP, 1e-12), dtype=np.float64)


def build_world_map(fused: Any, *, sightings: RunReturns | None = None, cell: float = CELL,
                    max_thickness: float = MAX_THICKNESS, min_returns: int = MIN_RETURNS, reach: float = WALL_REACH,
                    far_reach: float = FAR_WALL_REACH, region_reach: float = REGION_REACH,
                    observed_reach: float = OBSERVED_REACH, simplify: float = 0.03, one_sided: bool | None = None,
                    **params: Any) -> WorldMap:
    """Refit a run into a :class:`WorldMap`, rounded to the precision of its file
    (:meth:`WorldMap.quantised`).

    ``sightings`` is what every position of the run saw (:func:`returns_of_positions`; by
    default ``fused``'s own positions, :func:`returns_of_fused`): the walls are fitted to
    its returns and its beams measure their trust; the observed region is swept by ``fused``'s
    positions (a :class:`FusedMap`), which hold the run's local models.
    The walls are fitted to the returns no farther than ``reach`` from their position
    (:func:`occtool.fuse._walls.fit_segments`
    with ``cell``, ``max_thickness`` and ``min_returns``), and apart from them to the returns
    up to ``far_reach`` that lie farther than :data:`FAR_WALL_GAP` from all of those (walls
    the run saw only from afar); each is trusted by its returns' share among them and its
    band's free points, the beams' free parts up to ``region_reach`` inside it every
    :data:`FREE_STEP` metres (:func:`occtool.fuse._walls.free_in_bands`). The
    beams up to ``observed_reach`` sweep the observed region, those up to ``region_reach``
    the part of it the Nav2 raster may call free (:attr:`WorldMap.free_region`, kept in
    memory, not in the file; the file keeps ``region_reach`` as :attr:`WorldMap.free_reach`);
    both are simplified by ``simplify`` metres (Douglas-Peucker, topology kept). ``one_sided``: let
    walls seen from one side face it (``None``: when ``sightings`` are a scanning laser's;
    on the noisy clouds of fixtures/tum-fr3-cabinet facing walls lowered the world map's
    AUC on each of five splits, docs/map.md). The map speaks for
    ``fused``'s robot's body band. ``params`` go to :class:`WorldMap` (``width``,
    ``free_level``...). The defaults were chosen on inner splits of the training scans of
    four CARMEN logs (docs/map.md).
    """
    for name, value in (("reach", reach), ("region_reach", region_reach), ("observed_reach", observed_reach)):
        if not value > 0:
            raise InputError(f"{name} must be a positive number of metres, got {value}")
    if not simplify >= 0:
        raise InputError(f"simplify must be a number of metres >= 0, got {simplify}")
    # The fused positions' own returns sweep the regions; made after the walls, which take
    # the most memory, when the run's sightings are given (campus x4: 29 MB).
    run = returns_of_fused(fused) if sightings is None else sightings
    one_sided = run.scanning_laser if one_sided is None else one_sided
    fit: dict[str, Any] = {"cell": cell, "max_thickness": max_thickness, "min_returns": min_returns}
    points, owner = run.return_points(reach)
    segments: Segments = fit_segments(points, owner, owner_positions=run.poses[:, :2] if one_sided else None, **fit)
    del owner  # the far walls ask only where the near returns lie (campus x10: 22 MB)
    if far_reach > reach:
        segments = _with_far_walls(segments, run, points, reach, far_reach, one_sided, fit)
    del points  # a large run's returns: not held through the unions below
    release_free_memory()
    trust = wall_trust(segments, run, region_reach)
    own = run if sightings is None else returns_of_fused(fused)
    regions = [_observed_region(own.ranges, own.poses, r, simplify)
               for r in (observed_reach, min(region_reach, observed_reach))]
    import shapely

    low, high = fused.robot.body_band
    z0 = float(np.median(fused._pose_array[:, 2]))
    shares = {"wall_share": NAV2_WALL_SHARE, "doubted_share": NAV2_DOUBTED_SHARE} if run.scanning_laser else {}
    world = WorldMap(segments.start, segments.end, segments.thickness, trust, regions[0], band=(z0 + low, z0 + high),
                     positions=own.poses[:, :2], facing=segments.facing,
                     **{"free_reach": region_reach, **shares, **params})
    # Rounded to the file's precision now, so that the map written is the map used.
    world = world.quantised()
    # The Nav2 raster's free space: the region the beams swept within region_reach, as
    # before the region reached farther (its returns on free cells, docs/figures.md), on the
    # grid a map of it and the same walls would have (not made: campus x10's 600,000
    # segments rounded a second time took 90 MB).
    free_region = quantise_region(regions[1], *extent(segments.start, segments.end, own.poses[:, :2], regions[1]))
    shapely.prepare(free_region)
    world.free_region = free_region
    release_free_memory()  # the unions' GEOS garbage, before the raster
    return world


__all__ = ["BAND_HALF_WIDTH", "BAND_SPACING", "FAR_WALL_GAP", "FAR_WALL_REACH", "FREE_STEP", "NAV2_DOUBTED_SHARE",
           "NAV2_WALL_SHARE", "OBSERVED_REACH", "REGION_REACH", "THROUGH_MARGIN", "WALL_REACH", "build_world_map",
           "wall_trust"]
