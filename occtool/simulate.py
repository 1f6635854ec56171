"""Synthetic scenes with their ground truth, seen by a simulated stereo camera.

A :class:`Scene` is a set of vertical prisms (a 2D footprint polygon extruded from
``z_min`` to ``z_max`` above the floor): walls, boxes, a table top on thin legs, a low
pallet. The robot stands at the origin facing +x (REP-103); the scene's x, y are
sensor-centred, its z is measured up from the floor. :func:`simulate_scene` casts the
rays of a stereo camera on a pan-tilt unit at the sensor against the prisms and the
floor and returns the registered :class:`~occtool.features.Features` (sensor frame,
z relative to the sensor) together with the scene, which is the truth that
:mod:`occtool.evaluate` scores navigation polygons against.

The camera model, the scenes and the truth file format are described in
``docs/scenes.md``.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from occtool.errors import InputError
from occtool.features import Features
from occtool.io._atomic import atomic_write
from occtool.limits import MAX_DISTANCE, MAX_FEATURES, MAX_RANGE_NOISE
from occtool.robot import Robot

FloatArray = NDArray[np.float64]

TRUTH_FORMAT = "occtool-scene-truth"
TRUTH_VERSION = 1

#: Pan-tilt limits of the simulated camera, radians (tilt 0 is horizontal, negative looks down).
TILT_RANGE: tuple[float, float] = (math.radians(-50.0), math.radians(30.0))
#: Default stereo depth noise coefficient: sigma(r) = range_noise * r**2 metres.
DEFAULT_RANGE_NOISE = 0.01
#: Farthest range at which the stereo matcher still registers a feature, metres.
DEFAULT_SENSOR_RANGE = 6.0
#: Nearest range of the stereo matcher (the cameras' overlap starts here), metres.
MIN_SENSOR_RANGE = 0.2

# Index marking a ray that hit the floor or nothing at all in :func:`cast_rays`.
FLOOR = -1
NOTHING = -2


@dataclass(frozen=True)
class Obstacle:
    """A vertical prism: a footprint polygon extruded between two heights above the floor.

    Parameters
    ----------
    name
        A label for reports ("wall north", "table top").
    footprint
        The polygon's vertices ``((x, y), ...)`` in metres, robot frame, not closed.
    z_min, z_max
        Bottom and top of the prism above the floor, metres.
    textured
        Whether the stereo camera finds features on it. Untextured surfaces (white
        walls, glass) still block rays and the robot but register nothing.
    """

    name: str
    footprint: tuple[tuple[float, float], ...]
    z_min: float
    z_max: float
    textured: bool = True

    def __post_init__(self) -> None:
        try:
            coords = tuple((float(x), float(y)) for x, y in self.footprint)
        except (TypeError, ValueError):
            raise InputError(f"obstacle {self.name!r}: footprint must be a list of [x, y] pairs") from None
        if len(coords) > 3 and coords[0] == coords[-1]:
            coords = coords[:-1]
        if len(coords) < 3:
            raise InputError(f"obstacle {self.name!r}: footprint needs at least 3 vertices, got {len(coords)}")
        if not np.isfinite(np.asarray(coords)).all():
            raise InputError(f"obstacle {self.name!r}: footprint has a NaN or infinite coordinate")
        z_min, z_max = float(self.z_min), float(self.z_max)
        if not (np.isfinite(z_min) and np.isfinite(z_max)) or z_min < 0.0 or z_max <= z_min:
            raise InputError(
                f"obstacle {self.name!r}: need 0 <= z_min < z_max (finite), got z_min={z_min}, z_max={z_max}"
            )
        polygon = shapely.Polygon(coords)
        if not polygon.is_valid or polygon.area <= 0.0:
            raise InputError(f"obstacle {self.name!r}: footprint is not a simple polygon with positive area")
        object.__setattr__(self, "footprint", coords)
        object.__setattr__(self, "z_min", z_min)
        object.__setattr__(self, "z_max", z_max)
        object.__setattr__(self, "textured", bool(self.textured))

    @property
    def polygon(self) -> shapely.Polygon:
        """The footprint as a shapely polygon."""
        return shapely.Polygon(self.footprint)

    def rotated(self, yaw: float) -> Obstacle:
        """The obstacle turned by ``yaw`` radians about the vertical axis through the origin."""
        c, s = math.cos(yaw), math.sin(yaw)
        turned = tuple((c * x - s * y, s * x + c * y) for x, y in self.footprint)
        return replace(self, footprint=turned)

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "footprint": [[x, y] for x, y in self.footprint],
            "z_min": self.z_min,
            "z_max": self.z_max,
            "textured": self.textured,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Obstacle:
        if not isinstance(data, Mapping):
            raise InputError("an obstacle must be a JSON object")
        missing = [k for k in ("footprint", "z_min", "z_max") if k not in data]
        if missing:
            raise InputError(f"obstacle {data.get('name', '?')!r} lacks {', '.join(missing)}")
        try:
            return cls(
                name=str(data.get("name", "")),
                footprint=tuple(tuple(p) for p in data["footprint"]),
                z_min=float(data["z_min"]),
                z_max=float(data["z_max"]),
                textured=bool(data.get("textured", True)),
            )
        except (TypeError, ValueError) as exc:
            if isinstance(exc, InputError):
                raise
            raise InputError(f"obstacle {data.get('name', '?')!r}: {exc}") from None


def box(name: str, x0: float, y0: float, x1: float, y1: float, z_min: float, z_max: float, *,
        textured: bool = True) -> Obstacle:
    """An axis-aligned box from corner ``(x0, y0)`` to ``(x1, y1)`` between two heights."""
    xa, xb = sorted((x0, x1))
    ya, yb = sorted((y0, y1))
    return Obstacle(name, ((xa, ya), (xb, ya), (xb, yb), (xa, yb)), z_min, z_max, textured)


@dataclass(frozen=True)
class Scene:
    """A synthetic environment around the robot: its ground truth.

    Parameters
    ----------
    obstacles
        The prisms; x, y in the sensor-centred robot frame, z above the floor.
    robot
        The robot standing at the origin (its sensor height places the camera).
    name, description
        What the scene is, for reports.
    """

    obstacles: tuple[Obstacle, ...]
    robot: Robot = field(default_factory=Robot)
    name: str = ""
    description: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "obstacles", tuple(self.obstacles))

    def rotated(self, yaw: float) -> Scene:
        """The scene turned by ``yaw`` radians (counter-clockwise seen from above) about the robot."""
        return replace(self, obstacles=tuple(o.rotated(yaw) for o in self.obstacles))

    def with_robot(self, robot: Robot) -> Scene:
        """The same obstacles around a different robot."""
        return replace(self, robot=robot)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready description (the truth file's content)."""
        return {
            "format": TRUTH_FORMAT,
            "version": TRUTH_VERSION,
            "frame_id": "base_link",
            "units": "m",
            "z_reference": "floor",
            "name": self.name,
            "description": self.description,
            "robot": {
                "radius": self.robot.radius,
                "sensor_height": self.robot.sensor_height,
                "body_height": self.robot.body_height,
                "ground_clearance": self.robot.ground_clearance,
            },
            "obstacles": [o.to_dict() for o in self.obstacles],
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Scene:
        """Rebuild a scene from :meth:`to_dict` output; :class:`InputError` if it is malformed."""
        if not isinstance(data, Mapping):
            raise InputError("a scene truth must be a JSON object")
        if data.get("format") != TRUTH_FORMAT:
            raise InputError(f"not a scene truth file (format is {data.get('format')!r}, expected {TRUTH_FORMAT!r})")
        version = data.get("version")
        if not isinstance(version, int) or version > TRUTH_VERSION or version < 1:
            raise InputError(f"unsupported scene truth version {version!r} (this occtool reads 1..{TRUTH_VERSION})")
        if data.get("units", "m") != "m":
            raise InputError(f"scene truth units must be 'm', got {data.get('units')!r}")
        robot_data = data.get("robot", {})
        if not isinstance(robot_data, Mapping):
            raise InputError("scene truth 'robot' must be an object")
        try:
            robot = Robot(**{k: float(robot_data[k]) for k in
                             ("radius", "sensor_height", "body_height", "ground_clearance") if k in robot_data})
        except (TypeError, ValueError) as exc:
            if isinstance(exc, InputError):
                raise
            raise InputError(f"scene truth robot: {exc}") from None
        obstacles = data.get("obstacles")
        if not isinstance(obstacles, list):
            raise InputError("scene truth needs an 'obstacles' list")
        return cls(
            obstacles=tuple(Obstacle.from_dict(o) for o in obstacles),
            robot=robot,
            name=str(data.get("name", "")),
            description=str(data.get("description", "")),
        )

    def save_truth(self, path: str | os.PathLike[str]) -> None:
        """Write the scene as a truth JSON file (atomically: complete or absent)."""
        with atomic_write(path, "w") as handle:
            json.dump(self.to_dict(), handle, indent=1)
            handle.write("\n")


def load_truth(path: str | os.PathLike[str]) -> Scene:
    """Read a truth file written by :meth:`Scene.save_truth`.

    Raises
    ------
    InputError
        If the file is not JSON or not a valid scene truth; the message names the file.
    """
    from occtool.io.json import read_json

    data = read_json(path, error=InputError)
    try:
        return Scene.from_dict(data)
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None


# --- the scenes ----------------------------------------------------------------------

WALL_HEIGHT = 2.5
WALL_THICKNESS = 0.1


def _wall(name: str, x0: float, y0: float, x1: float, y1: float, *, textured: bool = True) -> Obstacle:
    """A wall whose inner face runs along the given axis-aligned segment, thickened outward."""
    t = WALL_THICKNESS
    if y0 == y1:  # along x: thicken away from the origin
        side = t if y0 > 0 else -t
        return box(name, x0, y0, x1, y0 + side, 0.0, WALL_HEIGHT, textured=textured)
    side = t if x0 > 0 else -t
    return box(name, x0, y0, x0 + side, y1, 0.0, WALL_HEIGHT, textured=textured)


def _table(x0: float, y0: float, x1: float, y1: float, top_z: float = 0.70, thickness: float = 0.05,
           leg: float = 0.04) -> list[Obstacle]:
    """A table: a thin top and four thin legs reaching to the floor."""
    parts = [box("table top", x0, y0, x1, y1, top_z, top_z + thickness)]
    inset = 0.05
    for i, (lx, ly) in enumerate([(x0 + inset, y0 + inset), (x1 - inset - leg, y0 + inset),
                                  (x1 - inset - leg, y1 - inset - leg), (x0 + inset, y1 - inset - leg)]):
        parts.append(box(f"table leg {i + 1}", lx, ly, lx + leg, ly + leg, 0.0, top_z))
    return parts


def _office() -> list[Obstacle]:
    # Room interior x in [-1.5, 3.5] (5 m), y in [-2.8, 1.2] (4 m). The 1 m doorway in the
    # left wall (y = 1.2, x in [-0.3, 0.7]) leads into open space with nothing in sensor
    # range; with a 0.25 m radius it leaves a 0.5 m channel in configuration space.
    return [
        _wall("wall back", -1.5, -2.9, -1.5, 1.3),
        _wall("wall front", 3.5, -2.9, 3.5, 1.3),
        _wall("wall right", -1.6, -2.8, 3.6, -2.8),
        _wall("wall left (behind door)", -1.6, 1.2, -0.3, 1.2),
        _wall("wall left (ahead of door)", 0.7, 1.2, 3.6, 1.2),
        box("door lintel", -0.3, 1.2, 0.7, 1.3, 2.1, WALL_HEIGHT),
        box("box large", 1.6, -1.8, 2.2, -1.2, 0.0, 0.8),
        box("box small", -1.2, 0.3, -0.8, 0.8, 0.0, 0.5),
        box("pallet", -0.9, -1.5, -0.1, -0.9, 0.0, 0.15),
        box("cable cover", 0.3, -0.75, 1.3, -0.65, 0.0, 0.03),
        *_table(0.9, -0.2, 2.1, 0.6),
    ]


def _corridor() -> list[Obstacle]:
    # A 2 m wide corridor along x; an opening 1 m wide on the left at x in [0.8, 1.8]
    # into a side room; the corridor ends in a wall 4.5 m ahead.
    return [
        _wall("wall right", -7.0, -1.0, 4.6, -1.0),
        _wall("wall left (behind opening)", -7.0, 1.0, 0.8, 1.0),
        _wall("wall left (beyond opening)", 1.8, 1.0, 4.6, 1.0),
        _wall("wall end", 4.5, -1.1, 4.5, 1.1),
        _wall("side room far wall", -0.5, 3.5, 3.5, 3.5),
        box("side room wall west", 0.7, 1.0, 0.8, 3.6, 0.0, WALL_HEIGHT),
        box("side room wall east", 1.8, 1.0, 1.9, 3.6, 0.0, WALL_HEIGHT),
        box("bin", 2.6, -0.95, 2.95, -0.6, 0.0, 0.6),
        box("radiator", -2.0, 0.88, -1.0, 1.0, 0.15, 0.75),
    ]


def _clutter() -> list[Obstacle]:
    # A storage room crowded with boxes of many heights, some hanging shelves and
    # objects below the ground clearance, so that straight-line reachability matters.
    return [
        _wall("wall back", -3.0, -3.1, -3.0, 3.1),
        _wall("wall front", 3.0, -3.1, 3.0, 3.1),
        _wall("wall right", -3.1, -3.0, 3.1, -3.0),
        _wall("wall left", -3.1, 3.0, 3.1, 3.0),
        box("crate 1", 0.7, -0.3, 1.1, 0.2, 0.0, 0.4),
        box("crate 2", 1.6, 0.6, 2.1, 1.3, 0.0, 1.2),
        box("crate 3", -0.9, 0.8, -0.4, 1.2, 0.0, 0.25),
        box("crate 4", -1.8, -1.2, -1.2, -0.5, 0.0, 0.9),
        box("crate 5", 0.3, -1.6, 0.9, -1.1, 0.0, 0.6),
        Obstacle("barrel", tuple((-0.2 + 0.25 * math.cos(a), 1.9 + 0.25 * math.sin(a))
                                 for a in np.linspace(0, 2 * math.pi, 16, endpoint=False)), 0.0, 0.9),
        box("wall shelf", 2.4, -2.0, 3.0, -0.4, 0.55, 0.6),
        box("hanging lamp", -0.6, -0.6, -0.4, -0.4, 0.85, 1.9),
        box("rug", -2.0, 0.5, -1.2, 2.0, 0.0, 0.02),
        box("cable", -0.2, 0.5, 1.4, 0.55, 0.0, 0.03),
        box("pipe overhead", -3.0, 2.2, 3.0, 2.4, 1.6, 1.8),
    ]


def _open() -> list[Obstacle]:
    # A hall larger than the sensor range: nothing textured in most directions but the
    # floor, one white (untextured) wall that blocks without features, a pillar and a bench.
    return [
        _wall("white wall", 1.4, -3.0, 1.4, 3.0, textured=False),
        Obstacle("pillar", tuple((-1.2 + 0.2 * math.cos(a), -1.0 + 0.2 * math.sin(a))
                                 for a in np.linspace(0, 2 * math.pi, 12, endpoint=False)), 0.0, WALL_HEIGHT),
        box("bench", -0.6, 1.2, 0.6, 1.6, 0.0, 0.45),
    ]


def _aisle() -> list[Obstacle]:
    # A 1.1 m aisle along x between two rows of shelves (to 2 m), each row broken by a
    # narrow gap (0.5 m on the left, 0.6 m on the right: the robot's diameter and a
    # little more, no passage once shrunk but area in front of them to keep). A beam sticks
    # out of the right row 0.3 m above the floor into the aisle; a sign hangs across the
    # aisle from 0.9 m, into the body's height; the aisle ends in a wall 4 m ahead.
    return [
        box("shelf left (behind gap)", -3.5, 0.55, 1.0, 1.15, 0.0, 2.0),
        box("shelf left (beyond gap)", 1.5, 0.55, 4.1, 1.15, 0.0, 2.0),
        box("shelf right (behind gap)", -3.5, -1.15, -0.4, -0.55, 0.0, 2.0),
        box("shelf right (beyond gap)", 0.2, -1.15, 4.1, -0.55, 0.0, 2.0),
        _wall("wall end", 4.0, -1.2, 4.0, 1.2),
        _wall("wall back", -3.5, -1.2, -3.5, 1.2),
        box("beam", 1.9, -0.55, 2.0, -0.25, 0.25, 0.35),
        box("sign", -1.3, -0.4, -1.25, 0.4, 0.9, 1.3),
    ]


def _chair(name: str, x: float, y: float, yaw: float) -> list[Obstacle]:
    """A chair: four 3 cm legs, a 0.45 m seat 3 cm thick at 0.45 m, a thin back to 0.9 m."""
    size, leg, seat_z = 0.45, 0.03, 0.45
    c, s = math.cos(yaw), math.sin(yaw)

    def placed(x0: float, y0: float, x1: float, y1: float) -> tuple[tuple[float, float], ...]:
        corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
        return tuple((x + c * u - s * v, y + s * u + c * v) for u, v in corners)

    half = size / 2.0
    parts = [Obstacle(f"{name} seat", placed(-half, -half, half, half), seat_z - 0.03, seat_z)]
    for i, (u, v) in enumerate([(-half, -half), (half - leg, -half), (half - leg, half - leg), (-half, half - leg)]):
        parts.append(Obstacle(f"{name} leg {i + 1}", placed(u, v, u + leg, v + leg), 0.0, seat_z - 0.03))
    parts.append(Obstacle(f"{name} back", placed(-half, half - leg, half, half), seat_z, 0.9))
    return parts


def _chairs() -> list[Obstacle]:
    # A 5 x 5 m room with three chairs close around the robot: 3 cm legs that one or two
    # rays meet, seats at 0.45 m that the body cannot pass under.
    return [
        _wall("wall back", -2.0, -2.6, -2.0, 2.6),
        _wall("wall front", 3.0, -2.6, 3.0, 2.6),
        _wall("wall right", -2.1, -2.5, 3.1, -2.5),
        _wall("wall left", -2.1, 2.5, 3.1, 2.5),
        *_chair("chair 1", 1.0, 0.3, 0.2),
        *_chair("chair 2", -0.4, 1.1, 1.9),
        *_chair("chair 3", 0.2, -1.2, -0.6),
    ]


def _hall() -> list[Obstacle]:
    # An open hall: textured walls beyond the sensor's range (nothing but the floor seen
    # there), and two rows of 0.3 m pillars 1.6 m apart, the nearest 0.9 m away.
    pillars = []
    for i, (x, y) in enumerate([(0.9, 0.8), (0.9, -0.8), (2.5, 0.8), (2.5, -0.8), (-0.7, 0.8), (-0.7, -0.8),
                                (-2.3, 0.8), (-2.3, -0.8)]):
        pillars.append(box(f"pillar {i + 1}", x - 0.15, y - 0.15, x + 0.15, y + 0.15, 0.0, WALL_HEIGHT))
    return [
        *pillars,
        _wall("wall far ahead", 8.0, -8.0, 8.0, 8.0),
        _wall("wall far behind", -8.0, -8.0, -8.0, 8.0),
    ]


_BUILDERS: dict[str, Callable[[], list[Obstacle]]] = {
    "office": _office,
    "corridor": _corridor,
    "clutter": _clutter,
    "open": _open,
    "aisle": _aisle,
    "chairs": _chairs,
    "hall": _hall,
}

#: The built-in scenes: name -> description.
SCENES: dict[str, str] = {
    "office": (
        "A 5 x 4 m room: walls 1.5 m behind and 3.5 m ahead, a 1 m doorway 1.2 m to the left opening "
        "onto empty space, a table (5 cm top at 0.70 m on thin legs) 0.9 m ahead, boxes, a 15 cm "
        "pallet behind right and a 3 cm cable cover that the robot drives over."
    ),
    "corridor": (
        "A 2 m wide corridor ending 4.5 m ahead, with a 1 m opening on the left into a side room, "
        "a bin and a wall-mounted radiator (0.15-0.75 m)."
    ),
    "clutter": (
        "A 6 x 6 m storage room crowded with crates of many heights, a barrel, a wall shelf and a "
        "hanging lamp (overhangs), a rug and a cable under the ground clearance."
    ),
    "open": (
        "An open hall beyond sensor range in most directions (only the floor has features there), "
        "an untextured white wall 1.4 m ahead, a pillar and a low bench."
    ),
    "aisle": (
        "A 1.1 m aisle between rows of shelves with narrow gaps (0.5 and 0.6 m), a beam sticking out "
        "0.3 m above the floor and a sign hanging across the aisle from 0.9 m."
    ),
    "chairs": (
        "A 5 x 5 m room with three chairs around the robot: 3 cm legs, seats at 0.45 m, thin backs to 0.9 m."
    ),
    "hall": (
        "An open hall with walls beyond the sensor's range and two rows of 0.3 m pillars 1.6 m apart, "
        "the nearest 0.9 m away."
    ),
}


def build_scene(name: str, *, robot: Robot | None = None, yaw: float = 0.0) -> Scene:
    """The built-in scene ``name`` (see :data:`SCENES`) around ``robot``, turned by ``yaw``.

    Raises
    ------
    InputError
        If there is no scene of that name.
    """
    if name not in _BUILDERS:
        raise InputError(f"unknown scene {name!r}: choose one of {', '.join(SCENES)}")
    scene = Scene(tuple(_BUILDERS[name]()), robot or Robot(), name, SCENES[name])
    return scene.rotated(yaw) if yaw else scene


# --- ray casting ---------------------------------------------------------------------

def _cross(ax: FloatArray | float, ay: FloatArray | float, bx: FloatArray | float,
           by: FloatArray | float) -> FloatArray:
    return ax * by - ay * bx  # type: ignore[return-value]  # an array whenever one argument is


def cast_rays(
    scene: Scene, directions: ArrayLike, *, max_range: float = np.inf
) -> tuple[FloatArray, NDArray[np.int64]]:
    """Cast rays from the sensor against the scene's prisms and the floor.

    Parameters
    ----------
    scene
        The scene; the sensor sits at ``scene.robot.sensor_height`` above the floor at x = y = 0.
    directions
        ``(N, 3)`` ray directions in the sensor frame (need not be unit length).
    max_range
        Rays hitting nothing closer than this report ``inf``.

    Returns
    -------
    ranges
        ``(N,)`` distance from the sensor to the first surface along each unit ray, or ``inf``.
    surface
        ``(N,)`` index into ``scene.obstacles`` of the surface hit, :data:`FLOOR` (-1) for the
        floor, :data:`NOTHING` (-2) when nothing is hit within ``max_range``.
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    norm = np.linalg.norm(d, axis=1)
    if not (np.isfinite(norm) & (norm > 0)).all():
        raise InputError("every ray direction must be a finite, non-zero vector")
    d = d / norm[:, None]
    height = scene.robot.sensor_height
    n = d.shape[0]
    best = np.full(n, np.inf)
    surface = np.full(n, NOTHING, dtype=np.int64)
    eps = 1e-12

    with np.errstate(divide="ignore", invalid="ignore"):
        floor_t = np.where(d[:, 2] < -eps, -height / d[:, 2], np.inf)
    hit = floor_t < best
    best[hit], surface[hit] = floor_t[hit], FLOOR

    for index, obstacle in enumerate(scene.obstacles):
        z_lo, z_hi = obstacle.z_min - height, obstacle.z_max - height  # sensor frame
        vertices = np.asarray(obstacle.footprint)
        edges = np.roll(vertices, -1, axis=0) - vertices
        # Side faces: solve t * d_xy = a + u * e (a vertex, e its edge) for the range t and
        # the edge fraction u, for all rays at once.
        for (ax, ay), (ex, ey) in zip(vertices, edges):
            denom = _cross(d[:, 0], d[:, 1], ex, ey)
            with np.errstate(divide="ignore", invalid="ignore"):
                t = _cross(ax, ay, ex, ey) / denom
                u = _cross(ax, ay, d[:, 0], d[:, 1]) / denom
                z = t * d[:, 2]
            ok = (np.abs(denom) > eps) & (t > eps) & (u >= 0.0) & (u <= 1.0) & (z >= z_lo) & (z <= z_hi) & (t < best)
            best[ok], surface[ok] = t[ok], index
        # Top and bottom caps: horizontal polygons at z_hi and z_lo.
        polygon = obstacle.polygon
        shapely.prepare(polygon)
        for z_cap in (z_hi, z_lo):
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(np.abs(d[:, 2]) > eps, z_cap / d[:, 2], np.inf)
            candidate = (t > eps) & (t < best)
            if not candidate.any():
                continue
            idx = np.flatnonzero(candidate)
            inside = shapely.contains_xy(polygon, t[idx] * d[idx, 0], t[idx] * d[idx, 1])
            idx = idx[inside]
            best[idx], surface[idx] = t[idx], index

    beyond = best > max_range
    best[beyond], surface[beyond] = np.inf, NOTHING
    return best, surface


def camera_directions(n: int, rng: np.random.Generator) -> FloatArray:
    """``n`` view directions of the pan-tilt camera: pan uniform over 360 degrees, tilt in :data:`TILT_RANGE`."""
    pan = rng.uniform(-math.pi, math.pi, n)
    tilt = rng.uniform(TILT_RANGE[0], TILT_RANGE[1], n)
    c = np.cos(tilt)
    return np.column_stack([c * np.cos(pan), c * np.sin(pan), np.sin(tilt)])


def match_evidence(ranges: FloatArray, rng: np.random.Generator) -> FloatArray:
    """Evidence from a simulated stereo match error: mostly 0.7..1.0, a little lower far away."""
    error = 0.15 * np.abs(rng.standard_normal(ranges.shape[0])) + 0.02 * ranges
    return np.clip(1.0 - error, 0.05, 1.0)


def simulate_scene(
    name: str | Scene,
    *,
    n_features: int = 10000,
    seed: int = 0,
    range_noise: float = DEFAULT_RANGE_NOISE,
    outlier_rate: float = 0.05,
    robot: Robot | None = None,
    yaw: float = 0.0,
    sensor_range: float = DEFAULT_SENSOR_RANGE,
) -> tuple[Features, Scene]:
    """Register features in a scene with a simulated pan-tilt stereo camera.

    The camera at the sensor looks in directions drawn uniformly in pan (360 degrees) and
    tilt (:data:`TILT_RANGE`); a view direction whose ray meets a textured surface (the
    floor included) within ``sensor_range`` yields one feature. Its range carries
    Gaussian stereo noise with standard deviation ``range_noise * r**2``; a share
    ``outlier_rate`` of the features are mismatches placed at a range uniform in
    [0.2 m, ``sensor_range``] along the same ray. Evidence comes from a simulated match
    error (see :func:`match_evidence`), outliers included.

    Parameters
    ----------
    name
        A scene name from :data:`SCENES`, or a :class:`Scene`.
    n_features
        Number of features to register.
    seed
        Random seed; the result is a function of all arguments.
    range_noise
        Stereo noise coefficient, metres per square metre of range.
    outlier_rate
        Share of features at a wrong range, in [0, 1].
    robot
        The robot (sensor height, body); default ``Robot()`` or the given scene's robot.
    yaw
        Turn the whole scene, features and truth alike, by this many radians.
    sensor_range
        Farthest range at which features are registered, metres.

    Returns
    -------
    features
        The registered features, sensor-centred robot frame.
    scene
        The truth: the scene as simulated, turned by ``yaw``.

    Examples
    --------
    >>> features, scene = simulate_scene("office", n_features=500, seed=1)
    >>> len(features), scene.name
    (500, 'office')
    """
    if isinstance(name, Scene):
        scene = name if robot is None else name.with_robot(robot)
    else:
        scene = build_scene(name, robot=robot)
    if not isinstance(n_features, (int, np.integer)) or n_features < 0:
        raise InputError(f"the number of features must be a whole number >= 0, got {n_features!r}")
    if n_features > MAX_FEATURES:
        raise InputError(f"n_features must be at most {MAX_FEATURES:,}, got {n_features:,}")
    if not (np.isfinite(range_noise) and range_noise >= 0):
        raise InputError(f"range noise must be a finite number >= 0, got {range_noise}")
    if range_noise > MAX_RANGE_NOISE:
        raise InputError(f"range_noise must be at most {MAX_RANGE_NOISE:g} (per metre squared), got {range_noise:g}")
    if not 0.0 <= outlier_rate <= 1.0:
        raise InputError(f"outlier rate must lie in [0, 1], got {outlier_rate}")
    if not (np.isfinite(sensor_range) and sensor_range > MIN_SENSOR_RANGE):
        raise InputError(f"sensor range must be a finite number > {MIN_SENSOR_RANGE} m, got {sensor_range}")
    if sensor_range > MAX_DISTANCE:
        raise InputError(f"sensor_range must be at most {MAX_DISTANCE:g} m, got {sensor_range:g}")
    if not np.isfinite(yaw):
        raise InputError(f"yaw must be finite, got {yaw}")

    rng = np.random.default_rng(seed)
    textured = np.array([o.textured for o in scene.obstacles] + [True], dtype=bool)  # last: floor
    found_dirs: list[FloatArray] = []
    found_ranges: list[FloatArray] = []
    have = 0
    batch = max(64, int(n_features * 1.5))
    for _ in range(200):
        if have >= n_features:
            break
        dirs = camera_directions(batch, rng)
        ranges, surface = cast_rays(scene, dirs, max_range=sensor_range)
        seen = (surface != NOTHING) & (ranges >= MIN_SENSOR_RANGE)
        seen &= textured[np.where(surface == FLOOR, -1, surface)]
        found_dirs.append(dirs[seen])
        found_ranges.append(ranges[seen])
        have += int(seen.sum())
        rate = max(seen.mean(), 0.01)
        batch = max(64, int((n_features - have) / rate * 1.2))
    if have < n_features:
        raise InputError(f"scene {scene.name!r} shows too few textured surfaces to register {n_features} features")
    dirs = np.concatenate([np.empty((0, 3)), *found_dirs])[:n_features]
    true_range = np.concatenate([np.empty(0), *found_ranges])[:n_features]

    measured = true_range + rng.standard_normal(n_features) * range_noise * true_range**2
    outlier = rng.random(n_features) < outlier_rate
    measured[outlier] = rng.uniform(MIN_SENSOR_RANGE, sensor_range, int(outlier.sum()))
    measured = np.maximum(measured, 0.5 * MIN_SENSOR_RANGE)
    evidence = match_evidence(true_range, rng)
    features = Features(dirs * measured[:, None], evidence)
    if yaw:
        return features.rotated(yaw), scene.rotated(yaw)
    return features, scene


def save_features_csv(features: Features, path: str | os.PathLike[str], comments: Sequence[str] = ()) -> None:
    """Write features as CSV with header ``x,y,z,m`` after ``#`` comment lines (atomically).

    Coordinates to 0.1 mm and evidence to 3 decimals: :func:`occtool.io.csv.write_csv`
    with ``decimals=(4, 3)``.
    """
    from occtool.io.csv import write_csv

    write_csv(features, path, comments=comments, decimals=(4, 3))


__all__ = [
    "FLOOR",
    "NOTHING",
    "SCENES",
    "TILT_RANGE",
    "Obstacle",
    "Scene",
    "box",
    "build_scene",
    "camera_directions",
    "cast_rays",
    "load_truth",
    "match_evidence",
    "save_features_csv",
    "simulate_scene",
]
