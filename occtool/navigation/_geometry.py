"""Small polygon helpers of the extraction: cyclic neighbours, star polygons, the circle."""

from __future__ import annotations

import functools

import numpy as np
import shapely
from numpy.typing import NDArray
from shapely.geometry import Polygon
from shapely.geometry.base import BaseGeometry

FloatArray = NDArray[np.float64]

#: The robot, at the origin of the robot frame.
ORIGIN = shapely.Point(0.0, 0.0)
#: The max-range circle is drawn with this many times ``n_angles`` vertices (at least
#: :data:`MIN_CIRCLE_VERTICES`), so its chords sag far less than a ray step.
CIRCLE_OVERSAMPLING = 4
MIN_CIRCLE_VERTICES = 720


@functools.lru_cache(maxsize=16)
def circle_polygon(radius: float, vertices: int) -> Polygon:
    """The circle of ``radius`` drawn with ``vertices`` vertices (cached: maps reuse it)."""
    theta = 2.0 * np.pi * np.arange(vertices) / vertices
    return Polygon(np.column_stack([radius * np.cos(theta), radius * np.sin(theta)]))


def cyclic_next(values: NDArray[np.generic]) -> NDArray[np.generic]:
    """``values`` moved one place back, cyclically: ``np.roll(values, -1, axis=0)`` without its overhead."""
    return np.concatenate((values[1:], values[:1]))


def cyclic_previous(values: NDArray[np.generic]) -> NDArray[np.generic]:
    """``values`` moved one place on, cyclically: ``np.roll(values, 1, axis=0)``."""
    return np.concatenate((values[-1:], values[:-1]))


def star_polygon(distances: FloatArray, alpha: FloatArray) -> Polygon:
    """The polygon through ``distances`` along the rays ``alpha`` from the origin."""
    return Polygon(np.column_stack([distances * np.cos(alpha), distances * np.sin(alpha)]))


def component_at_origin(geometry: BaseGeometry) -> Polygon:
    """The polygon of ``geometry`` that holds the robot (the origin) strictly inside."""
    for part in getattr(geometry, "geoms", [geometry]):
        # The function, not the method: the same predicate without the method's wrapper (a
        # third of its cost, called two or three times a map).
        if isinstance(part, Polygon) and shapely.contains(part, ORIGIN):
            return part
    return Polygon()
