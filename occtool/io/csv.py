"""Read and write range features as CSV.

The format (docs/formats.md): a header row naming the columns, then one feature per
row. ``x, y, z`` are metres in the sensor-centred robot frame (REP-103: x forward,
y left, z up); ``m`` (or ``evidence``) is the evidence value in [0, 1]. Extra columns
are ignored and ``#`` starts a comment. Optional columns group rows into robot
positions: ``position`` (an integer id), or a pose ``pose_x, pose_y, pose_yaw``
(and ``pose_z``) in the world frame, and ``stamp`` (seconds).

Parsing is vectorised (:func:`numpy.loadtxt`, compiled code); only when it fails does a
slower pass run, to name the offending line or, with ``skip_invalid``, to drop it.
"""

from __future__ import annotations

import functools
import logging
import os
import warnings
from collections.abc import Callable, Iterable, Sequence
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray

from occtool.errors import InputError
from occtool.features import Features, Note, Pose, Position, RangeLog
from occtool.io.positions import assign_positions, to_reference_frame
from occtool.io.read_options import ReadOptions, as_read_options, options_as_keywords
from occtool.limits import MAX_COORDINATE

logger = logging.getLogger(__name__)

EVIDENCE_ALIASES = ("m", "evidence")
POSE_COLUMNS = ("pose_x", "pose_y", "pose_z", "pose_yaw")
STAMP_ALIASES = ("stamp", "time", "t")


def open_text(path: str | os.PathLike[str]) -> IO[str]:
    """Open a text file for reading, decompressing gzip and bzip2 (told by content) transparently."""
    from occtool._files import open_input

    return open_input(path, "r")


def _content(line: str) -> str:
    """A line without its comment and surrounding blanks (what numpy.loadtxt sees)."""
    return line.split("#", 1)[0].strip()


class _Layout:
    """Which column holds what, found from the header row."""

    # A plain class, not a dataclass: each dataclass made was about 1 ms of a fresh
    # process's import, for a record only this module builds and reads.
    __slots__ = ("header_line", "names", "xyz", "evidence", "position", "pose", "stamp")

    def __init__(self, header_line: int, names: tuple[str, ...], xyz: tuple[int, int, int], evidence: int | None,
                 position: int | None, pose: tuple[int, int, int | None, int] | None, stamp: int | None) -> None:
        self.header_line, self.names, self.xyz = header_line, names, xyz
        self.evidence, self.position, self.pose, self.stamp = evidence, position, pose, stamp

    @property
    def used(self) -> tuple[int, ...]:
        """Column indices to parse, in the order x, y, z, [m], [position], [pose...], [stamp]."""
        columns = list(self.xyz)
        for extra in (self.evidence, self.position):
            if extra is not None:
                columns.append(extra)
        if self.pose is not None:
            columns.extend(c for c in self.pose if c is not None)
        if self.stamp is not None:
            columns.append(self.stamp)
        return tuple(columns)


def _find_layout(handle: IO[str], name: str, evidence_field: str, constant_evidence: float | None) -> _Layout:
    line_number = 0
    for line in handle:
        line_number += 1
        text = _content(line)
        if text:
            break
    else:
        raise InputError(f"{name} is empty (no header row and no data)")
    names = tuple(c.strip().strip('"').strip("'").lower() for c in text.split(","))
    index = {n: i for i, n in enumerate(names)}
    missing = [c for c in ("x", "y", "z") if c not in index]
    if missing:
        raise InputError(
            f"{name}, line {line_number}: the header needs columns x, y, z (missing {', '.join(missing)}); "
            f"found {', '.join(names)}"
        )
    evidence_column: int | None = None
    wanted = evidence_field.lower() if evidence_field else "evidence"
    if wanted in index:
        evidence_column = index[wanted]
    elif wanted in EVIDENCE_ALIASES:
        evidence_column = next((index[a] for a in EVIDENCE_ALIASES if a in index), None)
    if evidence_column is None and constant_evidence is None:
        raise InputError(
            f"{name}, line {line_number}: no evidence column ('{wanted}'"
            f"{' or m' if wanted in EVIDENCE_ALIASES else ''}): add one or give a constant with evidence="
        )
    pose = None
    if "pose_x" in index or "pose_y" in index or "pose_yaw" in index:
        absent = [c for c in ("pose_x", "pose_y", "pose_yaw") if c not in index]
        if absent:
            raise InputError(f"{name}, line {line_number}: pose columns need {', '.join(absent)} as well")
        pose = (index["pose_x"], index["pose_y"], index.get("pose_z"), index["pose_yaw"])
    stamp = next((index[a] for a in STAMP_ALIASES if a in index), None)
    return _Layout(
        header_line=line_number,
        names=names,
        xyz=(index["x"], index["y"], index["z"]),
        evidence=evidence_column,
        position=index.get("position"),
        pose=pose,
        stamp=stamp,
    )


def _slow_parse(
    handle: Iterable[str], layout: _Layout
) -> tuple[NDArray[np.float64], NDArray[np.int64], list[tuple[int, str]]]:
    """Parse row by row: the fallback that finds the lines that do not parse.

    Returns the values of the rows that parse, the file line number of each and the
    ``(line number, problem)`` of each row that does not.
    """
    used = layout.used
    width = max(used) + 1
    rows: list[list[float]] = []
    lines: list[int] = []
    unparsable: list[tuple[int, str]] = []
    line_number = layout.header_line
    for line in handle:
        line_number += 1
        text = _content(line)
        if not text:
            continue
        fields = text.split(",")
        problem = None
        if len(fields) < width:
            problem = f"has {len(fields)} columns, the header names {len(layout.names)}"
        else:
            try:
                values = [float(fields[c]) for c in used]
            except ValueError:
                bad = next(c for c in used if not _is_float(fields[c]))
                problem = f"column '{layout.names[bad]}' is not a number: {fields[bad].strip()!r}"
        if problem is not None:
            unparsable.append((line_number, problem))
            continue
        rows.append(values)
        lines.append(line_number)
    data = np.array(rows, dtype=np.float64).reshape(-1, len(used))
    return data, np.array(lines, dtype=np.int64), unparsable


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _data_line_numbers(path: str | os.PathLike[str], layout: _Layout) -> NDArray[np.int64]:
    """The file line number of every data row (a second pass, run only to report an error)."""
    numbers = []
    with open_text(path) as handle:
        for line_number, line in enumerate(handle, start=1):
            if line_number > layout.header_line and _content(line):
                numbers.append(line_number)
    return np.array(numbers, dtype=np.int64)


def read_csv(path: str | os.PathLike[str], options: ReadOptions | None = None, **keywords: Any) -> RangeLog:
    """Read a CSV feature file into a :class:`~occtool.features.RangeLog`.

    Parameters
    ----------
    path
        The CSV file (``.csv``, optionally ``.gz`` or ``.bz2`` compressed).
    options, **keywords
        The reading options (:class:`~occtool.io.ReadOptions`, or its fields by name). A CSV
        file uses ``evidence_field`` (the evidence column; ``"evidence"``, the default, also
        accepts ``m``), ``evidence`` (constant evidence for every row, when the file has no
        evidence column), ``position_tolerance`` and ``group_by`` (``"message"``: every
        distinct consecutive pose its own position), and ``skip_invalid`` (drop bad rows:
        not numeric, NaN or infinite, evidence outside [0, 1], a point at the origin, and
        report their count in ``notes`` instead of failing).

    Returns
    -------
    RangeLog
        One position per ``position`` id or pose group; one position if there are no
        pose columns.

    Raises
    ------
    InputError
        For an empty file, a missing column, or a bad row (naming its line).
    """
    settings = as_read_options(options, **keywords)
    evidence = settings.evidence
    name = str(path)
    line_numbers: NDArray[np.int64] | None = None
    unparsable: list[tuple[int, str]] = []
    with open_text(path) as handle:
        layout = _find_layout(handle, name, settings.evidence_field, evidence)
        try:
            with warnings.catch_warnings():
                # A header without rows is reported below as an InputError, not a warning.
                warnings.simplefilter("ignore", UserWarning)
                data = np.loadtxt(
                    handle, delimiter=",", comments="#", usecols=layout.used, ndmin=2, dtype=np.float64
                )
            parsed = True
        except ValueError:
            parsed = False
    if not parsed:
        with open_text(path) as handle:
            for _ in range(layout.header_line):
                handle.readline()
            data, line_numbers, unparsable = _slow_parse(handle, layout)
    notes: list[str] = []
    if data.shape[0] == 0 and not unparsable:
        raise InputError(f"{name} has a header but no data rows")

    data, skipped = _checked_rows(name, layout, data, line_numbers, unparsable, evidence, settings.skip_invalid,
                                  functools.partial(_data_line_numbers, path, layout))
    columns = {c: data[:, k] for k, c in enumerate(layout.used)}
    points = np.column_stack([columns[c] for c in layout.xyz])
    # (mypy: without an evidence column the layout has a constant evidence, checked in _find_layout.)
    m = columns[layout.evidence] if layout.evidence is not None else np.full(data.shape[0], float(evidence))  # type: ignore[arg-type]
    if skipped:
        notes.append(Note.warn(f"skipped {skipped} invalid row(s) of {name}"))
        logger.debug("skipped %d invalid rows of %s", skipped, name)
    if data.shape[0] == 0:
        raise InputError(f"{name} holds no valid rows ({skipped} skipped)")

    return _group_rows(name, layout, columns, points, m, settings.position_tolerance, settings.group_by, notes)


options_as_keywords(read_csv)


def _group_rows(
    name: str,
    layout: _Layout,
    columns: dict[int, NDArray[np.float64]],
    points: NDArray[np.float64],
    m: NDArray[np.float64],
    tolerance: Sequence[float],
    group_by: str,
    notes: list[str],
) -> RangeLog:
    n = points.shape[0]
    stamps = columns[layout.stamp] if layout.stamp is not None else None
    pose_rows = None
    if layout.pose is not None:
        px, py, pz, pyaw = layout.pose
        pose_rows = np.column_stack(
            [columns[px], columns[py], columns[pz] if pz is not None else np.zeros(n), columns[pyaw]]
        )

    if layout.position is not None:
        ids = columns[layout.position]
        if not np.all(ids == np.round(ids)):
            raise InputError(f"{name}: the 'position' column must hold whole numbers")
        _, first_index, labels = np.unique(ids, return_index=True, return_inverse=True)
        # Number positions in order of first appearance in the file.
        order = np.argsort(np.argsort(first_index))
        labels = order[labels.reshape(-1)]
    elif pose_rows is not None:
        # A scan is a run of rows with the same pose; scans are grouped by tolerance.
        changes = np.flatnonzero(np.any(np.diff(pose_rows, axis=0) != 0.0, axis=1)) + 1
        starts = np.concatenate([[0], changes])
        run_poses = [Pose(*map(float, pose_rows[s])) for s in starts]
        run_labels = assign_positions(run_poses, tolerance=tolerance, group_by=group_by)
        run_of_row = np.repeat(np.arange(len(starts)), np.diff(np.append(starts, n)))
        labels = run_labels[run_of_row]
    else:
        # A plain feature file is the features of one robot position, as the paper's sensor gives.
        labels = np.zeros(n, dtype=np.int64)

    order = np.argsort(labels, kind="stable")
    sorted_labels = labels[order]
    boundaries = np.flatnonzero(np.diff(sorted_labels)) + 1
    positions: list[Position] = []
    dropped = 0
    for rows in np.split(order, boundaries):
        if rows.size == 0:
            continue
        pts = points[rows]
        pose = None
        if pose_rows is not None:
            pose = Pose(*map(float, pose_rows[rows[0]]))
            own = pose_rows[rows]
            if np.any(own != pose_rows[rows[0]]):
                pts = to_reference_frame(pts, own, pose)
                keep = (np.abs(pts) > 0.0).any(axis=1)
                dropped += int((~keep).sum())
                pts, rows = pts[keep], rows[keep]
        positions.append(
            Position(
                index=len(positions),
                features=Features(pts, m[rows]),
                pose=pose,
                stamp=float(stamps[rows[0]]) if stamps is not None else None,
                source=name if layout.position is None else f"{name} position {int(columns[layout.position][rows[0]])}",
            )
        )
    if dropped:
        notes.append(f"{dropped} point(s) fell on their position's sensor origin and were dropped")
    return RangeLog(positions=positions, source=name, notes=notes)


def write_csv(
    features_or_log: Features | RangeLog | Position,
    path: str | os.PathLike[str],
    *,
    comments: Sequence[str] = (),
    decimals: tuple[int, int] | None = None,
) -> None:
    """Write features (or every position of a log) as CSV, atomically.

    A :class:`RangeLog` with several positions or with poses gets a ``position``
    column and, where poses are known, ``pose_x, pose_y, pose_z, pose_yaw`` columns,
    and a ``stamp`` column when every position has a time stamp; points stay in each
    position's sensor-centred frame, so reading the file back gives the same
    positions, poses, stamps and features. Values are written as the shortest decimal
    that reads back to the same number.

    Parameters
    ----------
    features_or_log
        What to write.
    path
        Output file, or ``"-"`` for standard output.
    comments
        Lines written first, each after ``# `` (readers skip them).
    decimals
        Fixed decimals of the coordinates and of the evidence (``(4, 3)`` for a compact
        synthetic log); the shortest round-trip text when None.
    """
    from occtool._files import atomic_write

    if isinstance(features_or_log, Features):
        positions = [Position(0, features_or_log)]
    elif isinstance(features_or_log, Position):
        positions = [features_or_log]
    else:
        positions = list(features_or_log.positions)
    with_position = len(positions) > 1
    with_pose = any(p.pose is not None for p in positions)
    # A column holds numbers only: stamps are written when every position has one.
    with_stamp = bool(positions) and all(p.stamp is not None for p in positions)
    header = ["x", "y", "z", "m"]
    if with_position:
        header.append("position")
    if with_pose:
        header.extend(POSE_COLUMNS)
    if with_stamp:
        header.append("stamp")
    blocks = []
    for k, position in enumerate(positions):
        f = position.features
        columns = [f.points, f.evidence[:, None]]
        if with_position:
            columns.append(np.full((len(f), 1), float(k)))
        if with_pose:
            pose = position.pose or Pose()
            columns.append(np.tile([pose.x, pose.y, pose.z, pose.yaw], (len(f), 1)))
        if with_stamp:
            columns.append(np.full((len(f), 1), float(position.stamp)))  # type: ignore[arg-type]  # with_stamp: every stamp is set
        blocks.append(np.hstack(columns))
    table = np.vstack(blocks) if blocks else np.empty((0, len(header)))
    # repr of a Python float is the shortest text that reads back to the same double.
    point = ["{!r}"] * 4 if decimals is None else [f"{{:.{decimals[0]}f}}"] * 3 + [f"{{:.{decimals[1]}f}}"]
    template = ",".join(
        point + (["{:.0f}"] if with_position else []) + (["{!r}"] * 4 if with_pose else [])
        + (["{!r}"] if with_stamp else [])
    )
    with atomic_write(path, "w") as handle:
        for line in comments:
            handle.write(f"# {line}\n")
        handle.write(",".join(header) + "\n")
        rows = table.tolist()
        for start in range(0, len(rows), 65536):
            chunk = rows[start : start + 65536]
            handle.write("\n".join(template.format(*row) for row in chunk) + "\n")



def _checked_rows(
    name: str, layout: _Layout, data: NDArray[np.float64], line_numbers: NDArray[np.int64] | None,
    unparsable: list[tuple[int, str]], evidence: float | None, skip_invalid: bool,
    lines_of: Callable[[], NDArray[np.int64]] | None = None,
) -> tuple[NDArray[np.float64], int]:
    """The rows of a chunk that are valid, and the count of those dropped (``skip_invalid``);
    an :class:`InputError` naming the first bad row otherwise (the checks of :func:`read_csv`)."""
    points = data[:, :3]  # x, y, z come first in layout.used
    m = data[:, 3] if layout.evidence is not None else np.full(data.shape[0], float(evidence))  # type: ignore[arg-type]
    not_finite = ~np.isfinite(data).all(axis=1)
    outside = ~not_finite & ((m < 0.0) | (m > 1.0))
    at_origin = ~not_finite & ~(np.abs(points) > 0.0).any(axis=1)
    too_far = ~not_finite & ~(np.abs(points) <= MAX_COORDINATE).all(axis=1)
    bad_reason = np.zeros(data.shape[0], dtype=np.int8)
    bad_reason[too_far] = 4
    bad_reason[at_origin] = 3
    bad_reason[outside] = 2
    bad_reason[not_finite] = 1
    bad = bad_reason > 0
    if (bad.any() or unparsable) and not skip_invalid:
        problems = list(unparsable[:1])
        if bad.any():
            first = int(np.argmax(bad))
            numbers = line_numbers if line_numbers is not None else lines_of()  # type: ignore[misc]
            reason = {
                1: "a value is NaN or infinite",
                2: f"evidence {float(m[first])!r} lies outside [0, 1]",
                3: "the point lies at the sensor origin (0, 0, 0) and has no direction",
                4: f"the point lies farther than {MAX_COORDINATE:g} m from the sensor: not range data",
            }[int(bad_reason[first])]
            problems.append((int(numbers[first]), reason))
        line, problem = min(problems)
        raise InputError(f"{name}, line {line}: {problem} (pass skip_invalid=True to drop bad rows)")
    if bad.any():
        data = data[~bad]
    return data, len(unparsable) + int(bad.sum())
