"""Scene geometry: :class:`Obstacle` prisms, the :class:`Scene` around the robot, truth files."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import shapely

from occtool._files import atomic_write
from occtool.errors import InputError
from occtool.robot import Robot

TRUTH_FORMAT = "occtool-scene-truth"
TRUTH_VERSION = 1


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
    from occtool._json import read_json

    data = read_json(path, error=InputError)
    try:
        return Scene.from_dict(data)
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None
