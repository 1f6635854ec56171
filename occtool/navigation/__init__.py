"""The navigation map: the polygon a robot may drive to, obstacle and exploration points.

This is Section 4 of the paper. The inverted occupancy model ``r = F^-1(alpha, h, m)``
is cut at the threshold ``m`` and a few sensor-frame heights ``h``; each cut, swept over
the pan angle, gives the free polygon at that height (horizontal distance
``sqrt(r^2 - h^2)``). The polygons are shrunk by the robot's radius and intersected,
cut to what the robot can reach in a straight line (the paper's promise, which the
shrink alone does not keep past a door jamb), then clipped to the max-range disk. The
polygon's boundary strictly inside that circle carries obstacle points; where the polygon
lies on the circle it carries exploration points.

Everything here is model-agnostic: :func:`navigation_map` takes any ``inverse_range``
callable, a fitted :class:`occtool.fit.OccupancyRegressor`'s method or a grid's ray
marcher alike. With ``slope_bounds`` (the largest pan, height and range weights of a
piecewise-linear model) the map also holds *between* the slices and rays: see
docs/navigation.md for the argument.

Coordinates are REP-103 robot-frame x, y in metres centred at the sensor; heights are
sensor-frame (the floor is at ``-robot.sensor_height``).

The parts, one concept a module (private; everything public is imported from here):

================  =====================================================================
``_extract``      :func:`navigation_map`, step by step: sweep, bound, cap, shrink, clip
``_heights``      the cut heights and the threshold margin that holds between them
``_visibility``   what the robot reaches in a straight line
``_points``       obstacle and exploration points on the polygon's boundary
``_raycast``      rays from the origin against polygon edges (also used by evaluate)
``_geometry``     small polygon helpers: cyclic neighbours, star polygons, the circle
``_result``       :class:`NavigationMap`, :class:`Slice`, :class:`NavigationWarning`
================  =====================================================================
"""

from occtool.navigation._extract import (
    MAX_POINTS,
    RETURN_SNAP,
    SHRINK_QUAD_SEGMENTS,
    FreeBounds,
    InverseRange,
    horizontal_distances,
    navigation_map,
    pan_angles,
)
from occtool.navigation._geometry import CIRCLE_OVERSAMPLING, MIN_CIRCLE_VERTICES
from occtool.navigation._heights import (
    BOUND_HEIGHT_STEP,
    DEFAULT_HEIGHT_MARGIN,
    DEFAULT_HEIGHT_SPACING,
    MAX_SLICES,
    MIN_AUTO_SLICE_SPACING,
    add_slices,
    default_heights,
    farthest_from_slices,
    height_lipschitz,
)
from occtool.navigation._points import MIN_SECTOR_LENGTH, TIP_REACH, boundary_points, circle_sectors, spike_tips
from occtool.navigation._raycast import ray_boundary_distances
from occtool.navigation._result import NavigationMap, NavigationWarning, Slice
from occtool.navigation._visibility import visible_from_origin

__all__ = [
    "BOUND_HEIGHT_STEP",
    "CIRCLE_OVERSAMPLING",
    "DEFAULT_HEIGHT_MARGIN",
    "DEFAULT_HEIGHT_SPACING",
    "MAX_POINTS",
    "RETURN_SNAP",
    "MAX_SLICES",
    "MIN_AUTO_SLICE_SPACING",
    "MIN_CIRCLE_VERTICES",
    "MIN_SECTOR_LENGTH",
    "SHRINK_QUAD_SEGMENTS",
    "TIP_REACH",
    "FreeBounds",
    "InverseRange",
    "NavigationMap",
    "NavigationWarning",
    "Slice",
    "add_slices",
    "boundary_points",
    "circle_sectors",
    "default_heights",
    "farthest_from_slices",
    "height_lipschitz",
    "horizontal_distances",
    "navigation_map",
    "pan_angles",
    "ray_boundary_distances",
    "spike_tips",
    "visible_from_origin",
]
