"""occtool: parametric occupancy models and navigation maps from robot range data.

Data flows one way::

    log -> Features -> samples (sensor model) -> MinMaxTree (fit) -> inverse
        -> navigation polygon, obstacle and exploration points -> GeoJSON

Coordinates follow ROS REP-103 (x forward, y left, z up; metres, radians). Features
are expressed in the robot frame centred at the sensor: pan angle ``alpha =
atan2(y, x)``, height ``h = z`` and range ``r = |p|``.
"""

from __future__ import annotations

__version__ = "0.1.0"

from occtool.errors import (  # noqa: F401
    InputError,
    MissingDependencyError,
    ModelFormatError,
    NotFittedError,
    OcctoolError,
)
from occtool.features import Features, Pose, Position, RangeLog  # noqa: F401
