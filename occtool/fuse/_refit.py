"""Refitting a run into its world map (:func:`build_world_map`): walls fitted to the returns,
trusted by the beams that saw through them, over the region the positions observed
(:mod:`occtool.fuse._world` says what the map is)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.fuse._sightings import RunReturns, returns_of_fused
from occtool.fuse._walls import CELL, MAX_THICKNESS, MIN_RETURNS, Segments, fit_segments, seen_through
from occtool.fuse._world import WorldMap
from occtool.limits import release_free_memory

FloatArray = NDArray[np.float64]

#: A beam passing a segment's middle more than this in front of its own return saw through it (metres).
THROUGH_MARGIN = 0.1

#: Returns no farther than this from their position place walls (metres).
WALL_REACH = 16.0

#: Beams sweep the observed region and see through walls no farther than this from their
#: position (metres): a far beam's angle and its pose's error place it less surely.
REGION_REACH = 8.0


def _observed_region(distances: FloatArray, poses: FloatArray, reach: float) -> Any:
    """Union of what each position (``poses`` ``(P, 4)`` x, y, z, yaw) saw: rays up to
    ``distances`` (``(P, bins)``, at most ``reach``) at the bins' centres."""
    import shapely

    bins = distances.shape[1]
    angles = -math.pi + (np.arange(bins) + 0.5) * (2.0 * math.pi / bins)
    r = np.minimum(distances, reach)
    seen = (r > 0).any(axis=1)
    if not seen.any():
        return shapely.MultiPolygon()
    a = angles[None, :] + poses[seen, 3:4]
    rings = np.stack([poses[seen, 0:1] + r[seen] * np.cos(a), poses[seen, 1:2] + r[seen] * np.sin(a)], axis=-1)
    return shapely.union_all(shapely.make_valid(shapely.polygons(rings)))


def build_world_map(fused: Any, *, sightings: RunReturns | None = None, cell: float = CELL,
                    max_thickness: float = MAX_THICKNESS, min_returns: int = MIN_RETURNS, reach: float = WALL_REACH,
                    region_reach: float = REGION_REACH, simplify: float = 0.03, one_sided: bool | None = None,
                    **params: Any) -> WorldMap:
    """Refit a run into a :class:`WorldMap`, rounded to the precision of its file
    (:meth:`WorldMap.quantised`).

    ``sightings`` is what every position of the run saw (:func:`returns_of_positions`; by
    default ``fused``'s own positions, :func:`returns_of_fused`): the walls are fitted to
    its returns and its beams see through them; the observed region is swept by ``fused``'s
    positions (a :class:`FusedMap`), which hold the run's local models.
    The walls are fitted to the returns no farther than ``reach`` from their position
    (:func:`occtool.fuse._walls.fit_segments`
    with ``cell``, ``max_thickness`` and ``min_returns``); the beams up to ``region_reach``
    see through them and sweep the observed region, which is
    simplified by ``simplify`` metres (Douglas-Peucker, topology kept). ``one_sided``: let
    walls seen from one side face it (``None``: when ``sightings`` are a scanning laser's;
    on the noisy clouds of fixtures/tum-fr3-cabinet facing walls lowered the world map's
    AUC on each of five splits, docs/map.md). The map speaks for
    ``fused``'s robot's body band. ``params`` go to :class:`WorldMap` (``width``,
    ``free_level``...). The defaults were chosen on inner splits of the training scans of
    four CARMEN logs (docs/map.md).
    """
    import shapely

    for name, value in (("reach", reach), ("region_reach", region_reach)):
        if not value > 0:
            raise InputError(f"{name} must be a positive number of metres, got {value}")
    own = returns_of_fused(fused)
    run = own if sightings is None else sightings
    points, owner = run.return_points(reach)
    one_sided = run.scanning_laser if one_sided is None else one_sided
    segments: Segments = fit_segments(points, owner, viewpoints=run.poses[owner, :2] if one_sided else None,
                                      cell=cell, max_thickness=max_thickness, min_returns=min_returns)
    through = seen_through(segments.middle, run.poses, run.ranges, margin=THROUGH_MARGIN, reach=region_reach)
    trust = segments.hits / np.maximum(segments.hits + through, 1)
    region = _observed_region(own.ranges, own.poses, region_reach)
    if simplify > 0 and not region.is_empty:
        region = shapely.simplify(region, simplify, preserve_topology=True)
    low, high = fused.robot.body_band
    z0 = float(np.median(fused._pose_array[:, 2]))
    world = WorldMap(segments.start, segments.end, segments.thickness, trust, region, band=(z0 + low, z0 + high),
                     positions=own.poses[:, :2], facing=segments.facing, **params)
    # Rounded to the file's precision now, so that the map written is the map used.
    world = world.quantised()
    release_free_memory()  # the unions' GEOS garbage, before the raster
    return world


__all__ = ["REGION_REACH", "THROUGH_MARGIN", "WALL_REACH", "build_world_map"]
