"""What the robot reaches in a straight line: the part of the shrunk free area the origin sees."""

from __future__ import annotations

import math

import numpy as np
import shapely
from numpy.typing import NDArray
from shapely.geometry import Polygon
from shapely.geometry.polygon import orient

from occtool.features import wrap_angle
from occtool.navigation._geometry import component_at_origin, cyclic_next, cyclic_previous
from occtool.navigation._raycast import edges_within, first_hits

FloatArray = NDArray[np.float64]


def _gaps_overlapping(rays: FloatArray, low: FloatArray, high: FloatArray) -> NDArray[np.bool_]:
    """Which gaps between sorted rays in ``[-pi, pi)`` (gap j from ray j to ray j+1, the last
    wrapping round) overlap an arc from ``low`` counter-clockwise to ``high``."""
    count = len(rays)
    # An arc overlaps the gaps from the one holding its low end to the one holding its high end.
    first = (np.searchsorted(rays, low, side="right") - 1) % count
    last = (np.searchsorted(rays, high, side="left") - 1) % count
    wraps = last < first
    marks = np.bincount(first, minlength=count + 1) - np.bincount(last + 1, minlength=count + 1)
    # An arc past the last ray runs on from gap `first` to the end and from gap 0 to `last`.
    marks[0] += np.count_nonzero(wraps)
    marks[count] -= np.count_nonzero(wraps)
    return np.cumsum(marks[:-1]) > 0


def visible_from_origin(region: Polygon, angles: FloatArray, reach: float) -> Polygon:
    """The part of ``region`` the origin sees: where the segment from the origin stays inside.

    The shrunk free area holds every point where the robot's body fits, but not every one
    it can drive to straight: past a door jamb or a pole close by, the body swept along
    the way would clip the obstacle. The swept body stays free exactly when the centre's
    segment stays in the shrunk area, so the reachable part is what the origin sees of it.

    Seen from the origin, the counter-clockwise boundary hides something only where it
    runs back (clockwise), behind a silhouette vertex where it turns. Rays along
    ``angles`` and just either side of every silhouette end at their first hit of the
    boundary. Between two rays with no backward edge in between, a ray cannot leave the
    region and come back, so all of it is seen; between the others the region is cut
    along the chord between the two hits: exact along each shadow edge (the silhouette
    rays), and otherwise short of the visible part only where its boundary bulges away
    from the origin between two rays.

    Parameters
    ----------
    region
        The shrunk free polygon, holding the origin.
    angles
        ``(N,)`` evenly spaced ray angles, radians.
    reach
        Distance beyond which nothing matters (the max range), metres.

    Returns
    -------
    Polygon
        ``region`` itself when it hides nothing within reach.
    """
    region = orient(region, sign=1.0)  # GEOS's shrink returns the outer ring clockwise
    ring = shapely.get_coordinates(region.exterior)[:-1]
    following = cyclic_next(ring)
    outside = reach / math.cos(math.pi / len(angles)) * (1 + 1e-6) + 1e-9
    step = following - ring
    near = edges_within(ring, step, outside)
    # Edge i runs clockwise, as seen from the origin, when v_i x v_i+1 < 0.
    backward = (ring[:, 0] * following[:, 1] - ring[:, 1] * following[:, 0] < 0) & near
    if not backward.any():
        return region
    silhouette = (backward != cyclic_previous(backward)) & (np.hypot(ring[:, 0], ring[:, 1]) <= outside)
    corners = np.arctan2(ring[silhouette, 1], ring[silhouette, 0])
    side = 1e-7  # radians either side of a silhouette vertex
    rays = np.unique(wrap_angle(np.concatenate([angles, corners - side, corners + side])))

    shadowed = _gaps_overlapping(
        rays,
        np.arctan2(following[backward, 1], following[backward, 0]),  # a backward edge's smaller angle ...
        np.arctan2(ring[backward, 1], ring[backward, 0]),  # ... and its larger
    )
    # Only the rays bounding a shadowed gap need casting.
    cast = np.flatnonzero(shadowed | cyclic_previous(shadowed))  # type: ignore[operator]  # _previous keeps the bool dtype
    near_edges = np.flatnonzero(near)
    distance, edge, where = first_hits(ring[near_edges], step[near_edges], rays[cast])
    hits = np.minimum(distance, outside)

    # Two vertices per ray: where the gap before it ends, where the gap after it begins;
    # a gap in the open lets the region through whole, a shadowed one cuts it on the chord.
    radii = np.full(len(rays), outside)
    radii[cast] = hits
    radii = np.column_stack([np.where(cyclic_previous(shadowed), radii, outside), np.where(shadowed, radii, outside)])
    cut = np.stack([radii * np.cos(rays)[:, None], radii * np.sin(rays)[:, None]], axis=-1).reshape(-1, 2)

    # Each hit is made a vertex of the region too, so the cut's vertices coincide with the
    # region's exactly: a hit merely near an edge leaves GEOS's overlay a near-degenerate
    # crossing, which it resolves in a fallback several times as slow.
    inside = np.flatnonzero(distance < outside)
    order = inside[np.lexsort((where[inside], edge[inside]))]
    points = cut.reshape(-1, 2, 2)[cast[order], 0]
    points = np.where(shadowed[cast[order] - 1, None], points, cut.reshape(-1, 2, 2)[cast[order], 1])
    split = Polygon(np.insert(ring, near_edges[edge[order]] + 1, points, axis=0),
                    [interior.coords for interior in region.interiors])
    return component_at_origin(shapely.intersection(split, Polygon(cut)))
