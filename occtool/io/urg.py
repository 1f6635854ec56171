"""Read BreezySLAM's raw Hokuyo URG logs (the MINES ParisTech rover's ``exp1.dat``).

One scan per line, whitespace-separated numbers (``../shared/data/mines_paristech_urg/SOURCE.md``)::

    time_us  ?  left_ticks  right_ticks  (20 telemetry values)  r_0 ... r_681 (mm)  (one more value)

The 682 ranges cover -120 to +120 degrees counterclockwise (beam 0 on the right); 0 is no
detection and is dropped (a URG's 0 is an error code, not "nothing within range").
The poses are **wheel odometry**, dead-reckoned with BreezySLAM's rover model (wheel
radius 77 mm, half axle 165 mm, 2000 ticks a half turn of the wheel, the laser 145 mm
ahead of the axle): they drift, and ``occtool map`` registers the scans
(:mod:`occtool.register`) rather than trusting them.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from typing import Any

import numpy as np

from occtool.errors import InputError
from occtool.features import Note, Pose, RangeLog
from occtool.io.positions import Scan, build_log
from occtool.io.read_options import ReadOptions, as_read_options, options_as_keywords

#: Fields before the ranges, the ranges, and the trailing value of a line.
HEADER_FIELDS = 24
BEAMS = 682
FIELDS = HEADER_FIELDS + BEAMS + 1
FIELD_OF_VIEW = math.radians(240.0)
WHEEL_RADIUS = 0.077
HALF_AXLE = 0.165
TICKS_PER_DEGREE = 2000.0 / 180.0
LASER_OFFSET = 0.145
#: The URG-04LX's reach, metres: a free ray (no_return_range) goes no further.
MAX_RANGE = 5.6


def looks_like_urg(first_line: str) -> bool:
    """Whether a line has the layout of a BreezySLAM URG log line."""
    fields = first_line.split()
    if len(fields) != FIELDS:
        return False
    try:
        [float(v) for v in fields]
    except ValueError:
        return False
    return True


def _odometry(left: float, right: float, previous: tuple[float, float] | None, pose: Pose) -> Pose:
    """The rover's pose after the wheels turned from ``previous`` ticks to ``left``, ``right``,
    as BreezySLAM's ``Rover`` computes it: travel ``r (dL + dR)``, turn ``r (dR - dL) / b``
    (twice the textbook differential drive's; with the textbook's halves the registered
    scans travel 2.2x as far and turn 2.2x as much as the odometry says, measured on exp1)."""
    if previous is None:
        return pose
    d_left = math.radians((left - previous[0]) / TICKS_PER_DEGREE)
    d_right = math.radians((right - previous[1]) / TICKS_PER_DEGREE)
    travel = WHEEL_RADIUS * (d_left + d_right)
    turn = WHEEL_RADIUS * (d_right - d_left) / HALF_AXLE
    heading = pose.yaw + turn / 2.0
    return Pose(pose.x + travel * math.cos(heading), pose.y + travel * math.sin(heading), 0.0, pose.yaw + turn)


def iter_urg_scans(path: str | os.PathLike[str], *, evidence: float = 0.9, skip_invalid: bool = False,
                   notes: list[str] | None = None) -> Iterator[Scan]:
    """The scans of a URG log, each at its laser's odometry pose."""
    from occtool.io.csv import open_text

    name = str(path)
    angles = -FIELD_OF_VIEW / 2 + FIELD_OF_VIEW / (BEAMS - 1) * np.arange(BEAMS)
    c, s = np.cos(angles), np.sin(angles)
    robot = Pose()
    previous: tuple[float, float] | None = None
    skipped = dropped = readings = 0
    with open_text(path) as handle:
        for line_number, line in enumerate(handle, start=1):
            fields = line.split()
            if not fields or fields[0].startswith("#"):
                continue
            try:
                if len(fields) != FIELDS:
                    raise ValueError(f"has {len(fields)} values, expected {FIELDS} (a BreezySLAM URG line)")
                values = np.array(fields, dtype=np.float64)
                if not np.isfinite(values).all():
                    raise ValueError("holds a value that is not finite")
            except ValueError as exc:
                if not skip_invalid:
                    detail = str(exc) if "expected" in str(exc) or "finite" in str(exc) else "holds a field that is not a number"
                    raise InputError(f"{name}, line {line_number}: the line {detail}") from None
                skipped += 1
                continue
            robot = _odometry(values[2], values[3], previous, robot)
            previous = (values[2], values[3])
            laser = Pose(robot.x + LASER_OFFSET * math.cos(robot.yaw), robot.y + LASER_OFFSET * math.sin(robot.yaw),
                         0.0, robot.yaw)
            ranges = values[HEADER_FIELDS:HEADER_FIELDS + BEAMS] / 1000.0
            valid = (ranges > 0.0) & (ranges <= MAX_RANGE)
            readings += BEAMS
            dropped += int(BEAMS - valid.sum())
            r = ranges[valid]
            points = np.column_stack([r * c[valid], r * s[valid], np.zeros(r.size)])
            yield Scan(points, np.full(r.size, evidence), laser, values[0] / 1e6, f"{name}:{line_number}")
    if notes is not None:
        notes.append("poses: wheel odometry (BreezySLAM's rover model), not corrected: occtool map registers the scans")
        if dropped:
            notes.append(f"dropped {dropped} of {readings} readings of 0 (no detection) or beyond {MAX_RANGE:g} m")
        if skipped:
            notes.append(Note.warn(f"skipped {skipped} line(s) that do not parse"))


def read_urg(path: str | os.PathLike[str], options: ReadOptions | None = None, **keywords: Any) -> RangeLog:
    """Read a BreezySLAM URG log (see the module's docstring) into positions on its odometry.

    ``options`` and ``keywords`` are the reading options (:class:`~occtool.io.ReadOptions`,
    or its fields by name): a URG log uses ``evidence``, ``position_tolerance``,
    ``group_by`` and ``skip_invalid``.
    """
    settings = as_read_options(options, **keywords)
    notes: list[str] = []
    scans: list[Scan] = list(iter_urg_scans(path, evidence=settings.constant_evidence,
                                            skip_invalid=settings.skip_invalid, notes=notes))
    if not scans:
        raise InputError(f"{path} holds no scans")
    log = build_log(scans, source=str(path), tolerance=settings.position_tolerance, group_by=settings.group_by,
                    notes=notes)
    log.pose_kind = "odometry"
    return log


options_as_keywords(read_urg)


__all__ = ["iter_urg_scans", "looks_like_urg", "read_urg"]
