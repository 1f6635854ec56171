"""The built-in scenes' names and descriptions, in a module without numpy: the command
line lists them in ``occtool simulate --help`` (a cold start), and
:func:`occtool.simulate.build_scene` builds them (:mod:`occtool.simulate._catalogue`)."""

from __future__ import annotations

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

__all__ = ["SCENES"]
