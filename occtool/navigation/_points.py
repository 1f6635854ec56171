"""Obstacle and exploration points on the boundary of a navigation polygon.

Where the polygon lies on the max-range circle it carries exploration points (positive
reinforcement); where its boundary runs inside the circle, obstacle points (negative).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import shapely
from numpy.typing import NDArray
from shapely.geometry import Polygon

from occtool.navigation._geometry import MIN_CIRCLE_VERTICES, cyclic_next
from occtool.navigation._raycast import ray_boundary_distances

FloatArray = NDArray[np.float64]

#: Arcs shorter than this (metres) where the polygon merely grazes the circle carry no
#: exploration point.
MIN_SECTOR_LENGTH = 1e-6


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
    tolerance = max_range * (1.0 - math.cos(math.pi / circle_vertices)) * 1.01 + 1e-9 * max_range
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
        evenly spaced angles in their sectors.
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
    directions = np.column_stack([np.cos(obstacle_angles), np.sin(obstacle_angles)])
    obstacles = (reach[keep, None] * directions[keep]).reshape(-1, 2)
    return obstacles, exploration
