"""occtool: parametric occupancy models and navigation maps from robot range data.

Data flows one way::

    log -> Features -> samples (sensor model) -> MinMaxTree (fit) -> inverse
        -> navigation polygon, obstacle and exploration points -> GeoJSON

Coordinates follow ROS REP-103 (x forward, y left, z up; metres, radians). Features
are expressed in the robot frame centred at the sensor: pan angle ``alpha =
atan2(y, x)``, height ``h = z`` and range ``r = |p|``.

The names below are the library's front door; each is imported on first use (PEP 562),
so ``import occtool`` (and ``occtool --help``) loads neither numpy nor scipy::

    from occtool import OccupancyRegressor, navigation_map, read_log, load_model, save_model
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from occtool._lazy import lazy_attributes
from occtool._version import __version__

# public name -> module that defines it
_LAZY: dict[str, str] = {
    "OccupancyRegressor": "occtool.fit",
    "navigation_map": "occtool.navigation",
    "NavigationMap": "occtool.navigation",
    "read_log": "occtool.io",
    "load_model": "occtool.formats.model",
    "save_model": "occtool.formats.model",
    "Features": "occtool.features",
    "Pose": "occtool.features",
    "Position": "occtool.features",
    "RangeLog": "occtool.features",
    "Robot": "occtool.robot",
    "OcctoolError": "occtool.errors",
    "InputError": "occtool.errors",
    "ModelFormatError": "occtool.errors",
    "NotFittedError": "occtool.errors",
    "MissingDependencyError": "occtool.errors",
}

__all__ = [
    "Features",
    "InputError",
    "MissingDependencyError",
    "ModelFormatError",
    "NavigationMap",
    "NotFittedError",
    "OccupancyRegressor",
    "OcctoolError",
    "Pose",
    "Position",
    "RangeLog",
    "Robot",
    "__version__",
    "load_model",
    "navigation_map",
    "read_log",
    "save_model",
]

if TYPE_CHECKING:  # pragma: no cover - what the lazy names are, for type checkers and IDEs
    from occtool.errors import InputError, MissingDependencyError, ModelFormatError, NotFittedError, OcctoolError
    from occtool.features import Features, Pose, Position, RangeLog
    from occtool.fit import OccupancyRegressor
    from occtool.formats.model import load_model, save_model
    from occtool.io import read_log
    from occtool.navigation import NavigationMap, navigation_map
    from occtool.robot import Robot


__getattr__, __dir__ = lazy_attributes(__name__, _LAZY, globals())
