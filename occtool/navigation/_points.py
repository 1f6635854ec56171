"""Obstacle and exploration points on the boundary of a navigation polygon.

Where the polygon lies on the max-range circle it carries exploration points (positive
reinforcement); where its boundary runs inside the circle, obstacle points (negative):
where evenly spaced rays first meet it, and at the tips of the spikes those rays miss.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import shapely
from numpy.typing import NDArray
from shapely.geometry import Polygon

from occtool.navigation._geometry import MIN_CIRCLE_VERTICES, cyclic_next, cyclic_previous
from occtool.navigation._raycast import ray_boundary_distances
from occtool.neighbours import BRUTE_FORCE_PAIRS, NeighbourIndex

FloatArray = NDArray[np.float64]

#: Arcs shorter than this (metres) where the polygon merely grazes the circle carry no
#: exploration point.
MIN_SECTOR_LENGTH = 1e-6
#: A spike's tip gets an obstacle point of its own unless a ray's point lies within this
#: share of the spacing of it: half, the most by which a point of a wall facing the robot
#: at the max range misses the nearest of the evenly spaced rays' points.
TIP_REACH = 0.5


def _circle_tolerance(max_range: float, circle_vertices: int) -> float:
    """How far inside ``max_range`` a point still lies "on the circle": the chord sag of the
    disk drawn with ``circle_vertices`` vertices, and a little more for rounding."""
    return max_range * (1.0 - math.cos(math.pi / circle_vertices)) * 1.01 + 1e-9 * max_range


def circle_sectors(polygon: Polygon, max_range: float, circle_vertices: int) -> list[tuple[float, float]]:
    """The angular sectors where the polygon's boundary lies on the max-range circle.

    Parameters
    ----------
    polygon
        A polygon clipped to the max-range disk drawn with ``circle_vertices`` vertices,
        holding the origin, outer ring counter-clockwise.
    max_range
        Radius of the circle, metres.
    circle_vertices
        Vertices of the disk it was clipped to: its chords sag by
        ``max_range * (1 - cos(pi / circle_vertices))``, the tolerance for "on the circle".

    Returns
    -------
    list of (start, span)
        Start angle (radians, counter-clockwise from x) and angular span of each sector;
        one sector ``(0, 2 pi)`` when the polygon is the whole disk.
    """
    ring = shapely.get_coordinates(polygon.exterior)[:-1]
    if len(ring) < 3:
        return []
    tolerance = _circle_tolerance(max_range, circle_vertices)
    on_circle = np.hypot(ring[:, 0], ring[:, 1]) >= max_range - tolerance
    following = cyclic_next(ring)
    middle = (ring + following) / 2.0
    # Both ends on the circle is not enough: an obstacle's chord can join two of its points.
    is_arc = on_circle & cyclic_next(on_circle) & (np.hypot(middle[:, 0], middle[:, 1]) >= max_range - tolerance)
    if is_arc.all():
        return [(0.0, 2.0 * np.pi)]
    if not is_arc.any():
        return []
    # Rotate the ring to start on an edge off the circle, so no run wraps around the end.
    shift = int(np.flatnonzero(~is_arc)[0])
    is_arc = np.concatenate((is_arc[shift:], is_arc[:shift]))
    edges = np.diff(np.concatenate([[0], is_arc.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    # The angles of the runs' ends only (a few of the ring's hundreds of vertices).
    ends = ring[(np.concatenate([starts, stops]) + shift) % len(ring)]
    theta = np.arctan2(ends[:, 1], ends[:, 0])
    sectors = []
    for start, end in zip(theta[:len(starts)], theta[len(starts):]):  # a run of arc edges, vertex to vertex
        span = (end - start) % (2.0 * np.pi)
        if span * max_range >= MIN_SECTOR_LENGTH:
            sectors.append((float(start), float(span)))
    return sectors


def _sector_angles(sectors: Sequence[tuple[float, float]], max_range: float, spacing: float) -> FloatArray:
    """Evenly spaced angles in each sector: at the middles of equal parts at most ``spacing`` long."""
    angles = []
    for start, span in sectors:
        count = max(1, math.ceil(span * max_range / spacing - 1e-9))
        angles.append(start + (np.arange(count) + 0.5) * span / count)
    return np.concatenate(angles) if angles else np.empty(0)


def spike_tips(polygon: Polygon, max_range: float, circle_vertices: int = MIN_CIRCLE_VERTICES,
               min_distance: float = 0.0) -> FloatArray:
    """The tips of the polygon's spikes: outer-ring vertices farther from the origin than both
    their neighbours, between ``min_distance`` and the max-range circle.

    Evenly spaced rays miss a spike narrower than the angle between them and report the
    wall beside it, or nothing when that lies inside the robot's disc; its tip is the
    farthest the free space reaches there, where the obstacle beyond it begins.

    Parameters
    ----------
    polygon
        The navigation polygon, as for :func:`boundary_points`. Only its outer ring is read:
        shrinking a star polygon, cutting it to what the origin sees and clipping it to a
        disk leave no holes.
    max_range
        Radius of the circle, metres: a tip on it (within the chord sag of the disk drawn
        with ``circle_vertices`` vertices) is where the free space runs on out of range, an
        exploration sector's, not an obstacle's.
    circle_vertices
        Vertices of the disk the polygon was clipped to.
    min_distance
        No tip nearer the origin than this, metres (inside the robot, as for
        :func:`boundary_points`).

    Returns
    -------
    numpy.ndarray
        ``(T, 2)`` vertices, in the ring's order.
    """
    ring = shapely.get_coordinates(polygon.exterior)[:-1]
    if len(ring) < 3:
        return np.empty((0, 2))
    distance = np.hypot(ring[:, 0], ring[:, 1])
    # Strictly farther than the previous vertex and no nearer than the next: a tip GEOS
    # wrote twice (it repeats vertices) or flat between two vertices at the same distance
    # counts once, at its first vertex.
    tip = (distance > cyclic_previous(distance)) & (distance >= cyclic_next(distance))
    tip &= (distance >= min_distance) & (distance < max_range - _circle_tolerance(max_range, circle_vertices))
    return ring[tip]


def _near_any(queries: FloatArray, points: FloatArray, reach: float) -> NDArray[np.bool_]:
    """Whether any of ``points`` lies within ``reach`` of each query (squared distances below
    ``reach * reach``, summed as :class:`occtool.neighbours.NeighbourIndex` sums them)."""
    if len(queries) * len(points) > BRUTE_FORCE_PAIRS:
        return np.isfinite(NeighbourIndex(points, reach=reach).query(queries)[0][:, 0])
    # A map's few tips and few dozen rays: every pair at once is a twentieth of the cost of
    # building the index (4 us against 80).
    squared = np.square(points[None, :, 0] - queries[:, None, 0])
    squared += np.square(points[None, :, 1] - queries[:, None, 1])
    return np.any(squared < reach * reach, axis=1)


def boundary_points(
    polygon: Polygon, max_range: float, spacing: float, circle_vertices: int = MIN_CIRCLE_VERTICES,
    min_distance: float = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """Obstacle and exploration points of a navigation polygon clipped to the max-range disk.

    Parameters
    ----------
    polygon
        The navigation polygon (holding the origin, counter-clockwise).
    max_range
        Radius of the bounding circle, metres.
    spacing
        Arc length on the circle between neighbouring points, metres; every sector gets at
        least one point, so a doorway narrower than the spacing is not missed.
    circle_vertices
        Vertices of the disk the polygon was clipped to.
    min_distance
        No obstacle point nearer the origin than this (the robot's radius): where the
        boundary runs inside the robot's own disc (the unseen space behind a laser, a wall
        the body touches) a point would lie inside the robot, which tells a planner nothing.

    Returns
    -------
    obstacle_points, exploration_points
        ``(K, 2)`` arrays: obstacle points on the boundary inside the circle (and not
        within ``min_distance`` of the origin), exploration points on the circle, each at
        evenly spaced angles in their sectors; the obstacle points also at the tips of the
        spikes (:func:`spike_tips`) that no ray's point lies within ``TIP_REACH *
        spacing`` of, merged with the rays' in the order of their angles.
    """
    on_circle = circle_sectors(polygon, max_range, circle_vertices)
    explore_angles = _sector_angles(on_circle, max_range, spacing)
    exploration = max_range * np.column_stack([np.cos(explore_angles), np.sin(explore_angles)])
    if on_circle and on_circle[0][1] >= 2.0 * np.pi:
        return np.empty((0, 2)), exploration
    if on_circle:
        order = sorted(on_circle)
        blocked = []
        for (start, span), (next_start, _) in zip(order, order[1:] + order[:1]):
            gap = (next_start - (start + span)) % (2.0 * np.pi)
            if gap * max_range >= MIN_SECTOR_LENGTH:
                blocked.append((start + span, gap))
    else:
        blocked = [(0.0, 2.0 * np.pi)]
    obstacle_angles = _sector_angles(blocked, max_range, spacing)
    reach = ray_boundary_distances(polygon, obstacle_angles)
    keep = np.isfinite(reach) & (reach >= min_distance)
    obstacle_angles = obstacle_angles[keep]
    obstacles = reach[keep, None] * np.column_stack([np.cos(obstacle_angles), np.sin(obstacle_angles)])
    tips = spike_tips(polygon, max_range, circle_vertices, min_distance)
    if len(tips) and len(obstacles):
        # Only tips the rays' points do not already mark: adding every tip would also add
        # the vertices that rounding leaves a hair farther than their neighbours along a
        # wall the rays sample well (a round room's ring is half such "tips").
        tips = tips[~_near_any(tips, obstacles, TIP_REACH * spacing)]
    if len(tips) == 0:
        return obstacles.reshape(-1, 2), exploration
    # In the rays' order: counter-clockwise from where the first obstacle sector starts.
    # (No blocked sector wide enough for a ray: the tips alone, from angle 0.)
    start = blocked[0][0] if blocked else 0.0
    angles = np.concatenate([obstacle_angles, np.arctan2(tips[:, 1], tips[:, 0])])
    merged = np.argsort((angles - start) % (2.0 * np.pi), kind="stable")
    return np.concatenate([obstacles, tips])[merged], exploration
