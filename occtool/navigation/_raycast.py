"""Casting rays from the origin against polygon edges: the first hit of each ray.

The navigation maps' ray caster: the navigation map casts rays to its polygon's boundary
(obstacle points, the straight-line cut). :mod:`occtool.scoring` casts the truth's rays
with its own (``occtool.scoring._rays``): the judge of a map shares no code with it.
"""

from __future__ import annotations

import numpy as np
import shapely
from numpy.typing import NDArray
from shapely.geometry import Polygon

from occtool.features import wrap_angle

FloatArray = NDArray[np.float64]

#: Ray/edge pairs intersected at a time when casting rays to a polygon's boundary.
RAY_CAST_BLOCK = 1 << 20
#: Radians by which an edge's angular extent is widened when pairing it with the rays
#: that may hit it (rounding is ~1e-15; the intersection test decides).
RAY_ANGLE_SLACK = 1e-9


def first_hits(
    start: FloatArray, step: FloatArray, angles: FloatArray
) -> tuple[FloatArray, NDArray[np.intp], FloatArray]:
    """First hit of each ray from the origin among the edges ``start -> start + step``.

    Returns the distance along each ray (``inf`` for a miss), the index of the edge hit
    and where along it (0 at ``start``, 1 at its end).
    """
    count = len(angles)
    reach = np.full(count, np.inf)
    edge = np.zeros(count, dtype=np.intp)
    where = np.zeros(count)
    if len(start) == 0 or count == 0:
        return reach, edge, where
    # A ray can only hit an edge whose angular extent, seen from the origin, holds the
    # ray's angle: pair each edge with the rays in its extent (sorted rays, searchsorted)
    # instead of intersecting every ray with every edge. The extent is widened by
    # RAY_ANGLE_SLACK, far more than rounding; the intersection test below decides.
    ends = start + step
    first_angle = np.arctan2(start[:, 1], start[:, 0])
    turn = wrap_angle(np.arctan2(ends[:, 1], ends[:, 0]) - first_angle)
    low = first_angle + np.minimum(turn, 0.0) - RAY_ANGLE_SLACK
    high = low + np.abs(turn) + 2.0 * RAY_ANGLE_SLACK
    # An edge through (or grazing) the origin spans about pi: pair it with every ray.
    wide = np.abs(turn) >= np.pi - 1e-6
    low[wide], high[wide] = -4.0 * np.pi, 4.0 * np.pi
    key = wrap_angle(angles)  # in [-pi, pi), as the extents (+- 2 pi)
    ray_order = np.argsort(key, kind="stable")
    sorted_key = key[ray_order]
    # Each extent turned back and on by a turn too, for the rays past +-pi; only the edges
    # whose turned extent reaches a ray, in the same order (turned back, as is, turned on),
    # so the pairs are those of every edge in all three.
    index = np.arange(len(start))
    back = high - 2.0 * np.pi >= sorted_key[0]
    on = low + 2.0 * np.pi <= sorted_key[-1]
    edges = np.concatenate([index[back], index, index[on]])
    lows = np.concatenate([low[back] - 2.0 * np.pi, low, low[on] + 2.0 * np.pi])
    highs = np.concatenate([high[back] - 2.0 * np.pi, high, high[on] + 2.0 * np.pi])
    first = np.searchsorted(sorted_key, lows, side="left")
    pairs = np.maximum(np.searchsorted(sorted_key, highs, side="right") - first, 0)
    # Rays and edges in the same arithmetic as a full (ray x edge) cast, so the same hits.
    cos, sin = np.cos(angles), np.sin(angles)
    start_cross_step = start[:, 0] * step[:, 1] - start[:, 1] * step[:, 0]
    total = np.cumsum(pairs)
    for lo, hi in _blocks(total, RAY_CAST_BLOCK):  # bounds the pair temporaries
        counts = pairs[lo:hi]
        pair_edge = np.repeat(edges[lo:hi], counts)
        if len(pair_edge) == 0:
            continue
        offset = np.arange(len(pair_edge)) - np.repeat(np.cumsum(counts) - counts, counts)
        pair_ray = ray_order[np.repeat(first[lo:hi], counts) + offset]
        dx, dy = cos[pair_ray], sin[pair_ray]
        edge_start, edge_step = start[pair_edge], step[pair_edge]
        # origin + t d = start + s step  ->  t = (start x step) / (d x step), s = (start x d) / (d x step)
        denominator = dx * edge_step[:, 1] - dy * edge_step[:, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = start_cross_step[pair_edge] / denominator
            s = (edge_start[:, 0] * dy - edge_start[:, 1] * dx) / denominator
        t[~((denominator != 0) & (s >= 0) & (s <= 1) & (t > 0))] = np.inf
        # The nearest hit of each ray: sorted by ray, then distance; the first of each ray.
        order = np.lexsort((t, pair_ray))
        by_ray = pair_ray[order]
        best = order[np.flatnonzero(np.concatenate([[True], by_ray[1:] != by_ray[:-1]]))]
        best = best[t[best] < reach[pair_ray[best]]]
        rays = pair_ray[best]
        reach[rays], edge[rays], where[rays] = t[best], pair_edge[best], s[best]
    return reach, edge, where


def _blocks(cumulative: NDArray[np.intp], size: int) -> list[tuple[int, int]]:
    """Consecutive ranges of items whose counts (given as a running total) add up to about ``size``."""
    if len(cumulative) == 0 or cumulative[-1] <= size:
        return [(0, len(cumulative))]
    cuts = np.unique(np.searchsorted(cumulative, np.arange(size, int(cumulative[-1]), size), side="right"))
    bounds = [0, *(int(c) for c in cuts if 0 < c < len(cumulative)), len(cumulative)]
    return list(zip(bounds[:-1], bounds[1:]))


def edges_within(start: FloatArray, step: FloatArray, within: float) -> NDArray[np.bool_]:
    """Which edges ``start -> start + step`` come within ``within`` of the origin."""
    # Closest point of each edge to the origin: start + clip(-start.step / |step|^2) step.
    length2 = np.einsum("ij,ij->i", step, step)
    along = np.clip(-np.einsum("ij,ij->i", start, step) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
    return np.hypot(*(start + along[:, None] * step).T) <= within


def ray_boundary_distances(polygon: Polygon, angles: FloatArray, within: float | None = None) -> FloatArray:
    """Distance from the origin along each ray to the polygon's outer boundary, first hit.

    Parameters
    ----------
    polygon
        Polygon holding the origin.
    angles
        ``(J,)`` ray angles, radians.
    within
        Only look for hits this close to the origin, metres (edges wholly farther are
        skipped, which makes the cast cheap in open space); rays with no hit so close get
        ``inf``.

    Returns
    -------
    numpy.ndarray
        ``(J,)`` metres (``inf`` for a ray that misses).
    """
    ring = shapely.get_coordinates(polygon.exterior)
    start, step = ring[:-1], np.diff(ring, axis=0)
    if within is not None:
        near = edges_within(start, step, within)
        start, step = start[near], step[near]
    return first_hits(start, step, np.asarray(angles, dtype=np.float64))[0]
