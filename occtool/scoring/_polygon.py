"""Score a navigation polygon against a scene's truth.

The truth is the *reachable region*: the points the robot's centre can drive to in a
straight line from the origin without any part of its body touching an obstacle,
within the max-range disk. The body is a cylinder of radius ``robot_radius`` from the
ground clearance to the body height; an obstacle blocks when its vertical extent
overlaps that band. In configuration space the blocking obstacles are their
footprints grown by the radius (the C-space obstacles), and straight-line reachability
makes the region the visibility polygon of the origin among them: star-shaped around
the robot, as the paper's navigation polygon is.

:func:`evaluate_navigation` compares a polygon with that region (IoU) and measures how
much of the polygon would put the body into an obstacle (violation). See
``docs/scenes.md`` for the definitions.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray
from shapely.geometry.base import BaseGeometry

from occtool.errors import InputError
from occtool.features import Features, Pose
from occtool.guard import guard_candidates
from occtool.limits import MAX_RAYS
from occtool.robot import Robot
from occtool.scoring._metrics import OVERLAY_GRID
from occtool.scoring._rays import ray_reach
from occtool.simulate import Obstacle, Scene

FloatArray = NDArray[np.float64]

#: Rays of the angular sweep that traces the reachable region (0.05 degree apart).
DEFAULT_RAYS = 7200
#: Segments per quarter circle when growing footprints by the robot radius.
_QUAD_SEGS = 16
_ORIGIN = shapely.Point(0.0, 0.0)


def blocking_obstacles(scene: Scene) -> list[Obstacle]:
    """The obstacles whose vertical extent overlaps the body band of ``scene.robot``.

    Anything entirely at or below the ground clearance is driven over; anything entirely
    at or above the body height passes over the robot.
    """
    low, high = scene.robot.ground_clearance, scene.robot.body_height
    return [o for o in scene.obstacles if o.z_max > low and o.z_min < high]


def configuration_obstacles(scene: Scene, *, robot_radius: float | None = None) -> BaseGeometry:
    """The union of the blocking footprints grown by the robot radius (C-space obstacles)."""
    radius = scene.robot.radius if robot_radius is None else float(robot_radius)
    _check_nonnegative("robot radius", radius)
    footprints = [o.polygon for o in blocking_obstacles(scene)]
    if not footprints:
        return shapely.Polygon()
    grown = shapely.buffer(np.asarray(footprints, dtype=object), radius, quad_segs=_QUAD_SEGS) if radius > 0 \
        else np.asarray(footprints, dtype=object)
    # Footprints that touch (shelves either side of a gap of the robot's diameter) give
    # nearly coincident edges once grown: see OVERLAY_GRID.
    return shapely.union_all(grown, grid_size=OVERLAY_GRID)


def _check_nonnegative(what: str, value: float) -> None:
    if not (np.isfinite(value) and value >= 0):
        raise InputError(f"{what} must be a finite number >= 0, got {value}")


def _boundary_segments(geometry: BaseGeometry) -> tuple[FloatArray, FloatArray]:
    """Start and end points of every boundary segment of a (multi)polygon."""
    starts: list[FloatArray] = []
    ends: list[FloatArray] = []
    for ring in shapely.get_parts(shapely.boundary(geometry)) if not geometry.is_empty else []:
        coords = np.asarray(shapely.get_coordinates(ring))
        if len(coords) < 2:
            continue
        starts.append(coords[:-1])
        ends.append(coords[1:])
    if not starts:
        return np.empty((0, 2)), np.empty((0, 2))
    return np.concatenate(starts), np.concatenate(ends)


def _reach(obstacles: BaseGeometry, angles: FloatArray, max_range: float) -> FloatArray:
    """Distance along each pan angle to the first C-space obstacle, capped at ``max_range``.

    Cast by scoring's own ray caster (:func:`occtool.scoring._rays.ray_reach`), never the
    navigation maps': the judge shares no code with what it judges.
    """
    starts, ends = _boundary_segments(obstacles)
    # Only segments that come within the disk can cut a ray short of max_range.
    if starts.shape[0]:
        near = shapely.distance(shapely.linestrings(np.stack([starts, ends], axis=1)), _ORIGIN) <= max_range
        starts, ends = starts[near], ends[near]
    return ray_reach(starts, ends, angles, max_range)


def true_reach(scene: Scene, angles: ArrayLike, *, robot_radius: float | None = None,
               max_range: float) -> FloatArray:
    """How far the robot's centre can go in a straight line along each pan angle.

    Parameters
    ----------
    scene
        The truth.
    angles
        Pan angles, radians (0 straight ahead, counter-clockwise).
    robot_radius
        Metres (default: the scene robot's radius).
    max_range
        The distances are capped here, metres.

    Returns
    -------
    numpy.ndarray
        Distances in metres, the shape of ``angles``; all 0 when the robot already
        touches an obstacle.
    """
    _check_nonnegative("max range", max_range)
    alpha = np.asarray(angles, dtype=np.float64)
    obstacles = configuration_obstacles(scene, robot_radius=robot_radius)
    if not obstacles.is_empty and obstacles.intersects(_ORIGIN):
        return np.zeros(alpha.shape)
    return _reach(obstacles, alpha.reshape(-1), max_range).reshape(alpha.shape)


def reachable_region(
    scene: Scene,
    *,
    robot_radius: float | None = None,
    max_range: float,
    n_rays: int = DEFAULT_RAYS,
) -> BaseGeometry:
    """The true region the robot's centre can reach in a straight line from the origin.

    Parameters
    ----------
    scene
        The truth; its robot gives the ground clearance and body height.
    robot_radius
        Radius of the robot's body, metres (default: the scene robot's radius).
    max_range
        Radius of the disk the region is bounded by, metres.
    n_rays
        Rays of the angular sweep from the origin; the region is the polygon through
        their first contacts with the C-space obstacles (or the disk).

    Returns
    -------
    shapely.Polygon
        Star-shaped around the origin; empty if the robot already touches an obstacle.
    """
    _check_nonnegative("max range", max_range)
    if n_rays < 8:
        raise InputError(f"need at least 8 rays to trace the reachable region, got {n_rays}")
    if n_rays > MAX_RAYS:
        raise InputError(f"n_rays must be at most {MAX_RAYS:,}, got {n_rays:,}")
    obstacles = configuration_obstacles(scene, robot_radius=robot_radius)
    if max_range == 0 or (not obstacles.is_empty and obstacles.intersects(_ORIGIN)):
        return shapely.Polygon()
    angles = np.linspace(-math.pi, math.pi, n_rays, endpoint=False)
    reach = _reach(obstacles, angles, max_range)
    ring = np.column_stack([reach * np.cos(angles), reach * np.sin(angles)])
    region = shapely.Polygon(ring)
    if not region.is_valid:
        region = _polygonal(shapely.make_valid(region))
    # Chords between neighbouring rays that meet a convex arc of an obstacle cut a sliver
    # into it; removing the obstacles keeps the truth free of any body contact.
    if not obstacles.is_empty:
        region = shapely.difference(region, obstacles, grid_size=OVERLAY_GRID)
    if region.geom_type != "Polygon":
        # Only the part around the robot is reachable; any other crumb is an artefact.
        parts = [p for p in shapely.get_parts(region) if p.geom_type == "Polygon" and p.intersects(_ORIGIN)]
        region = parts[0] if parts else shapely.Polygon()
    return region


@dataclass(frozen=True)
class Evaluation:
    """How a navigation polygon compares with the truth.

    Attributes
    ----------
    iou
        Area of (polygon ∩ truth) / area of (polygon ∪ truth); 1 is perfect.
    violation
        Share of the polygon's area where the robot's centre would put its body into an
        obstacle: area(polygon ∩ C-space obstacles) / area(polygon); 0 is safe.
    area
        Area of the navigation polygon, square metres.
    truth_area
        Area of the reachable region, square metres.
    coverage
        Share of the reachable region the polygon covers (recall).
    excess
        Share of the polygon outside the reachable region (not straight-line reachable,
        whether blocked or shadowed).
    robot_radius, max_range
        The parameters of the truth used.
    obstacle_accuracy
        Share of the obstacle points given whose direction truly holds an obstacle
        within the max range (its true reach is shorter than the max range by more
        than the point tolerance); ``None`` when no obstacle points were given.
    exploration_accuracy
        Share of the exploration points given whose direction is truly open to the
        max range (within the point tolerance); ``None`` when none were given.
    """

    iou: float
    violation: float
    area: float
    truth_area: float
    coverage: float
    excess: float
    robot_radius: float
    max_range: float
    obstacle_accuracy: float | None = None
    exploration_accuracy: float | None = None

    def to_dict(self) -> dict[str, float]:
        """The scores as plain floats (point accuracies only when they were measured)."""
        return {k: float(v) for k, v in asdict(self).items() if v is not None}


def as_polygon(polygon: BaseGeometry | ArrayLike) -> BaseGeometry:
    """A shapely polygon from a shapely geometry or a ``(K, 2)`` vertex array."""
    if isinstance(polygon, BaseGeometry):
        geometry = polygon
    else:
        coords = np.asarray(polygon, dtype=np.float64)
        if coords.size == 0:
            return shapely.Polygon()
        if coords.ndim != 2 or coords.shape[1] != 2 or coords.shape[0] < 3:
            raise InputError(f"a polygon needs a (K >= 3, 2) vertex array, got shape {coords.shape}")
        if not np.isfinite(coords).all():
            raise InputError("the polygon has a NaN or infinite vertex")
        geometry = shapely.Polygon(coords)
    if geometry.geom_type not in ("Polygon", "MultiPolygon", "GeometryCollection"):
        raise InputError(f"expected a polygon, got a {geometry.geom_type}")
    if not geometry.is_valid:
        geometry = shapely.make_valid(geometry)
    return _polygonal(geometry)


def _polygonal(geometry: BaseGeometry) -> BaseGeometry:
    # make_valid can leave collapsed edges as lines; they have no area and would make
    # the overlays mixed-dimensional, which GEOS refuses.
    if geometry.geom_type in ("Polygon", "MultiPolygon"):
        return geometry
    parts = [p for p in shapely.get_parts(geometry) if p.geom_type in ("Polygon", "MultiPolygon")]
    return shapely.union_all(parts, grid_size=OVERLAY_GRID) if parts else shapely.Polygon()


def evaluate_navigation(
    polygon: BaseGeometry | ArrayLike,
    scene: Scene,
    *,
    robot_radius: float | None = None,
    max_range: float,
    n_rays: int = DEFAULT_RAYS,
    obstacle_points: ArrayLike | None = None,
    exploration_points: ArrayLike | None = None,
    point_tolerance: float = 0.05,
) -> Evaluation:
    """Score a navigation polygon (robot frame, metres) against the scene's truth.

    Parameters
    ----------
    polygon
        The navigation polygon: a shapely (multi)polygon or a ``(K, 2)`` vertex array.
    scene
        The truth (as returned by :func:`occtool.simulate.simulate_scene`).
    robot_radius
        Robot radius used for the truth, metres (default: the scene robot's).
    max_range
        The navigation map's max range, metres.
    n_rays
        Resolution of the reachable-region sweep.
    obstacle_points, exploration_points
        Optional ``(K, 2)`` points of the navigation map (robot frame); only their
        directions are judged (see :class:`Evaluation`).
    point_tolerance
        Metres short of the max range that still count as reaching it.

    Returns
    -------
    Evaluation

    Examples
    --------
    >>> from occtool.simulate import build_scene
    >>> scene = build_scene("office")
    >>> truth = reachable_region(scene, max_range=1.0)
    >>> round(evaluate_navigation(truth, scene, max_range=1.0).iou, 6)
    1.0
    """
    radius = scene.robot.radius if robot_radius is None else float(robot_radius)
    geometry = as_polygon(polygon)
    truth = reachable_region(scene, robot_radius=radius, max_range=max_range, n_rays=n_rays)
    obstacles = configuration_obstacles(scene, robot_radius=radius)
    area = float(geometry.area)
    truth_area = float(truth.area)
    overlap = _overlap(geometry, truth)
    union = area + truth_area - overlap
    blocked = _overlap(geometry, obstacles)
    return Evaluation(
        iou=_share(overlap, union, empty=1.0),
        violation=_share(blocked, area, empty=0.0),
        area=area,
        truth_area=truth_area,
        coverage=_share(overlap, truth_area, empty=1.0 if area == 0 else 0.0),
        excess=_share(area - overlap, area, empty=0.0),
        robot_radius=radius,
        max_range=float(max_range),
        obstacle_accuracy=_point_accuracy(obstacle_points, scene, radius, max_range, point_tolerance, open_=False),
        exploration_accuracy=_point_accuracy(exploration_points, scene, radius, max_range, point_tolerance,
                                             open_=True),
    )


def blind_radius(obstacle: Obstacle, robot: Robot, *, tilt_range: tuple[float, float],
                 min_range: float = 0.0) -> float:
    """Horizontal distance (m) inside which no ray of the sensor reaches ``obstacle``'s part
    in the robot's body band: the blind zone of a sensor at ``robot.sensor_height`` whose
    rays leave at tilts in ``tilt_range`` (radians, 0 horizontal, negative down) and
    register nothing nearer than ``min_range`` metres.

    The part of the obstacle that blocks the body spans ``max(z_min, ground clearance)`` to
    ``min(z_max, body height)`` above the floor (sensor-frame heights ``low`` .. ``high``).
    A column of it at horizontal distance ``rho`` meets a ray of tilt ``t`` at height
    ``rho tan t``; some ray of the field of view meets it when ``high >= rho tan(t_min)``
    and ``low <= rho tan(t_max)``. (The stereo camera, tilts down to -50 degrees at 1 m:
    a pallet 0.15 m high is seen from 0.71 m, the floor's blocking layer from 0.80 m.)
    The minimum range is taken at the part's farthest height from the sensor, the
    smaller radius: occlusion by other obstacles is not considered, so what is called
    blind here no ray can see whatever else stands in the room.
    """
    low = max(obstacle.z_min, robot.ground_clearance) - robot.sensor_height
    high = min(obstacle.z_max, robot.body_height) - robot.sensor_height
    t_min, t_max = tilt_range
    radius = 0.0
    if high < 0.0:  # below the sensor: only rays tilted down reach it
        radius = high / math.tan(t_min) if t_min < 0.0 else math.inf
    if low > 0.0:  # above it: only rays tilted up
        radius = max(radius, low / math.tan(t_max) if t_max > 0.0 else math.inf)
    nearest_height = max(abs(low), abs(high))
    return max(radius, math.sqrt(max(0.0, min_range * min_range - nearest_height * nearest_height)))


def observable_footprints(scene: Scene, *, tilt_range: tuple[float, float],
                          min_range: float = 0.0) -> list[tuple[Obstacle, BaseGeometry]]:
    """Each blocking obstacle of ``scene`` with the part of its footprint the sensor can
    see in its body band (:func:`blind_radius`): the footprint less the disk of its blind
    radius around the sensor (empty when all of it lies inside)."""
    out = []
    for obstacle in blocking_obstacles(scene):
        radius = blind_radius(obstacle, scene.robot, tilt_range=tilt_range, min_range=min_range)
        polygon = obstacle.polygon
        if radius > 0.0:
            # 256 segments a quarter: the disk's chords cut inside the circle by < 20 um at 1 m,
            # so next to nothing blind is counted as seen.
            polygon = shapely.difference(polygon, _ORIGIN.buffer(radius, quad_segs=256), grid_size=OVERLAY_GRID) \
                if np.isfinite(radius) else shapely.Polygon()
        out.append((obstacle, polygon))
    return out


def violation_by_observability(
    polygon: BaseGeometry | ArrayLike,
    scene: Scene,
    *,
    tilt_range: tuple[float, float],
    min_range: float = 0.0,
    robot_radius: float | None = None,
) -> dict[str, float]:
    """The violation of :func:`evaluate_navigation` split by what the sensor could see.

    ``observable``: share of the polygon inside the C-space obstacles of the blocking
    obstacles' observable parts (:func:`observable_footprints`); ``unobservable``: the
    rest of the violation, in C-space only of parts inside the sensor's blind zone, which
    no ray of that sensor could have seen from where the robot stands (a map cannot know
    them). ``violation`` is their sum, the full violation. Shares of the polygon's area.
    """
    radius = scene.robot.radius if robot_radius is None else float(robot_radius)
    _check_nonnegative("robot radius", radius)
    geometry = as_polygon(polygon)
    area = float(geometry.area)
    obstacles = configuration_obstacles(scene, robot_radius=radius)
    seen = [part for _, part in observable_footprints(scene, tilt_range=tilt_range, min_range=min_range)
            if not part.is_empty]
    seen_space = shapely.union_all(shapely.buffer(np.asarray(seen, dtype=object), radius, quad_segs=_QUAD_SEGS),
                                   grid_size=OVERLAY_GRID) \
        if seen else shapely.Polygon()
    blocked = _overlap(geometry, obstacles)
    observable = _overlap(geometry, seen_space)
    return {"violation": _share(blocked, area, empty=0.0), "observable": _share(observable, area, empty=0.0),
            "unobservable": _share(max(blocked - observable, 0.0), area, empty=0.0)}


def _point_accuracy(points: ArrayLike | None, scene: Scene, radius: float, max_range: float, tolerance: float,
                    *, open_: bool) -> float | None:
    if points is None:
        return None
    xy = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if xy.shape[0] == 0:
        return None
    if not np.isfinite(xy).all():
        raise InputError("a navigation point has a NaN or infinite coordinate")
    _check_nonnegative("point tolerance", tolerance)
    reach = true_reach(scene, np.arctan2(xy[:, 1], xy[:, 0]), robot_radius=radius, max_range=max_range)
    reaches_range = reach >= max_range - tolerance
    return float(np.mean(reaches_range if open_ else ~reaches_range))


def _overlap(a: BaseGeometry, b: BaseGeometry) -> float:
    """Area of ``a`` ∩ ``b``, snap-rounded (see OVERLAY_GRID); 0 when either is empty."""
    if a.is_empty or b.is_empty:
        return 0.0
    return float(shapely.intersection(a, b, grid_size=OVERLAY_GRID).area)


def _share(part: float, whole: float, *, empty: float) -> float:
    # Overlay round-off can push a ratio a hair past its bounds.
    return min(1.0, max(0.0, part / whole)) if whole > 0 else empty


def robot_frame_points(points: ArrayLike, pose: Pose) -> FloatArray:
    """Move ``(K, 2)`` world-frame points into the robot frame of the robot at ``pose``."""
    xy = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    dx, dy = xy[:, 0] - pose.x, xy[:, 1] - pose.y
    return np.column_stack([c * dx + s * dy, -s * dx + c * dy])


def robot_frame_polygon(polygon: BaseGeometry, pose: Pose) -> BaseGeometry:
    """Move a polygon from a world frame back into the robot frame of the robot at ``pose``."""
    return shapely.transform(polygon, lambda xy: robot_frame_points(xy, pose))


def returns_within_body(
    features: Features, polygon: BaseGeometry, robot: Robot, level: float = 0.6
) -> NDArray[np.bool_]:
    """Which returns of a position's own data the robot's body would touch somewhere in its polygon.

    A return (evidence at or above ``level``, inside the body's height band, beyond the
    robot's current footprint: :func:`occtool.guard.guard_candidates`) lying closer than
    the robot's radius to the navigation polygon (robot frame, metres). The same-scan
    safety check of real logs, where there is no other truth; ``False`` everywhere for an
    empty polygon.
    """
    returns = guard_candidates(features, features.evidence, robot, level)
    touched = np.zeros(len(features), dtype=bool)
    if polygon.is_empty or not returns.any():
        return touched
    distance = shapely.distance(polygon, shapely.points(features.points[returns, :2]))
    touched[np.flatnonzero(returns)] = distance < robot.radius * (1 - 1e-9)
    return touched


__all__ = [
    "Evaluation",
    "as_polygon",
    "blind_radius",
    "blocking_obstacles",
    "configuration_obstacles",
    "evaluate_navigation",
    "observable_footprints",
    "reachable_region",
    "returns_within_body",
    "robot_frame_points",
    "robot_frame_polygon",
    "true_reach",
    "violation_by_observability",
]
