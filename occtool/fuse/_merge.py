"""Merging saved world maps (:func:`merge_maps`): many robots' ``world.occmap`` files, one map.

Each input is a :class:`WorldMap` (segments, observed region, positions) in its own frame;
a rigid transform ``(x, y, yaw)`` per input places it in the merged frame (REP-103: metres,
radians counter-clockwise; the input's point ``p`` lands at ``R(yaw) p + (x, y)``). The
merged map is

* **the segments of every input, each wall once**: every segment is first written in the
  codes of the merged file (its middle on the common grid of :data:`UNIT`, its direction in
  steps of pi/256, its half-length, thickness and trust in bytes, its facing), exact
  duplicates are one, and a segment is dropped when another one *covers* it: both its end
  points lie within the other's band (their thicknesses and :data:`COVER_MARGIN` across its
  line, :data:`COVER_MARGIN` past its ends), its direction lies within
  :data:`COVER_ANGLE_STEPS` of the other's, they do not face opposite sides, and the other
  ranks higher: longer, then more trusted, then by its codes (a total order, so no two
  segments drop each other). Two robots that saw a wall give it twice, a few centimetres
  apart: the map keeps the longer piece (longer first kept fewer segments and scored
  higher on held-out scans than more trusted first, docs/map.md). A map's own segments
  cover one another too: a map merged alone loses its covered pieces;
* **the union of the observed regions**, on the grid (GEOS's snap-rounding overlay);
* **the positions of every input**, distinct, sorted by their grid codes.

What the merge computes is a function of the *set* of segments, positions and regions, in
the canonical order of their codes: the same bytes whatever the order of the inputs.
Merging is associative in its segments and positions with one exception: a segment ``s``
dropped because ``t`` covers it, where ``t`` is itself dropped because ``u`` covers it
and ``u`` does not cover ``s``; ``merge(merge(a, b), c)`` then keeps or drops ``s``
depending on which of ``s``, ``t``, ``u`` met in the inner merge. The region's union is
snap-rounded at each merge, so nested merges may move a vertex where boundaries cross by a
unit (5 mm). Both differences move :meth:`WorldMap.predict` by little (tests/test_merge.py
measures it).

The inputs must agree on the map's settings (the robot's body band and the occupancy
parameters): a map speaks for one body band.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.formats._occmap_packing import DIRECTION_STEPS, HALF_UNIT, _grid, _segment_ends, _tiles, direction_codes
from occtool.formats.occmap import UNIT, MapArrays
from occtool.fuse._world import WorldMap
from occtool.fuse._world3d import WorldMap3D

FloatArray = NDArray[np.float64]
Transform = tuple[float, float, float]

#: A segment covers another whose end points lie within this of its band (metres, past
#: both thicknesses across its line and past its ends along it).
COVER_MARGIN = 0.05
#: ... and whose direction lies within this many steps of pi/256 of its own (22.5 degrees);
#: a segment shorter than :data:`COVER_MARGIN` has no direction to compare.
COVER_ANGLE_STEPS = 32


class _Codes:
    """Segments as the merged file codes them, the middle in absolute grid units (so that
    codes agree whatever the merged map's origin)."""

    def __init__(self, middle: NDArray[np.int64], step: NDArray[np.int64], half: NDArray[np.int64],
                 thickness: NDArray[np.int64], trust: NDArray[np.int64], facing: NDArray[np.int64]) -> None:
        self.table = np.column_stack([middle.reshape(-1, 2), step, half, thickness, trust, facing]).astype(np.int64)

    @classmethod
    def of_table(cls, table: NDArray[np.int64]) -> _Codes:
        codes = cls.__new__(cls)
        codes.table = table
        return codes

    def __len__(self) -> int:
        return int(self.table.shape[0])

    # The columns.
    middle = property(lambda self: self.table[:, 0:2])
    step = property(lambda self: self.table[:, 2])
    half = property(lambda self: self.table[:, 3])
    thickness = property(lambda self: self.table[:, 4])
    trust = property(lambda self: self.table[:, 5])
    facing = property(lambda self: self.table[:, 6])


def _rotate(xy: FloatArray, transform: Transform | None) -> FloatArray:
    if transform is None:
        return xy
    x, y, yaw = transform
    c, s = math.cos(yaw), math.sin(yaw)
    return np.column_stack([c * xy[:, 0] - s * xy[:, 1] + x, s * xy[:, 0] + c * xy[:, 1] + y])


def _segment_codes(world: WorldMap, transform: Transform | None, unit: float, half_unit: float) -> _Codes:
    """``world``'s segments placed by ``transform`` and coded on the merged grid (as
    :func:`occtool.formats.occmap.quantise` codes a map: a segment coded already is unchanged)."""
    start, end = _rotate(world.start, transform), _rotate(world.end, transform)
    span = end - start
    middle = np.round(0.5 * (start + end) / unit).astype(np.int64)
    step, half = direction_codes(span, half_unit)
    # The coded direction lies in [0, pi): a segment turned round faces the other way.
    angle = step * (math.pi / DIRECTION_STEPS)
    turned = span[:, 0] * np.cos(angle) + span[:, 1] * np.sin(angle)
    facing = np.where(half > 0, np.sign(turned), 0).astype(np.int64) * world.facing.astype(np.int64)
    thickness = np.clip(np.round(world.thickness * 1000.0), 0, 255).astype(np.int64)
    trust = np.clip(np.round(world.trust * 255.0), 0, 255).astype(np.int64)
    return _Codes(middle, step, half, thickness, trust, facing)


#: Segments whose covering candidates are found at once (bounds the pairs held in memory).
COVER_CHUNK = 4096


def _covered(codes: _Codes, unit: float, half_unit: float) -> NDArray[np.bool_]:
    """Which segments another one of higher rank covers (module docstring)."""
    from scipy.spatial import cKDTree

    n = len(codes)
    dropped = np.zeros(n, dtype=bool)
    if n < 2:
        return dropped
    half = codes.half * half_unit
    thickness = codes.thickness / 1000.0
    angle = codes.step * (math.pi / DIRECTION_STEPS)
    axis = np.column_stack([np.cos(angle), np.sin(angle)])
    rank = _rank(codes)
    index = cKDTree(codes.middle * unit)
    # A segment t covers only segments whose middle lies in its band: within this of its middle.
    radius = half + 2.0 * COVER_MARGIN + thickness + float(thickness.max())
    for first in range(0, n, COVER_CHUNK):  # a loop over chunks of segments, each vectorised
        block = np.arange(first, min(first + COVER_CHUNK, n))
        near = index.query_ball_point(codes.middle[block] * unit, radius[block], return_sorted=False)
        counts = np.fromiter((len(found) for found in near), dtype=np.int64, count=block.size)
        t = np.repeat(block, counts)
        s = np.concatenate([np.asarray(found, dtype=np.int64) for found in near]) if t.size else t
        gap = np.abs(codes.step[t] - codes.step[s])
        wrapped = gap > DIRECTION_STEPS // 2
        gap = np.where(wrapped, DIRECTION_STEPS - gap, gap)
        aligned = (gap <= COVER_ANGLE_STEPS) | (half[s] < COVER_MARGIN)
        # Facings compare along the same direction: a pair coded across the wrap of pi runs opposite.
        facing_s = np.where(wrapped, -codes.facing[s], codes.facing[s])
        keep = (rank[t] > rank[s]) & aligned & (codes.facing[t] * facing_s >= 0)
        t, s = t[keep], s[keep]
        normal = np.column_stack([-axis[t, 1], axis[t, 0]])
        across_limit = thickness[t] + thickness[s] + COVER_MARGIN
        inside = np.ones(t.size, dtype=bool)
        # From the middles' difference in whole units: the test is the same wherever the pair lies.
        between = (codes.middle[s] - codes.middle[t]) * unit
        for sign in (-1.0, 1.0):  # both end points of s
            rel = between + sign * half[s, None] * axis[s]
            across = np.abs(rel[:, 0] * normal[:, 0] + rel[:, 1] * normal[:, 1])
            along = np.abs(rel[:, 0] * axis[t, 0] + rel[:, 1] * axis[t, 1]) - half[t]
            inside &= (across <= across_limit) & (along <= COVER_MARGIN)
        dropped[s[inside]] = True
    return dropped


def _rank(codes: _Codes) -> NDArray[np.int64]:
    """Each segment's place in the total order of :func:`_covered`: half-length, trust, then the rest."""
    table = codes.table
    # np.lexsort's last key is the primary one: half-length, trust, middle, direction, thickness, facing.
    order = np.lexsort((table[:, 6], table[:, 4], table[:, 2], table[:, 1], table[:, 0], table[:, 5], table[:, 3]))
    rank = np.empty(len(codes), dtype=np.int64)
    rank[order] = np.arange(len(codes))
    return rank


def _check(maps: Sequence[WorldMap], transforms: Sequence[Transform | None] | None) -> list[Transform | None]:
    if not len(maps):
        raise InputError("no maps to merge")
    if transforms is None:
        return [None] * len(maps)
    if len(transforms) != len(maps):
        raise InputError(f"{len(transforms)} transforms for {len(maps)} maps: give one per map (None: none)")
    out: list[Transform | None] = []
    for k, transform in enumerate(transforms):
        if transform is None:
            out.append(None)
            continue
        try:
            if isinstance(transform, (str, bytes)):  # "123" would unpack as 1, 2, 3
                raise TypeError
            x, y, yaw = (float(v) for v in transform)
        except (TypeError, ValueError):
            raise InputError(f"transform {k + 1} must be three numbers x, y, yaw, got {transform!r}") from None
        if not all(math.isfinite(v) for v in (x, y, yaw)):
            raise InputError(f"transform {k + 1} must be finite numbers x, y, yaw, got {transform!r}")
        out.append(None if (x, y, yaw) == (0.0, 0.0, 0.0) else (x, y, yaw))
    return out


def _settings(maps: Sequence[WorldMap]) -> dict[str, Any]:
    first = maps[0].params()
    for k, world in enumerate(maps[1:], 2):
        other = world.params()
        for key in first:
            if other[key] != first[key]:
                raise InputError(f"maps 1 and {k} differ in {key} ({first[key]} and {other[key]}): "
                                 "merged maps must share the body band and the occupancy settings")
    return first


def merge_maps(maps: Sequence[WorldMap], transforms: Sequence[Transform | None] | None = None) -> WorldMap:
    """One :class:`WorldMap` of several (module docstring), at the precision of its file.

    Parameters
    ----------
    maps
        World maps (:func:`occtool.fuse.load_map` reads them from ``world.occmap`` files).
    transforms
        One per map, or ``None``: the rigid transform ``(x, y, yaw)`` (metres, radians)
        that places each map in the merged frame (``None`` for a map already there).

    Returns
    -------
    WorldMap
        The merged map; the same whatever the order of ``maps`` (with their transforms),
        and written by :meth:`WorldMap.save` to the same bytes.
    """
    import shapely

    placed = _check(maps, transforms)
    for k, world in enumerate(maps, 1):
        if not isinstance(world, WorldMap):
            raise InputError(f"map {k}: {_NOT_2D}" if isinstance(world, WorldMap3D)
                             else f"map {k} is a {type(world).__name__}, not a WorldMap")
    maps = [world if world.unit is not None and world.half_unit is not None else world.quantised()
            for world in maps]
    settings = _settings(maps)
    unit = max(float(world.unit or UNIT) for world in maps)
    half_unit = max(float(world.half_unit or HALF_UNIT) for world in maps)
    codes = _Codes.of_table(np.unique(np.concatenate(
        [_segment_codes(world, t, unit, half_unit).table for world, t in zip(maps, placed, strict=True)]), axis=0))
    codes = _Codes.of_table(codes.table[~_covered(codes, unit, half_unit)])
    positions = np.unique(np.concatenate(
        [np.round(_rotate(world.positions, t) / unit).astype(np.int64).reshape(-1, 2)
         for world, t in zip(maps, placed, strict=True)]), axis=0)
    regions = [_place_region(world.region, t) for world, t in zip(maps, placed, strict=True)
               if not world.region.is_empty]
    # Distinct, in a canonical order: GEOS's union is exact up to snap rounding, and its
    # output's order (and the snapping of a polygon met twice) follows its input.
    regions = [shapely.from_wkb(wkb) for wkb in sorted({shapely.to_wkb(r) for r in regions})]
    region = (shapely.normalize(shapely.union_all(regions, grid_size=unit)) if regions
              else shapely.MultiPolygon())
    return _assemble(codes, positions, region, settings, unit, half_unit)


def _place_region(region: Any, transform: Transform | None) -> Any:
    import shapely

    if transform is None:
        return shapely.normalize(region)
    return shapely.normalize(shapely.transform(region, lambda xy: _rotate(xy, transform)))


def _assemble(codes: _Codes, positions: NDArray[np.int64], region: Any, settings: dict[str, Any], unit: float,
              half_unit: float) -> WorldMap:
    """The merged map on its file's grid: the segments in the file's order, each number as
    :func:`occtool.formats.occmap.decode` would read it back."""
    import shapely

    from occtool.formats.occmap import _areal

    angle = codes.step * (math.pi / DIRECTION_STEPS)
    reach = (codes.half * half_unit)[:, None] * np.column_stack([np.abs(np.cos(angle)), np.abs(np.sin(angle))])
    corners = [codes.middle * unit - reach, codes.middle * unit + reach, positions * unit]
    if not region.is_empty:
        x0, y0, x1, y1 = shapely.bounds(region)
        corners.append(np.array([[x0, y0], [x1, y1]]))
    both = np.concatenate(corners)
    lower, upper = (both.min(axis=0), both.max(axis=0)) if both.size else (np.zeros(2), np.zeros(2))
    origin, grid_unit = _grid(lower, upper, unit)
    if grid_unit != unit:
        raise InputError(f"the merged map spans {float(np.max(upper - lower)):.0f} m, more than a "
                         f"{unit:g} m grid holds: merge fewer or nearer maps")
    base = np.round(origin / unit).astype(np.int64)
    middles = codes.middle - base
    # Listed as the file lists them: tile by tile, within a tile in the codes' order.
    order, _ = _tiles(middles)
    table = codes.table[order]
    middles = middles[order]
    start, end = _segment_ends(middles, table[:, 2].astype(np.uint8), table[:, 3].astype(np.uint8), origin, unit,
                               half_unit)
    snapped = origin + (positions - base).astype(np.float64) * unit
    if not region.is_empty:
        region = _areal(shapely.transform(region, lambda xy: origin + np.round((xy - origin) / unit) * unit))
    band = settings["band"]
    rest = {key: value for key, value in settings.items() if key != "band"}
    arrays = MapArrays(start, end, table[:, 4] / 1000.0, table[:, 5] / 255.0, region, (band[0], band[1]), snapped,
                       table[:, 6].astype(np.int8), rest, unit, origin, half_unit)
    return WorldMap.from_arrays(arrays)


def _load(path: Any) -> WorldMap:
    """:func:`occtool.fuse.load_map` of a file or of a folder's ``world.occmap`` (``occtool
    map``'s output); a 3D map (version 5 or 6) is refused."""
    import os

    from occtool.fuse._load import load_map

    if os.path.isdir(path):
        path = os.path.join(path, "world.occmap")
    world = load_map(path)
    if not isinstance(world, WorldMap):
        raise InputError(f"{path}: {_NOT_2D}")
    return world


#: Why a 3D map is refused.
_NOT_2D = "a 3D world map (occmap version 5 or 6); occtool merges 2D world maps (versions 1-4)"


def merge_files(paths: Sequence[Any], output: Any, transforms: Sequence[Transform | None] | None = None, *,
                overwrite: bool = True) -> WorldMap:
    """``occtool merge``: the ``.occmap`` files ``paths`` (a folder: its ``world.occmap``),
    with one transform each or ``None``, merged by :func:`merge_maps` and written to
    ``output`` atomically; returns the merged map."""
    merged = merge_maps([_load(path) for path in paths], transforms)
    merged.save(output, overwrite=overwrite)
    return merged


__all__ = ["COVER_ANGLE_STEPS", "COVER_MARGIN", "merge_files", "merge_maps"]
