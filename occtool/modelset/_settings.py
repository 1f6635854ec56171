"""What a log's models are fitted with: the estimator for its positions and the digest of
its settings (see :mod:`occtool.modelset`).

Apart from the model sets' machinery (:mod:`occtool.modelset._common`, ``_fit``): a single
``occtool fit`` needs these two alone, and the rest's import (its dataclasses, threads and
signals) was a few ms of every fresh fit.
"""

from __future__ import annotations

import hashlib
import json
import logging
from collections.abc import Sequence
from typing import Any

#: The model sets' logger (:data:`occtool.modelset._common.log` is the same one).
log = logging.getLogger("occtool.modelset")


def settings_digest(estimator: Any) -> str:
    """sha256 of everything besides the features that decides a model's bytes: the fit
    parameters, sensor model, robot and occtool's version."""
    from occtool._version import __version__
    from occtool.robot import Robot
    from occtool.sensor import SensorModel

    params = {k: v for k, v in estimator.get_params().items() if k not in ("progress", "sensor", "robot")}
    sensor = estimator.sensor if estimator.sensor is not None else SensorModel()
    robot = estimator.robot if estimator.robot is not None else Robot()
    content = {
        "fit": params,
        "sensor": sensor.to_dict(),
        "robot": {k: float(getattr(robot, k)) for k in ("radius", "sensor_height", "body_height", "ground_clearance")},
        "occtool": __version__,
    }
    return hashlib.sha256(json.dumps(content, sort_keys=True, default=repr).encode()).hexdigest()


#: The data's floor and the robot's (``sensor_height`` below the sensor) disagree beyond this, metres.
FLOOR_DISAGREEMENT = 0.15


class _GeometrySurvey:
    """What :func:`estimator_for_log` needs to know of a log's positions, gathered one
    position at a time: their count, whether all are planar, for the estimator's robot
    and a planar laser's the first position with geometry findings and how many have some,
    and each position's lowest large horizontal layer (:func:`occtool._floor.lowest_layer`)."""

    def __init__(self, estimator: Any, planar_defaults: bool, floor_defaults: bool | None = None) -> None:
        from dataclasses import replace

        from occtool.robot import PLANAR_LASER_BODY_HEIGHT, PLANAR_LASER_SENSOR_HEIGHT, Robot

        self.estimator = estimator
        self.planar_defaults = planar_defaults
        self.floor_defaults = planar_defaults if floor_defaults is None else floor_defaults
        robot = estimator.robot if estimator.robot is not None else Robot()
        self.robots = {"given": robot}
        if planar_defaults:
            self.robots["planar"] = replace(robot, sensor_height=PLANAR_LASER_SENSOR_HEIGHT,
                                            body_height=PLANAR_LASER_BODY_HEIGHT)
        self.count = 0
        self.all_planar = True
        self.first: dict[str, tuple[int, list[str]] | None] = dict.fromkeys(self.robots)
        self.flagged: dict[str, int] = dict.fromkeys(self.robots, 0)
        #: Each position's lowest large layer: in the world (its pose's z added) and below its sensor.
        self.layers: list[tuple[float, float]] = []

    def add(self, position: Any) -> None:
        from occtool._floor import lowest_layer
        from occtool.sensor import geometry_findings, is_planar

        self.count += 1
        features = position.features
        if self.planar_defaults and self.all_planar:
            self.all_planar = is_planar(features)
        layer = lowest_layer(features.points[features.evidence > 0.0], top=0.0)
        if layer is not None:
            z = position.pose.z if position.pose is not None else 0.0
            self.layers.append((z + layer[0], layer[0]))
        for name, robot in self.robots.items():
            if name == "planar" and not self.all_planar:
                continue  # its findings are read only for a log planar throughout
            # The floor is judged across positions (floor_height), not one by one.
            findings = geometry_findings(features, robot, floor_layer=False)
            if findings:
                self.flagged[name] += 1
                if self.first[name] is None:
                    self.first[name] = (position.index, findings)

    def floor_height(self) -> tuple[float, int] | None:
        """The sensor's height above the floor the positions agree on (the median over the
        positions that see it) and how many see it; ``None`` when no floor is supported."""
        import numpy as np

        from occtool._floor import common_floor

        if not self.layers:
            return None
        world, below = np.array(self.layers).T
        found = common_floor(world)
        if found is None:
            return None
        members = found[1]
        return round(float(np.median(-below[members])), 2), int(np.count_nonzero(members))

    def _check_floor(self, estimator: Any, robot: Any) -> Any:
        """The estimator with the data's sensor height when the user gave none and the data's
        floor disagrees with the robot's; a warning naming ``--sensor-height`` either way."""
        from dataclasses import replace

        found = self.floor_height()
        if found is None or abs(found[0] - robot.sensor_height) <= FLOOR_DISAGREEMENT:
            return estimator
        height, seen = found
        where = (f"the floor that {seen} of the {self.count} positions see lies {height:.2f} m below the sensor"
                 if self.count > 1 else f"the floor lies {height:.2f} m below the sensor")
        if self.floor_defaults:  # no height given: the data's floor sets it
            log.warning("%s: --sensor-height %.2f taken from the data instead of the default %g; give "
                        "--sensor-height to choose", where, height, robot.sensor_height)
            robot = replace(robot, sensor_height=height)
            return type(estimator)(**{**estimator.get_params(deep=False), "robot": robot})
        log.warning("%s, not %g m as --sensor-height says: give --sensor-height %.2f", where,
                    robot.sensor_height, height)
        return estimator

    def result(self) -> Any:
        """The estimator for the log (logging what :func:`estimator_for_log` logs)."""
        from occtool.fit import DEFAULT_FOCUS_RANGE, PLANAR_FOCUS_RANGE

        estimator = self.estimator
        name = "given"
        if self.planar_defaults and self.count and self.all_planar:
            name = "planar"
            robot = self.robots[name]
            params = {**estimator.get_params(deep=False), "robot": robot}
            if params.get("focus_range") == DEFAULT_FOCUS_RANGE:
                params["focus_range"] = PLANAR_FOCUS_RANGE
            estimator = type(estimator)(**params)
            log.info("a planar laser log: sensor height %g m, body height %g m, focus range %g m",
                     robot.sensor_height, robot.body_height, estimator.focus_range)
        first, flagged = self.first[name], self.flagged[name]
        if first is not None:
            index, findings = first
            where = f"position {index}: " if self.count > 1 else ""
            more = f" (and {flagged - 1} more position(s))" if flagged > 1 else ""
            for finding in findings:
                log.warning("%s%s%s", where, finding, more)
        if name == "given":
            estimator = self._check_floor(estimator, self.robots[name])
        return estimator


def estimator_for_log(estimator: Any, positions: Sequence[Any], *, planar_defaults: bool = False,
                      floor_defaults: bool | None = None) -> Any:
    """The estimator a log's positions are fitted with, and a warning for each place the
    data and the sensor geometry disagree.

    With ``planar_defaults``, a log whose returns all lie in one plane (a 2D laser, as
    CARMEN logs) gets a planar scanner's robot (:data:`occtool.robot.PLANAR_LASER_SENSOR_HEIGHT`,
    ``..._BODY_HEIGHT``) instead of the estimator's, and, unless the estimator's focus range
    is other than the default, a laser's (:data:`occtool.fit.PLANAR_FOCUS_RANGE`): the
    command line does so unless the user gave a sensor or body height. Each finding of
    :func:`occtool.sensor.geometry_findings` is logged as one warning (the first position's,
    with a count of the others that have findings too).

    The floor is judged across the positions: each one's lowest large horizontal layer
    below its sensor, and the lowest height many of them agree on in the world
    (:mod:`occtool._floor`; never the most populated layer, which may be a table top).
    When the sensor's height above it differs from the robot's ``sensor_height`` by more
    than :data:`FLOOR_DISAGREEMENT`, one warning names ``--sensor-height`` and the height
    the data gives; with ``floor_defaults`` (by default ``planar_defaults``: the command
    line's when no height was given) a log that is not planar takes that height (the other
    findings are still the given robot's). ``occtool fit`` and ``occtool map``
    (:func:`occtool.fuse.fuse_log`) both call this. ``positions`` may be any iterable read
    once (a :func:`occtool.io.iter_positions` stream): only two numbers per position are
    held.
    """
    survey = _GeometrySurvey(estimator, planar_defaults, floor_defaults)
    for position in positions:
        survey.add(position)
    return survey.result()
