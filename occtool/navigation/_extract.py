"""Extracting the navigation map from a model's inverse (Section 4 of the paper).

:func:`navigation_map` reads as the method, one step a function: check the parameters,
choose the cut heights and the margin (:mod:`occtool.navigation._heights`), sweep the pan
angle at each height, bound each ray by its neighbours and cap it by the return guard (or
carry it on to the guarded returns it stops just short of), shrink the free area by the
robot's radius, keep what the robot sees in a straight line, clip to the max-range circle,
then place the obstacle and exploration points.
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Callable, Mapping

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray
from shapely.geometry import Polygon
from shapely.geometry.polygon import orient

from occtool.errors import InputError
from occtool.features import wrap_angle
from occtool.guard import ReturnGuard
from occtool.limits import MAX_ANGLES, MAX_DISTANCE
from occtool.navigation._geometry import (
    CIRCLE_OVERSAMPLING,
    MIN_CIRCLE_VERTICES,
    circle_polygon,
    component_at_origin,
    cyclic_next,
    cyclic_previous,
    star_polygon,
)
from occtool.navigation._heights import Cuts, cut_heights, requested_heights
from occtool.navigation._points import boundary_points
from occtool.navigation._result import NavigationMap, NavigationWarning, Slice
from occtool.navigation._visibility import visible_from_origin
from occtool.robot import Robot

FloatArray = NDArray[np.float64]
InverseRange = Callable[[FloatArray, FloatArray, float], ArrayLike]
#: ``free_bounds(alpha_low, alpha_high, h_edges, level) -> (H - 1, N)``: lower bounds of the
#: free horizontal distance over boxes of pan angle x height
#: (:meth:`occtool.tree.InverseTree.horizontal_lower_bound`).
FreeBounds = Callable[[FloatArray, FloatArray, FloatArray, float], FloatArray]

#: Segments per quarter circle of the arcs the shrink draws round obstacle corners.
#: GEOS rounds the chords of each arc to the nearest whole number (``int(angle / quantum
#: + 0.5)``, quantum = pi / 2 / quad_segs), so one chord may span up to 1.5 quanta and cut
#: inside the arc to ``cos(0.75 quantum)`` of its radius: :func:`shrink_distance` allows
#: for that. With 16 a quarter and one quantum a chord allowed for (``radius / cos(pi /
#: 64)``), a chord could come 0.15 % of the radius inside it, and on a random room
#: (tests/test_navigation.py) a robot of radius 0.344 m was mapped 7 um inside its radius
#: of a sharp corner. 32 a quarter shrinks by ``radius / cos(3 pi / 256)``, 0.07 % more
#: than the radius instead of 0.12 %: on the seven scenes (1k and 3k features, seed 0)
#: IoU against the truth moved by -4e-5 to +1.6e-4, violation by under 5e-6, extraction
#: time the same.
SHRINK_QUAD_SEGMENTS = 32
#: Most obstacle and exploration points a map may carry (a guard against a tiny spacing).
MAX_POINTS = 20_000
#: A ray whose model crossing stops at most this far (m) in front of the guarded returns
#: around it is carried on to them (``return_snap``). The fitted pieces cross the threshold
#: in front of a surface (a smooth summary of a sharp step, with bounded slopes): the
#: polygon stopped 0.1-0.3 m short of walls, which closed a 1 m aisle to 0.6 of its area.
#: Measured over 7 scenes x 3 seeds at 1k-10k features: IoU against the truth up by up to
#: 0.17 at 0.5 m (aisle 10k: 0.60-0.61 -> 0.73-0.77), the worst collision 0.35 % (0.38 %
#: without); 0.3 m gave about two thirds of the gain, and 0.5 m lost no IoU anywhere
#: against 0.3 m, nor added collision beyond 0.05 % of one polygon.
RETURN_SNAP = 0.5


def navigation_map(
    inverse_range: InverseRange,
    *,
    robot: Robot,
    threshold: float = 0.6,
    heights: ArrayLike | None = None,
    max_range: float = 1.5,
    n_angles: int = 360,
    point_spacing: float | None = None,
    slope_bounds: Mapping[str, float] | None = None,
    slice_spacing: float | None = None,
    straight_line: bool = True,
    guard: ReturnGuard | None = None,
    free_bounds: FreeBounds | None = None,
    return_snap: float = RETURN_SNAP,
    slices: bool = True,
) -> NavigationMap:
    """Extract the navigation polygon, obstacle and exploration points from a model.

    Cuts the inverse at the threshold and each height, sweeping the pan angle; shrinks the
    free area by the robot radius, keeps what the robot can reach in a straight line and
    clips it to the max-range circle; then places obstacle points on its boundary inside
    the circle and exploration points where it lies on the circle (docs/navigation.md).

    Parameters
    ----------
    inverse_range
        ``inverse_range(alpha, h, level) -> r``: the distance from the sensor along the
        ray at pan angle ``alpha`` and height ``h`` where the occupancy first reaches
        ``level``; ``inf`` where it never does, 0 where it does at the sensor. It must
        broadcast; it is called once with ``alpha`` of shape ``(1, N)`` and ``h`` of
        shape ``(H, 1)``.
    robot
        The robot: its radius shrinks the polygon, its body band gives the default
        heights and the band the map must hold for.
    threshold
        Occupancy at or above which space is an obstacle.
    heights
        Sensor-frame heights to cut at, metres (floor at ``-robot.sensor_height``);
        default :func:`default_heights`.
    max_range
        Radius of the circle bounding the polygon, metres.
    n_angles
        Pan angles swept, evenly spaced.
    point_spacing
        Arc length on the max-range circle between neighbouring obstacle or exploration
        points, metres; default the robot radius but at least a tenth of the max range.
        Every sector gets at least one point, so a channel the robot fits through is
        not missed however narrow its sector.
    slope_bounds
        ``{"a_max", "b_max", "c_max"}``: the largest pan weight magnitude, height weight
        magnitude and range weight of the model's linear pieces. With them the map
        also holds between slices and rays (docs/navigation.md): the threshold is lowered
        by the most the model can vary between a body height and its nearest slice and
        between a pan angle and its nearest ray, and each ray's distance becomes the
        least of its own and its neighbours'.
    slice_spacing
        With ``slope_bounds``: the largest gap between slices, metres; slices are added
        between (and beyond) the requested heights until no gap is wider. Default:
        enough slices for a height margin of :data:`DEFAULT_HEIGHT_MARGIN`, but not
        closer than :data:`MIN_AUTO_SLICE_SPACING`. Without ``slope_bounds`` it still adds
        slices, with no margin.
    straight_line
        Keep only what the robot reaches in a straight line with its body clear
        (:func:`visible_from_origin`), as the paper promises; if false, every point where
        the body fits, including those behind a door jamb or a pole close by.
    guard
        The position's own returns (a fitted model's ``guard_``,
        :class:`~occtool.guard.ReturnGuard`): each ray's free distance is capped by the
        guarded returns around it before the shrink, so the polygon keeps every one at
        least the robot's radius away, whatever the model's pieces say.
    return_snap
        With ``guard``: a ray whose free distance stops at most this far (metres) in
        front of the guarded returns around it is carried on to them, where the surface
        was measured (the model's crossing lies in front of it by design); the cap above
        still holds. The space between was seen through: by the return's own ray, and
        for a planar scan by the beams beside it. 0 keeps the model's crossing.
    slices
        Whether the map carries its slices (the free area cut at each requested height,
        :attr:`NavigationMap.slices`). False leaves them out, and with ``free_bounds`` the
        inverse is then not evaluated at all: a run's placed maps keep none (no file holds
        them), and evaluating them was 0.3 ms of a campus keyframe's 3.7.

    Returns
    -------
    NavigationMap

    Raises
    ------
    InputError
        For a parameter out of its domain (a height below the floor, a non-positive max
        range, ...) or an ``inverse_range`` that returns NaN or a wrongly shaped array.

    Warns
    -----
    NavigationWarning
        When the robot is in collision where it stands (the polygon is empty) or when the
        margin leaves no threshold to cut at.

    Examples
    --------
    A circular room of radius 3 m seen from its centre:

    >>> room = lambda alpha, h, level: np.sqrt(3.0 ** 2 + h ** 2) + 0 * alpha
    >>> nav = navigation_map(room, robot=Robot(radius=0.25), max_range=1.5)
    >>> round(nav.polygon.area / (np.pi * 1.5 ** 2), 3), len(nav.obstacle_points)
    (1.0, 0)
    """
    threshold, max_range, n_angles, point_spacing = _checked_parameters(
        threshold, max_range, n_angles, point_spacing, slice_spacing, robot)
    return_snap = float(return_snap)
    if not (math.isfinite(return_snap) and 0.0 <= return_snap <= MAX_DISTANCE):
        raise InputError(f"return_snap must be a number of metres from 0 to {MAX_DISTANCE:g}, got {return_snap}")
    radius = float(robot.radius)
    if heights is None and slope_bounds is None:
        requested, cuts = _default_cuts(robot, n_angles, slice_spacing, free_bounds is not None)
    else:
        requested = requested_heights(heights, robot)
        cuts = cut_heights(requested, robot, n_angles, slope_bounds=slope_bounds, slice_spacing=slice_spacing,
                           exact_bounds=free_bounds is not None)
    level = threshold - cuts.margin
    if cuts.margin > 0 and level <= 0:
        warnings.warn(
            f"the margin {cuts.margin:.3g} that makes the map hold between slices lowers the threshold "
            f"{threshold:g} to {level:.3g}: expect an empty map; cut at more heights (a smaller slice_spacing=)",
            NavigationWarning,
            stacklevel=2,
        )

    alpha = pan_angles(n_angles)
    # Chords between rays sag inside the circle through their ends by cos(pi / n): read far
    # enough that after the shrink the free space still covers the max-range circle.
    # GEOS draws the arcs round obstacle corners with chords, which cut inside the true
    # arc: shrink by a little more than the radius so the chords keep the full radius.
    shrink = shrink_distance(radius)
    read_range = (max_range + shrink) / math.cos(math.pi / n_angles) * (1 + 1e-6) + 1e-9
    distances, slice_distances = _sweep(inverse_range, free_bounds, alpha, requested if slices else None,
                                        cuts.heights, level, read_range)
    cut_slices = []
    if slice_distances is not None:
        slice_polygons = shapely.polygons(
            np.stack([slice_distances * np.cos(alpha), slice_distances * np.sin(alpha)], axis=-1)
        )
        cut_slices = [Slice(float(height), polygon) for height, polygon in zip(requested, slice_polygons)]

    nearest = _nearest_per_ray(distances, alpha, between_rays=cuts.between_rays, guard=guard, snap=return_snap)
    circle_vertices = max(CIRCLE_OVERSAMPLING * n_angles, MIN_CIRCLE_VERTICES)
    polygon = _free_polygon(nearest, alpha, radius=radius, shrink=shrink, max_range=max_range,
                            straight_line=straight_line, circle_vertices=circle_vertices)
    if polygon.is_empty:
        if level > 0:  # otherwise the margin warning above says why
            warnings.warn(_collision_message(distances, cuts.heights, robot, level), NavigationWarning,
                          stacklevel=2)
        obstacles = exploration = np.empty((0, 2))
    else:
        polygon = orient(polygon, sign=1.0)  # RFC 7946: outer ring counter-clockwise
        obstacles, exploration = boundary_points(polygon, max_range, point_spacing, circle_vertices,
                                                 min_distance=radius)

    return NavigationMap(
        polygon=polygon,
        slices=cut_slices,
        obstacle_points=obstacles,
        exploration_points=exploration,
        threshold=threshold,
        effective_threshold=float(level),
        heights=tuple(float(h) for h in requested),
        robot_radius=radius,
        max_range=max_range,
        n_angles=n_angles,
        point_spacing=point_spacing,
        sensor_height=float(robot.sensor_height),
        body_height=float(robot.body_height),
        ground_clearance=float(robot.ground_clearance),
        slice_heights=tuple(float(h) for h in cuts.heights),
        margin=float(cuts.margin),
        straight_line=bool(straight_line),
        return_snap=return_snap if guard is not None else 0.0,
    )


@functools.lru_cache(maxsize=16)
def _default_cuts(robot: Robot, n_angles: int, slice_spacing: float | None,
                  exact_bounds: bool) -> tuple[FloatArray, Cuts]:
    """The default heights of ``robot`` and their cuts without slope bounds, made once for
    every map of a run (the same robot and options each time; 0.1 ms a map), read-only."""
    requested = requested_heights(None, robot)
    cuts = cut_heights(requested, robot, n_angles, slope_bounds=None, slice_spacing=slice_spacing,
                       exact_bounds=exact_bounds)
    requested.setflags(write=False)
    cuts.heights.setflags(write=False)
    return requested, cuts


def shrink_distance(radius: float, quad_segs: int = SHRINK_QUAD_SEGMENTS) -> float:
    """How far to shrink the free area (GEOS ``buffer``, ``quad_segs`` chords a quarter
    circle) so that even its chords round obstacle corners keep ``radius`` from them.

    GEOS draws an arc of angle ``theta`` round a corner with ``int(theta / q + 0.5)``
    chords of equal angle, ``q = pi / 2 / quad_segs``, or with one chord when that is 0: a
    chord spans less than ``1.5 q`` (one chord for an arc just under ``1.5 q``), and its
    middle lies ``cos(angle / 2)`` of the arc's radius from the corner.
    """
    return radius / math.cos(0.75 * math.pi / (2 * quad_segs))


def _checked_parameters(threshold: float, max_range: float, n_angles: int, point_spacing: float | None,
                        slice_spacing: float | None, robot: Robot) -> tuple[float, float, int, float]:
    """``threshold``, ``max_range``, ``n_angles`` and ``point_spacing`` (default: the robot's
    radius, but at least a tenth of the max range) checked and converted."""
    threshold, max_range = float(threshold), float(max_range)
    if not 0.0 < threshold < 1.0:
        # Occupancy lives in [0, 1]: at 1 or above nothing is ever an obstacle (a threshold
        # of 1.5 put 6 % of a map in collision, 5 put 45 %), at 0 everything is.
        raise InputError(f"threshold must lie strictly between 0 and 1, got {threshold}")
    if not (math.isfinite(max_range) and max_range > 0):
        raise InputError(f"max range must be a finite number > 0, got {max_range}")
    if max_range > MAX_DISTANCE:
        raise InputError(f"max_range must be at most {MAX_DISTANCE:g} m, got {max_range:g}")
    if int(n_angles) != n_angles or n_angles < 8:
        raise InputError(f"the number of angles must be an integer >= 8, got {n_angles}")
    if n_angles > MAX_ANGLES:
        raise InputError(f"n_angles must be at most {MAX_ANGLES:,} (0.01 degree apart), got {n_angles:,}")
    if point_spacing is None:
        point_spacing = max(float(robot.radius), max_range / 10.0)
    point_spacing = float(point_spacing)
    if not (math.isfinite(point_spacing) and point_spacing > 0):
        raise InputError(f"point spacing must be a finite number > 0, got {point_spacing}")
    if 2.0 * math.pi * max_range / point_spacing > MAX_POINTS:
        raise InputError(
            f"point spacing {point_spacing:g} m would put over {MAX_POINTS} points on the {max_range:g} m circle"
        )
    if slice_spacing is not None and not (math.isfinite(slice_spacing) and slice_spacing > 0):
        raise InputError(f"slice spacing must be a finite number > 0, got {slice_spacing}")
    return threshold, max_range, int(n_angles), point_spacing


def _sweep(inverse_range: InverseRange, free_bounds: FreeBounds | None, alpha: FloatArray,
           requested: FloatArray | None, cuts: FloatArray, level: float,
           read_range: float) -> tuple[FloatArray, FloatArray | None]:
    """The free distances the polygon is made of, one row per cut (with ``free_bounds``:
    per height box), and those of the requested slices (None without ``requested``)."""
    if free_bounds is None:
        distances = horizontal_distances(inverse_range, alpha, cuts, level, read_range)
        return distances, None if requested is None else distances[np.searchsorted(cuts, requested)]
    requested_distances = None if requested is None else horizontal_distances(
        inverse_range, alpha, requested, level, read_range)
    return _bounded_distances(free_bounds, alpha, cuts, level, read_range), requested_distances


def _nearest_per_ray(distances: FloatArray, alpha: FloatArray, *, between_rays: bool,
                     guard: ReturnGuard | None, snap: float = 0.0) -> FloatArray:
    """Each ray's free distance over every cut, bounded by its neighbours' when the margin
    covers the model between rays, and capped by the guarded returns around it; carried
    on to those returns when it stops at most ``snap`` in front of them."""
    # Star polygons on common rays: the one through the per-ray least distance lies
    # inside their intersection (each triangle between two rays lies inside every
    # slice's) and touches it at every ray, and shrinking commutes with intersecting, so
    # one shrink of one polygon replaces a shrink per slice.
    nearest = distances.min(axis=0)
    if between_rays:
        # With the margin, a point occupied between two rays is no nearer than the nearer
        # ray's distance; the chord between the rays can reach past that, unless each ray
        # takes the least of its own and its neighbours' distances.
        nearest = np.minimum(nearest, np.minimum(cyclic_previous(nearest), cyclic_next(nearest)))
    if guard is not None:
        bound = guard.ray_bounds(alpha)
        nearest = np.minimum(nearest, bound)
        # ``bound`` is the least guarded return over the ray's window (its neighbours'
        # rays included), so the carried-on star polygon still holds none strictly inside.
        # A ray the model closes at the sensor stays closed: the robot is in collision.
        near = np.isfinite(bound) & (nearest > 0) & (bound - nearest <= snap)
        nearest = np.where(near, bound, nearest)
    return nearest


def _free_polygon(nearest: FloatArray, alpha: FloatArray, *, radius: float, shrink: float, max_range: float,
                  straight_line: bool, circle_vertices: int) -> Polygon:
    """The star polygon through ``nearest`` shrunk by the robot's radius (``shrink``), cut to
    what the robot sees in a straight line and clipped to the max-range disk: the part
    around the robot, empty when the robot is in collision."""
    if not nearest.min() > 0:
        return Polygon()
    polygon = star_polygon(nearest, alpha)
    # Sub-nanometre radii are a point robot: shrinking by them only feeds GEOS and the
    # ray casting denormal numbers (overflow in the intersection arithmetic).
    if radius > 1e-9:
        polygon = component_at_origin(polygon.buffer(-shrink, quad_segs=SHRINK_QUAD_SEGMENTS))
        if straight_line and not polygon.is_empty:
            polygon = visible_from_origin(polygon, alpha, max_range)
    return component_at_origin(shapely.intersection(polygon, circle_polygon(max_range, circle_vertices)))


def _collision_message(distances: FloatArray, cuts: FloatArray, robot: Robot, level: float) -> str:
    """Why the polygon is empty: where occupancy reaches ``level`` within the robot's radius."""
    radius = float(robot.radius)
    # With free_bounds a row of distances is the box from one cut to the next.
    rows = cuts if distances.shape[0] == cuts.size else cuts[:-1]
    blocked = rows[distances.min(axis=1) <= radius * 1.001]
    where = (
        f"at heights {blocked.min() + robot.sensor_height:.2f} to {blocked.max() + robot.sensor_height:.2f} m "
        "above the floor"
        if blocked.size else "between its rays"
    )
    return (f"the robot is in collision where it stands: occupancy reaches {level:.3g} within its "
            f"radius {radius:g} m {where}, so the navigation polygon is empty")


def pan_angles(n_angles: int) -> FloatArray:
    """``n_angles`` evenly spaced pan angles in ``[-pi, pi)``, the first straight ahead.

    They go counter-clockwise (ahead, left, behind, right), the order of a
    counter-clockwise polygon ring; angles past ``pi`` are wrapped so that a model fitted
    on ``atan2`` angles is evaluated on its own domain.
    """
    alpha = 2.0 * np.pi * np.arange(n_angles) / n_angles
    return np.where(alpha >= np.pi, alpha - 2.0 * np.pi, alpha)


def horizontal_distances(
    inverse_range: InverseRange, alpha: FloatArray, heights: FloatArray, level: float, read_range: float
) -> FloatArray:
    """Free horizontal distance per height and pan angle: ``sqrt(r^2 - h^2)``, capped.

    Parameters
    ----------
    inverse_range
        ``r = F^-1(alpha, h, level)``, broadcasting over ``alpha`` and ``h``.
    alpha
        ``(N,)`` pan angles, radians.
    heights
        ``(H,)`` sensor-frame heights, metres.
    level
        Occupancy level to invert at.
    read_range
        Cap for distances (``inf`` where the model stays free along the whole ray).

    Returns
    -------
    numpy.ndarray
        ``(H, N)`` metres; 0 where the ray is blocked before it reaches height ``h``
        (``r < |h|``).
    """
    ranges = np.asarray(inverse_range(alpha[None, :], heights[:, None], level), dtype=np.float64)
    try:
        ranges = np.broadcast_to(ranges, (heights.size, alpha.size))
    except ValueError:
        raise InputError(
            f"inverse_range returned shape {ranges.shape}, expected one that broadcasts to "
            f"({heights.size} heights, {alpha.size} angles)"
        ) from None
    # A negative range (a raw inverse tree: the level is crossed behind the sensor) means
    # occupied at the sensor; capping the rest keeps inf out of the arithmetic. The clip
    # makes the one new array (the callable's may be shared); the rest works in place.
    distances = np.clip(ranges, 0.0, 2.0 * (read_range + np.abs(heights).max()))
    if np.isnan(distances.min()):  # the clip and the minimum both keep NaN
        raise InputError("inverse_range returned NaN ranges: the model cannot be inverted there")
    np.square(distances, out=distances)
    np.subtract(distances, np.square(heights)[:, None], out=distances)
    np.maximum(distances, 0.0, out=distances)
    np.sqrt(distances, out=distances)
    return np.minimum(distances, read_range, out=distances)


def _bounded_distances(free_bounds: FreeBounds, alpha: FloatArray, edges: FloatArray, level: float,
                       read_range: float) -> FloatArray:
    """``(len(edges) - 1, n)``: per height box, each ray's least free distance over the two
    angle intervals beside it (from the previous ray to the next), at most ``read_range``.

    An interval that crosses +-pi is bounded in two parts (the paper's linear basis jumps there).
    """
    n = alpha.size
    step = 2.0 * math.pi / n
    low = wrap_angle(alpha)
    high = low + step
    crossing = high > math.pi
    lows = np.concatenate([low, np.full(int(crossing.sum()), -math.pi)])
    highs = np.concatenate([np.minimum(high, math.pi), high[crossing] - 2.0 * math.pi])
    bounds = np.asarray(free_bounds(lows, highs, edges, level), dtype=np.float64)
    if bounds.shape != (edges.size - 1, lows.size):
        raise InputError(f"free_bounds returned shape {bounds.shape}, expected {(edges.size - 1, lows.size)}")
    if np.isnan(bounds).any():
        raise InputError("free_bounds returned NaN")
    interval = bounds[:, :n].copy()
    interval[:, crossing] = np.minimum(interval[:, crossing], bounds[:, n:])
    # Ray i lies between interval i - 1 (from the previous ray) and interval i (to the next).
    per_ray = np.minimum(interval, np.roll(interval, 1, axis=1))
    return np.minimum(np.maximum(per_ray, 0.0), read_range)
