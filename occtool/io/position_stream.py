"""A range log's positions, read one at a time: what :func:`occtool.io.iter_positions` returns.

A :class:`PositionStream` is iterable as often as needed; each iteration reads the file
again and yields the positions :func:`occtool.io.read_log` would return, identical
(features, poses, stamps, sources, order), with the log's ``notes`` complete after a full
iteration. What is held at a time depends on the format:

``carmen``
    one line, and the scans of the position being gathered (:class:`~occtool.io.carmen.CarmenScans`:
    the first iteration reads the laser lines once more first, for the no-return sentinel,
    so a bad line anywhere is an error before the first position).
``csv``
    a chunk of rows, and the rows of the position being gathered (:mod:`occtool.io.csv_stream`,
    ``iter_csv``: it needs each position's rows to be contiguous, and falls back to reading
    the file whole when they are not).
``mcap``, ``rosbag``
    one message, and the scans of the position being gathered (:class:`~occtool.io.mcap._reader.McapScans`:
    whether poses come from ``/tf`` or odometry depends on the whole file, so the first
    iteration decodes every message once first, keeping counts only, and raises any
    error before the first position). occtool's own feature channel is read whole (its
    messages are sorted by position).
``tum``, ``3dmatch``
    one depth frame, and the scans of the position being gathered
    (:class:`~occtool.io.depth_folders.DepthFolderScans`: the first iteration reads up to 40
    frames first, for the floor that levels the world).
``xyz``, ``pcd``, ``ply``
    the whole file (one position in practice): read by :func:`occtool.io.read_log`.

Who streams: :func:`occtool.modelset.fit_model_set` (``occtool fit LOG -o DIR/``) and
``occtool info LOG``. ``occtool map`` keeps :func:`~occtool.io.read_log`: choosing
keyframes and fusing compare positions across the whole log.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from occtool.features import Position
    from occtool.io.read_options import ReadOptions


class PositionStream:
    """The positions of one log, streamed (see the module's docstring).

    Parameters
    ----------
    path
        The log.
    fmt
        Its format (one of :data:`occtool.io.FORMATS`).
    options
        Checked reading options (as :func:`occtool.io.iter_positions` makes them).
    """

    def __init__(self, path: str | os.PathLike[str], fmt: str, options: ReadOptions) -> None:
        self.path = path
        self.source = str(path)
        self.format = fmt
        self.options = options
        self.notes: list[str] = []
        self._carmen: Any = None
        self._mcap: Any = None
        self._depth: Any = None

    def _mcap_scans(self) -> Any:
        from occtool.io.mcap._reader import McapScans

        opener = None
        if self.format == "rosbag":
            from occtool.io.rosbag import BagReader

            opener = BagReader
        o = self.options
        return McapScans(self.path, topics=o["topics"], evidence_field=o["evidence_field"], evidence=o["evidence"],
                         use_intensities=o["use_intensities"], sensor_frame=o["sensor_frame"],
                         base_frame=o["base_frame"], skip_invalid=o["skip_invalid"],
                         no_return_range=o["no_return_range"], depth_features=o["depth_features"],
                         depth_noise=o["depth_noise"], depth_max_range=o["depth_max_range"], opener=opener)

    def __iter__(self) -> Iterator[Position]:
        from occtool.io import _read_errors

        with _read_errors(self.path):
            yield from self._positions()

    def _positions(self) -> Iterator[Position]:
        from occtool.io.positions import group_scans

        options = self.options
        tolerance, group_by = options["position_tolerance"], options["group_by"]
        if self.format == "carmen":
            from occtool.io import DEFAULT_CONSTANT_EVIDENCE
            from occtool.io.carmen import CarmenScans

            if self._carmen is None:
                evidence = options["evidence"]
                self._carmen = CarmenScans(
                    self.path, evidence=DEFAULT_CONSTANT_EVIDENCE if evidence is None else float(evidence),
                    skip_invalid=options["skip_invalid"], no_return_range=options["no_return_range"],
                )
            scans = self._carmen
            self.notes = scans.notes
            yield from group_scans(scans, source=scans.name, tolerance=tolerance, group_by=group_by, notes=scans.notes)
            return
        if self.format == "csv":
            from occtool.io.csv_stream import iter_csv

            self.notes = []
            yield from iter_csv(self.path, evidence_field=options["evidence_field"], evidence=options["evidence"],
                                position_tolerance=tolerance, group_by=group_by, skip_invalid=options["skip_invalid"],
                                notes=self.notes)
            return
        if self.format in ("tum", "3dmatch"):
            from occtool.io.depth_folders import DepthFolderScans

            if self._depth is None:
                self._depth = DepthFolderScans(
                    self.path, format=self.format, skip_invalid=options["skip_invalid"],
                    no_return_range=options["no_return_range"], depth_features=options["depth_features"],
                    depth_noise=options["depth_noise"], depth_max_range=options["depth_max_range"])
            scans = self._depth
            self.notes = scans.notes
            yield from group_scans(scans, source=scans.name, tolerance=tolerance, group_by=group_by, notes=scans.notes)
            return
        if self.format in ("mcap", "rosbag"):
            if self._mcap is None:
                self._mcap = self._mcap_scans()
            if self._mcap.prepare():
                scans = self._mcap
                self.notes = scans.notes
                yield from group_scans(scans, source=scans.name, tolerance=tolerance, group_by=group_by,
                                       notes=scans.notes)
                return
        from occtool.io import _read_format

        log = _read_format(self.path, self.format, options)
        self.notes = list(log.notes)
        yield from log.positions


__all__ = ["PositionStream"]
