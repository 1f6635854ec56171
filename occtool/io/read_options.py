"""The options every range-log reader shares, declared once: :class:`ReadOptions`.

Each field holds one option with its default, and :meth:`ReadOptions.__post_init__` its
check. Every reader (:func:`occtool.io.read_log`, :func:`~occtool.io.iter_positions` and
each format's: :func:`~occtool.io.csv.read_csv`, :func:`~occtool.io.mcap.read_mcap`,
:func:`~occtool.io.carmen.read_carmen`, ...) is called ``reader(path, options=None,
**keywords)``: a :class:`ReadOptions`, or its fields by name, and reads the fields its
format has from it. :func:`options_as_keywords` gives each such reader the signature of
the fields, from the dataclass.

So a new reader option is a new field here (default and check), its use in the reader
of the format that has it, and its entry in the command line's table
(``occtool.cli.options.LOG_FLAGS``); nothing else lists the options.

This module is light (no numpy at import): the command line reads its defaults for
``--help``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any

from occtool.errors import InputError
from occtool.limits import MAX_DISTANCE

#: Every format :func:`occtool.io.read_log` reads (the registry is :mod:`occtool.io._formats`).
FORMATS = ("csv", "mcap", "carmen", "xyz", "pcd", "ply", "rosbag", "urg", "tum", "3dmatch", "scans")
#: Evidence of data without an evidence field (laser scans, plain points) when ``evidence`` is None.
DEFAULT_CONSTANT_EVIDENCE = 0.9
#: ``(metres, radians)``: consecutive scans this close to a position's first scan join it.
DEFAULT_POSITION_TOLERANCE = (0.25, 0.26)
GROUP_BY_CHOICES = ("position", "message")
#: Depth images (:mod:`occtool.io.depth`): features kept of one frame, the noise coefficient
#: k of ``sigma = k z**2`` (a Kinect-class structured-light camera) and the farthest depth
#: taken as a return, metres. Here, in a light module, for the command line's defaults
#: and read_log's checks (io.depth's import is a few ms of every fresh fit).
DEFAULT_DEPTH_FEATURES = 10_000
DEFAULT_DEPTH_NOISE = 0.0015
DEFAULT_DEPTH_MAX_RANGE = 8.0
#: Nearest depth taken as a measurement, metres (below: invalid).
DEFAULT_DEPTH_MIN_RANGE = 0.1


def check_no_return_range(value: float | None, name: str = "no-return range") -> float | None:
    """Validate ``no_return_range`` (or another distance option, ``name`` in messages):
    ``None``, or a finite number of metres > 0, at most :data:`~occtool.limits.MAX_DISTANCE`.

    Raises
    ------
    InputError
        For zero, a negative number, NaN, infinity or a value that is not a number.
    """
    if value is None:
        return None
    try:
        number = float(value) if not isinstance(value, bool) else float("nan")
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a finite number of metres > 0, got {value!r}") from None
    if not (number > 0.0 and number < float("inf")):
        raise InputError(f"{name} must be a finite number of metres > 0, got {value!r}")
    if number > MAX_DISTANCE:
        raise InputError(f"{name} must be at most {MAX_DISTANCE:g} m, got {value!r}")
    return number


def check_tolerance(tolerance: Sequence[float]) -> tuple[float, float]:
    """Validate a ``(distance, angle)`` tolerance in metres and radians."""
    try:
        values = tuple(float(v) for v in tolerance)
    except (TypeError, ValueError):
        values = ()
    if len(values) != 2 or not all(math.isfinite(v) and v >= 0 for v in values):
        raise InputError(
            f"position tolerance must be two numbers >= 0 (metres, radians), got {tolerance!r}"
        )
    return values[0], values[1]


def check_depth_noise(value: float) -> float:
    """``noise`` of :func:`occtool.io.depth.noise_evidence`: a finite number of metres per square metre in [0, 1]."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise InputError(f"depth noise must be a number in [0, 1] (metres per square metre), got {value!r}") from None
    if not 0.0 <= number <= 1.0:
        raise InputError(f"depth noise must be a number in [0, 1] (metres per square metre), got {value!r}")
    return number


def check_depth_max_range(value: float) -> float:
    """The farthest depth taken as a return: a finite number of metres > the minimum range, bounded."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise InputError(f"depth max range must be a number of metres, got {value!r}") from None
    if not DEFAULT_DEPTH_MIN_RANGE < number <= MAX_DISTANCE:
        raise InputError(f"depth max range must lie in ({DEFAULT_DEPTH_MIN_RANGE:g}, {MAX_DISTANCE:g}] metres, "
                         f"got {value!r}")
    return number


def check_depth_features(value: int) -> int:
    """The per-frame feature budget: a whole number in [1, MAX_FEATURES]."""
    import numpy as np  # numpy's integers are whole numbers too; imported when checked, not for --help

    from occtool.limits import MAX_FEATURES

    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= int(value) <= MAX_FEATURES:
        raise InputError(f"depth features must be a whole number in [1, {MAX_FEATURES:,}] a frame, got {value!r}")
    return int(value)


def check_poses_file(value: str | os.PathLike[str] | None) -> str | None:
    """``None``, or the path of a poses file that exists and can be read (as a string)."""
    if value is None:
        return None
    if isinstance(value, (bytes, bool)) or not isinstance(value, (str, os.PathLike)):
        raise InputError(f"poses must be the path of a poses file, got {value!r}")
    path = os.fspath(value)
    if not os.path.isfile(path):
        raise InputError(f"poses file {path} does not exist" if not os.path.exists(path)
                         else f"poses file {path} is not a file")
    if not os.access(path, os.R_OK):
        raise InputError(f"poses file {path} cannot be read (permission denied)")
    return path


def check_format(value: str | None) -> str | None:
    """``None`` (from the file), or one of :data:`FORMATS` in any case (``dat`` is ``xyz``)."""
    if value is None:
        return None
    fmt = str(value).lower()
    fmt = "xyz" if fmt == "dat" else fmt
    if fmt not in FORMATS:
        raise InputError(f"unknown format {value!r}: expected one of {', '.join(FORMATS)}")
    return fmt


@dataclass(frozen=True)
class ReadOptions:
    """How to read a range log: every option of :func:`occtool.io.read_log`, checked.

    Building one checks every field (an :class:`~occtool.errors.InputError` naming the
    option); :meth:`replace` gives a copy with some fields changed, checked again.

    Attributes
    ----------
    format
        One of :data:`FORMATS`; by default chosen from the content and extension.
    topics
        MCAP and ROS bag topics to read (all must exist); by default the one supported
        range channel.
    evidence_field
        Point field (PointCloud2, PCD, PLY) or CSV column holding the evidence value.
    evidence
        Constant evidence for data without an evidence field (laser scans, plain
        points); :data:`DEFAULT_CONSTANT_EVIDENCE` there by default. CSV needs it only if
        it has no ``m`` column.
    use_intensities
        For laser scans, take the evidence from the intensities scaled into [0, 1]
        by the scan's largest intensity.
    sensor_frame, base_frame
        MCAP frames: points are moved from the sensor frame into the base frame with
        ``/tf_static``; by default the message's frame and ``base_link``.
    position_tolerance
        ``(metres, radians)``: consecutive scans within this distance and yaw of a
        position's first scan belong to that position.
    group_by
        ``"position"`` (see above) or ``"message"`` (each scan its own position).
    skip_invalid
        Drop invalid rows/points (NaN, evidence outside [0, 1], at the origin, a line
        that does not parse) and report the count in ``notes`` instead of failing.
    no_return_range
        Laser scans (CARMEN, ``sensor_msgs/msg/LaserScan``, ``foxglove.LaserScan``):
        ``None`` drops beams that returned nothing within the laser's range (noted);
        a number R of metres > 0 keeps each as a *free ray*, a feature along its beam
        at ``min(R, the beam's max range)`` with evidence 0 (free up to there, nothing
        about an obstacle). Other data (point clouds, CSV) has no such beams and
        ignores it. Depth images: pixels with no return (+inf, beyond
        ``depth_max_range``) become free rays at ``min(R, depth_max_range)``.
    no_return_code
        Laser logs that log a beam without a return as a code (CARMEN): readings at or
        above this many metres are no return. By default the log's own: its repeated
        largest readings (:func:`occtool.io.carmen.no_return_limit`).
    depth_features
        Depth images: most features kept of each frame, sampled on a regular pixel grid.
    depth_noise
        Depth images: ``k`` of the depth noise ``sigma = k z**2`` metres that gives each
        pixel its evidence (:func:`occtool.io.depth.noise_evidence`).
    depth_max_range
        Depth images: farther depths are no returns, metres.
    poses
        Folders of scans and point-cloud files (``scans``, :mod:`occtool.io.scans`): a
        KITTI-style poses file, line i the row-major 3x4 scan-to-world transform of scan i.

    Examples
    --------
    >>> ReadOptions(no_return_range=5).no_return_range
    5.0
    >>> ReadOptions(group_by="scan")
    Traceback (most recent call last):
    ...
    occtool.errors.InputError: group-by must be one of position, message, got 'scan'
    """

    format: str | None = None
    topics: Sequence[str] | None = None
    evidence_field: str = "evidence"
    evidence: float | None = None
    use_intensities: bool = False
    sensor_frame: str | None = None
    base_frame: str | None = None
    position_tolerance: Sequence[float] = DEFAULT_POSITION_TOLERANCE
    group_by: str = "position"
    skip_invalid: bool = False
    no_return_range: float | None = None
    no_return_code: float | None = None
    depth_features: int = DEFAULT_DEPTH_FEATURES
    depth_noise: float = DEFAULT_DEPTH_NOISE
    depth_max_range: float = DEFAULT_DEPTH_MAX_RANGE
    poses: str | None = None

    def __post_init__(self) -> None:
        # The order is read_log's of old: a user with two wrong options hears of the same one first.
        checked: dict[str, Any] = {"position_tolerance": check_tolerance(self.position_tolerance)}
        if self.group_by not in GROUP_BY_CHOICES:
            raise InputError(f"group-by must be one of {', '.join(GROUP_BY_CHOICES)}, got {self.group_by!r}")
        if self.evidence is not None and not (0.0 <= float(self.evidence) <= 1.0):
            raise InputError(f"constant evidence must lie in [0, 1], got {self.evidence}")
        checked["format"] = check_format(self.format)
        checked["no_return_range"] = check_no_return_range(self.no_return_range)
        checked["no_return_code"] = check_no_return_range(self.no_return_code, "no-return code")
        checked["depth_features"] = check_depth_features(self.depth_features)
        checked["depth_noise"] = check_depth_noise(self.depth_noise)
        checked["depth_max_range"] = check_depth_max_range(self.depth_max_range)
        checked["poses"] = check_poses_file(self.poses)
        for name, value in checked.items():
            object.__setattr__(self, name, value)  # frozen: the checked value replaces the given one

    @property
    def constant_evidence(self) -> float:
        """The evidence of data without an evidence field: ``evidence``, or the default."""
        return DEFAULT_CONSTANT_EVIDENCE if self.evidence is None else float(self.evidence)

    def replace(self, **changes: Any) -> ReadOptions:
        """A copy with ``changes``, checked (as :func:`dataclasses.replace`)."""
        import dataclasses

        return dataclasses.replace(self, **changes) if changes else self


#: The field names, in declaration order (the keywords of :func:`occtool.io.read_log`).
OPTION_NAMES: tuple[str, ...] = tuple(f.name for f in fields(ReadOptions))


def as_read_options(options: ReadOptions | None = None, /, **keywords: Any) -> ReadOptions:
    """``options`` (default: all defaults) with ``keywords`` replacing its fields, checked.

    Raises
    ------
    TypeError
        For a keyword that is no field (as Python says of an unknown keyword argument).
    InputError
        For an invalid value.
    """
    if options is not None and not isinstance(options, ReadOptions):
        raise TypeError(f"options must be a ReadOptions, got {type(options).__name__}")
    unknown = [name for name in keywords if name not in OPTION_NAMES]
    if unknown:
        raise TypeError(f"unexpected keyword argument '{unknown[0]}': the reading options are "
                        f"{', '.join(OPTION_NAMES)}")
    if options is None:
        return ReadOptions(**keywords)
    return options.replace(**keywords)


def options_as_keywords(function: Any) -> Any:
    """Give ``function(path, options=None, **keywords)`` (or such a class) the signature it
    accepts: each :class:`ReadOptions` field a keyword-only parameter with the field's
    default, read from the dataclass (for ``help()``, editors, and the tests holding the
    readers' keywords to the fields). Returns ``function``."""
    import inspect  # loaded already by dataclasses

    signature = inspect.signature(function)
    parameters = [p for p in signature.parameters.values() if p.kind is not inspect.Parameter.VAR_KEYWORD]
    parameters += [inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, default=f.default, annotation=f.type)
                   for f in fields(ReadOptions)]
    function.__signature__ = signature.replace(parameters=parameters)
    return function


__all__ = ["DEFAULT_CONSTANT_EVIDENCE", "DEFAULT_DEPTH_FEATURES", "DEFAULT_DEPTH_MAX_RANGE", "DEFAULT_DEPTH_MIN_RANGE",
           "DEFAULT_DEPTH_NOISE", "DEFAULT_POSITION_TOLERANCE", "FORMATS", "GROUP_BY_CHOICES", "OPTION_NAMES",
           "ReadOptions", "as_read_options", "check_depth_features", "check_depth_max_range", "check_depth_noise", "check_format", "check_poses_file",
           "check_no_return_range", "check_tolerance", "options_as_keywords"]
