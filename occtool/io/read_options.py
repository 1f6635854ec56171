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

#: Depth images (:mod:`occtool.io.depth`): features kept of one frame, the noise coefficient
#: k of ``sigma = k z**2`` (a Kinect-class structured-light camera) and the farthest depth
#: taken as a return, metres. Here, in a light module, for the command line's defaults.
DEFAULT_DEPTH_FEATURES = 10_000
DEFAULT_DEPTH_NOISE = 0.0015
DEFAULT_DEPTH_MAX_RANGE = 8.0


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


__all__ = ["DEFAULT_DEPTH_FEATURES", "DEFAULT_DEPTH_MAX_RANGE", "DEFAULT_DEPTH_NOISE", "ReadOptions"]
