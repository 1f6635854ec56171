"""The keywords every range-log reader shares, named and typed once.

:func:`occtool.io.read_log` takes all of them; each format's reader
(:func:`~occtool.io.csv.read_csv`, :func:`~occtool.io.mcap.read_mcap`,
:func:`~occtool.io.carmen.read_carmen`, :func:`~occtool.io.pointcloud.read_pointcloud`)
takes the ones its format has, with the same names and defaults (a test holds them to it).
A caller that passes reader settings along (the CLI's log options, a config file) can
type them as :class:`ReadOptions`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TypedDict

from occtool.errors import InputError

#: Depth images (:mod:`occtool.io.depth`): features kept of one frame, the noise coefficient
#: k of ``sigma = k z**2`` (a Kinect-class structured-light camera) and the farthest depth
#: taken as a return, metres. Here, in a light module, for the command line's defaults
#: and read_log's checks (io.depth's import is a few ms of every fresh fit).
DEFAULT_DEPTH_FEATURES = 10_000
DEFAULT_DEPTH_NOISE = 0.0015
DEFAULT_DEPTH_MAX_RANGE = 8.0
#: Nearest depth taken as a measurement, metres (below: invalid).
DEFAULT_DEPTH_MIN_RANGE = 0.1


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
    from occtool.limits import MAX_DISTANCE

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
    import numpy as np

    from occtool.limits import MAX_FEATURES

    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= int(value) <= MAX_FEATURES:
        raise InputError(f"depth features must be a whole number in [1, {MAX_FEATURES:,}] a frame, got {value!r}")
    return int(value)


class ReadOptions(TypedDict, total=False):
    """Keyword arguments of :func:`occtool.io.read_log` (see there for their meaning)."""

    format: str | None
    topics: Sequence[str] | None
    evidence_field: str
    evidence: float | None
    use_intensities: bool
    sensor_frame: str | None
    base_frame: str | None
    position_tolerance: Sequence[float]
    group_by: str
    skip_invalid: bool
    no_return_range: float | None
    depth_features: int
    depth_noise: float
    depth_max_range: float


__all__ = ["DEFAULT_DEPTH_FEATURES", "DEFAULT_DEPTH_MAX_RANGE", "DEFAULT_DEPTH_MIN_RANGE", "DEFAULT_DEPTH_NOISE", "ReadOptions",
           "check_depth_features", "check_depth_max_range", "check_depth_noise"]
