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


__all__ = ["ReadOptions"]
