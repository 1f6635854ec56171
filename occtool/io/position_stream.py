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
``scans``
    one scan file, and the scans of the position being gathered
    (:class:`~occtool.io.scans.ScanSequence`: the first iteration reads and checks the poses
    file first).
``xyz``, ``pcd``, ``ply``
    the whole file (one position in practice): read by :func:`occtool.io.read_log`.

Who streams: :func:`occtool.modelset.fit_model_set` (``occtool fit LOG -o DIR/``) and
``occtool info LOG``. ``occtool map`` keeps :func:`~occtool.io.read_log`: choosing
keyframes and fusing compare positions across the whole log.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
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

    def __init__(self, path: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], fmt: str,
                 options: ReadOptions) -> None:
        self.path = path
        self.source = str(path) if isinstance(path, (str, os.PathLike)) else " ".join(str(p) for p in path)
        self.format = fmt
        self.options = options
        self.notes: list[str] = []
        self._source: Any = None  # the format's streaming source, kept across iterations

    def __iter__(self) -> Iterator[Position]:
        from occtool.io._formats import read_errors

        with read_errors(self.path):
            yield from self._positions()

    def _positions(self) -> Iterator[Position]:
        from occtool.io._formats import STREAMS, read_whole

        stream = STREAMS.get(self.format)
        if stream is not None:
            if self._source is None:
                self._source = stream(self.path, self.format, self.options)
            positions = self._source.positions()
            if positions is not None:
                self.notes = self._source.notes
                yield from positions
                return
        log = read_whole(self.path, self.format, self.options)
        self.notes = list(log.notes)
        yield from log.positions


__all__ = ["PositionStream"]
