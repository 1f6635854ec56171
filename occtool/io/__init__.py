"""Reading range logs and writing features.

:func:`read_log` is the one entry point every command uses: it picks the reader by
the file's content and extension (or ``format=``) and returns a
:class:`~occtool.features.RangeLog` whose positions hold features in the
sensor-centred robot frame. :func:`iter_positions` yields the same positions one at
a time, for fitting a long log in bounded memory. Supported formats (docs/formats.md):

``csv``
    header ``x,y,z,m`` (+ optional ``position`` / ``pose_*`` columns), ``.gz``/``.bz2`` too.
``mcap``
    ROS 2 ``sensor_msgs/msg/PointCloud2`` and ``LaserScan``, ``foxglove.PointCloud`` and
    ``foxglove.LaserScan`` (JSON or protobuf), and occtool's own JSON channel.
``carmen``
    CARMEN ``FLASER``/``RLASER``/``ROBOTLASER1`` logs (``.log``, ``.log.gz``).
``xyz``
    plain ``x y z`` point lines, as OctoMap's ``scan.dat`` (``.dat``, ``.xyz``, ``.bz2``/``.gz``).
``pcd``, ``ply``
    point-cloud files, ASCII or binary.
``rosbag``
    ROS 1 ``.bag`` and ROS 2 ``.db3`` bags (with their ``metadata.yaml``), through
    ``rosbags``: the same messages and ``--topic`` as MCAP.
``urg``
    BreezySLAM's raw Hokuyo URG logs (one line of 682 ranges and wheel ticks a scan, as
    the MINES ParisTech ``exp1.dat``): poses from wheel odometry.
``tum``, ``3dmatch``
    folders of depth PNGs with camera poses: TUM RGB-D (``depth.txt``) and 3DMatch /
    7-Scenes (``frame-NNNNNN.depth.png``), :mod:`occtool.io.depth_folders`.
``scans``
    a folder of 3D scans (``*.pcd``, ``*.ply``, KITTI ``*.bin``), or several point-cloud
    files given as a list, each file a scan, with a KITTI-style poses file (``poses=``):
    :mod:`occtool.io.scans`.

The readers are imported only when used, and nothing here imports the model or
GeoJSON writers.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from occtool.errors import InputError
from occtool.io._detect import detect_format
from occtool.io.read_options import (
    DEFAULT_CONSTANT_EVIDENCE,
    FORMATS,
    ReadOptions,
    as_read_options,
    check_no_return_range,
    options_as_keywords,
)

if TYPE_CHECKING:
    from occtool.features import Features, Position, RangeLog
    from occtool.io.position_stream import PositionStream

__all__ = ["DEFAULT_CONSTANT_EVIDENCE", "FORMATS", "ReadOptions", "check_no_return_range", "describe_log",
           "detect_format", "iter_positions", "read_log", "write_csv", "write_mcap"]

def read_log(path: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], options: ReadOptions | None = None, **keywords: Any) -> RangeLog:
    """Read a range log into positions of features.

    Parameters
    ----------
    path
        The log file (or a folder of depth frames or scans), or several files: point clouds
        read as one scan sequence (format ``scans``, each file a scan), or range logs read as
        one log (their positions one after the other; their poses must share a frame).
    options
        How to read it: a :class:`~occtool.io.read_options.ReadOptions`, whose fields are
        the options (``format``, ``topics``, ``evidence``, ``no_return_range``, ...; see
        there for each one's meaning and default). Default: every default.
    **keywords
        The same options by name, replacing those of ``options``:
        ``read_log(path, no_return_range=5)``.

    Returns
    -------
    RangeLog
        Positions in recording order, with ``notes`` for the user.

    Raises
    ------
    InputError
        For unreadable or invalid data, or an invalid option, naming the file and what is wrong.
    TypeError
        For a keyword that is no reading option.

    Examples
    --------
    >>> log = read_log("fixtures/office/features.csv")  # doctest: +SKIP
    >>> features = log.single().features                # doctest: +SKIP
    """
    path, fmt, checked = _checked(path, options, keywords)
    if fmt == LOGS:
        return _read_logs(path, checked)
    from occtool.io._formats import read_errors, read_whole

    with read_errors(path):
        return read_whole(path, fmt, checked)


#: The format name of several range logs given at once (not point clouds): one log of
#: their positions, in the order given, their poses in one frame.
LOGS = "logs"


def _read_logs(paths: Any, options: ReadOptions) -> RangeLog:
    """Several logs as one: each read with ``options``, their positions one after the other
    (numbered anew), their notes named by file. Their poses must share a frame: a robot's
    runs in one building mapped by the same SLAM, or several robots' in a common frame."""
    from dataclasses import replace

    from occtool.features import Note, RangeLog, note_level

    positions: list[Position] = []
    notes: list[str] = []
    kinds: set[str | None] = set()
    for each in paths:
        log = read_log(each, options)
        for position in log.positions:
            positions.append(replace(position, index=len(positions)))
        notes += [Note(f"{Path(each).name}: {note}", note_level(note)) for note in log.notes]
        kinds.add(log.pose_kind)
    merged = RangeLog(positions, source=" + ".join(str(p) for p in paths), notes=notes)
    merged.pose_kind = kinds.pop() if len(kinds) == 1 else None
    return merged


def iter_positions(path: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], options: ReadOptions | None = None,
                   **keywords: Any) -> PositionStream:
    """The positions of a range log, read one at a time (bounded memory).

    ``options`` and ``keywords`` are those of :func:`read_log`, checked here. The result is
    an iterable of :class:`~occtool.features.Position`; each iteration reads the file from
    its start and yields the same positions, in the same order and with the same features,
    poses and stamps as ``read_log(path, options, **keywords).positions``; ``notes`` is
    complete after a full iteration. What is held at a time depends on the format: see
    :class:`~occtool.io.position_stream.PositionStream`.

    Raises
    ------
    InputError
        For invalid options or a file of no supported format, here; for invalid data,
        while iterating (naming the file and what is wrong).
    """
    from occtool.io.position_stream import PositionStream

    path, fmt, checked = _checked(path, options, keywords)
    if fmt == LOGS:
        raise InputError("several logs are read whole (read_log), not streamed: give one log at a time")
    return PositionStream(path, fmt, checked)


def _checked(path: str | os.PathLike[str] | Sequence[str | os.PathLike[str]], options: ReadOptions | None,
             keywords: dict[str, Any]) -> tuple[Any, str, ReadOptions]:
    """The log's path (a list of one file: the file), format and reading options, checked
    (see :func:`read_log`)."""
    paths = [path] if isinstance(path, (str, os.PathLike)) else list(path)
    for each in paths:
        if not Path(each).exists():
            raise FileNotFoundError(2, "No such file or directory", str(each))
    checked = as_read_options(options, **keywords)
    if len(paths) != 1:  # several point clouds: one scan sequence; several logs: one log
        from occtool.io.scans import FILE_FORMATS

        if checked.format is None:
            formats = [detect_format(each) for each in paths]
            clouds = [f in FILE_FORMATS or f == "scans" for f in formats]  # a KITTI .bin detects as scans
            if all(clouds) or checked.poses is not None:
                return paths, "scans", checked
            if any(clouds):
                raise InputError(f"{paths[clouds.index(True)]} is a point cloud and {paths[clouds.index(False)]} a "
                                 "range log: give several point clouds (one scan sequence) or several logs")
            return paths, LOGS, checked
        if checked.format == "scans":
            return paths, "scans", checked
        return paths, LOGS, checked
    path = paths[0]
    fmt = checked.format or detect_format(paths[0])
    if checked.poses is not None and fmt != "scans":
        if fmt not in ("pcd", "ply", "xyz"):
            raise InputError(f"poses= applies to scans (a folder of *.pcd, *.ply or *.bin files, or point-cloud "
                             f"files), and {paths[0]} is {fmt}")
        fmt = "scans"  # a point-cloud file with a poses file: a sequence of one scan
    if checked.topics and fmt not in ("mcap", "rosbag"):
        raise InputError(f"topics= applies to MCAP logs only, and {path} is {fmt}")
    return path, fmt, checked


options_as_keywords(read_log)
options_as_keywords(iter_positions)


def describe_log(path: str | os.PathLike[str], *, skip_invalid: bool = False,
                 no_return_range: float | None = None) -> Any:
    """A rich renderable describing a range log, for ``occtool info LOG``.

    For MCAP: the channels (topic, schema, encoding, message count) and whether
    occtool can read each, from the summary section (the file is not scanned). For
    other formats: the format, size and counts of features and positions; an invalid
    row is an :class:`InputError` naming it, as for every command that reads the log,
    unless ``skip_invalid`` (then the skipped rows are counted in a note);
    ``no_return_range`` is as for :func:`read_log`.
    """
    from rich.console import Group
    from rich.table import Table

    target = Path(path)
    if not target.exists():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    fmt = detect_format(target)
    # A folder (depth frames, scans): the bytes of the files in it, not of the folder's entry.
    size = sum(p.stat().st_size for p in target.iterdir() if p.is_file()) if target.is_dir() else target.stat().st_size
    header = Table.grid(padding=(0, 2))
    header.add_column(style="bold")
    header.add_column(overflow="fold")  # a long path or note wraps, it is not cut to "..."
    header.add_row("file", str(target))
    header.add_row("format", fmt)
    header.add_row("size", f"{size:,} bytes")
    if fmt == "mcap":
        from occtool.io.mcap import describe_channels

        rows, extra = describe_channels(target)
        table = Table(title="channels", show_lines=False)
        for column in ("topic", "schema", "encoding", "messages", "occtool reads it"):
            # Topic and schema are what --topic and the user need: folded onto the next line
            # in a narrow terminal, never cut to "...".
            table.add_column(column, justify="right" if column == "messages" else "left",
                             overflow="fold" if column in ("topic", "schema") else "ellipsis")
        for row in rows:
            table.add_row(row.topic, row.schema, row.encoding, "?" if row.messages is None else f"{row.messages:,}",
                          row.support)
        for key, value in extra.items():
            header.add_row(key, value)
        kinds = {row.kind for row in rows if not (row.kind == "transforms" and row.topic.endswith("tf_static"))}
        header.add_row("poses", _pose_words("tf" if "transforms" in kinds else
                                            "odometry" if "odometry" in kinds else None))
        return Group(header, table)
    stream = iter_positions(target, format=fmt, skip_invalid=skip_invalid, no_return_range=no_return_range)
    positions = features = 0
    has_poses = False
    for position in stream:  # one at a time: a long log is counted in bounded memory
        positions += 1
        features += len(position.features)
        has_poses = has_poses or position.pose is not None
    header.add_row("positions", f"{positions:,}")
    header.add_row("features", f"{features:,}")
    kind = None
    if has_poses:
        kind = "odometry" if fmt == "urg" or any(n.startswith("poses from odometry") for n in stream.notes) else \
            "tf" if any(n.startswith("poses from /tf") for n in stream.notes) else "log"
    header.add_row("poses", _pose_words(kind, fmt))
    for note in stream.notes:
        header.add_row("note", note)
    return header


def _pose_words(kind: str | None, fmt: str = "mcap") -> str:
    """What ``occtool info`` says of a log's poses, and what ``occtool map`` does with them."""
    if kind is None:
        return "none: occtool map registers the scans (occtool.register; --no-register maps one position)"
    if kind == "odometry":
        return "wheel odometry (drifts): occtool map registers the scans seeded by it (--no-register keeps it)"
    if kind == "tf":
        return "/tf: occtool map uses them (--register re-aligns the scans, seeded by them)"
    where = {"carmen": "each laser line's x y theta (corrected in a *-corrected log)",
             "csv": "the pose columns"}.get(fmt, "the log's own")
    return f"{where}: occtool map uses them (--register re-aligns the scans, seeded by them)"


def write_csv(features_or_log: Features | RangeLog | Position, path: str | os.PathLike[str]) -> None:
    """Write features or a whole log as CSV (see :func:`occtool.io.csv.write_csv`)."""
    from occtool.io.csv import write_csv as _write_csv

    _write_csv(features_or_log, path)


def write_mcap(log: RangeLog | Features, path: str | os.PathLike[str]) -> None:
    """Write a log as MCAP on occtool's JSON channel (see :func:`occtool.io.mcap.write_mcap`)."""
    from occtool.io.mcap import write_mcap as _write_mcap

    _write_mcap(log, path)
