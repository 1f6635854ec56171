"""The catalogue of built-in scenes: :data:`SCENES` and :func:`build_scene`."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from occtool.errors import InputError
from occtool.robot import Robot
from occtool.simulate._names import SCENES
from occtool.simulate._scene import Obstacle, Scene, box

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
