"""The truth's own ray caster: how far each ray from the origin goes before it meets an edge.

Scoring judges the navigation maps, so it shares no code with the maps it judges: this
is deliberately not :mod:`occtool.navigation._raycast`. It is the plain method: every ray
against every edge. For a ray of angle ``a`` the edge's endpoints are turned by ``-a``,
into the ray's frame, where the ray is the positive x axis: the edge meets the ray when
its endpoints' y lie on both sides of 0 (or on it), and where the line between them
crosses y = 0 at some x > 0, x is the distance along the ray.

To keep it cheap the rays are taken a few hundred at a time, neighbours in angle, and only
the edges that reach into their wedge are turned (an edge wholly clockwise of the wedge's
first ray, wholly anticlockwise of its last, or wholly behind the origin cannot meet any
of its rays). That test is only a filter, widened by a nanometre; the turned endpoints
alone decide.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: Rays cast together: neighbours in angle, sharing one filter of the edges.
RAYS_PER_BLOCK = 256
#: At most this many ray/edge pairs at a time (bounds the temporaries: 8 MB each).
PAIRS_PER_BLOCK = 1 << 20
#: Metres by which the filter's half-planes are widened (rounding is ~1e-15 m).
FILTER_SLACK = 1e-9


def _turned(c: FloatArray | float, s: FloatArray | float, x: FloatArray, y: FloatArray) -> tuple:
    """Points ``(x, y)`` in the frame of the ray ``(c, s) = (cos a, sin a)``: along it, and left of it."""
    return c * x + s * y, c * y - s * x


def ray_reach(start: FloatArray, end: FloatArray, angles: FloatArray, max_range: float) -> FloatArray:
    """Distance from the origin along each ray to its first crossing of an edge, capped at ``max_range``.

    Parameters
    ----------
    start, end
        ``(K, 2)`` endpoints of the edges, metres.
    angles
        ``(J,)`` ray angles, radians, any value (0 along +x, counter-clockwise).
    max_range
        Distance given to a ray that meets no edge nearer, metres.

    Returns
    -------
    numpy.ndarray
        ``(J,)`` metres. A ray through an edge's endpoint (grazing a vertex) meets it there.
        An edge lying along a ray is skipped: on a closed ring the edges either side of it
        end where it ends, so the ray meets those at its near end. Only crossings beyond the
        origin count (x > 0): an origin inside or on an obstacle is for the caller to judge
        (:func:`occtool.scoring.true_reach` gives 0 then).
    """
    angles = np.asarray(angles, dtype=np.float64).reshape(-1)
    reach = np.full(angles.shape, float(max_range))
    if len(start) == 0 or len(angles) == 0:
        return reach
    x1, y1 = start[:, 0], start[:, 1]
    x2, y2 = end[:, 0], end[:, 1]
    # Neighbours in angle: the rays sorted by their direction's angle in [-pi, pi].
    order = np.argsort(np.arctan2(np.sin(angles), np.cos(angles)), kind="stable")
    block = max(1, min(RAYS_PER_BLOCK, PAIRS_PER_BLOCK // len(start)))
    for lo in range(0, len(order), block):
        rays = order[lo:lo + block]
        c, s = np.cos(angles[rays]), np.sin(angles[rays])
        edges = _edges_in_wedge(c, s, x1, y1, x2, y2)
        if not edges.any():
            continue
        u1, v1 = _turned(c[:, None], s[:, None], x1[edges], y1[edges])
        u2, v2 = _turned(c[:, None], s[:, None], x2[edges], y2[edges])
        meets = (np.minimum(v1, v2) <= 0.0) & (np.maximum(v1, v2) >= 0.0) & (v1 != v2)
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.where(meets, u1 + (u2 - u1) * (v1 / (v1 - v2)), np.inf)
        x[~(x > 0.0)] = np.inf
        reach[rays] = np.minimum(reach[rays], x.min(axis=1))
    return reach


def _edges_in_wedge(c: FloatArray, s: FloatArray, x1: FloatArray, y1: FloatArray, x2: FloatArray,
                    y2: FloatArray) -> NDArray[np.bool_]:
    """Which edges may meet a ray of the wedge spanned by the directions ``(c, s)``, sorted by angle.

    All edges when the wedge is a quarter turn or wider (then it is not worth filtering).
    """
    first, last = math.atan2(s[0], c[0]), math.atan2(s[-1], c[-1])
    if last - first >= math.pi / 2:
        return np.ones(len(x1), dtype=bool)
    middle = 0.5 * (first + last)
    keep = np.ones(len(x1), dtype=bool)
    # Not wholly right of the first ray, left of the last, or behind the middle one.
    for angle, side, sign in ((first, 1, 1.0), (last, 1, -1.0), (middle, 0, 1.0)):
        a = _turned(math.cos(angle), math.sin(angle), x1, y1)[side] * sign
        b = _turned(math.cos(angle), math.sin(angle), x2, y2)[side] * sign
        keep &= np.maximum(a, b) >= -FILTER_SLACK
    return keep


__all__ = ["ray_reach"]
