"""The robot's body, as the navigation map and the evaluation see it.

Heights here are given above the floor, as a user measures them; the sensor-frame
heights the model works in (``h``, z relative to the sensor centre) follow from
``sensor_height``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from occtool.errors import InputError
from occtool.limits import MAX_ROBOT_SIZE

#: Defaults for a planar (2D) laser scanner, as in CARMEN logs: such a laser sits low on
#: a small robot, and its plane must lie inside the body band, not at its top edge as with
#: the general defaults (sensor 1 m up, body 1 m tall).
PLANAR_LASER_SENSOR_HEIGHT = 0.3
PLANAR_LASER_BODY_HEIGHT = 0.5


@dataclass(frozen=True)
class Robot:
    """A cylindrical robot carrying its range sensor.

    Parameters
    ----------
    radius
        Radius of the robot's footprint, metres. The navigation polygon is shrunk by it.
    sensor_height
        Height of the sensor centre (pan-tilt unit) above the floor, metres.
    body_height
        Height of the top of the robot above the floor, metres.
    ground_clearance
        Obstacles lower than this above the floor are driven over (floor texture, cables),
        metres. Anything taller, a pallet 15 cm high say, blocks the robot.
    """

    radius: float = 0.25
    sensor_height: float = 1.0
    body_height: float = 1.0
    ground_clearance: float = 0.05

    def __post_init__(self) -> None:
        for name in ("radius", "sensor_height", "body_height", "ground_clearance"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise InputError(f"robot {name.replace('_', ' ')} must be a finite number >= 0, got {value}")
            if value > MAX_ROBOT_SIZE:
                raise InputError(f"robot {name} must lie in [0, {MAX_ROBOT_SIZE:g}] metres, got {value:g}")
        if self.body_height <= self.ground_clearance:
            raise InputError(
                f"body height {self.body_height} m must exceed the ground clearance {self.ground_clearance} m"
            )

    @property
    def floor_h(self) -> float:
        """The floor's height in the sensor frame (negative: below the sensor)."""
        return -self.sensor_height

    @property
    def body_band(self) -> tuple[float, float]:
        """Lowest and highest sensor-frame height the body occupies (above the clearance)."""
        return (self.ground_clearance - self.sensor_height, self.body_height - self.sensor_height)
