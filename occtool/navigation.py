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
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray
from shapely.geometry import Polygon
from shapely.geometry.base import BaseGeometry
from shapely.geometry.polygon import orient

from occtool.errors import InputError
from occtool.features import Pose
from occtool.guard import ReturnGuard
from occtool.limits import MAX_ANGLES, MAX_DISTANCE
from occtool.robot import Robot

FloatArray = NDArray[np.float64]
InverseRange = Callable[[FloatArray, FloatArray, float], ArrayLike]
#: ``free_bounds(alpha_low, alpha_high, h_edges, level) -> (H - 1, N)``: lower bounds of the
#: free horizontal distance over boxes of pan angle x height (:meth:`occtool.tree.InverseTree.horizontal_lower_bound`).
FreeBounds = Callable[[FloatArray, FloatArray, FloatArray, float], FloatArray]

#: Default spacing of the default heights across the robot's body band, metres.
DEFAULT_HEIGHT_SPACING = 0.25
#: With slope bounds and no ``slice_spacing``: slices are added until the height part of
#: the threshold margin is at most this (occupancy units) ...
DEFAULT_HEIGHT_MARGIN = 0.05
#: ... but never closer than this, metres, so a very steep model cannot ask for
#: thousands of slices; the rest of the margin then lowers the threshold.
MIN_AUTO_SLICE_SPACING = 0.01
#: The max-range circle is drawn with this many times ``n_angles`` vertices (at least
#: :data:`MIN_CIRCLE_VERTICES`), so its chords sag far less than a ray step.
CIRCLE_OVERSAMPLING = 4
MIN_CIRCLE_VERTICES = 720
#: Arcs shorter than this (metres) where the polygon merely grazes the circle carry no
#: exploration point.
MIN_SECTOR_LENGTH = 1e-6
#: Segments per quarter circle of the arcs the shrink draws round obstacle corners.
SHRINK_QUAD_SEGMENTS = 16
#: With ``free_bounds``: the body band is covered by boxes at most this tall, metres (the
#: bound is exact piece by piece; a box spanning the height where two pieces of a group
#: trade places gives a little away, less the thinner the box).
BOUND_HEIGHT_STEP = 0.1
#: Most heights a map may be cut at (a guard against a tiny slice spacing or a huge body).
MAX_SLICES = 10_000
#: Most obstacle and exploration points a map may carry (a guard against a tiny spacing).
MAX_POINTS = 20_000
#: Ray/edge pairs intersected at a time when casting rays to a polygon's boundary.
RAY_CAST_BLOCK = 1 << 20
#: Radians by which an edge's angular extent is widened when pairing it with the rays
#: that may hit it (rounding is ~1e-15; the intersection test decides).
RAY_ANGLE_SLACK = 1e-9


_ORIGIN = shapely.Point(0.0, 0.0)


class NavigationWarning(UserWarning):
    """The navigation map was extracted but is degenerate (robot in collision, ...)."""


@dataclass(frozen=True, eq=False)
class Slice:
    """The free area at one sensor-frame height, before the shrink by the robot radius.

    Parameters
    ----------
    height
        Sensor-frame height of the cut, metres (negative below the sensor).
    polygon
        The star-shaped polygon of horizontal free distances swept over the pan angle,
        robot-frame x, y metres, out to the read range (max range plus robot radius).
    """

    height: float
    polygon: Polygon


@dataclass(frozen=True, eq=False)
class NavigationMap:
    """A local navigation map and the parameters it was extracted with.

    Parameters
    ----------
    polygon
        Where the robot can drive in a straight line with its whole body clear: a
        shapely Polygon, x/y metres in ``frame_id``, outer ring counter-clockwise
        (RFC 7946). Empty when the robot is in collision where it stands.
    slices
        The free area at each requested height (:class:`Slice`), unshrunk.
    obstacle_points
        ``(K, 2)`` points on the polygon's boundary strictly inside the max-range circle,
        at evenly spaced angles in each obstacle sector (negative reinforcement).
    exploration_points
        ``(K, 2)`` points on the max-range circle where the polygon reaches it, at evenly
        spaced angles in each such sector (positive reinforcement).
    threshold
        The occupancy level asked for.
    effective_threshold
        The level the model was actually cut at: ``threshold`` minus the margin that
        makes the map hold between slices and rays (equal to ``threshold`` without
        slope bounds).
    heights
        The requested sensor-frame heights, metres, ascending.
    robot_radius, max_range
        Metres.
    n_angles
        Pan angles swept (evenly spaced, the first straight ahead).
    point_spacing
        Arc length on the max-range circle between neighbouring points, metres.
    sensor_height, body_height, ground_clearance
        The robot's geometry above the floor, metres.
    slice_heights
        Every height the model was cut at: the requested ones and any added to hold the
        map between them.
    margin
        ``threshold - effective_threshold``.
    straight_line
        Whether the polygon was cut to what the robot reaches in a straight line.
    frame_id
        ``"base_link"`` for the robot frame, else the world frame the map was moved to.
    pose
        The robot's world pose when the map is in a world frame.
    extra
        Further properties a GeoJSON file carried, kept for writing it back.
    """

    polygon: Polygon
    slices: list[Slice]
    obstacle_points: FloatArray
    exploration_points: FloatArray
    threshold: float
    effective_threshold: float
    heights: tuple[float, ...]
    robot_radius: float
    max_range: float
    n_angles: int
    point_spacing: float
    sensor_height: float = 1.0
    body_height: float = 1.0
    ground_clearance: float = 0.05
    slice_heights: tuple[float, ...] = ()
    margin: float = 0.0
    straight_line: bool = True
    frame_id: str = "base_link"
    pose: Pose | None = None
    extra: Mapping[str, object] = field(default_factory=dict)

    @property
    def is_empty(self) -> bool:
        """True when there is nowhere to go (the robot is in collision)."""
        return bool(self.polygon.is_empty)

    def in_world(self, pose: Pose, frame_id: str = "map") -> NavigationMap:
        """The same map moved from the robot frame into a world frame by the robot's pose.

        Parameters
        ----------
        pose
            The robot's pose in the world frame (x, y, yaw are used).
        frame_id
            Name of the world frame (REP-105: ``map`` or ``odom``).

        Returns
        -------
        NavigationMap
            Polygon, slices and points rotated by ``pose.yaw`` and moved by ``(x, y)``.
        """
        if self.frame_id != "base_link":
            raise InputError(f"the navigation map is already in the {self.frame_id!r} frame")

        def move(geometry: BaseGeometry) -> BaseGeometry:
            return shapely.transform(geometry, pose.to_world)

        return replace(
            self,
            polygon=move(self.polygon),
            slices=[Slice(s.height, move(s.polygon)) for s in self.slices],
            obstacle_points=pose.to_world(self.obstacle_points),
            exploration_points=pose.to_world(self.exploration_points),
            frame_id=frame_id,
            pose=pose,
        )


# --- heights ------------------------------------------------------------------------------


def default_heights(robot: Robot, spacing: float = DEFAULT_HEIGHT_SPACING) -> FloatArray:
    """Sensor-frame heights spanning the robot's body band.

    The band (from the ground clearance to the top of the body) is split into
    ``ceil(band / spacing)`` equal parts and cut at their midpoints, which puts every
    body height as close to a cut as that many cuts can.

    Parameters
    ----------
    robot
        The robot whose :attr:`~occtool.robot.Robot.body_band` is spanned.
    spacing
        Largest distance between neighbouring heights, metres.

    Returns
    -------
    numpy.ndarray
        Ascending heights, metres.

    Examples
    --------
    >>> default_heights(Robot(sensor_height=1.0, body_height=1.0, ground_clearance=0.0)).round(3)
    array([-0.875, -0.625, -0.375, -0.125])
    """
    low, high = robot.body_band
    count = max(1, math.ceil((high - low) / spacing - 1e-9))
    return low + (np.arange(count) + 0.5) * (high - low) / count


def farthest_from_slices(heights: ArrayLike, band: tuple[float, float]) -> float:
    """The largest distance from a height of ``band`` (or between the heights) to a slice.

    Parameters
    ----------
    heights
        Slice heights, metres.
    band
        ``(low, high)`` heights that must be covered, metres.

    Returns
    -------
    float
        Metres; the heights' own span is covered too when it reaches beyond the band.
    """
    cuts = np.sort(np.asarray(heights, dtype=np.float64))
    low, high = min(band[0], cuts[0]), max(band[1], cuts[-1])
    gaps = np.diff(cuts) / 2.0
    return float(max(cuts[0] - low, high - cuts[-1], gaps.max(initial=0.0)))


def add_slices(heights: ArrayLike, band: tuple[float, float], spacing: float) -> FloatArray:
    """Insert heights so that no body height is farther than ``spacing / 2`` from a slice.

    The requested heights are kept; each gap between them is split evenly, and slices
    are added below the lowest and above the highest down to and up to the band ends.

    Parameters
    ----------
    heights
        Requested heights, metres.
    band
        ``(low, high)`` heights that must be covered, metres.
    spacing
        Largest allowed gap between neighbouring slices, metres.

    Returns
    -------
    numpy.ndarray
        Ascending heights including the requested ones.
    """
    cuts = np.unique(np.asarray(heights, dtype=np.float64))
    parts = [cuts]
    for lower, upper in zip(cuts[:-1], cuts[1:]):
        pieces = math.ceil((upper - lower) / spacing - 1e-9)
        if pieces > 1:
            parts.append(lower + (upper - lower) * np.arange(1, pieces) / pieces)
    below = cuts[0] - band[0]
    if below > spacing / 2:
        parts.append(cuts[0] - spacing * np.arange(1, math.ceil((below - spacing / 2) / spacing - 1e-9) + 1))
    above = band[1] - cuts[-1]
    if above > spacing / 2:
        parts.append(cuts[-1] + spacing * np.arange(1, math.ceil((above - spacing / 2) / spacing - 1e-9) + 1))
    return np.unique(np.concatenate(parts))


# --- slope bounds and margin --------------------------------------------------------------


def _checked_bounds(slope_bounds: Mapping[str, float]) -> tuple[float, float, float]:
    values = []
    for key in ("a_max", "b_max", "c_max"):
        if key not in slope_bounds:
            raise InputError(f"slope bounds need a_max, b_max and c_max; {key} is missing")
        value = float(slope_bounds[key])
        if not math.isfinite(value) or value < 0:
            raise InputError(f"slope bound {key} must be a finite number >= 0, got {slope_bounds[key]}")
        values.append(value)
    return values[0], values[1], values[2]


def height_lipschitz(slope_bounds: Mapping[str, float]) -> float:
    """How fast the occupancy can change with height at a fixed horizontal distance.

    At a fixed pan angle and horizontal distance ``rho``, a piece ``a alpha + b h + c r + d``
    with ``r = sqrt(rho^2 + h^2)`` changes with ``h`` at ``b + c h / r``, and ``|h / r| <= 1``;
    min and max nodes keep the largest of their children's rates.

    Parameters
    ----------
    slope_bounds
        ``a_max``, ``b_max``, ``c_max`` of the model's pieces.

    Returns
    -------
    float
        ``b_max + c_max``, occupancy per metre.
    """
    _, b_max, c_max = _checked_bounds(slope_bounds)
    return b_max + c_max


# --- extraction ---------------------------------------------------------------------------


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
    low = np.mod(alpha + math.pi, 2.0 * math.pi) - math.pi
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


@functools.lru_cache(maxsize=16)
def _circle(radius: float, vertices: int) -> Polygon:
    theta = 2.0 * np.pi * np.arange(vertices) / vertices
    return Polygon(np.column_stack([radius * np.cos(theta), radius * np.sin(theta)]))


def _next(values: NDArray[np.generic]) -> NDArray[np.generic]:
    """``values`` moved one place back, cyclically: ``np.roll(values, -1, axis=0)`` without its overhead."""
    return np.concatenate((values[1:], values[:1]))


def _previous(values: NDArray[np.generic]) -> NDArray[np.generic]:
    """``values`` moved one place on, cyclically: ``np.roll(values, 1, axis=0)``."""
    return np.concatenate((values[-1:], values[:-1]))


def _star_polygon(distances: FloatArray, alpha: FloatArray) -> Polygon:
    return Polygon(np.column_stack([distances * np.cos(alpha), distances * np.sin(alpha)]))


def _component_at_origin(geometry: BaseGeometry) -> Polygon:
    """The polygon of ``geometry`` that holds the robot (the origin) strictly inside."""
    for part in getattr(geometry, "geoms", [geometry]):
        if isinstance(part, Polygon) and part.contains(_ORIGIN):
            return part
    return Polygon()


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
    n_angles = int(n_angles)
    radius = float(robot.radius)
    if point_spacing is None:
        point_spacing = max(radius, max_range / 10.0)
    point_spacing = float(point_spacing)
    if not (math.isfinite(point_spacing) and point_spacing > 0):
        raise InputError(f"point spacing must be a finite number > 0, got {point_spacing}")
    if 2.0 * math.pi * max_range / point_spacing > MAX_POINTS:
        raise InputError(
            f"point spacing {point_spacing:g} m would put over {MAX_POINTS} points on the {max_range:g} m circle"
        )
    if slice_spacing is not None and not (math.isfinite(slice_spacing) and slice_spacing > 0):
        raise InputError(f"slice spacing must be a finite number > 0, got {slice_spacing}")

    band = robot.body_band
    if heights is None and (band[1] - band[0]) / DEFAULT_HEIGHT_SPACING > MAX_SLICES:
        raise InputError(f"a body band of {band[1] - band[0]:g} m would need over {MAX_SLICES} cuts")
    requested = default_heights(robot) if heights is None else np.asarray(heights, dtype=np.float64).ravel()
    if requested.size == 0:
        raise InputError("at least one height is needed")
    if requested.size > MAX_SLICES:
        raise InputError(f"heights holds {requested.size:,} heights, more than {MAX_SLICES:,}")
    if not np.isfinite(requested).all():
        raise InputError(f"heights must be finite numbers, got {requested.tolist()}")
    if (requested <= robot.floor_h).any():
        raise InputError(
            f"height {requested.min():g} m is at or below the floor ({robot.floor_h:g} m in the sensor frame, "
            f"sensor height {robot.sensor_height:g} m)"
        )
    requested = np.unique(requested)

    margin = 0.0
    if free_bounds is not None:
        # Exact bounds over boxes: no Lipschitz margin, no added slices.
        slope_bounds, slice_spacing = None, None
    if slope_bounds is not None:
        a_max, _, _ = _checked_bounds(slope_bounds)
        lipschitz = height_lipschitz(slope_bounds)
        if slice_spacing is None and lipschitz > 0:
            slice_spacing = max(2.0 * DEFAULT_HEIGHT_MARGIN / lipschitz, MIN_AUTO_SLICE_SPACING)
    if slice_spacing is not None:
        extent = max(band[1], requested[-1]) - min(band[0], requested[0])
        if extent / slice_spacing > MAX_SLICES:
            raise InputError(
                f"slice spacing {slice_spacing:g} m would cut the {extent:g} m the heights and body span over "
                f"{MAX_SLICES} times"
            )
    cuts = requested if slice_spacing is None else add_slices(requested, band, float(slice_spacing))
    if free_bounds is not None:
        # Box edges: the requested heights and the band's ends, split to BOUND_HEIGHT_STEP.
        edges = np.unique(np.concatenate([requested, [band[0], band[1]]]))
        cuts = add_slices(edges, (edges[0], edges[-1]), BOUND_HEIGHT_STEP)
    # Keep added slices above the floor: a cut on the floor sees only the floor.
    cuts = cuts[cuts > robot.floor_h]
    if slope_bounds is not None:
        margin = lipschitz * farthest_from_slices(cuts, band) + a_max * np.pi / n_angles
    level = threshold - margin
    if margin > 0 and level <= 0:
        warnings.warn(
            f"the margin {margin:.3g} that makes the map hold between slices lowers the threshold "
            f"{threshold:g} to {level:.3g}: expect an empty map; cut at more heights (--slice-spacing)",
            NavigationWarning,
            stacklevel=2,
        )

    alpha = pan_angles(n_angles)
    # Chords between rays sag inside the circle through their ends by cos(pi / n): read far
    # enough that after the shrink the free space still covers the max-range circle.
    # GEOS draws the arcs round obstacle corners with chords, which cut inside the true
    # arc: shrink by a little more than the radius so the chords keep the full radius.
    shrink = radius / math.cos(math.pi / (4 * SHRINK_QUAD_SEGMENTS))
    read_range = (max_range + shrink) / math.cos(math.pi / n_angles) * (1 + 1e-6) + 1e-9
    if free_bounds is None:
        distances = horizontal_distances(inverse_range, alpha, cuts, level, read_range)
        requested_rows = np.searchsorted(cuts, requested)
        requested_distances = distances[requested_rows]
    else:
        requested_distances = horizontal_distances(inverse_range, alpha, requested, level, read_range)
        distances = _bounded_distances(free_bounds, alpha, cuts, level, read_range)
    slice_polygons = shapely.polygons(
        np.stack([requested_distances * np.cos(alpha), requested_distances * np.sin(alpha)], axis=-1)
    )
    slices = [Slice(float(height), polygon) for height, polygon in zip(requested, slice_polygons)]

    # Star polygons on common rays: the one through the per-ray least distance lies
    # inside their intersection (each triangle between two rays lies inside every
    # slice's) and touches it at every ray, and shrinking commutes with intersecting, so
    # one shrink of one polygon replaces a shrink per slice.
    nearest = distances.min(axis=0)
    if slope_bounds is not None:
        # With the margin, a point occupied between two rays is no nearer than the nearer
        # ray's distance; the chord between the rays can reach past that, unless each ray
        # takes the least of its own and its neighbours' distances.
        nearest = np.minimum(nearest, np.minimum(_previous(nearest), _next(nearest)))
    if guard is not None:
        nearest = np.minimum(nearest, guard.ray_bounds(alpha))
    circle_vertices = max(CIRCLE_OVERSAMPLING * n_angles, MIN_CIRCLE_VERTICES)
    polygon = Polygon()
    if nearest.min() > 0:
        free = _star_polygon(nearest, alpha)
        polygon = free
        # Sub-nanometre radii are a point robot: shrinking by them only feeds GEOS and the
        # ray casting denormal numbers (overflow in the intersection arithmetic).
        if radius > 1e-9:
            polygon = _component_at_origin(free.buffer(-shrink, quad_segs=SHRINK_QUAD_SEGMENTS))
            if straight_line and not polygon.is_empty:
                polygon = visible_from_origin(polygon, alpha, max_range)
        polygon = _component_at_origin(shapely.intersection(polygon, _circle(max_range, circle_vertices)))
    if polygon.is_empty:
        if level > 0:  # otherwise the margin warning above says why
            # With free_bounds a row of distances is the box from one cut to the next.
            rows = cuts if distances.shape[0] == cuts.size else cuts[:-1]
            blocked = rows[distances.min(axis=1) <= radius * 1.001]
            where = (
                f"at heights {blocked.min() + robot.sensor_height:.2f} to {blocked.max() + robot.sensor_height:.2f} m "
                "above the floor"
                if blocked.size else "between its rays"
            )
            warnings.warn(
                f"the robot is in collision where it stands: occupancy reaches {level:.3g} within its "
                f"radius {radius:g} m {where}, so the navigation polygon is empty",
                NavigationWarning,
                stacklevel=2,
            )
        obstacles = exploration = np.empty((0, 2))
    else:
        polygon = orient(polygon, sign=1.0)  # RFC 7946: outer ring counter-clockwise
        obstacles, exploration = boundary_points(polygon, max_range, point_spacing, circle_vertices,
                                                 min_distance=radius)

    return NavigationMap(
        polygon=polygon,
        slices=slices,
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
        slice_heights=tuple(float(h) for h in cuts),
        margin=float(margin),
        straight_line=bool(straight_line),
    )


# --- obstacle and exploration points ------------------------------------------------------


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
    ring = np.asarray(polygon.exterior.coords)[:-1]
    if len(ring) < 3:
        return []
    tolerance = max_range * (1.0 - math.cos(math.pi / circle_vertices)) * 1.01 + 1e-9 * max_range
    on_circle = np.hypot(ring[:, 0], ring[:, 1]) >= max_range - tolerance
    following = _next(ring)
    middle = (ring + following) / 2.0
    # Both ends on the circle is not enough: an obstacle's chord can join two of its points.
    is_arc = on_circle & _next(on_circle) & (np.hypot(middle[:, 0], middle[:, 1]) >= max_range - tolerance)
    theta = np.arctan2(ring[:, 1], ring[:, 0])
    if is_arc.all():
        return [(0.0, 2.0 * np.pi)]
    if not is_arc.any():
        return []
    # Rotate the ring to start on an edge off the circle, so no run wraps around the end.
    shift = int(np.flatnonzero(~is_arc)[0])
    is_arc = np.concatenate((is_arc[shift:], is_arc[:shift]))
    theta = np.concatenate((theta[shift:], theta[:shift]))
    edges = np.diff(np.concatenate([[0], is_arc.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    sectors = []
    for first, last in zip(starts, stops):  # a run of arc edges from vertex first to vertex last
        start, end = theta[first], theta[last % len(theta)]
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


def _first_hits(
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
    turn = np.mod(np.arctan2(ends[:, 1], ends[:, 0]) - first_angle + np.pi, 2.0 * np.pi) - np.pi
    low = first_angle + np.minimum(turn, 0.0) - RAY_ANGLE_SLACK
    high = low + np.abs(turn) + 2.0 * RAY_ANGLE_SLACK
    # An edge through (or grazing) the origin spans about pi: pair it with every ray.
    wide = np.abs(turn) >= np.pi - 1e-6
    low[wide], high[wide] = -4.0 * np.pi, 4.0 * np.pi
    key = np.mod(angles + np.pi, 2.0 * np.pi) - np.pi  # in [-pi, pi), as the extents (+- 2 pi)
    ray_order = np.argsort(key, kind="stable")
    sorted_key = key[ray_order]
    edges = np.arange(3 * len(start)) % len(start)
    lows = np.concatenate([low - 2.0 * np.pi, low, low + 2.0 * np.pi])
    highs = np.concatenate([high - 2.0 * np.pi, high, high + 2.0 * np.pi])
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


def _edges_within(start: FloatArray, step: FloatArray, within: float) -> NDArray[np.bool_]:
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
        near = _edges_within(start, step, within)
        start, step = start[near], step[near]
    return _first_hits(start, step, np.asarray(angles, dtype=np.float64))[0]


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
    following = _next(ring)
    outside = reach / math.cos(math.pi / len(angles)) * (1 + 1e-6) + 1e-9
    step = following - ring
    near = _edges_within(ring, step, outside)
    # Edge i runs clockwise, as seen from the origin, when v_i x v_i+1 < 0.
    backward = (ring[:, 0] * following[:, 1] - ring[:, 1] * following[:, 0] < 0) & near
    if not backward.any():
        return region
    silhouette = (backward != _previous(backward)) & (np.hypot(ring[:, 0], ring[:, 1]) <= outside)
    corners = np.arctan2(ring[silhouette, 1], ring[silhouette, 0])
    side = 1e-7  # radians either side of a silhouette vertex
    rays = np.unique(np.mod(np.concatenate([angles, corners - side, corners + side]) + np.pi, 2.0 * np.pi) - np.pi)

    shadowed = _gaps_overlapping(
        rays,
        np.arctan2(following[backward, 1], following[backward, 0]),  # a backward edge's smaller angle ...
        np.arctan2(ring[backward, 1], ring[backward, 0]),  # ... and its larger
    )
    # Only the rays bounding a shadowed gap need casting.
    cast = np.flatnonzero(shadowed | _previous(shadowed))  # type: ignore[operator]  # _previous keeps the bool dtype
    near_edges = np.flatnonzero(near)
    distance, edge, where = _first_hits(ring[near_edges], step[near_edges], rays[cast])
    hits = np.minimum(distance, outside)

    # Two vertices per ray: where the gap before it ends, where the gap after it begins;
    # a gap in the open lets the region through whole, a shadowed one cuts it on the chord.
    radii = np.full(len(rays), outside)
    radii[cast] = hits
    radii = np.column_stack([np.where(_previous(shadowed), radii, outside), np.where(shadowed, radii, outside)])
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
    return _component_at_origin(shapely.intersection(split, Polygon(cut)))


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


__all__ = [
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
    "visible_from_origin",
]
