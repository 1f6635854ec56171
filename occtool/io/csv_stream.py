"""Streaming a CSV log's positions in chunks of rows (:func:`iter_csv`, for
:func:`occtool.io.iter_positions`): the parsing, checks and grouping of :mod:`occtool.io.csv`,
applied a chunk at a time."""

from __future__ import annotations

import functools
import os
import warnings
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.features import Features, Note, Pose, Position
from occtool.io.csv import (
    _checked_rows,
    _content,
    _find_layout,
    _Layout,
    _slow_parse,
    logger,
    open_text,
    read_csv,
)
from occtool.io.positions import to_reference_frame
from occtool.io.read_options import ReadOptions, as_read_options, options_as_keywords

#: Text parsed at a time when a CSV log is streamed (:func:`iter_csv`): about 4 MB, tens
#: of thousands of rows.
CHUNK_BYTES = 1 << 22


def iter_csv(
    path: str | os.PathLike[str],
    options: ReadOptions | None = None,
    *,
    notes: list[str] | None = None,
    **keywords: Any,
) -> Iterator[Position]:
    """The positions of a CSV feature file, parsed :data:`CHUNK_BYTES` of text at a time.

    ``options`` and ``keywords`` are :func:`read_csv`'s. Yields what :func:`read_csv`
    returns, position by position, holding one chunk and
    the rows of the position being gathered; the notes are appended to ``notes`` at the
    end, and a bad row is an :class:`InputError` when its chunk is reached (the first bad
    row of the file, as :func:`read_csv` names it). A file without ``position`` or pose
    columns is one position, held whole.

    Ordering: a position's rows must be contiguous. Rows grouped by pose are so by
    definition (a new pose after others starts a new position); a ``position`` column is
    checked first, in a pass that parses that column alone, and when an id comes back
    after another (rows of positions interleaved), or the column does not parse, the file
    is read whole by :func:`read_csv` instead, with the same result.
    """
    settings = as_read_options(options, **keywords)
    evidence = settings.evidence
    name = str(path)
    notes = notes if notes is not None else []
    with open_text(path) as handle:
        layout = _find_layout(handle, name, settings.evidence_field, evidence)
    if layout.position is not None and not _ids_are_contiguous(path, layout, layout.position):
        log = read_csv(path, settings)
        notes.extend(log.notes)
        yield from log.positions
        return
    gatherer = _RowGatherer(name, layout, settings.position_tolerance, settings.group_by)
    rows = 0
    skipped = 0
    with open_text(path) as handle:
        for _ in range(layout.header_line):
            handle.readline()
        line_number = layout.header_line
        while True:
            lines = handle.readlines(CHUNK_BYTES)
            if not lines:
                break
            first_line, line_number = line_number + 1, line_number + len(lines)
            data, line_numbers, unparsable = _parse_chunk(lines, first_line, layout)
            rows += data.shape[0]
            data, bad_count = _checked_rows(name, layout, data, line_numbers, unparsable, evidence, settings.skip_invalid,
                                            functools.partial(_chunk_line_numbers, lines, first_line))
            skipped += bad_count
            yield from gatherer.add(data, evidence)
    if rows == 0 and not skipped:
        raise InputError(f"{name} has a header but no data rows")
    if skipped:
        notes.append(Note.warn(f"skipped {skipped} invalid row(s) of {name}"))
        logger.debug("skipped %d invalid rows of %s", skipped, name)
    if gatherer.count == 0 and not gatherer.pending:
        raise InputError(f"{name} holds no valid rows ({skipped} skipped)")
    yield from gatherer.finish()
    if gatherer.dropped:
        notes.append(f"{gatherer.dropped} point(s) fell on their position's sensor origin and were dropped")


options_as_keywords(iter_csv)


def _ids_are_contiguous(path: str | os.PathLike[str], layout: _Layout, column: int) -> bool:
    """Whether every position id's rows form one run (parsing the ``position`` column alone)."""
    finished: set[float] = set()
    current: float | None = None
    with open_text(path) as handle:
        for _ in range(layout.header_line):
            handle.readline()
        while lines := handle.readlines(CHUNK_BYTES):
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", UserWarning)
                    ids = np.loadtxt(lines, delimiter=",", comments="#", usecols=(column,), ndmin=1,
                                     dtype=np.float64)
            except ValueError:
                return False
            if ids.size == 0:
                continue
            if not (np.isfinite(ids).all() and np.all(ids == np.round(ids))):
                return False
            starts = np.flatnonzero(np.diff(ids)) + 1
            for value in ids[np.concatenate([[0], starts])].tolist():
                if value == current:
                    continue
                if value in finished:
                    return False
                if current is not None:
                    finished.add(current)
                current = value
    return True


def _chunk_line_numbers(lines: list[str], first_line: int) -> NDArray[np.int64]:
    """The file line number of every data row of a chunk (run only to report an error)."""
    return np.array([first_line + k for k, line in enumerate(lines) if _content(line)], dtype=np.int64)


def _parse_chunk(
    lines: list[str], first_line: int, layout: _Layout
) -> tuple[NDArray[np.float64], NDArray[np.int64] | None, list[tuple[int, str]]]:
    """Values of the rows of ``lines`` (file lines from ``first_line``) that parse, their
    line numbers (``None`` from the fast path: :func:`_chunk_line_numbers` finds them), and
    the rows that do not parse."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            data = np.loadtxt(lines, delimiter=",", comments="#", usecols=layout.used, ndmin=2, dtype=np.float64)
        return data.reshape(-1, len(layout.used)), None, []
    except ValueError:
        pass
    shifted = _Layout(first_line - 1, layout.names, layout.xyz, layout.evidence, layout.position, layout.pose,
                      layout.stamp)
    data, numbers, unparsable = _slow_parse(iter(lines), shifted)
    return data, numbers, unparsable


class _RowGatherer:
    """Rows of a CSV log in file order, cut into positions as :func:`_group_rows` cuts them:
    at a new ``position`` id, or at a pose run that starts a new position (tolerance)."""

    def __init__(self, name: str, layout: _Layout, tolerance: Sequence[float], group_by: str) -> None:
        from occtool.io.positions import check_tolerance
        from occtool.io.read_options import GROUP_BY_CHOICES

        if group_by not in GROUP_BY_CHOICES:
            raise InputError(f"group-by must be one of {', '.join(GROUP_BY_CHOICES)}, got {group_by!r}")
        self.name = name
        self.layout = layout
        self.max_distance, self.max_angle = check_tolerance(tolerance)
        self.group_by = group_by
        self.column = {c: k for k, c in enumerate(layout.used)}
        self.pending: list[NDArray[np.float64]] = []
        self.last: NDArray[np.float64] | None = None  # the last row's id or pose
        self.reference: Pose | None = None
        self.evidence: float | None = None
        self.count = 0
        self.dropped = 0

    def _poses(self, data: NDArray[np.float64]) -> NDArray[np.float64]:
        px, py, pz, pyaw = self.layout.pose  # type: ignore[misc]  # only called with pose columns
        c = self.column
        z = data[:, c[pz]] if pz is not None else np.zeros(data.shape[0])
        return np.column_stack([data[:, c[px]], data[:, c[py]], z, data[:, c[pyaw]]])

    def _starts(self, data: NDArray[np.float64]) -> list[int]:
        """Rows of ``data`` that start a new position."""
        layout = self.layout
        if layout.position is not None:
            keys = data[:, [self.column[layout.position]]]
            if not np.all(keys == np.round(keys)):
                raise InputError(f"{self.name}: the 'position' column must hold whole numbers")
        elif layout.pose is not None:
            keys = self._poses(data)
        else:
            return []
        changes = np.flatnonzero(np.any(np.diff(keys, axis=0) != 0.0, axis=1)) + 1
        first_changes = self.last is None or bool(np.any(keys[0] != self.last))
        run_starts = ([0] if first_changes else []) + changes.tolist()
        self.last = keys[-1].copy()
        if layout.position is not None:
            return [s for s in run_starts if s > 0 or self.pending]
        starts = []
        # A loop over pose runs (scans), not rows: as assign_positions.
        for s in run_starts:
            pose = Pose(*map(float, keys[s]))
            if self.reference is None:
                self.reference = pose
                continue
            if self.group_by == "message" or (
                float(np.hypot(pose.x - self.reference.x, pose.y - self.reference.y)) > self.max_distance
                or float(abs((pose.yaw - self.reference.yaw + np.pi) % (2.0 * np.pi) - np.pi)) > self.max_angle
            ):
                starts.append(s)
                self.reference = pose
        return starts

    def add(self, data: NDArray[np.float64], evidence: float | None) -> Iterator[Position]:
        """Take the valid rows of a chunk; yield the positions they complete."""
        self.evidence = evidence
        if data.shape[0] == 0:
            return
        begin = 0
        for start in self._starts(data):
            if start > begin:
                self.pending.append(data[begin:start])
            if self.pending:
                yield self._position()
            begin = start
        self.pending.append(data[begin:])

    def finish(self) -> Iterator[Position]:
        """The last position."""
        if self.pending:
            yield self._position()

    def _position(self) -> Position:
        layout, c = self.layout, self.column
        block = np.concatenate(self.pending) if len(self.pending) > 1 else self.pending[0]
        self.pending = []
        points = np.ascontiguousarray(block[:, :3])
        m = (np.ascontiguousarray(block[:, c[layout.evidence]]) if layout.evidence is not None
             else np.full(block.shape[0], float(self.evidence)))  # type: ignore[arg-type]  # checked in _find_layout
        pose = None
        if layout.pose is not None:
            pose_rows = self._poses(block)
            pose = Pose(*map(float, pose_rows[0]))
            if np.any(pose_rows != pose_rows[0]):
                points = to_reference_frame(points, pose_rows, pose)
                keep = (np.abs(points) > 0.0).any(axis=1)
                self.dropped += int((~keep).sum())
                points, m = points[keep], m[keep]
        stamp = float(block[0, c[layout.stamp]]) if layout.stamp is not None else None
        source = self.name if layout.position is None else f"{self.name} position {int(block[0, c[layout.position]])}"
        self.count += 1
        return Position(index=self.count - 1, features=Features(points, m), pose=pose, stamp=stamp, source=source)


__all__ = ["CHUNK_BYTES", "iter_csv"]
